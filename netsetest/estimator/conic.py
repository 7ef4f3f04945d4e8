"""Node i's SDP assembled for Clarabel directly: an exactly equivalent, smaller, well-scaled conic problem.

The LMI of :mod:`netsetest.estimator.sdp` (docs/design.md §2), written as M ⪰ 0 with

    M(P, L, τ) = [[P, Π(L)], [Π(L)ᵀ, N(τ)]],   Π(L) = Π₀ − L ℓᵀ,   N(τ) = ρ e₁e₁ᵀ − Σ_m τ_m Q_m,

τ ≥ 0, minimise trace(P), is rewritten with exact steps before it reaches the solver; the answer is
mapped back to (P, L, τ) of that LMI, which :func:`netsetest.estimator.certificate.certify` verifies as before.

1. **One scalar for the innovation noise** (``aggregate``).  A ball fact 1 − η_k²/β_k ≥ 0 on a single
   slot k that no sector fact touches and whose column of Π₀ is zero (every v_j, and the s_j of
   non-saturating neighbours) enters M only through the column −L ℓ_k and the entry τ_k in N₁₁.
   Eliminating the slot (Schur) leaves L Lᵀ ℓ_k² β_k / τ_k in the P block.  For a budget t = Σ τ_k,
   Σ_k ℓ_k² β_k / τ_k is smallest, (Σ_k |ℓ_k| √β_k)² / t, at τ_k = t |ℓ_k| √β_k / Σ|ℓ|√β
   (Cauchy–Schwarz).  So all of them together are exactly one slot ξ with column −L and the fact
   1 − ξ²/B² ≥ 0, B = Σ_k |ℓ_k| √β_k; ξ's multiplier is split back over the original facts that way.
2. **Second-order cones instead of a matrix inequality** (``cones``, variant ``scheduled``).  Where
   N(τ) is diagonal on a group of slots — a ball fact no sector fact touches, ξ, and without
   saturation the constant slot η₁ — the Schur complement splits M ⪰ 0 into
   P ⪰ P_c + Σ_k β_k Π_k Π_kᵀ / τ_k, with Π_k the columns of Π(L) of group k and P_c bounded by the
   LMI over the remaining, coupled slots.  Minimising trace(P) is then minimising trace(P_c) + Σ_k t_k
   with the rotated cones β_k ‖Π_k(L)‖² ≤ t_k τ_k.  Without saturation nothing is coupled and the SDP
   is a small SOCP; with it the sector facts keep one LMI over the slots they couple (η₁, z_i, s_j, w,
   v⁺, φ).  The P handed to certify() is the smallest one for the solver's (L, τ):
   P_c + Σ_k β_k Π_k Π_kᵀ / τ_k.  ``per-rule`` shares P between four LMIs, so it keeps them (with
   step 1 and the scaling of step 3).
3. **Scaling.**  Congruences of M that change nothing but the numbers the solver sees: the P rows by
   S⁻¹ with S Sᵀ = P_prev (the node's previous shape: P̃ = S⁻¹PS⁻ᵀ is near I, L̃ = S⁻¹L); each ball
   slot by √β_k (every ball fact then has −1 on its diagonal); each φ slot by a bound of h|r| from its
   sector fact (φ is of the size of h|r|, far smaller than the other slots); and each sector fact's
   multiplier by the size of its scaled Q (τ̂ = κτ).  Without them the SAIM problems need 30–40
   iterations and Clarabel stops up to 0.5 % above the optimum; with them 10–17 iterations and the
   optimum to about 1e-6.  Clarabel's own equilibration is then switched off (it made matters worse).
4. **Clique cones** (``decompose``, scheduled with saturation).  The remaining LMI is sparse: a sector
   fact couples its φ slot only with η₁ and the slots of its r.  It is split into one PSD cone per
   clique — {η₁, z_i, φ_i, φ⁺}, {φ⁺, w, v⁺}, {η₁, φ_j, s_j} per saturating neighbour, P's rows in
   each — whose matrices add up to the LMI (entries held by several cliques get free split
   variables).  Exact by Agler's theorem (chordal sparsity; coverage and the running-intersection
   property are checked when the node is set up).  Measured against Clarabel's own chordal
   decomposition of the same LMI: the same optimum (to 2e-6), about 10 % less time, and no
   per-step decomposition analysis.

Per step the values are filled into a sparsity pattern built once per node (per pattern key) with
numpy; the node keeps one Clarabel solver per pattern and updates its data in place
(``solver.update``), so Clarabel's set-up (KKT symbolic factorisation) is paid once, not per step.
No cvxpy, no scipy.sparse, no canonicalisation.  Where Clarabel refuses updates (``per-rule``, whose
LMIs Clarabel decomposes itself) a fresh solver is set up per step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Union

import clarabel
import numpy as np

from netsetest.estimator.problem import EtaLayout, Solution, StepData
from netsetest.estimator.sum_of_norms import SumOfNorms
from netsetest.models.sensor import NA

SQ2 = math.sqrt(2.0)
_P_ENTRIES = [(i, j) for j in range(NA) for i in range(j + 1)]  # variables P̃_ij, i ≤ j (svec order)


class CscMatrix:
    """The compressed-sparse-column matrix Clarabel reads (its attributes are scipy's), without scipy.

    Importing scipy.sparse would add ~0.1 s (and a few MB) to a node process's start-up for three arrays.
    Rows within each column must be sorted and unique (``has_canonical_format``).
    """

    format = "csc"
    has_canonical_format = True

    def __init__(self, data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, shape: tuple[int, int]) -> None:
        self.data, self.indices, self.indptr, self.shape = data, indices, indptr, shape
        self.nnz = len(data)

    @classmethod
    def empty(cls, m: int, n: int) -> CscMatrix:
        return cls(np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(n + 1, dtype=np.int64), (m, n))

    def toarray(self) -> np.ndarray:
        out = np.zeros(self.shape)
        for c in range(self.shape[1]):
            sl = slice(self.indptr[c], self.indptr[c + 1])
            out[self.indices[sl], c] = self.data[sl]
        return out


def _copy_settings(st: clarabel.DefaultSettings) -> clarabel.DefaultSettings:
    out = clarabel.DefaultSettings()
    for name in dir(st):
        if not name.startswith("_") and not callable(getattr(st, name)):
            try:
                setattr(out, name, getattr(st, name))
            except (AttributeError, TypeError):
                pass
    return out


def default_settings() -> clarabel.DefaultSettings:
    """Clarabel settings of the fast path; every answer is certified afterwards (certificate.certify).

    Tolerances stay at 1e-8: looser ones (1e-7, 1e-6) save one or two iterations but let the SAIM
    answers drift 3e-5 / 2e-4 above the optimum (2–7 % before the scaling of step 3).  Equilibration
    is off because the assembly scales the problem itself (on: +5 iterations and worse optima in
    SAIM); presolve is off so that Clarabel allows updating the data in place.
    """
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.max_iter = 100
    st.tol_gap_abs = 1e-8
    st.tol_gap_rel = 1e-8
    st.tol_feas = 1e-8
    st.equilibrate_enable = False
    st.presolve_enable = False
    return st


@dataclass(frozen=True)
class _Group:
    """Slots on which N(τ) is diagonal and owned by one ball fact (``fact`` is its compact index)."""

    fact: int
    slots: tuple[int, ...]  # () for ξ
    bound: float  # β of the ball fact (B² for ξ)


TemplateKey = tuple[bool, bool]
"""(ξ is used, the η₁ slot has its own cone): the two per-step choices that change the pattern."""


def _tri(i: int, j: int) -> tuple[int, float]:
    """svec index of entry (i, j) of a symmetric matrix and its factor (off-diagonals × √2)."""
    i, j = min(i, j), max(i, j)
    return j * (j + 1) // 2 + i, (1.0 if i == j else SQ2)


# ---------------------------------------------------------------------- the values of one step


@dataclass(frozen=True)
class _Values:
    """What a step's entries of A and b are computed from (d η slots, n the LMI slots)."""

    ell: np.ndarray  # (d,) ℓ
    facts: tuple[np.ndarray, ...]  # Q_m, each (d, d)
    pi0: tuple[np.ndarray, ...]  # Π₀ per LMI, each (NA, d)
    S: np.ndarray  # (NA, NA) with S Sᵀ = P_prev: the congruence of the P rows
    Sinv: np.ndarray | None  # (NA, NA) S⁻¹ (only with an LMI: its off-diagonal block)
    sc: np.ndarray  # (n,) scale of each LMI slot
    kappa: np.ndarray  # (n_tau,) scale of each multiplier
    B: float  # ξ's bound Σ_k |ℓ_k| √β_k
    rho: float  # ρ_i
    lmi_slots: list[int]  # the η slots of the LMI


# Entries of A, one block per group of entries in pattern order; ``values`` gives them for a step.


@dataclass(frozen=True)
class _Const:
    """Entries that do not change from step to step."""

    v: np.ndarray

    def values(self, s: _Values) -> np.ndarray:
        return self.v


@dataclass(frozen=True)
class _SocL:
    """2√β ℓ_s S[a, c] for (s, a, c): the L̃ columns of a ball group's rotated cone."""

    group: _Group

    def values(self, s: _Values) -> np.ndarray:
        g = self.group
        return (2.0 * math.sqrt(g.bound) * s.ell[list(g.slots)][:, None, None] * s.S[None, :, :]).ravel()


@dataclass(frozen=True)
class _SocXi:
    """2 B S[a, c]: the L̃ columns of ξ's rotated cone."""

    def values(self, s: _Values) -> np.ndarray:
        return (2.0 * s.B * s.S).ravel()


@dataclass(frozen=True)
class _Soc0:
    """2 ℓ₀ S[a, c]: the L̃ columns of the η₁ slot's cone."""

    def values(self, s: _Values) -> np.ndarray:
        return (2.0 * float(s.ell[0]) * s.S).ravel()


@dataclass(frozen=True)
class _LmiL:
    """−L̃ ℓᵀ D in the LMI's off-diagonal block (``f`` the svec factors)."""

    f: np.ndarray

    def values(self, s: _Values) -> np.ndarray:
        return self.f * np.repeat(s.sc * s.ell[s.lmi_slots], NA)


@dataclass(frozen=True)
class _LmiXi:
    """ξ's column −B L̃ in the LMI (``per-rule``)."""

    f: np.ndarray

    def values(self, s: _Values) -> np.ndarray:
        return self.f * s.B


@dataclass(frozen=True)
class _LmiTau:
    """τ̂_c Q̂_m: the structural entries (gi, gj) of fact m, at LMI positions (li, lj)."""

    m: int
    gi: np.ndarray
    gj: np.ndarray
    li: np.ndarray
    lj: np.ndarray
    f: np.ndarray
    c: int

    def values(self, s: _Values) -> np.ndarray:
        return self.f * s.facts[self.m][self.gi, self.gj] * s.sc[self.li] * s.sc[self.lj] / s.kappa[self.c]


_ABlock = Union[_Const, _SocL, _SocXi, _Soc0, _LmiL, _LmiXi, _LmiTau]  # a runtime alias

# Rows of b that change per step (the others stay at b_const); ``fill`` writes them for a step.


@dataclass(frozen=True)
class _Rho:
    rows: list[int]
    sign: float = 1.0

    def fill(self, b: np.ndarray, s: _Values) -> None:
        b[self.rows] = s.rho if self.sign > 0 else -s.rho


@dataclass(frozen=True)
class _SocPi0:
    """2√β Π₀[a, s] for (s, a): the constant part of a ball group's rotated cone."""

    rows: list[int]
    group: _Group

    def fill(self, b: np.ndarray, s: _Values) -> None:
        g = self.group
        b[self.rows] = (2.0 * math.sqrt(g.bound) * s.pi0[0][:, list(g.slots)].T).ravel()


@dataclass(frozen=True)
class _LmiPi0:
    """S⁻¹ Π₀ D of LMI r in its off-diagonal block (``f`` the svec factors)."""

    rows: list[int]
    r: int
    f: np.ndarray

    def fill(self, b: np.ndarray, s: _Values) -> None:
        assert s.Sinv is not None  # an LMI block exists only with an LMI
        b[self.rows] = self.f * ((s.Sinv @ s.pi0[self.r][:, s.lmi_slots]) * s.sc).T.ravel()


_BBlock = Union[_Rho, _SocPi0, _LmiPi0]  # a runtime alias


# ---------------------------------------------------------------------- the pattern of a template key


@dataclass(frozen=True)
class _Variables:
    """Column indices of the conic variables: P̃ (svec), per LMI L̃ and τ̂, the cone epigraphs t."""

    nv: int
    iP: list[int]
    iL: list[list[int]]
    iT: list[list[int]]
    iTt: list[int]
    groups: list[_Group]


class _Builder:
    """Collects a template's A entries (rows × columns, one value block each), rows of b and cones."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.a_blocks: list[_ABlock] = []
        self.b_blocks: list[_BBlock] = []
        self.cones: list = []
        self.n_rows = 0
        self.n_split = 0  # free variables of entries shared by several cliques (after all others)

    def put(self, block: _ABlock, r: list[int] | np.ndarray, c: list[int] | np.ndarray) -> None:
        self.rows.append(np.asarray(r, dtype=int))
        self.cols.append(np.asarray(c, dtype=int))
        self.a_blocks.append(block)

    def newrows(self, k: int) -> list[int]:
        start = self.n_rows
        self.n_rows += k
        return list(range(start, start + k))


@dataclass(frozen=True)
class _Template:
    """The sparsity pattern and variable map of one template key; values are filled per step."""

    key: TemplateKey
    var: _Variables
    nv: int  # variables, split variables included
    n_rows: int
    cones: list
    a_blocks: list[_ABlock]  # in entry order
    b_blocks: list[_BBlock]
    order: np.ndarray  # csc order of the entries: data = values[order]
    indices: np.ndarray
    indptr: np.ndarray
    lmi_rows: list[int]  # first row of each LMI block (each clique cone)
    lmi_n: int  # size of the (undecomposed) LMI
    decomposed: bool

    @property
    def iP(self) -> list[int]:
        return self.var.iP

    @property
    def iL(self) -> list[list[int]]:
        return self.var.iL

    @property
    def iT(self) -> list[list[int]]:
        return self.var.iT

    @property
    def iTt(self) -> list[int]:
        return self.var.iTt

    @property
    def groups(self) -> list[_Group]:
        return self.var.groups


@dataclass(frozen=True)
class ConicData:
    """Clarabel's problem of one step: minimise ½xᵀPx + qᵀx subject to b − A x ∈ cones (P = 0)."""

    P: CscMatrix  # (nv, nv), empty: the objective is linear
    q: np.ndarray  # (nv,)
    A: CscMatrix  # (n_rows, nv)
    b: np.ndarray  # (n_rows,)
    cones: list
    key: TemplateKey  # which template (and which kept solver) this is


@dataclass(frozen=True)
class InverseData:
    """What maps a conic point x back to (P, L_ℓ, τ_ℓ) of the LMI (cvxpy's ``inverse_data``)."""

    tpl: _Template
    S: np.ndarray  # (NA, NA) the congruence of the P rows
    sc: np.ndarray  # (n,) scale of each LMI slot
    kappa: np.ndarray  # (n_tau,) scale of each multiplier
    B: float  # ξ's bound
    agg_w: np.ndarray  # (n_agg,) |ℓ_k| √β_k of the aggregated facts
    pi0: np.ndarray  # (NA, d) Π₀ of the first LMI
    ell: np.ndarray  # (d,) ℓ
    rho: float

    @property
    def use_xi(self) -> bool:
        return self.tpl.key[0]

    @property
    def slot0_cone(self) -> bool:
        return self.tpl.key[1]


class ConicSolver:
    """Assembles and solves the reduced conic problem of one node; structure fixed by the topology.

    As cvxpy's Clarabel interface: :meth:`apply` turns a step's data into Clarabel's (:class:`ConicData`)
    plus what maps the answer back (:class:`InverseData`), :meth:`solve_via_data` runs the kept solver
    of the template, :meth:`invert` returns the :class:`~netsetest.estimator.problem.Solution`;
    :meth:`solve` does the three.  A template (the pattern of A, b and the cones) is built once per
    :data:`TemplateKey` by one ``_put_*`` method per cone group.

    ``aggregate`` (step 1), ``cones`` (step 2) and ``decompose`` (step 4) can be switched off, e.g. to
    check that they change nothing but the speed; the scalings of step 3 are congruences, always on.
    """

    def __init__(
        self,
        lay: EtaLayout,
        n_lmi: int,
        settings: clarabel.DefaultSettings | None = None,
        aggregate: bool = True,
        cones: bool = True,
        decompose: bool = True,
        closed_form: bool = True,
    ) -> None:
        self.lay, self.n_lmi = lay, n_lmi
        self._solvers: dict[TemplateKey, clarabel.DefaultSolver] = {}
        # the readings' update (ν slots) has a non-zero gain every step, close to the last one: Newton
        # starts there (2–3 iterations instead of 6–8); everywhere else it starts as it always did
        self._warm_start = bool(lay.nu)
        self._last_L: np.ndarray | None = None
        self.settings = settings or default_settings()
        facts = lay.facts
        self.sector = [m for m, f in enumerate(facts) if f.kind == "sector"]
        coupled: set[int] = set()
        for m in self.sector:
            coupled |= set(facts[m].slots) | set(facts[m].support)
        self.coupled = coupled
        self.balls = [m for m, f in enumerate(facts) if f.kind == "ball"]
        # step 1: single-slot balls off every sector fact with a zero Π₀ column → one slot ξ
        self.agg = (
            [m for m in self.balls if len(facts[m].slots) == 1 and facts[m].slots[0] in lay.pi0_zero and facts[m].slots[0] not in coupled]
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
                inside = [s in coupled for s in facts[m].slots]
                assert all(inside) or not any(inside), "a ball fact is either coupled or not"
        # step 2: scheduled → cones for the uncoupled balls; the coupled slots keep one LMI
        self.socp = n_lmi == 1 and cones
        if self.socp:
            self.lmi_slots = sorted(coupled | {0}) if self.sector else []
            self.groups = [
                _Group(c, facts[m].slots, facts[m].bound)
                for c, m in enumerate(self.kept)
                if facts[m].kind == "ball" and not (set(facts[m].slots) & coupled)
            ]
            grouped = {g.fact for g in self.groups}
            self.lmi_facts = [c for c in range(len(self.kept)) if c not in grouped]
        else:
            slots = {0}
            for m in self.kept:
                slots |= set(facts[m].slots) | set(facts[m].support)
            self.lmi_slots = sorted(slots)
            self.groups = []
            self.lmi_facts = list(range(len(self.kept)))
        # step 3: √β for ball slots (static); φ slots get a per-step scale
        self.scale = np.ones(lay.dim)
        for m in self.kept:
            if facts[m].kind == "ball":
                for s in facts[m].slots:
                    self.scale[s] = math.sqrt(facts[m].bound)
        self.lmi_pos = {s: k for k, s in enumerate(self.lmi_slots)}
        self.sector_lmi = [(c, self.kept[c]) for c in self.lmi_facts if facts[self.kept[c]].kind == "sector"]
        self.ball_compact = [c for c, m in enumerate(self.kept) if facts[m].kind == "ball"]
        # the clique cones pay off (and were tuned) with the φ⁺ slot; without it (a derived sector proved
        # that the own sensor does not saturate) the clique problem stalled (InsufficientProgress) on
        # paper SAIM steps where the one LMI solved in 8-13 iterations
        self.cliques = self._cliques() if (decompose and self.socp and lay.phi_new is not None) else None
        self._templates: dict[TemplateKey, _Template] = {}
        self.last_iterations = 0
        # no LMI block (NSNIM, scheduled): closed form over τ, Newton over L (estimator/sum_of_norms.py)
        self.newton = closed_form and self.socp and not self.lmi_slots
        if self.newton:
            self._cols = np.array([s for g in self.groups for s in g.slots], dtype=int)
            self._col_sqrtb = np.array([math.sqrt(g.bound) for g in self.groups for _ in g.slots])
            self._onehot = np.zeros((len(self._cols), len(self.groups)))
            self._onehot[np.arange(len(self._cols)), [k for k, g in enumerate(self.groups) for _ in g.slots]] = 1.0

    @property
    def settings(self) -> clarabel.DefaultSettings:
        return self._settings

    @settings.setter
    def settings(self, st: clarabel.DefaultSettings) -> None:
        self._settings = st
        # the clique problems (saturation): the cliques are ours, and iterative refinement of the KKT
        # solves bought nothing there (same widths to 1e-7, no fallback in 1440 SAIM node-steps with
        # paper and worst-case signals) for 12-15 % of the time; the SOCP keeps it (one fallback without)
        self.settings_decomposed = _copy_settings(st)
        self.settings_decomposed.chordal_decomposition_enable = False
        self.settings_decomposed.iterative_refinement_enable = False
        self._solvers.clear()

    def _cliques(self) -> list[list[int]] | None:
        """Cliques (LMI-local indices, P's rows in each) that decompose the LMI exactly, or None.

        The sector facts of the node's own sensor share z_i: {η₁, z_i, their φ} is one block, the rest
        of their supports (w, v⁺ for φ⁺) another; every other sector fact is {η₁, φ_j, s_j}.  The
        decomposition is exact (Agler: a PSD matrix with chordal sparsity is a sum of PSD matrices
        on its maximal cliques) when every entry of the LMI lies in a clique and the cliques have the
        running-intersection property; both are checked here, else Clarabel decomposes on its own.
        """
        facts, z = self.lay.facts, set(self.lay.z)
        own = [m for m in self.sector if set(facts[m].support) & z]
        blocks: list[set[int]] = []
        if own:
            base = {0} | z | {facts[m].slots[0] for m in own}
            blocks.append(base)
            for m in own:
                rest = (set(facts[m].support) | {facts[m].slots[0]}) - base
                if rest:
                    blocks.append(rest | {facts[m].slots[0]})
        for m in self.sector:
            if m not in own:
                blocks.append(set(facts[m].support) | {facts[m].slots[0]})
        blocks = [b for b in blocks if not any(b < o for o in blocks)]
        # every LMI entry inside a block: the slots, and the off-diagonal entries of the sector facts
        covered = set().union(*blocks)
        if covered != set(self.lmi_slots):
            return None
        for m in self.sector:
            p = facts[m].slots[0]
            for u in facts[m].support:
                if not any(p in b and u in b for b in blocks):
                    return None
        # running intersection: a maximum-weight spanning tree of the clique graph has weight Σ|C| − |∪C|
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
        if weight != sum(len(b) for b in blocks) - len(covered):
            return None
        return [list(range(NA)) + sorted(NA + self.lmi_pos[x] for x in b) for b in blocks]

    # ------------------------------------------------------------------ pattern (once per key)

    # ------------------------------------------------------------------ pattern (once per key)

    def _template(self, key: TemplateKey) -> _Template:
        """The pattern of one template key, built on first use: the cones in the order the rows hold them."""
        if key in self._templates:
            return self._templates[key]
        use_xi, slot0_cone = key
        var = self._variables(use_xi, slot0_cone)
        bld = _Builder()
        self._put_xi_pin(bld, var, use_xi)
        self._put_nonneg(bld, var, use_xi, slot0_cone)
        self._put_group_cones(bld, var)
        if slot0_cone:
            self._put_slot0_cone(bld, var, use_xi)
        lmi_rows, n = self._put_lmis(bld, var, use_xi) if self.lmi_slots else ([], 0)
        tpl = self._templates[key] = self._finish(bld, var, key, lmi_rows, n)
        return tpl

    def _variables(self, use_xi: bool, slot0_cone: bool) -> _Variables:
        """P̃ (svec, only with an LMI), per LMI L̃ (NA) and τ̂ (n_tau), then one epigraph t per cone."""
        nv = 0
        iP = list(range(nv, nv + len(_P_ENTRIES))) if self.lmi_slots else []
        nv += len(iP)
        iL, iT = [], []
        for _ in range(self.n_lmi):
            iL.append(list(range(nv, nv + NA)))
            nv += NA
            iT.append(list(range(nv, nv + self.n_tau)))
            nv += self.n_tau
        groups = list(self.groups)
        if self.socp and use_xi:
            groups.append(_Group(self.xi, (), 0.0))  # type: ignore[arg-type]  # xi is set whenever balls were aggregated (use_xi)
        n_t = len(groups) + (1 if slot0_cone else 0)
        iTt = list(range(nv, nv + n_t))
        nv += n_t
        return _Variables(nv, iP, iL, iT, iTt, groups)

    def _put_xi_pin(self, bld: _Builder, var: _Variables, use_xi: bool) -> None:
        """ξ's multiplier of a step without ξ is pinned to 0 (zero cone)."""
        if self.xi is None or use_xi:
            return
        rr = bld.newrows(self.n_lmi)
        bld.put(_Const(np.ones(self.n_lmi)), rr, [var.iT[r][self.xi] for r in range(self.n_lmi)])
        bld.cones.append(clarabel.ZeroConeT(self.n_lmi))

    def _put_nonneg(self, bld: _Builder, var: _Variables, use_xi: bool, slot0_cone: bool) -> None:
        """τ ≥ 0 and, for a pure SOCP whose η₁ column is zero, the budget Σ τ ≤ ρ (one nonnegative cone)."""
        iT = var.iT
        tcols = [iT[r][c] for r in range(self.n_lmi) for c in range(self.n_tau) if not (c == self.xi and not use_xi)]
        rr = bld.newrows(len(tcols))
        bld.put(_Const(-np.ones(len(tcols))), rr, tcols)
        n_nn = len(tcols)
        if self.socp and not self.lmi_slots and not slot0_cone:
            balls_c = self._balls_compact(use_xi)
            (r0,) = bld.newrows(1)
            bld.put(_Const(np.ones(len(balls_c))), [r0] * len(balls_c), [iT[0][c] for c in balls_c])
            bld.b_blocks.append(_Rho([r0]))
            n_nn += 1
        bld.cones.append(clarabel.NonnegativeConeT(n_nn))

    def _balls_compact(self, use_xi: bool) -> list[int]:
        """Compact multiplier indices of the ball facts (ξ included when used)."""
        return self.ball_compact + ([self.xi] if use_xi else [])  # type: ignore[list-item]  # xi is set whenever use_xi

    def _put_group_cones(self, bld: _Builder, var: _Variables) -> None:
        """Rotated cones β ‖Π_k(L)‖² ≤ t τ  ⇔  ‖(t − τ, 2√β Π_k)‖ ≤ t + τ, with L = S L̃, one per group."""
        for k, g in enumerate(var.groups):
            r0, r1 = bld.newrows(2)
            bld.put(_Const(np.array([-1.0, -1.0, -1.0, 1.0])), [r0, r0, r1, r1], [var.iTt[k], var.iT[0][g.fact], var.iTt[k], var.iT[0][g.fact]])
            ns = max(len(g.slots), 1)
            xr = bld.newrows(ns * NA)
            rr_ = np.repeat(np.asarray(xr), NA)  # (slot, a) rows × c columns of S
            cc_ = np.tile(np.asarray(var.iL[0]), ns * NA)
            bld.put(_SocL(g) if g.slots else _SocXi(), rr_, cc_)
            if g.slots:
                bld.b_blocks.append(_SocPi0(xr, g))
            bld.cones.append(clarabel.SecondOrderConeT(2 + ns * NA))

    def _put_slot0_cone(self, bld: _Builder, var: _Variables, use_xi: bool) -> None:
        """ℓ₀² ‖L‖² ≤ t₀ λ₀ with λ₀ = ρ − Σ τ over the balls (a pure SOCP with ℓ₀ ≠ 0)."""
        balls_c = self._balls_compact(use_xi)
        r0, r1 = bld.newrows(2)
        t0 = var.iTt[-1]
        bld.put(_Const(np.r_[-1.0, -1.0, np.ones(len(balls_c)), -np.ones(len(balls_c))]),
                [r0, r1] + [r0] * len(balls_c) + [r1] * len(balls_c), [t0, t0] + [var.iT[0][c] for c in balls_c] * 2)
        bld.b_blocks.append(_Rho([r0]))
        bld.b_blocks.append(_Rho([r1], -1.0))
        xr = bld.newrows(NA)
        bld.put(_Soc0(), np.repeat(np.asarray(xr), NA), np.tile(np.asarray(var.iL[0]), NA))
        bld.cones.append(clarabel.SecondOrderConeT(2 + NA))

    def _put_lmis(self, bld: _Builder, var: _Variables, use_xi: bool) -> tuple[list[int], int]:
        """LMIs [[P̃, Π̃_r], [Π̃_rᵀ, Ñ_r]] ⪰ 0 (upper triangle, column-wise, off-diagonals × √2), one PSD
        cone each or, decomposed, one per clique; returns the first row of each cone and the LMI size."""
        xi_in_lmi = (not self.socp) and use_xi
        n = NA + len(self.lmi_slots) + (1 if xi_in_lmi else 0)
        cliques = self.cliques if self.n_lmi == 1 else None
        lmi_rows: list[int] = []
        for r in range(self.n_lmi):
            vm = self._lmi_rows_whole(bld, n, lmi_rows) if cliques is None else self._lmi_rows_cliques(bld, var, n, cliques, lmi_rows)
            row_of = lambda x: int(vm[x])  # noqa: E731 - svec entry of the LMI → row of A
            self._put_lmi_p(bld, var, row_of)
            self._put_lmi_pi(bld, var, r, row_of, n, xi_in_lmi)
            self._put_lmi_n(bld, var, r, row_of, n, xi_in_lmi)
            if cliques is None:
                bld.cones.append(clarabel.PSDTriangleConeT(n))
        return lmi_rows, n

    @staticmethod
    def _lmi_rows_whole(bld: _Builder, n: int, lmi_rows: list[int]) -> np.ndarray:
        """One PSD cone: the LMI's svec entries on consecutive rows."""
        base = bld.newrows(n * (n + 1) // 2)[0]
        lmi_rows.append(base)
        return np.arange(base, base + n * (n + 1) // 2)

    def _lmi_rows_cliques(self, bld: _Builder, var: _Variables, n: int, cliques: list[list[int]], lmi_rows: list[int]) -> np.ndarray:
        """One PSD cone per clique; an entry held by several cliques gets free split variables (after all
        others) so that the cliques' matrices add up to the LMI."""
        vm = np.full(n * (n + 1) // 2, -1)
        owners: dict[int, list[int]] = {}
        for C in cliques:
            rr = bld.newrows(len(C) * (len(C) + 1) // 2)
            k = 0
            for jj in range(len(C)):
                for ii in range(jj + 1):
                    owners.setdefault(_tri(C[ii], C[jj])[0], []).append(rr[k])
                    k += 1
            lmi_rows.append(rr[0])
        diagonal = {_tri(i, i)[0] for i in range(n)}
        for ri, rws in owners.items():
            vm[ri] = rws[-1]  # the last clique holding an entry carries M's value minus the splits
            f = 1.0 if ri in diagonal else SQ2
            for other in rws[:-1]:
                col = var.nv + bld.n_split
                bld.put(_Const(np.array([-f, f])), [other, rws[-1]], [col, col])
                bld.n_split += 1
        for C in cliques:
            bld.cones.append(clarabel.PSDTriangleConeT(len(C)))
        return vm

    @staticmethod
    def _put_lmi_p(bld: _Builder, var: _Variables, row_of: Callable[[int], int]) -> None:
        """The P̃ block."""
        pr, pf = zip(*[_tri(i, j) for i, j in _P_ENTRIES])
        bld.put(_Const(-np.asarray(pf)), [row_of(x) for x in pr], var.iP)

    def _put_lmi_pi(self, bld: _Builder, var: _Variables, r: int, row_of: Callable[[int], int], n: int, xi_in_lmi: bool) -> None:
        """Π̃ = S⁻¹Π₀ D − L̃ ℓᵀ D: L̃_a at (a, slot kk), S⁻¹Π₀ D in b; ξ's column −B L̃ when it is in the LMI."""
        lr, lc, lf = [], [], []
        for kk in range(len(self.lmi_slots)):
            for a in range(NA):
                ri, f = _tri(a, NA + kk)
                lr.append(row_of(ri))
                lc.append(var.iL[r][a])
                lf.append(f)
        bld.put(_LmiL(np.asarray(lf)), lr, lc)
        bld.b_blocks.append(_LmiPi0(list(lr), r, np.asarray(lf)))
        if xi_in_lmi:
            xr_, xf_ = zip(*[_tri(a, n - 1) for a in range(NA)])
            bld.put(_LmiXi(np.asarray(xf_)), [row_of(x) for x in xr_], var.iL[r])

    def _put_lmi_n(self, bld: _Builder, var: _Variables, r: int, row_of: Callable[[int], int], n: int, xi_in_lmi: bool) -> None:
        """Ñ = ρ e₁e₁ᵀ − Σ τ̂ Q̂: the structural entries of each fact on the LMI slots; ρ in Ñ₁₁ (b), where
        the balls living in cones (and ξ) still cost their τ."""
        facts = self.lay.facts
        iT = var.iT
        for c in self.lmi_facts:
            m = self.kept[c]
            f_ = facts[m]
            if f_.kind == "ball":
                ent = [(0, 0)] + [(s, s) for s in f_.slots]
            else:
                p = f_.slots[0]
                ent = [(p, p)] + [(min(p, u), max(p, u)) for u in f_.support if u != p]
            gi = np.array([e[0] for e in ent])
            gj = np.array([e[1] for e in ent])
            li = np.array([self.lmi_pos[x] for x in gi])
            lj = np.array([self.lmi_pos[x] for x in gj])
            rr_, ff_ = zip(*[_tri(NA + x, NA + y) for x, y in zip(li, lj)])
            bld.put(_LmiTau(m, gi, gj, li, lj, np.asarray(ff_), c), [row_of(x) for x in rr_], [iT[r][c]] * len(ent))
        r00, _ = _tri(NA, NA)
        bld.b_blocks.append(_Rho([row_of(r00)]))
        extra = [g.fact for g in var.groups] if self.socp else []
        if xi_in_lmi:
            extra.append(self.xi)  # type: ignore[arg-type]  # xi is set whenever use_xi
        if extra:
            bld.put(_Const(np.ones(len(extra))), [row_of(r00)] * len(extra), [iT[r][c] for c in extra])
        if xi_in_lmi:
            rx, _ = _tri(n - 1, n - 1)
            bld.put(_Const(-np.ones(1)), [row_of(rx)], [iT[r][self.xi]])  # type: ignore[index]  # xi is set whenever use_xi

    def _finish(self, bld: _Builder, var: _Variables, key: TemplateKey, lmi_rows: list[int], n: int) -> _Template:
        """The csc order of the entries (the pattern is fixed: data = values[order]) and the template."""
        nv = var.nv + bld.n_split
        rows, cols = np.concatenate(bld.rows), np.concatenate(bld.cols)
        assert rows.min() >= 0 and all(min(b.rows) >= 0 for b in bld.b_blocks), "an LMI entry outside every clique"
        order = np.lexsort((rows, cols))
        assert len(set(zip(rows.tolist(), cols.tolist()))) == len(order), "duplicate entries in the pattern"
        return _Template(
            key=key, var=var, nv=nv, n_rows=bld.n_rows, cones=bld.cones, a_blocks=bld.a_blocks, b_blocks=bld.b_blocks,
            order=order, indices=rows[order].astype(np.int64), indptr=np.r_[0, np.cumsum(np.bincount(cols, minlength=nv))].astype(np.int64),
            lmi_rows=lmi_rows, lmi_n=n, decomposed=bool(self.lmi_slots) and self.cliques is not None and self.n_lmi == 1,
        )

    # ------------------------------------------------------------------ values (every step)

    def apply(self, data: StepData, rho: float) -> tuple[ConicData, InverseData]:
        """Clarabel's data for one step and what maps its answer back to (P, L, τ) (cvxpy's ``apply``)."""
        ell = data.ell
        agg_w = np.abs(ell[self.agg_slots]) * self.agg_sqrtb if self.agg else np.zeros(0)
        B = float(agg_w.sum())
        use_xi = self.xi is not None and B > 0.0
        has_lmi = bool(self.lmi_slots)
        slot0_cone = self.socp and not has_lmi and float(ell[0]) != 0.0
        tpl = self._template((use_xi, slot0_cone))
        # congruence of the P rows: P_prev = S Sᵀ (data.Mi = ρ^½ chol(P_prev))
        S = data.Mi / math.sqrt(rho)
        sc, kappa = self._slot_scales(data.facts, has_lmi)
        vals = _Values(ell, data.facts, data.pi0, S, np.linalg.inv(S) if has_lmi else None, sc, kappa, B, rho, self.lmi_slots)
        values = np.concatenate([blk.values(vals) for blk in tpl.a_blocks])
        b = np.zeros(tpl.n_rows)
        for blk in tpl.b_blocks:
            blk.fill(b, vals)
        A = CscMatrix(values[tpl.order], tpl.indices, tpl.indptr, (tpl.n_rows, tpl.nv))
        q = np.zeros(tpl.nv)
        if has_lmi:
            StS = S.T @ S  # trace(P_c) = trace(S P̃ Sᵀ)
            for k, (i, j) in enumerate(_P_ENTRIES):
                q[tpl.iP[k]] = StS[i, j] * (1.0 if i == j else 2.0)
        q[tpl.iTt] = 1.0
        conic = ConicData(CscMatrix.empty(tpl.nv, tpl.nv), q, A, b, tpl.cones, tpl.key)
        return conic, InverseData(tpl, S, sc, kappa, B, agg_w, data.pi0[0], ell, rho)

    def _slot_scales(self, Q: tuple[np.ndarray, ...], has_lmi: bool) -> tuple[np.ndarray, np.ndarray]:
        """Step 3's per-step scales: each LMI slot's (√β of a ball slot; a φ slot: a bound of h|r| from its
        sector fact's row, |φ| ≤ h|r| ≤ Σ_k h|g_k| σ_k) and each multiplier's κ (its scaled Q's size)."""
        facts = self.lay.facts
        sc = self.scale[self.lmi_slots] if has_lmi else np.zeros(0)
        kappa = np.ones(self.n_tau)
        if not self.sector_lmi:
            return sc, kappa
        sc = sc.copy()
        for _, m in self.sector_lmi:
            p = facts[m].slots[0]
            row = np.abs(Q[m][p])
            bound = 2.0 * float(row @ self.scale) - 2.0 * row[p] * self.scale[p]
            if bound > 0.0:
                sc[self.lmi_pos[p]] = bound
        for c, m in self.sector_lmi:
            p = self.lmi_pos[facts[m].slots[0]]
            kap = abs(Q[m][facts[m].slots[0], facts[m].slots[0]]) * sc[p] ** 2
            if kap > 0.0:
                kappa[c] = kap
        return sc, kappa

    # ------------------------------------------------------------------ solve and map back

    def solve(self, data: StepData, rho: float) -> Solution:
        """The step's answer: in closed form where there is no LMI block, else (or if that fails) from Clarabel."""
        if self.newton:
            sol = self._solve_sum_of_norms(data, rho)
            if sol is not None:
                return sol
        conic, inv = self.apply(data, rho)
        try:
            sol = self.solve_via_data(conic)
        except Exception as exc:  # a solver failure is a fallback step, not a crash
            self._solvers.pop(conic.key, None)
            return Solution(None, [], [], f"error: {exc}")
        status = str(sol.status)
        self.last_iterations = sol.iterations
        if status not in ("Solved", "AlmostSolved"):
            return Solution(None, [], [], status, sol.iterations)
        x = np.asarray(sol.x)
        if not np.all(np.isfinite(x)):
            return Solution(None, [], [], "non-finite", sol.iterations)
        return self.invert(x, inv, status, sol.iterations)

    def forget_warm_start(self) -> None:
        """Start the next closed-form solve afresh (after a warm-up on made-up data: a node that warmed up
        must answer bit for bit like one that did not)."""
        self._last_L = None

    def _solve_sum_of_norms(self, data: StepData, rho: float) -> Solution | None:
        """The pure SOCP by :class:`~netsetest.estimator.sum_of_norms.SumOfNorms`, mapped back as
        :meth:`invert` maps Clarabel's answer: τ_g = ρ a_g / Σ a, P = Σ_g β_g Π_gΠ_gᵀ/τ_g + (B²/τ_ξ + ℓ₀²/λ₀) L Lᵀ."""
        ell, pi0 = data.ell, data.pi0[0]
        agg_w = np.abs(ell[self.agg_slots]) * self.agg_sqrtb if self.agg else np.zeros(0)
        B = float(agg_w.sum())
        use_xi = self.xi is not None and B > 0.0
        ell0 = abs(float(ell[0]))
        problem = SumOfNorms(pi0[:, self._cols] * self._col_sqrtb, ell[self._cols] * self._col_sqrtb, self._onehot, (B if use_xi else 0.0) + ell0)
        found = problem.minimise(self._last_L) if self._last_L is not None else None
        if found is None:
            found = problem.minimise()
        if found is None:
            return None
        L, a, ln, iterations = found
        if self._warm_start and ln > 0.0:
            self._last_L = L.copy()
        a_xi, a0 = (B * ln if use_xi else 0.0), ell0 * ln
        total = float(a.sum()) + a_xi + a0
        tc = rho * a / total  # τ of each group, in the order of self.groups
        tau = np.zeros(len(self.lay.facts))
        for g, t in zip(self.groups, tc):
            tau[self.kept[g.fact]] = t
        Lc = L[:, None]
        pi = pi0 - Lc @ ell[None, :]
        P = np.zeros((NA, NA))
        for g, t in zip(self.groups, tc):
            cols = pi[:, list(g.slots)]
            P = P + g.bound * (cols @ cols.T) / t
        if a_xi > 0.0:  # (L = 0: ξ and the η₁ slot need no multiplier, their columns −L ℓ are zero)
            t_xi = rho * a_xi / total
            tau[self.agg] = t_xi * agg_w / B
            P = P + B**2 * (Lc @ Lc.T) / t_xi
        if a0 > 0.0:
            P = P + (ell0**2 / (rho * a0 / total)) * (Lc @ Lc.T)
        self.last_iterations = iterations
        return Solution(P, [Lc], [tau], "Solved (closed form)", iterations)

    def solve_via_data(self, conic: ConicData):  # clarabel's DefaultSolution
        """Solve with the node's solver for this template, its data updated in place where Clarabel
        allows it (no chordal decomposition of its own, no presolve, no equilibration): the set-up
        (KKT symbolic factorisation) is then paid once per node, not per step."""
        solver = self._solvers.get(conic.key)
        if solver is not None:
            try:
                solver.update(q=conic.q, A=conic.A.data, b=conic.b)
                return solver.solve()
            except Exception:  # refused update: set up a fresh solver below
                del self._solvers[conic.key]
        st = self.settings_decomposed if self._templates[conic.key].decomposed else self.settings
        solver = clarabel.DefaultSolver(conic.P, conic.q, conic.A, conic.b, conic.cones, st)
        if solver.is_data_update_allowed():
            self._solvers[conic.key] = solver
        return solver.solve()

    def unpack(self, x: np.ndarray, inv: InverseData) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """P_c (zero without an LMI), L_ℓ and τ_ℓ over the original facts, from a conic point x."""
        tpl, S = inv.tpl, inv.S
        Ls = [S @ x[i][:, None] for i in tpl.iL]
        taus = []
        for r in range(self.n_lmi):
            tc = np.maximum(x[tpl.iT[r]], 0.0) / inv.kappa
            tau = np.zeros(len(self.lay.facts))
            tau[self.kept] = tc[: len(self.kept)]
            if inv.use_xi:
                tau[self.agg] = tc[self.xi] * inv.agg_w / inv.B
            taus.append(tau)
        P = np.zeros((NA, NA))
        if self.lmi_slots:
            for k, (i, j) in enumerate(_P_ENTRIES):
                P[i, j] = P[j, i] = x[tpl.iP[k]]
            P = S @ P @ S.T
        return P, Ls, taus

    def invert(self, x: np.ndarray, inv: InverseData, status: str = "", iterations: int = 0) -> Solution:
        """(P, L_ℓ, τ_ℓ) of the LMI from the conic solution (cvxpy's ``invert``); in ``scheduled`` the
        smallest P for (L, τ)."""
        P, Ls, taus = self.unpack(x, inv)
        if self.socp:  # P = P_c + Σ β Π_k Π_kᵀ / τ_k
            L, tau, tpl = Ls[0], taus[0], inv.tpl
            tc = np.maximum(x[tpl.iT[0]], 0.0) / inv.kappa
            pi = inv.pi0 - L @ inv.ell[None, :]
            for g in tpl.groups:
                t = tc[g.fact]
                if t <= 0.0:
                    continue
                if g.slots:
                    cols = pi[:, list(g.slots)]
                    P = P + g.bound * (cols @ cols.T) / t
                else:  # ξ: column −L, bound B²
                    P = P + inv.B**2 * (L @ L.T) / t
            if inv.slot0_cone:
                lam0 = inv.rho - float(tau[self.balls].sum())
                if lam0 > 0.0:
                    P = P + (inv.ell[0] ** 2 / lam0) * (L @ L.T)
        return Solution(P, Ls, taus, status, iterations)


__all__ = ["ConicData", "ConicSolver", "CscMatrix", "InverseData", "default_settings"]
