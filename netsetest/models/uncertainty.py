"""The declared bound on the model mismatch e_k (docs/design.md §1, docs/plant.md).

Where a plant other than the T-S model generates the truth, the estimators' model becomes

    x_{k+1} = Ā_k x_k + B̄_k u_k + D̄_k w_k + e_k,    e_k ∈ 𝓔 = {G ζ : ζ ∈ 𝓩}                    (mismatch)

with G (NX, NX) and 𝓩 the unit box (``box``: |e_m| ≤ b_m, G = diag(b)) or the unit ball (``ellipsoid``:
eᵀE⁻¹e ≤ 1, G = chol(E)).  Every estimator and ``netsetest exact`` use 𝓔 (the SDP through one S-procedure
term per ball: a box gives two, an ellipsoid one); the collector checks every e_k of the truth against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from netsetest.models.sensor import NX

UncertaintyKind = Literal["box", "ellipsoid"]
HOLDS_RTOL = 1e-12  # the check of e_k against the bound, as for the noise and wind bounds


MVEE_TOL = 1e-7  # origin_mvee: Khachiyan's iteration stops at this relative step
MVEE_MAX_ITER = 10_000
DEFAULT_MARGIN = 0.1  # netsetest calibrate: the bound's half-widths and semi-axes enlarged by 10 % over what the training drives reached


@dataclass(frozen=True)
class ModelUncertainty:
    """e_k ∈ {G ζ : ζ in the unit box (``box``) or the unit ball (``ellipsoid``)}, G (NX, NX)."""

    kind: UncertaintyKind
    G: np.ndarray  # (NX, NX)

    @classmethod
    def box(cls, half_widths: tuple[float, float] | np.ndarray) -> ModelUncertainty:
        """|e_β| ≤ b_β, |e_r| ≤ b_r."""
        return cls("box", np.diag(np.asarray(half_widths, dtype=float)))

    @classmethod
    def ellipsoid(cls, E: np.ndarray) -> ModelUncertainty:
        """eᵀ E⁻¹ e ≤ 1 with E (NX, NX) symmetric positive definite."""
        E = np.asarray(E, dtype=float)
        return cls("ellipsoid", np.linalg.cholesky(0.5 * (E + E.T)))

    @property
    def E(self) -> np.ndarray:
        """The shape matrix: G Gᵀ for an ellipsoid; for a box, the diagonal of its half-widths squared."""
        return self.G @ self.G.T

    @property
    def balls(self) -> list[tuple[int, ...]]:
        """The ζ components that share one unit ball: each alone for a box, both for an ellipsoid."""
        return [(m,) for m in range(NX)] if self.kind == "box" else [tuple(range(NX))]

    def holds(self, e: np.ndarray) -> bool:
        """e ∈ 𝓔 (with the rounding tolerance of every other bound check)."""
        e = np.asarray(e, dtype=float)
        if not np.all(np.isfinite(e)):
            return False
        if self.kind == "box":
            return bool(np.all(np.abs(e) <= np.diag(self.G) * (1 + HOLDS_RTOL)))
        zeta = np.linalg.solve(self.G, e)  # E⁻¹ = G⁻ᵀG⁻¹: eᵀE⁻¹e = ‖G⁻¹e‖²
        return bool(zeta @ zeta <= 1 + HOLDS_RTOL)

    def ratio(self, e: np.ndarray) -> float:
        """e in the bound's own norm: max_m |e_m|/b_m for a box, √(eᵀE⁻¹e) for an ellipsoid (≤ 1: inside)."""
        zeta = np.linalg.solve(self.G, np.asarray(e, dtype=float))
        return float(np.abs(zeta).max() if self.kind == "box" else np.linalg.norm(zeta))

    def support(self, c: np.ndarray) -> float:
        """max_{e ∈ 𝓔} cᵀe (c (NX,)): ‖Gᵀc‖₁ for a box, ‖Gᵀc‖₂ for an ellipsoid."""
        g = self.G.T @ np.asarray(c, dtype=float)
        return float(np.abs(g).sum()) if self.kind == "box" else float(np.linalg.norm(g))

    def box_relation(self, centre: np.ndarray, half: np.ndarray) -> str:
        """The box centre ± half (NX,) against 𝓔: ``inside`` (all of it), ``disjoint`` (none of it, beyond the
        rounding tolerance) or ``overlap`` (some of it): a recorded e_k known only to a reference's accuracy."""
        c, h = np.asarray(centre, dtype=float), np.asarray(half, dtype=float)
        corners = [c + np.array(s) * h for s in ((-1, -1), (-1, 1), (1, -1), (1, 1))]
        if all(self.holds(e) for e in corners):
            return "inside"
        if self.kind == "box":
            b = np.diag(self.G) * (1 + HOLDS_RTOL)
            return "disjoint" if np.any(np.abs(c) - h > b) else "overlap"
        return "disjoint" if _nearest_in_box(np.linalg.inv(self.G), c - h, c + h) > 1 + HOLDS_RTOL else "overlap"

    @classmethod
    def covering_boxes(cls, kind: UncertaintyKind, centres: np.ndarray, halves: np.ndarray, margin: float) -> ModelUncertainty:
        """The bound of ``kind`` holding every box centres[k] ± halves[k] ((m, NX) each), enlarged by (1 + margin):
        a box |e_m| ≤ (1 + margin)·max_k (|c_k,m| + h_k,m), or the origin-centred minimum-area ellipse around every
        box's corners (its semi-axes enlarged): every e_k the boxes allow lies in it."""
        c, h = np.asarray(centres, dtype=float), np.asarray(halves, dtype=float)
        if kind == "box":
            return cls.box(np.maximum((np.abs(c) + h).max(axis=0), np.finfo(float).tiny) * (1 + margin))
        corners = np.vstack([c + np.array(s) * h for s in ((-1, -1), (-1, 1), (1, -1), (1, 1))])
        return cls.ellipsoid(origin_mvee(hull_2d(corners)) * (1 + margin) ** 2)

    def as_toml(self) -> str:
        """The ``[model_uncertainty]`` table that declares this bound."""
        r = lambda v: repr(float(v))  # noqa: E731  (every digit: a rounded bound could exclude a sample)
        if self.kind == "box":
            b = np.diag(self.G)
            return f"[model_uncertainty]\nbox = [{r(b[0])}, {r(b[1])}]\n"
        E = self.E
        return f"[model_uncertainty]\nellipsoid = [[{r(E[0, 0])}, {r(E[0, 1])}], [{r(E[0, 1])}, {r(E[1, 1])}]]\n"


def origin_mvee(points: np.ndarray) -> np.ndarray:
    """E of the minimum-volume ellipsoid {eᵀE⁻¹e ≤ 1} centred at 0 containing ``points`` (m, n).

    Khachiyan's algorithm on the symmetric set ±points (whose minimum ellipsoid is centred at 0), then
    E scaled up so that every point satisfies eᵀE⁻¹e ≤ 1 exactly (the iteration stops at a tolerance)."""
    pts = np.vstack([points, -points])
    m, n = pts.shape
    if np.linalg.matrix_rank(pts) < n:
        raise ValueError("the mismatch samples span fewer than two directions: no ellipsoid is bounded")
    u = np.full(m, 1.0 / m)
    for _ in range(MVEE_MAX_ITER):
        X = pts.T @ (u[:, None] * pts)  # Σ u_i p_i p_iᵀ
        g = np.einsum("ij,jk,ik->i", pts, np.linalg.inv(X), pts)  # p_iᵀ X⁻¹ p_i
        j = int(np.argmax(g))
        step = (g[j] - n) / (n * (g[j] - 1.0))
        if step < MVEE_TOL:
            break
        u *= 1.0 - step
        u[j] += step
    E = n * (pts.T @ (u[:, None] * pts))
    worst = float(np.max(np.einsum("ij,jk,ik->i", pts, np.linalg.inv(E), pts)))
    return E * max(worst, 1.0)


def _nearest_in_box(Ginv: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    """min ‖G⁻¹e‖ over the 2-D box lo ≤ e ≤ hi: 0 where it holds the origin, else the smallest over its four edges
    (a convex quadratic along each edge, its minimiser clamped to the edge)."""
    if np.all(lo <= 0) and np.all(hi >= 0):
        return 0.0
    best = np.inf
    for fixed in range(2):
        free = 1 - fixed
        for val in (lo[fixed], hi[fixed]):
            a, d = np.zeros(2), np.zeros(2)
            a[fixed], a[free], d[free] = val, lo[free], hi[free] - lo[free]
            p, q = Ginv @ a, Ginv @ d  # e(t) = a + t d, t ∈ [0, 1]: ‖p + t q‖²
            qq = float(q @ q)
            t = 0.0 if not qq else min(max(-float(p @ q) / qq, 0.0), 1.0)
            best = min(best, float(np.linalg.norm(p + t * q)))
    return best


def hull_2d(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of 2-D ``points`` (m, 2) (Andrew's monotone chain): an origin-centred minimum
    ellipse depends on them alone, and a long log's thousands of boxes have a few dozen."""
    pts = np.unique(np.asarray(points, dtype=float), axis=0)
    if len(pts) < 3:
        return pts

    def half(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and (out[-1][0] - out[-2][0]) * (p[1] - out[-2][1]) - (out[-1][1] - out[-2][1]) * (p[0] - out[-2][0]) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


__all__ = ["HOLDS_RTOL", "ModelUncertainty", "UncertaintyKind", "hull_2d", "origin_mvee"]
