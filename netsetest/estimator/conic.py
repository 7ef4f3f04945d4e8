"""Node i's SDP assembled for Clarabel directly: an exactly equivalent, smaller, well-scaled conic problem.

The LMI of :mod:`netsetest.estimator.sdp` (DESIGN.md §2), written as M ⪰ 0 with

    M(P, L, τ) = [[P, Π(L)], [Π(L)ᵀ, N(τ)]],   Π(L) = Π₀ − L ℓᵀ,   N(τ) = ρ e₁e₁ᵀ − Σ_m τ_m Q_m,

τ ≥ 0, minimise trace(P), is rewritten with exact steps before it reaches the solver; the answer is
mapped back to (P, L, τ) of that LMI, which :func:`netsetest.estimator.sdp.certify` verifies as before.

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
from dataclasses import dataclass, field

import clarabel
import numpy as np

from netsetest.estimator.sdp import EtaLayout, Solution
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
    """Clarabel settings of the fast path; every answer is certified afterwards (sdp.certify).

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


@dataclass
class _Template:
    """The sparsity pattern and variable map of one pattern key; values are filled per step."""

    nv: int
    iP: list[int]
    iL: list[list[int]]
    iT: list[list[int]]
    iTt: list[int]
    groups: list[_Group]
    cones: list
    n_rows: int
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    cols: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    blocks: list = field(default_factory=list)  # (kind, length, meta) in entry order
    b_const: np.ndarray = field(default_factory=lambda: np.zeros(0))
    b_blocks: list = field(default_factory=list)  # (kind, row indices, meta)
    order: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    indices: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    indptr: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    lmi_rows: list[int] = field(default_factory=list)  # first row of each LMI block (each clique cone)
    lmi_n: int = 0
    decomposed: bool = False


class ConicSolver:
    """Assembles and solves the reduced conic problem of one node; structure fixed by the topology.

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
    ) -> None:
        self.lay, self.n_lmi = lay, n_lmi
        self._solvers: dict[tuple[bool, bool], clarabel.DefaultSolver] = {}
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
        )  # fmt: skip
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
        self._templates: dict[tuple[bool, bool], _Template] = {}
        self.last_iterations = 0

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

    def _template(self, use_xi: bool, slot0_cone: bool) -> _Template:
        key = (use_xi, slot0_cone)
        if key in self._templates:
            return self._templates[key]
        facts, n_lmi = self.lay.facts, self.n_lmi
        has_lmi = bool(self.lmi_slots)
        nv = 0
        iP = list(range(nv, nv + len(_P_ENTRIES))) if has_lmi else []
        nv += len(iP)
        iL, iT = [], []
        for _ in range(n_lmi):
            iL.append(list(range(nv, nv + NA)))
            nv += NA
            iT.append(list(range(nv, nv + self.n_tau)))
            nv += self.n_tau
        groups = list(self.groups)
        if self.socp and use_xi:
            groups.append(_Group(self.xi, (), 0.0))  # type: ignore[arg-type]
        n_t = len(groups) + (1 if slot0_cone else 0)
        iTt = list(range(nv, nv + n_t))
        nv += n_t

        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        blocks: list[tuple] = []
        b_blocks: list[tuple] = []
        cones: list = []
        b_const: list[float] = []

        def put(kind: str, r: list[int] | np.ndarray, c: list[int] | np.ndarray, meta: object = None) -> None:
            r, c = np.asarray(r, dtype=int), np.asarray(c, dtype=int)
            rows.append(r)
            cols.append(c)
            blocks.append((kind, len(r), meta))

        def newrows(k: int) -> list[int]:
            start = len(b_const)
            b_const.extend([0.0] * k)
            return list(range(start, start + k))

        # ξ's multiplier of a step without ξ is pinned to 0
        if self.xi is not None and not use_xi:
            rr = newrows(n_lmi)
            put("const", rr, [iT[r][self.xi] for r in range(n_lmi)], np.ones(n_lmi))
            cones.append(clarabel.ZeroConeT(n_lmi))
        # τ ≥ 0  (and, for a pure SOCP whose η₁ column is zero, the budget Σ τ ≤ ρ)
        tcols = [iT[r][c] for r in range(n_lmi) for c in range(self.n_tau) if not (c == self.xi and not use_xi)]
        rr = newrows(len(tcols))
        put("const", rr, tcols, -np.ones(len(tcols)))
        n_nn = len(tcols)
        balls_c = self.ball_compact + ([self.xi] if use_xi else [])
        if self.socp and not has_lmi and not slot0_cone:
            (r0,) = newrows(1)
            put("const", [r0] * len(balls_c), [iT[0][c] for c in balls_c], np.ones(len(balls_c)))
            b_blocks.append(("rho", [r0], None))
            n_nn += 1
        cones.append(clarabel.NonnegativeConeT(n_nn))
        # rotated cones β ‖Π_k(L)‖² ≤ t τ  ⇔  ‖(t − τ, 2√β Π_k)‖ ≤ t + τ, with L = S L̃
        for k, g in enumerate(groups):
            r0, r1 = newrows(2)
            put("const", [r0, r0, r1, r1], [iTt[k], iT[0][g.fact], iTt[k], iT[0][g.fact]], np.array([-1.0, -1.0, -1.0, 1.0]))
            ns = max(len(g.slots), 1)
            xr = newrows(ns * NA)
            rr_ = np.repeat(np.asarray(xr), NA)  # (slot, a) rows × c columns of S
            cc_ = np.tile(np.asarray(iL[0]), ns * NA)
            put("soc_L" if g.slots else "soc_xi", rr_, cc_, g)
            if g.slots:
                b_blocks.append(("soc_pi0", xr, g))
            cones.append(clarabel.SecondOrderConeT(2 + ns * NA))
        if slot0_cone:  # ℓ₀² ‖L‖² ≤ t₀ λ₀, λ₀ = ρ − Σ τ over the balls
            r0, r1 = newrows(2)
            t0 = iTt[-1]
            put("const", [r0, r1] + [r0] * len(balls_c) + [r1] * len(balls_c),
                [t0, t0] + [iT[0][c] for c in balls_c] * 2,
                np.r_[-1.0, -1.0, np.ones(len(balls_c)), -np.ones(len(balls_c))])  # fmt: skip
            b_blocks.append(("rho", [r0], None))
            b_blocks.append(("-rho", [r1], None))
            xr = newrows(NA)
            put("soc_0", np.repeat(np.asarray(xr), NA), np.tile(np.asarray(iL[0]), NA), None)
            cones.append(clarabel.SecondOrderConeT(2 + NA))

        # LMIs [[P̃, Π̃_r], [Π̃_rᵀ, Ñ_r]] ⪰ 0 (upper triangle, column-wise, off-diagonals × √2)
        lmi_rows: list[int] = []
        n = 0
        n_split = 0  # free variables of entries shared by several cliques (after all others)
        if has_lmi:
            slots = self.lmi_slots
            xi_in_lmi = (not self.socp) and use_xi
            n = NA + len(slots) + (1 if xi_in_lmi else 0)

            def tri(i: int, j: int) -> tuple[int, float]:
                i, j = min(i, j), max(i, j)
                return j * (j + 1) // 2 + i, (1.0 if i == j else SQ2)

            cliques = self.cliques if n_lmi == 1 else None
            for r in range(n_lmi):
                if cliques is None:
                    base = newrows(n * (n + 1) // 2)[0]
                    vm = np.arange(base, base + n * (n + 1) // 2)  # svec entry of M → row
                    lmi_rows.append(base)
                else:  # one cone per clique; entries in several cliques are split (free variables)
                    vm = np.full(n * (n + 1) // 2, -1)
                    owners: dict[int, list[int]] = {}
                    for C in cliques:
                        rr = newrows(len(C) * (len(C) + 1) // 2)
                        k = 0
                        for jj in range(len(C)):
                            for ii in range(jj + 1):
                                owners.setdefault(tri(C[ii], C[jj])[0], []).append(rr[k])
                                k += 1
                        lmi_rows.append(rr[0])
                    for ri, rws in owners.items():
                        vm[ri] = rws[-1]  # the last clique holding an entry carries M's value minus the splits
                        f = 1.0 if ri in {tri(i, i)[0] for i in range(n)} else SQ2
                        for other in rws[:-1]:
                            put("const", [other, rws[-1]], [nv + n_split, nv + n_split], np.array([-f, f]))
                            n_split += 1
                    for C in cliques:
                        cones.append(clarabel.PSDTriangleConeT(len(C)))
                    base = 0
                row_of = lambda x: int(vm[x])  # noqa: E731
                pr, pf = zip(*[tri(i, j) for i, j in _P_ENTRIES])
                put("const", [row_of(x) for x in pr], iP, -np.asarray(pf))
                # Π̃ = S⁻¹Π₀ D − L̃ ℓᵀ D: L̃_a at (a, slot kk)
                lr, lc, lf = [], [], []
                for kk in range(len(slots)):
                    for a in range(NA):
                        ri, f = tri(a, NA + kk)
                        lr.append(row_of(ri))
                        lc.append(iL[r][a])
                        lf.append(f)
                put("lmi_L", lr, lc, np.asarray(lf))
                b_blocks.append(("lmi_pi0", [x for x in lr], (r, np.asarray(lf))))
                if xi_in_lmi:
                    xr_, xf_ = zip(*[tri(a, n - 1) for a in range(NA)])
                    put("lmi_xi", [row_of(x) for x in xr_], iL[r], np.asarray(xf_))
                # Ñ = ρ e₁e₁ᵀ − Σ τ̂ Q̂: the structural entries of each fact on the LMI slots
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
                    rr_, ff_ = zip(*[tri(NA + x, NA + y) for x, y in zip(li, lj)])
                    put("lmi_tau", [row_of(x) for x in rr_], [iT[r][c]] * len(ent), (m, gi, gj, li, lj, np.asarray(ff_), c))
                r00, _ = tri(NA, NA)
                b_blocks.append(("rho", [row_of(r00)], None))
                # balls living in cones (and ξ) still cost τ in Ñ₁₁
                extra = [g.fact for g in groups] if self.socp else []
                if xi_in_lmi:
                    extra.append(self.xi)
                if extra:
                    put("const", [row_of(r00)] * len(extra), [iT[r][c] for c in extra], np.ones(len(extra)))
                if xi_in_lmi:
                    rx, _ = tri(n - 1, n - 1)
                    put("const", [row_of(rx)], [iT[r][self.xi]], -np.ones(1))
                if cliques is None:
                    cones.append(clarabel.PSDTriangleConeT(n))

        nv += n_split
        tpl = _Template(nv=nv, iP=iP, iL=iL, iT=iT, iTt=iTt, groups=groups, cones=cones, n_rows=len(b_const))
        tpl.decomposed = has_lmi and self.cliques is not None and n_lmi == 1
        tpl.rows = np.concatenate(rows)
        assert tpl.rows.min() >= 0 and all(min(rr) >= 0 for _, rr, _ in b_blocks), "an LMI entry outside every clique"
        tpl.cols = np.concatenate(cols)
        tpl.blocks = blocks
        tpl.b_const = np.asarray(b_const)
        tpl.b_blocks = b_blocks
        tpl.lmi_rows, tpl.lmi_n = lmi_rows, n
        # csc order of the entries (fixed pattern): data = values[order]
        order = np.lexsort((tpl.rows, tpl.cols))
        assert len(set(zip(tpl.rows.tolist(), tpl.cols.tolist()))) == len(order), "duplicate entries in the pattern"
        tpl.order = order
        tpl.indices = tpl.rows[order].astype(np.int64)
        tpl.indptr = np.r_[0, np.cumsum(np.bincount(tpl.cols, minlength=nv))].astype(np.int64)
        self._templates[key] = tpl
        return tpl

    # ------------------------------------------------------------------ values (every step)

    def assemble(self, data: dict, rho: float) -> dict:
        """Clarabel data (P, q, A, b, cones) and the maps back to (P, L, τ), for one step."""
        facts = self.lay.facts
        ell = data["ell"]
        Q = data["facts"]
        agg_w = np.abs(ell[self.agg_slots]) * self.agg_sqrtb if self.agg else np.zeros(0)
        B = float(agg_w.sum())
        use_xi = self.xi is not None and B > 0.0
        has_lmi = bool(self.lmi_slots)
        ell0 = float(ell[0])
        slot0_cone = self.socp and not has_lmi and ell0 != 0.0
        tpl = self._template(use_xi, slot0_cone)

        # congruence of the P rows: P_prev = S Sᵀ (data["Mi"] = ρ^½ chol(P_prev))
        S = data["Mi"] / math.sqrt(rho)
        Sinv = np.linalg.inv(S)
        # φ slots: |φ| ≤ h|r| ≤ Σ_k h|g_k| σ_k (from the sector fact's row); multipliers by κ
        sc = self.scale[self.lmi_slots] if has_lmi else np.zeros(0)
        kappa = np.ones(self.n_tau)
        if self.sector_lmi:
            sc = sc.copy()
            for c, m in self.sector_lmi:
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

        vals = []
        for kind, length, meta in tpl.blocks:
            if kind == "const":
                vals.append(meta)
            elif kind == "soc_L":  # 2√β ℓ_s S[a, c] for (s, a, c)
                g = meta
                vals.append((2.0 * math.sqrt(g.bound) * ell[list(g.slots)][:, None, None] * S[None, :, :]).ravel())
            elif kind == "soc_xi":
                vals.append((2.0 * B * S).ravel())
            elif kind == "soc_0":
                vals.append((2.0 * ell0 * S).ravel())
            elif kind == "lmi_L":
                vals.append(meta * np.repeat(sc * ell[self.lmi_slots], NA))
            elif kind == "lmi_xi":
                vals.append(meta * B)
            elif kind == "lmi_tau":
                m, gi, gj, li, lj, ff, c = meta
                vals.append(ff * Q[m][gi, gj] * sc[li] * sc[lj] / kappa[c])
        values = np.concatenate(vals)
        b = tpl.b_const.copy()
        pi0 = data["pi0"]
        for kind, rr, meta in tpl.b_blocks:
            if kind == "rho":
                b[rr] = rho
            elif kind == "-rho":
                b[rr] = -rho
            elif kind == "soc_pi0":  # 2√β Π₀[a, s] for (s, a)
                b[rr] = (2.0 * math.sqrt(meta.bound) * pi0[0][:, list(meta.slots)].T).ravel()
            elif kind == "lmi_pi0":
                r, ff = meta
                b[rr] = ff * ((Sinv @ pi0[r][:, self.lmi_slots]) * sc).T.ravel()
        A = CscMatrix(values[tpl.order], tpl.indices, tpl.indptr, (tpl.n_rows, tpl.nv))
        q = np.zeros(tpl.nv)
        if has_lmi:
            StS = S.T @ S  # trace(P_c) = trace(S P̃ Sᵀ)
            for k, (i, j) in enumerate(_P_ENTRIES):
                q[tpl.iP[k]] = StS[i, j] * (1.0 if i == j else 2.0)
        q[tpl.iTt] = 1.0
        return {
            "P": CscMatrix.empty(tpl.nv, tpl.nv), "q": q, "A": A, "b": b, "cones": tpl.cones, "tpl": tpl, "key": (use_xi, slot0_cone),
            "S": S, "sc": sc, "kappa": kappa, "B": B, "agg_w": agg_w, "use_xi": use_xi,
            "slot0_cone": slot0_cone, "has_lmi": has_lmi,
        }  # fmt: skip

    # ------------------------------------------------------------------ solve and map back

    def solve(self, data: dict, rho: float) -> Solution:
        prob = self.assemble(data, rho)
        try:
            sol = self._solve(prob)
        except Exception as exc:  # noqa: BLE001 - a solver failure is a fallback step, not a crash
            self._solvers.pop(prob["key"], None)
            return Solution(None, [], [], f"error: {exc}")
        status = str(sol.status)
        self.last_iterations = sol.iterations
        if status not in ("Solved", "AlmostSolved"):
            return Solution(None, [], [], status, sol.iterations)
        x = np.asarray(sol.x)
        if not np.all(np.isfinite(x)):
            return Solution(None, [], [], "non-finite", sol.iterations)
        return self.recover(x, prob, data, rho, status, sol.iterations)

    def _solve(self, prob: dict):  # noqa: ANN202
        """Solve with the node's solver for this pattern, its data updated in place where Clarabel
        allows it (no chordal decomposition of its own, no presolve, no equilibration): the set-up
        (KKT symbolic factorisation) is then paid once per node, not per step."""
        key, tpl = prob["key"], prob["tpl"]
        solver = self._solvers.get(key)
        if solver is not None:
            try:
                solver.update(q=prob["q"], A=prob["A"].data, b=prob["b"])
                return solver.solve()
            except Exception:  # noqa: BLE001 - refused update: set up a fresh solver below
                del self._solvers[key]
        st = self.settings_decomposed if tpl.decomposed else self.settings
        solver = clarabel.DefaultSolver(prob["P"], prob["q"], prob["A"], prob["b"], prob["cones"], st)
        if solver.is_data_update_allowed():
            self._solvers[key] = solver
        return solver.solve()

    def unpack(self, x: np.ndarray, prob: dict) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
        """P_c (zero without an LMI), L_ℓ and τ_ℓ over the original facts, from a conic point x."""
        tpl, S = prob["tpl"], prob["S"]
        Ls = [S @ x[i][:, None] for i in tpl.iL]
        taus = []
        for r in range(self.n_lmi):
            tc = np.maximum(x[tpl.iT[r]], 0.0) / prob["kappa"]
            tau = np.zeros(len(self.lay.facts))
            tau[self.kept] = tc[: len(self.kept)]
            if prob["use_xi"]:
                tau[self.agg] = tc[self.xi] * prob["agg_w"] / prob["B"]
            taus.append(tau)
        P = np.zeros((NA, NA))
        if prob["has_lmi"]:
            for k, (i, j) in enumerate(_P_ENTRIES):
                P[i, j] = P[j, i] = x[tpl.iP[k]]
            P = S @ P @ S.T
        return P, Ls, taus

    def recover(self, x: np.ndarray, prob: dict, data: dict, rho: float, status: str = "", iterations: int = 0) -> Solution:
        """(P, L_ℓ, τ_ℓ) of the LMI from the conic solution; in ``scheduled`` the smallest P for (L, τ)."""
        P, Ls, taus = self.unpack(x, prob)
        if self.socp:  # P = P_c + Σ β Π_k Π_kᵀ / τ_k
            L, tau, tpl = Ls[0], taus[0], prob["tpl"]
            tc = np.maximum(x[tpl.iT[0]], 0.0) / prob["kappa"]
            pi = data["pi0"][0] - L @ data["ell"][None, :]
            for g in tpl.groups:
                t = tc[g.fact]
                if t <= 0.0:
                    continue
                if g.slots:
                    cols = pi[:, list(g.slots)]
                    P = P + g.bound * (cols @ cols.T) / t
                else:  # ξ: column −L, bound B²
                    P = P + prob["B"] ** 2 * (L @ L.T) / t
            if prob["slot0_cone"]:
                lam0 = rho - float(tau[self.balls].sum())
                if lam0 > 0.0:
                    P = P + (data["ell"][0] ** 2 / lam0) * (L @ L.T)
        return Solution(P, Ls, taus, status, iterations)


__all__ = ["ConicSolver", "CscMatrix", "default_settings"]
