"""What the exact rewriting (steps 1–4 of :mod:`netsetest.estimator.conic`) fixes for one node's layout, and
the few per-step quantities derived from it.

:class:`Reduction` is built once per pattern (layout and number of LMIs) and shared by the template, the
Clarabel solver and the closed form: which ball facts become ξ (step 1), which groups get their own cone and
which slots stay in the LMI (step 2), the static part of the scales (step 3), and the clique cones (step 4).
Per step it gives ξ's weights (:meth:`Reduction.aggregate`), the φ slots' and multipliers' scales
(:meth:`Reduction.slot_scales`), the multipliers over the original facts (:meth:`Reduction.fact_tau`), and
:func:`smallest_p` the P handed to certify() for an answer's (L, τ).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from netsetest.estimator.problem import EtaLayout, FactInfo
from netsetest.models.sensor import NA


@dataclass(frozen=True)
class Group:
    """Slots on which N(τ) is diagonal and owned by one ball fact (``fact`` is its compact index)."""

    fact: int
    slots: tuple[int, ...]  # () for ξ
    bound: float  # β of the ball fact (0 for ξ, whose bound B² changes per step)
    sqrt_bound: float  # √β (the cone's factor, computed once)


@dataclass(frozen=True)
class Aggregate:
    """Step 1 for one step: ξ stands for the aggregated facts, with bound B = Σ_k w_k."""

    w: np.ndarray  # (n_agg,) |ℓ_k| √β_k of the aggregated facts
    B: float
    use_xi: bool  # ξ exists and B > 0 (else its multiplier is pinned to 0)


@dataclass(frozen=True)
class StepScales:
    """What a step needs of the reduction before its solve, in one call (:meth:`Reduction.before`): ξ's weights (step 1)
    and the LMI slots' and multipliers' scales (step 3)."""

    agg: Aggregate
    sc: np.ndarray  # (len(lmi_slots),)
    kappa: np.ndarray  # (n_tau,)


class Reduction:
    """The static structure of one node's reduced problem (``n_lmi`` LMIs over the layout ``lay``).

    ``aggregate`` (step 1), ``cones`` (step 2) and ``decompose`` (step 4) can be switched off, e.g. to
    check that they change nothing but the speed; the scalings of step 3 are congruences, always on.
    """

    def __init__(self, lay: EtaLayout, n_lmi: int, aggregate: bool = True, cones: bool = True, decompose: bool = True) -> None:
        self.lay, self.n_lmi = lay, n_lmi
        facts = lay.facts
        self.sector = [m for m, f in enumerate(facts) if f.kind == "sector"]
        self.coupled: set[int] = set()
        for m in self.sector:
            self.coupled |= set(facts[m].slots) | set(facts[m].support)
        self.balls = [m for m, f in enumerate(facts) if f.kind == "ball"]
        self._aggregate(aggregate)
        # step 2: scheduled → cones for the uncoupled balls; the coupled slots keep one LMI
        self.socp = n_lmi == 1 and cones
        self.lmi_slots, self.groups, self.lmi_facts = self._split() if self.socp else self._whole()
        # step 3: √β for ball slots (static); φ slots get a per-step scale
        self.scale = np.ones(lay.dim)
        for m in self.kept:
            if facts[m].kind == "ball":
                self.scale[list(facts[m].slots)] = math.sqrt(facts[m].bound)
        self.lmi_pos = {s: k for k, s in enumerate(self.lmi_slots)}
        self.sector_lmi = [(c, self.kept[c]) for c in self.lmi_facts if facts[self.kept[c]].kind == "sector"]
        self.ball_compact = [c for c, m in enumerate(self.kept) if facts[m].kind == "ball"]
        # the clique cones pay off (and were tuned) with the φ⁺ slot; without it (a derived sector proved
        # that the own sensor does not saturate) the clique problem stalled (InsufficientProgress) on
        # paper SAIM steps where the one LMI solved in 8-13 iterations
        self.cliques = _cliques(facts, self.sector, set(lay.z), self.lmi_slots) if (decompose and self.socp and lay.phi_new is not None) else None

    def _aggregate(self, aggregate: bool) -> None:
        """Step 1: the single-slot balls off every sector fact with a zero Π₀ column become one slot ξ."""
        facts, lay = self.lay.facts, self.lay
        self.agg = (
            [m for m in self.balls if len(facts[m].slots) == 1 and facts[m].slots[0] in lay.pi0_zero and facts[m].slots[0] not in self.coupled]
            if aggregate
            else []
        )
        self.kept = [m for m in range(len(facts)) if m not in self.agg]
        self.xi = len(self.kept) if self.agg else None  # compact index of ξ's multiplier
        self.n_tau = len(self.kept) + (1 if self.agg else 0)
        self.agg_slots = np.array([facts[m].slots[0] for m in self.agg], dtype=int)
        self.agg_sqrtb = np.array([math.sqrt(facts[m].bound) for m in self.agg])
        for m in self.kept:
            if facts[m].kind == "ball":
                inside = [s in self.coupled for s in facts[m].slots]
                assert all(inside) or not any(inside), "a ball fact is either coupled or not"

    def _split(self) -> tuple[list[int], list[Group], list[int]]:
        """Scheduled: a cone per uncoupled ball; the LMI keeps η₁ and the coupled slots (none without a sector fact)."""
        facts = self.lay.facts
        lmi_slots = sorted(self.coupled | {0}) if self.sector else []
        groups = [
            Group(c, facts[m].slots, facts[m].bound, math.sqrt(facts[m].bound))
            for c, m in enumerate(self.kept)
            if facts[m].kind == "ball" and not (set(facts[m].slots) & self.coupled)
        ]
        grouped = {g.fact for g in groups}
        return lmi_slots, groups, [c for c in range(len(self.kept)) if c not in grouped]

    def _whole(self) -> tuple[list[int], list[Group], list[int]]:
        """No cones (``per-rule``, or switched off): every slot of a kept fact is in the LMI."""
        slots = {0}
        for m in self.kept:
            slots |= set(self.lay.facts[m].slots) | set(self.lay.facts[m].support)
        return sorted(slots), [], list(range(len(self.kept)))

    @property
    def closed_form(self) -> bool:
        """No LMI block (NSNIM, scheduled): the closed form over τ applies (conic/closed_form.py)."""
        return self.socp and not self.lmi_slots

    def cone_groups(self, use_xi: bool) -> list[Group]:
        """The groups with a rotated cone of their own: ξ last, when this step uses it."""
        if self.socp and use_xi:
            assert self.xi is not None  # use_xi only where balls were aggregated
            return [*self.groups, Group(self.xi, (), 0.0, 0.0)]
        return list(self.groups)

    def balls_compact(self, use_xi: bool) -> list[int]:
        """Compact multiplier indices of the ball facts (ξ included when used)."""
        if use_xi:
            assert self.xi is not None  # use_xi only where balls were aggregated
            return [*self.ball_compact, self.xi]
        return self.ball_compact

    # ------------------------------------------------------------------ per step: before the solve and after it

    def before(self, ell: np.ndarray, facts: tuple[np.ndarray, ...]) -> StepScales:
        """Everything the step needs of the reduction before its solve: ξ (:meth:`aggregate`) and the scales
        (:meth:`slot_scales`)."""
        sc, kappa = self.slot_scales(facts)
        return StepScales(self.aggregate(ell), sc, kappa)

    def after(
        self, P: np.ndarray, Ls: list[np.ndarray], tcs: list[np.ndarray], agg: Aggregate, pi0: np.ndarray, ell: np.ndarray, lam0: float | None, rho: float
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """Everything an answer needs of the reduction after the solve: τ over the original facts per LMI
        (:meth:`fact_tau`) and, in ``scheduled``, the smallest P for (L, τ) (:func:`smallest_p`, over this step's cone
        groups).  ``lam0``: the η₁ slot's multiplier (None: ρ less the balls' τ where the step gives that slot a cone, ℓ₀ ≠ 0
        in a pure SOCP; else 0)."""
        taus = [self.fact_tau(tc, agg) for tc in tcs]
        if not self.socp:
            return P, taus
        L = Ls[0]
        if lam0 is None:
            lam0 = rho - float(taus[0][self.balls].sum()) if self.closed_form and float(ell[0]) != 0.0 else 0.0
        return smallest_p(P, L, pi0 - L @ ell[None, :], self.cone_groups(agg.use_xi), tcs[0], agg.B, float(ell[0]), lam0), taus

    def aggregate(self, ell: np.ndarray) -> Aggregate:
        """ξ's weights and bound for the step's ℓ."""
        w = np.abs(ell[self.agg_slots]) * self.agg_sqrtb if self.agg else np.zeros(0)
        B = float(w.sum())
        return Aggregate(w, B, self.xi is not None and B > 0.0)

    def slot_scales(self, Q: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Step 3's per-step scales: each LMI slot's (√β of a ball slot; a φ slot: a bound of h|r| from its
        sector fact's row, |φ| ≤ h|r| ≤ Σ_k h|g_k| σ_k) and each multiplier's κ (its scaled Q's size)."""
        facts = self.lay.facts
        sc = self.scale[self.lmi_slots]
        kappa = np.ones(self.n_tau)
        for _, m in self.sector_lmi:
            p = facts[m].slots[0]
            row = np.abs(Q[m][p])
            bound = 2.0 * float(row @ self.scale) - 2.0 * row[p] * self.scale[p]
            if bound > 0.0:
                sc[self.lmi_pos[p]] = bound
        for c, m in self.sector_lmi:
            p = facts[m].slots[0]
            kap = abs(Q[m][p, p]) * sc[self.lmi_pos[p]] ** 2
            if kap > 0.0:
                kappa[c] = kap
        return sc, kappa

    def fact_tau(self, tc: np.ndarray, agg: Aggregate) -> np.ndarray:
        """τ over the original facts from the compact multipliers ``tc`` (n_tau,): ξ's split back over the
        aggregated facts in proportion to their weights (step 1)."""
        tau = np.zeros(len(self.lay.facts))
        tau[self.kept] = tc[: len(self.kept)]
        if agg.use_xi and self.xi is not None:
            tau[self.agg] = tc[self.xi] * agg.w / agg.B
        return tau


def smallest_p(P: np.ndarray, L: np.ndarray, pi: np.ndarray, groups: list[Group], tc: np.ndarray, B: float, ell0: float, lam0: float) -> np.ndarray:
    """The smallest P for (L, τ) in ``scheduled`` (step 2): P_c + Σ_k β_k Π_k Π_kᵀ / τ_k over the groups with
    τ_k = tc[k.fact] > 0 (ξ: column −L, bound B²), plus ℓ₀² L Lᵀ / λ₀ for the η₁ slot's cone when λ₀ > 0.
    ``L`` (NA, 1), ``pi`` = Π(L) (NA, d).  The groups' terms as one product C Cᵀ, C = the groups' columns of Π
    each scaled by √(β_k / τ_k) (numpy's A Aᵀ is exactly symmetric), the L Lᵀ terms with one factor."""
    cols: list[int] = []
    scale: list[float] = []
    ll = 0.0  # the factor of L Lᵀ
    for g in groups:
        t = float(tc[g.fact])
        if t <= 0.0:
            continue
        if g.slots:
            cols += g.slots
            scale += [math.sqrt(g.bound / t)] * len(g.slots)
        else:
            ll += B**2 / t
    if lam0 > 0.0:
        ll += ell0**2 / lam0
    if cols:
        C = pi[:, cols] * scale
        P = P + C @ C.T
    if ll > 0.0:
        P = P + ll * (L @ L.T)
    return P


# ---------------------------------------------------------------------- step 4: the clique cones


def _cliques(facts: list[FactInfo], sector: list[int], z: set[int], lmi_slots: list[int]) -> list[list[int]] | None:
    """Cliques (LMI-local indices, P's rows in each) that decompose the LMI exactly, or None.

    The decomposition is exact (Agler: a PSD matrix with chordal sparsity is a sum of PSD matrices on its
    maximal cliques) when every entry of the LMI lies in a clique and the cliques have the
    running-intersection property; both are checked here, else Clarabel decomposes on its own.
    """
    blocks = _clique_blocks(facts, sector, z)
    if not _covers(blocks, facts, sector, lmi_slots) or not _running_intersection(blocks):
        return None
    pos = {s: k for k, s in enumerate(lmi_slots)}
    return [list(range(NA)) + sorted(NA + pos[x] for x in b) for b in blocks]


def _clique_blocks(facts: list[FactInfo], sector: list[int], z: set[int]) -> list[set[int]]:
    """The sector facts of the node's own sensor share z_i: {η₁, z_i, their φ} is one block, the rest of
    their supports (w, v⁺ for φ⁺) another; every other sector fact is {η₁, φ_j, s_j}.  Maximal blocks only."""
    own = [m for m in sector if set(facts[m].support) & z]
    blocks: list[set[int]] = []
    if own:
        base = {0} | z | {facts[m].slots[0] for m in own}
        blocks.append(base)
        for m in own:
            rest = (set(facts[m].support) | {facts[m].slots[0]}) - base
            if rest:
                blocks.append(rest | {facts[m].slots[0]})
    blocks += [set(facts[m].support) | {facts[m].slots[0]} for m in sector if m not in own]
    return [b for b in blocks if not any(b < o for o in blocks)]


def _covers(blocks: list[set[int]], facts: list[FactInfo], sector: list[int], lmi_slots: list[int]) -> bool:
    """Every LMI entry inside a block: the slots, and the off-diagonal entries of the sector facts."""
    if set().union(*blocks) != set(lmi_slots):
        return False
    return all(any(f.slots[0] in b and u in b for b in blocks) for f in (facts[m] for m in sector) for u in f.support)


def _running_intersection(blocks: list[set[int]]) -> bool:
    """A maximum-weight spanning tree of the clique graph has weight Σ|C| − |∪C| (Kruskal)."""
    edges = sorted(((len(a & b), i, j) for i, a in enumerate(blocks) for j, b in enumerate(blocks) if i < j), reverse=True)
    parent = list(range(len(blocks)))

    def root(i: int) -> int:
        while parent[i] != i:
            i = parent[i]
        return i

    weight = 0
    for w, i, j in edges:
        ri, rj = root(i), root(j)
        if ri != rj:
            parent[ri] = rj
            weight += w
    return weight == sum(len(b) for b in blocks) - len(set().union(*blocks))


__all__ = ["Aggregate", "Group", "Reduction", "StepScales", "smallest_p"]
