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

    def as_toml(self) -> str:
        """The ``[model_uncertainty]`` table that declares this bound."""
        r = lambda v: repr(float(v))  # noqa: E731  (every digit: a rounded bound could exclude a sample)
        if self.kind == "box":
            b = np.diag(self.G)
            return f"[model_uncertainty]\nbox = [{r(b[0])}, {r(b[1])}]\n"
        E = self.E
        return f"[model_uncertainty]\nellipsoid = [[{r(E[0, 0])}, {r(E[0, 1])}], [{r(E[0, 1])}, {r(E[1, 1])}]]\n"


__all__ = ["HOLDS_RTOL", "ModelUncertainty", "UncertaintyKind"]
