"""Guaranteed set types a node may publish: ellipsoid, zonotope, interval box, and any of them cut by a region.

Each offers ``contains(point)`` (membership, with a relative tolerance for points on the boundary) and
``bounds()`` (per-coordinate interval hull, lower and upper arrays), so that the collector, records and
comparisons work for every type.  :class:`SlicedEllipsoid` (an ellipsoid cut by slabs) and
:class:`SumSet` (a zonotope plus a linear image of a sliced ellipsoid) are what the zonotopic
estimator needs to carry an ellipsoidal prior exactly (docs/estimators/zonotope_w_radius.md).
:class:`RegionSet` is a set estimator's own set cut by its region of x = (β, r) and a fault range
(estimator/region.py).
:func:`set_to_wire` / :func:`set_from_wire` give every type a checked dict form (with a ``type`` key) for
messages and records; a malformed one raises :class:`SetFormatError`, so a role can drop it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Literal, get_args

import clarabel
import numpy as np

from netsetest.polygon import REGION_NOT_NUMBERS, Polygon, region_problem

CutName = Literal["readings", "fault-size", "region", "health-pin", "health-fault"]
"""A cut of a step's sets (docs/estimator.md, "One step"; estimator/cuts.py for the SDP, estimator/region.py for the
set estimators): the names a published interval carries of the cuts that narrowed it (none: the solve's set alone)."""
CUT_NAMES: tuple[CutName, ...] = get_args(CutName)
IntervalCuts = tuple[tuple[CutName, ...], tuple[CutName, ...], tuple[CutName, ...]]
"""Per coordinate β, r, f: the cuts that narrowed the published interval, in the order they did."""
NO_CUTS: IntervalCuts = ((), (), ())

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

    def support(self, direction: np.ndarray) -> float:
        """max dᵀx over the box (+inf if unbounded along d); a zero d_i ignores an infinite side."""
        d = np.asarray(direction, dtype=float)
        side = np.where(d > 0, self.hi, self.lo)
        return float(np.sum(np.where(d != 0, d * side, 0.0)))

    def cut(self, slab: Slab) -> Box:
        """The interval hull of the box ∩ {lo ≤ aᵀx ≤ hi}: per coordinate j with a_j ≠ 0, a_j x_j lies in
        [lo − max Σ_{i≠j} a_i x_i, hi − min Σ_{i≠j} a_i x_i] (exact for one slab: the other coordinates
        range independently over the box).  The box itself if the two do not meet (an assumption broke)."""
        a = np.asarray(slab.a, dtype=float)
        if self.support(-a) > slab.hi or self.support(a) < slab.lo:
            return self
        lo, hi = self.lo.copy(), self.hi.copy()
        for j in np.flatnonzero(a):
            rest = a.copy()
            rest[j] = 0.0
            upper, lower = slab.hi + self.support(-rest), slab.lo - self.support(rest)  # bounds of a_j x_j
            if a[j] > 0:
                lo[j], hi[j] = max(lo[j], lower / a[j]), min(hi[j], upper / a[j])
            else:
                lo[j], hi[j] = max(lo[j], upper / a[j]), min(hi[j], lower / a[j])
        return Box(lo, hi)


@dataclass(frozen=True)
class Ellipsoid:
    """{x : (x − c)ᵀ P⁻¹ (x − c) ≤ ρ} (the estimator's published form, docs/design.md §2)."""

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
        lo, hi = self._hull
        return lo.copy(), hi.copy()

    @cached_property
    def _hull(self) -> tuple[np.ndarray, np.ndarray]:
        """The interval hull, made once per set (with slabs each side is an SOCP; the node, its region and the
        enclosing ellipsoid all ask for it)."""
        eye = np.eye(self.dim)
        return np.array([-self.support(-e) for e in eye]), np.array([self.support(e) for e in eye])

    def _ellipsoid_part(self, g: np.ndarray) -> tuple[float, np.ndarray]:
        """max gᵀe over the sliced ellipsoid, by an SOCP: variables e; cone rows as in analysis/exact."""
        P, A, b, cones = self._ellipsoid_socp
        sol = clarabel.DefaultSolver(P, -g, A, b, cones, _settings()).solve()
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            raise ValueError(f"support of a sliced ellipsoid: solver status {sol.status} (empty set?)")
        e = np.asarray(sol.x)
        return float(g @ e), e

    @cached_property
    def _ellipsoid_socp(self) -> tuple[Any, Any, np.ndarray, list]:
        """The SOCP of :meth:`_ellipsoid_part` but its objective: (P = 0, A, b, cones), the same for every
        direction, so made once per set (bounds() asks for six directions; Clarabel copies what it is given)."""
        from scipy import sparse  # here: the SDP nodes import this module and must start without scipy.sparse

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
        return sparse.csc_matrix((n, n)), sparse.csc_matrix(A), b, cones

    def contains(self, point: np.ndarray) -> bool:
        """Whether point = c + G b + M e with ‖b‖∞ ≤ 1 + tol and e in the sliced ellipsoid (an SOCP)."""
        from scipy import sparse  # here, see _ellipsoid_part

        z = self.zonotope
        n, m = z.generators.shape
        has_e = self.sliced is not None and self.M is not None
        ne = len(self.sliced.ellipsoid.center) if has_e else 0  # type: ignore[union-attr]  # has_e: sliced is set
        nv = m + ne
        slack = 1 + MEMBERSHIP_TOL
        eq_A = np.hstack([z.generators, self.M if has_e else np.zeros((n, 0))])  # type: ignore[list-item]  # has_e: M is set
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


@dataclass(frozen=True)
class RegionSet:
    """base ∩ (region × ℝ) ∩ {lo ≤ f ≤ hi} over [β, r, f]: a set estimator's own set, its region of x = (β, r)
    (a convex polygon, netsetest/polygon.py) and the fault range the own measurement proves over that region
    (estimator/region.py).  The truth must lie in all three."""

    base: Ellipsoid | Zonotope | Box | SumSet
    region: Polygon
    fault: tuple[float, float]
    cuts: IntervalCuts = NO_CUTS  # per coordinate, the cuts that narrowed the base set's interval (estimator/region.py)

    @cached_property
    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.base.bounds()
        low, high = self.region.bounds()
        lo[:2], hi[:2] = np.maximum(lo[:2], low), np.minimum(hi[:2], high)
        lo[2], hi[2] = max(lo[2], self.fault[0]), min(hi[2], self.fault[1])
        return lo, hi

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Each coordinate's interval of the base set intersected with the region's and the fault range (an
        outer bound of the intersection's interval hull)."""
        lo, hi = self._bounds
        return lo.copy(), hi.copy()

    def contains(self, point: np.ndarray) -> bool:
        slack = MEMBERSHIP_TOL * max(1.0, abs(float(point[2])))
        in_range = self.fault[0] - slack <= float(point[2]) <= self.fault[1] + slack
        return bool(in_range and self.region.contains(point[:2]) and self.base.contains(point))

    def support(self, direction: np.ndarray) -> float:
        """An upper bound of max dᵀx over the set: the least of the base set's and the region × fault range's."""
        d = np.asarray(direction, dtype=float)
        _, hi = self.region.interval(d[:2])
        return min(self.base.support(d), hi + float(d[2]) * (self.fault[1] if d[2] > 0 else self.fault[0]))


# ---------------------------------------------------------------- wire form

MAX_GENERATORS = 1024  # a published zonotope with more generators is refused (bounded message size)


def ellipsoid_bounds(xhat: np.ndarray, p_diag: np.ndarray, rho: float, last_range: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate bounds x̂ ∓ √(ρ P_jj) of {x : (x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ}, the last coordinate's within
    ``last_range`` (lo, hi) where the set is the ellipsoid intersected with that slab."""
    half = np.sqrt(rho * p_diag)
    lo, hi = xhat - half, xhat + half
    if last_range is not None:
        lo[-1], hi[-1] = max(lo[-1], last_range[0]), min(hi[-1], last_range[1])
    return lo, hi


class SetFormatError(ValueError):
    """A set in wire form that is malformed (wrong type, shape, non-finite, not SPD); drop the message."""


def _vec(d: dict, key: str, n: int | None = None) -> np.ndarray:
    v = np.asarray(d.get(key), dtype=float)
    if v.ndim != 1 or (n is not None and len(v) != n) or not np.all(np.isfinite(v)):
        raise SetFormatError(f"{key}: expected a finite vector" + (f" of length {n}" if n is not None else ""))
    return v


def _mat(d: dict, key: str, rows: int) -> np.ndarray:
    m = np.asarray(d.get(key), dtype=float)
    if m.ndim != 2 or m.shape[0] != rows or m.shape[1] > MAX_GENERATORS or not np.all(np.isfinite(m)):
        raise SetFormatError(f"{key}: expected a finite {rows}×m matrix with m ≤ {MAX_GENERATORS}")
    return m


def _generators(d: dict, dim: int) -> np.ndarray:
    """The (dim, m) generator matrix of a wire zonotope, whose "G" lists the m generators."""
    g = np.asarray(d.get("G"), dtype=float)
    if g.size == 0:
        return np.zeros((dim, 0))
    if g.ndim != 2 or g.shape[1] != dim or g.shape[0] > MAX_GENERATORS or not np.all(np.isfinite(g)):
        raise SetFormatError(f"G: expected at most {MAX_GENERATORS} finite generators of length {dim}")
    return g.T


def _spd(P: np.ndarray, key: str) -> np.ndarray:
    if not np.allclose(P, P.T) or np.linalg.eigvalsh((P + P.T) / 2).min() <= 0:
        raise SetFormatError(f"{key}: not symmetric positive definite")
    return P


def set_to_wire(s: Ellipsoid | Zonotope | Box | SumSet | RegionSet) -> dict:
    """A JSON/msgpack-ready dict with a ``type`` key; :func:`set_from_wire` inverts it exactly."""
    if isinstance(s, RegionSet):
        return {"type": "region", "set": set_to_wire(s.base), "region": s.region.flat(), "fault": [float(s.fault[0]), float(s.fault[1])]}
    if isinstance(s, Ellipsoid):
        return {"type": "ellipsoid", "center": s.center.tolist(), "P": s.P.tolist(), "rho": float(s.rho)}
    if isinstance(s, Zonotope):
        return {"type": "zonotope", "center": s.center.tolist(), "G": s.generators.T.tolist()}
    if isinstance(s, Box):
        return {"type": "box", "lo": s.lo.tolist(), "hi": s.hi.tolist()}
    out = {"type": "sum", "zonotope": set_to_wire(s.zonotope)}
    if s.sliced is not None and s.M is not None:
        out["M"] = s.M.tolist()
        out["ellipsoid"] = set_to_wire(s.sliced.ellipsoid)
        out["slabs"] = [[sl.a.tolist(), _inf_to_none(sl.lo), _inf_to_none(sl.hi)] for sl in s.sliced.slabs]
    return out


def _inf_to_none(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def set_from_wire(d: object, dim: int) -> Ellipsoid | Zonotope | Box | SumSet | RegionSet:
    """The set of :func:`set_to_wire`'s dict, checked (dimension ``dim``); SetFormatError if malformed."""
    if not isinstance(d, dict):
        raise SetFormatError("a set must be a mapping with a 'type'")
    kind = d.get("type")
    try:
        if kind == "ellipsoid":
            rho = float(d.get("rho"))  # type: ignore[arg-type]  # a missing rho raises TypeError, caught below as a malformed set
            if not (np.isfinite(rho) and rho > 0):
                raise SetFormatError("rho: expected a finite positive number")
            return Ellipsoid(_vec(d, "center", dim), _spd(_mat(d, "P", dim), "P"), rho)
        if kind == "zonotope":
            return Zonotope(_vec(d, "center", dim), _generators(d, dim))
        if kind == "box":
            lo, hi = _vec(d, "lo", dim), _vec(d, "hi", dim)
            if np.any(lo > hi):
                raise SetFormatError("box: lo > hi")
            return Box(lo, hi)
        if kind == "region":
            return _region_set(d, dim)
        if kind == "sum":
            return _sum_set(d, dim)
    except (TypeError, ValueError, IndexError, np.linalg.LinAlgError) as exc:
        if isinstance(exc, SetFormatError):
            raise
        raise SetFormatError(f"{kind}: {type(exc).__name__}: {exc}") from None
    raise SetFormatError(f"unknown set type {kind!r} (ellipsoid, zonotope, box, sum or region)")


def _sum_set(d: dict, dim: int) -> SumSet:
    """A ``sum`` set's parts, checked: a zonotope of the set's dimension, and where ``M`` is given an ellipsoid sliced
    by well-formed slabs (lo ≤ hi, a finite normal of the ellipsoid's dimension).  A missing or malformed part raises
    TypeError, ValueError or IndexError, which :func:`set_from_wire` reports as a malformed set."""
    z = set_from_wire(d.get("zonotope"), dim)
    if not isinstance(z, Zonotope) or z.generators.shape[0] != dim:
        raise SetFormatError("sum: 'zonotope' must be a zonotope of the set's dimension")
    if "M" not in d:
        return SumSet(z)
    el = set_from_wire(d.get("ellipsoid"), len(d.get("M")[0]))  # type: ignore[index]  # a missing M raises TypeError, caught by set_from_wire as a malformed set
    if not isinstance(el, Ellipsoid):
        raise SetFormatError("sum: 'ellipsoid' must be an ellipsoid")
    M = _mat(d, "M", dim)
    slabs = []
    for item in d.get("slabs") or []:
        a = np.asarray(item[0], dtype=float)
        s_lo = -np.inf if item[1] is None else float(item[1])
        s_hi = np.inf if item[2] is None else float(item[2])
        if a.shape != el.center.shape or not np.all(np.isfinite(a)) or np.isnan(s_lo) or np.isnan(s_hi) or s_lo > s_hi:
            raise SetFormatError("sum: a malformed slab")
        slabs.append(Slab(a, s_lo, s_hi))
    return SumSet(z, M, SlicedEllipsoid(el, tuple(slabs)))


def _region_set(d: dict, dim: int) -> RegionSet:
    """A ``region`` set's parts, checked: a base set that is not itself one, over [β, r, f] (dim 3), a region a node
    may publish (polygon.region_problem), and a finite fault range lo ≤ hi."""
    if dim != 3:
        raise SetFormatError(f"region: a region set is over [β, r, f] (dimension 3), not {dim}")
    base = set_from_wire(d.get("set"), dim)
    if isinstance(base, RegionSet):
        raise SetFormatError("region: its base set is a region set")
    coords = d.get("region")
    if not isinstance(coords, list) or not all(type(c) in (int, float) for c in coords):
        raise SetFormatError(f"{REGION_NOT_NUMBERS}: expected a list of numbers [β₁, r₁, β₂, r₂, …]")
    problem = region_problem(coords)
    if problem:
        raise SetFormatError(": ".join(problem))  # the reason first: decode drops the message under it
    fault = _vec(d, "fault", 2)
    if fault[0] > fault[1]:
        raise SetFormatError("region: fault range lo > hi")
    return RegionSet(base, Polygon.from_flat(coords), (float(fault[0]), float(fault[1])))
