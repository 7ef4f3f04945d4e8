"""The data of node i's per-step SDP, shared by the estimator (:mod:`netsetest.estimator.sdp`) and its
backends (:mod:`netsetest.estimator.conic`, :mod:`netsetest.estimator.lmi_cvxpy`).

The estimator builds a :class:`StepData` per step (the LMI of docs/design.md §2 as plain arrays over the η
slots of an :class:`EtaLayout`), a backend turns it into a :class:`Solution` (P, L_ℓ, τ_ℓ of that
LMI), and the certificate (:mod:`netsetest.estimator.certificate`) checks the answer.  This module
imports neither side, so neither imports the other.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from netsetest.estimator.sector import Sector
from netsetest.models.sensor import NA, NX, Sensor
from netsetest.models.uncertainty import ModelUncertainty

PatternKey = tuple[frozenset[int], bool, bool]
"""Which η slots exist this step: (neighbours with a φ slot, φ⁺ exists, predict (False: step 0), the reference
sensors whose reading of this very step the update uses (docs/network.md; non-empty: no neighbour slots))."""


@dataclass(frozen=True)
class FactInfo:
    """Structure of one quadratic fact ηᵀQ_m η ≥ 0, in the order of :attr:`StepData.facts`.

    ``ball``: 1 − Σ_{k ∈ slots} η_k²/bound (Q[0,0] = 1, Q[k,k] = −1/bound, nothing else).
    ``sector``: φ (h gᵀη − φ) with φ = η[slots[0]]; ``support`` are the slots where g may be non-zero.
    """

    kind: Literal["ball", "sector"]
    slots: tuple[int, ...]
    bound: float = 1.0
    support: tuple[int, ...] = ()


class EtaLayout:
    """Slot indices of η for node i and its in-neighbours N_i (fixed by the topology)."""

    z: list[int]  # z_i, the own prior's unit-ball coordinates (NA slots, after the constant slot 0)
    s: dict[int, int]  # s_j of each neighbour j ≠ i (its set through C̄_j: the scalar C̄_j M_j z_j = c_j s_j)
    w: int | None  # the disturbance (None at step 0, as e, v⁺ and φ⁺)
    e: list[int]  # ζ of the model mismatch, one per column of G
    v: dict[int, int]  # v_j, the measurement noise of each j ∈ N_i (i included)
    v_new: int | None  # the own measurement noise of step k+1
    nu: dict[int, int]  # ν_j of each reading used
    phi: dict[int, int]  # φ_j of each saturating sensor
    phi_new: int | None  # φ⁺ of the own sensor
    dim: int

    def __init__(
        self,
        node_id: int,
        neighbours: dict[int, Sensor],
        own: Sensor,
        W: float = 1.0,
        predict: bool = True,
        uncertainty: ModelUncertainty | None = None,
    ) -> None:
        """``saturated`` of each sensor says whether it has a φ slot; ``predict`` False: the step-0 update
        (the prior updated by the own measurement through the self slot: no w, e, v⁺ or φ⁺); ``uncertainty``:
        the declared model mismatch e = G ζ (one ζ slot per column of G, after w; None: no e slots)."""
        self.node_id = node_id
        self.neigh = list(neighbours)  # j ∈ N_i in a fixed order (may include i)
        self._place(neighbours, own, predict, uncertainty is not None)
        self.facts = self._facts(neighbours, own, W, uncertainty)
        self.n_facts = len(self.facts)
        # slots whose column of Π₀ is zero in every rule: they enter e⁺ only through L ℓᵀη
        self.pi0_zero = set(self.s.values()) | set(self.v.values()) | set(self.phi.values())

    def _place(self, neighbours: dict[int, Sensor], own: Sensor, predict: bool, mismatch: bool) -> None:
        """η's slots in order: 1 (slot 0), z_i, s_j (j ≠ i), w, e, v_j, v⁺, φ_j, φ⁺."""
        slots = itertools.count(1)
        self.z = [next(slots) for _ in range(NA)]
        self.s = {j: next(slots) for j in self.neigh if j != self.node_id}
        self.w = next(slots) if predict else None
        self.e = [next(slots) for _ in range(NX)] if predict and mismatch else []
        self.v = {j: next(slots) for j in self.neigh}
        self.v_new = next(slots) if predict else None
        # no saturation ⇒ φ_j ≡ 0: no slot (docs/design.md §2)
        self.phi = {j: next(slots) for j, sens in neighbours.items() if sens.saturated}
        self.phi_new = next(slots) if own.saturated and predict else None
        self.dim = next(slots)

    def _facts(self, neighbours: dict[int, Sensor], own: Sensor, W: float, uncertainty: ModelUncertainty | None) -> list[FactInfo]:
        """One quadratic fact per constraint, in this order."""
        facts = [FactInfo("ball", tuple(self.z))]
        facts += [FactInfo("ball", (self.s[j],)) for j in self.s]
        if self.w is not None:
            facts.append(FactInfo("ball", (self.w,), W))
        if self.e:  # 1 − ‖ζ_ball‖² per ball of the mismatch bound (a box: one per component)
            facts += [FactInfo("ball", tuple(self.e[m] for m in ball)) for ball in uncertainty.balls]  # type: ignore[union-attr]  # self.e is non-empty only with an uncertainty
        facts += [FactInfo("ball", (self.v[j],), neighbours[j].R) for j in self.v]
        if self.v_new is not None:
            facts.append(FactInfo("ball", (self.v_new,), own.R))
        for j in self.neigh:
            if j in self.phi:
                r_slots = tuple(self.z) if j == self.node_id else (self.s[j],)
                facts.append(FactInfo("sector", (self.phi[j],), support=(0, *r_slots)))
        if self.phi_new is not None:
            assert self.w is not None and self.v_new is not None  # φ⁺ exists only in a predicting step
            facts.append(FactInfo("sector", (self.phi_new,), support=(0, *self.z, self.w, *self.e, self.v_new, self.phi_new)))
        return facts


@dataclass(frozen=True)
class OwnUpdate:
    """The own measurement of step k+1 as a predicting step uses it (what the fallback bound needs).

    ``sensor`` is the own sensor with this step's Dv (widened when a proven reading interval replaces
    the measurement), h1 and ``saturated`` (whether φ⁺ exists); ``y`` and ``gamma`` the ỹ⁺ and γ⁺ used
    (the reading interval's centre and 1 when it replaces the measurement).
    """

    T: np.ndarray  # (NA, NA) descriptor gain T of (16)
    G: np.ndarray  # (NA, 1) descriptor gain G of (16)
    sensor: Sensor
    y: float
    gamma: float


@dataclass(frozen=True)
class StepData:
    """One step's LMI as plain arrays, d = ``lay.dim`` (the η slots of ``lay``).

    e⁺ = Π(L) η with Π(L) = Π₀ − L ℓᵀ; the truth satisfies ηᵀ Q_m η ≥ 0 for every Q_m in ``facts``;
    x̂⁺ = ``x_pred`` + L · ``innov_sum``.  Arrays are not copied: treat them as read-only.
    """

    pi0: tuple[np.ndarray, ...]  # Π₀ per LMI, each (NA, d): one (scheduled, step 0) or N_RULES (per-rule)
    ell: np.ndarray  # (d,) ℓ with ℓᵀη = Σ_j a_ij y̌_j(η)
    facts: tuple[np.ndarray, ...]  # Q_m, each (d, d), in the order of ``lay.facts``
    x_pred: np.ndarray  # (NA,) the L-free part of x̂⁺
    innov_sum: float  # Σ_j a_ij y̌_j of the received innovations
    Mi: np.ndarray  # (NA, NA) ρ_i^½ M_i = ρ_i^½ chol(P_i) of the previous set (times D^½ when weighted)
    lay: EtaLayout
    key: PatternKey  # the pattern (layout and solver) of this step
    sector: Sector | None  # the own sensor's sector of this step (None: no saturation modelled)
    own: OwnUpdate | None = None  # None at step 0 (no prediction)


@dataclass(frozen=True)
class Solution:
    """A backend's answer in the terms of the LMI: P (NA, NA), and per rule L_ℓ (NA, 1) and τ_ℓ (one per
    fact); P None if the backend has no answer (``status`` says why)."""

    P: np.ndarray | None
    L: list[np.ndarray]
    tau: list[np.ndarray]
    status: str
    iterations: int = 0


class ProblemSolver(Protocol):
    """A backend of one pattern: solves the step's LMI (for the node's ρ_i) as well as it can."""

    def solve(self, data: StepData, rho: float) -> Solution: ...


__all__ = ["EtaLayout", "FactInfo", "OwnUpdate", "PatternKey", "ProblemSolver", "Solution", "StepData"]
