"""Guaranteed set types a node may publish: ellipsoid, zonotope, interval box (issue 9).

Each offers ``contains(point)`` (membership, with a relative tolerance for points on the boundary) and
``bounds()`` (per-coordinate interval hull, lower and upper arrays), so that the collector, records and
comparisons work for every type.  :class:`SlicedEllipsoid` (an ellipsoid cut by slabs) and
:class:`SumSet` (a zonotope plus a linear image of a sliced ellipsoid) are what the zonotopic
estimator needs to carry an ellipsoidal prior exactly (docs/estimators/zonotope_w_radius.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import clarabel
import numpy as np
from scipy import sparse

MEMBERSHIP_TOL = 1e-9  # relative slack of contains(): a point on the boundary is inside


def _settings() -> clarabel.DefaultSettings:
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.presolve_enable = False
    st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = 1e-10
    return st


@dataclass(frozen=True)
class Box:
    """{x : lo ≤ x ≤ hi} (sides may be ±inf)."""

    lo: np.ndarray
    hi: np.ndarray

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.lo.copy(), self.hi.copy()

    def contains(self, point: np.ndarray) -> bool:
        slack = MEMBERSHIP_TOL * np.maximum(1.0, np.abs(point))
        return bool(np.all(point >= self.lo - slack) and np.all(point <= self.hi + slack))


@dataclass(frozen=True)
class Ellipsoid:
    """{x : (x − c)ᵀ P⁻¹ (x − c) ≤ ρ} (the estimator's published form, DESIGN.md §2)."""

    center: np.ndarray
    P: np.ndarray
    rho: float = 1.0

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        half = np.sqrt(self.rho * np.diag(self.P))
        return self.center - half, self.center + half

    def contains(self, point: np.ndarray) -> bool:
        e = point - self.center
        return bool(e @ np.linalg.solve(self.P, e) <= self.rho * (1 + MEMBERSHIP_TOL))

    def support(self, direction: np.ndarray) -> float:
        """max dᵀx over the ellipsoid: dᵀc + √(ρ dᵀPd)."""
        return float(direction @ self.center + np.sqrt(self.rho * direction @ self.P @ direction))


@dataclass(frozen=True)
class Zonotope:
    """⟨c, G⟩ = {c + G b : ‖b‖∞ ≤ 1}."""

    center: np.ndarray
    generators: np.ndarray  # (n, m)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Interval hull (001, Property 2): c ∓ Σ_j |G_ij|."""
        half = np.abs(self.generators).sum(axis=1)
        return self.center - half, self.center + half

    def support(self, direction: np.ndarray) -> float:
        return float(direction @ self.center + np.abs(direction @ self.generators).sum())

    def contains(self, point: np.ndarray) -> bool:
        return SumSet(self).contains(point)


@dataclass(frozen=True)
class Slab:
    """{x : lo ≤ aᵀx ≤ hi} (one side may be ±inf)."""

    a: np.ndarray
    lo: float
    hi: float


@dataclass(frozen=True)
class SlicedEllipsoid:
    """An ellipsoid intersected with slabs: the exact set of a prior updated by strip measurements."""

    ellipsoid: Ellipsoid
    slabs: tuple[Slab, ...] = ()


@dataclass(frozen=True)
class SumSet:
    """⟨c, G⟩ ⊕ M·S with S a :class:`SlicedEllipsoid` (absent: a plain zonotope).

    Support and membership are small second-order cone programs (Clarabel); with no slabs the
    support has the closed form ‖Gᵀd‖₁ + dᵀc + Mᵀd through the ellipsoid's support.
    """

    zonotope: Zonotope
    M: np.ndarray | None = None  # (n, dim S)
    sliced: SlicedEllipsoid | None = None

    @property
    def dim(self) -> int:
        return len(self.zonotope.center)

    def support(self, direction: np.ndarray) -> float:
        """max dᵀx over the set."""
        z = self.zonotope.support(direction)
        if self.sliced is None or self.M is None:
            return z
        g = self.M.T @ direction
        if not self.sliced.slabs:
            return z + self.sliced.ellipsoid.support(g)
        value, _ = self._ellipsoid_part(g)
        return z + value

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        eye = np.eye(self.dim)
        lo = np.array([-self.support(-e) for e in eye])
        hi = np.array([self.support(e) for e in eye])
        return lo, hi

    def _ellipsoid_part(self, g: np.ndarray) -> tuple[float, np.ndarray]:
        """max gᵀe over the sliced ellipsoid, by an SOCP: variables e; cone rows as in analysis/exact."""
        s = self.sliced
        assert s is not None
        el = s.ellipsoid
        n = len(el.center)
        li = np.linalg.inv(np.linalg.cholesky(el.P))
        rows, rhs = [], []
        for slab in s.slabs:
            if np.isfinite(slab.hi):
                rows.append(slab.a)
                rhs.append(slab.hi)
            if np.isfinite(slab.lo):
                rows.append(-slab.a)
                rhs.append(-slab.lo)
        A = np.vstack([np.array(rows).reshape(-1, n), np.zeros((1, n)), -li])
        b = np.r_[rhs, np.sqrt(el.rho), -li @ el.center]
        cones = [clarabel.NonnegativeConeT(len(rows)), clarabel.SecondOrderConeT(n + 1)]
        sol = clarabel.DefaultSolver(sparse.csc_matrix((n, n)), -g, sparse.csc_matrix(A), b, cones, _settings()).solve()
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            raise ValueError(f"support of a sliced ellipsoid: solver status {sol.status} (empty set?)")
        e = np.asarray(sol.x)
        return float(g @ e), e

    def contains(self, point: np.ndarray) -> bool:
        """Whether point = c + G b + M e with ‖b‖∞ ≤ 1 + tol and e in the sliced ellipsoid (an SOCP)."""
        z = self.zonotope
        n, m = z.generators.shape
        has_e = self.sliced is not None and self.M is not None
        ne = len(self.sliced.ellipsoid.center) if has_e else 0  # type: ignore[union-attr]
        nv = m + ne
        slack = 1 + MEMBERSHIP_TOL
        eq_A = np.hstack([z.generators, self.M if has_e else np.zeros((n, 0))])  # type: ignore[list-item]
        blocks_A = [eq_A, np.hstack([np.eye(m), np.zeros((m, ne))]), np.hstack([-np.eye(m), np.zeros((m, ne))])]
        blocks_b = [point - z.center, np.full(m, slack), np.full(m, slack)]
        cones = [clarabel.ZeroConeT(n)]
        n_lin = 2 * m
        if has_e:
            s = self.sliced
            assert s is not None
            for slab in s.slabs:
                for sign, bound in ((1.0, slab.hi), (-1.0, -slab.lo)):
                    if np.isfinite(bound):
                        blocks_A.append(np.r_[np.zeros(m), sign * slab.a][None, :])
                        blocks_b.append(np.array([bound + MEMBERSHIP_TOL * max(1.0, abs(bound))]))
                        n_lin += 1
            li = np.linalg.inv(np.linalg.cholesky(s.ellipsoid.P))
            blocks_A += [np.zeros((1, nv)), np.hstack([np.zeros((ne, m)), -li])]
            blocks_b += [np.array([np.sqrt(s.ellipsoid.rho * slack)]), -li @ s.ellipsoid.center]
        cones.append(clarabel.NonnegativeConeT(n_lin))
        if has_e:
            cones.append(clarabel.SecondOrderConeT(ne + 1))
        A = sparse.csc_matrix(np.vstack(blocks_A))
        sol = clarabel.DefaultSolver(sparse.csc_matrix((nv, nv)), np.zeros(nv), A, np.concatenate(blocks_b), cones, _settings()).solve()
        return str(sol.status) in ("Solved", "AlmostSolved")
