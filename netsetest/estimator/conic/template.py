"""The pattern of the reduced conic problem (A, b and the cones) per :data:`TemplateKey`, and its values per step.

A :class:`Template` is built once per key from the node's :class:`~netsetest.estimator.conic.reduction.Reduction`
by one method per cone group (:func:`build_template`); its entries come in value blocks, each of which
computes its entries for a step from :class:`StepValues`, so a step is a few numpy expressions and one
permutation into Clarabel's column order (:meth:`Template.fill`).  Rows are laid out cone by cone, in the
order of the template's cone list; PSD cones hold the upper triangle column-wise, off-diagonals × √2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import clarabel
import numpy as np

from netsetest.estimator.conic.reduction import Group, Reduction
from netsetest.estimator.problem import FactInfo
from netsetest.models.sensor import NA

SQ2 = math.sqrt(2.0)
P_ENTRIES = [(i, j) for j in range(NA) for i in range(j + 1)]  # variables P̃_ij, i ≤ j (svec order)
_P_I, _P_J = (np.array(v) for v in zip(*P_ENTRIES))
_P_TRACE = np.where(_P_I == _P_J, 1.0, 2.0)  # trace(S P̃ Sᵀ) counts an off-diagonal P̃_ij twice

TemplateKey = tuple[bool, bool]
"""(ξ is used, the η₁ slot has its own cone): the two per-step choices that change the pattern."""


def _tri(i: int, j: int) -> tuple[int, float]:
    """svec index of entry (i, j) of a symmetric matrix and its factor (off-diagonals × √2)."""
    i, j = min(i, j), max(i, j)
    return j * (j + 1) // 2 + i, (1.0 if i == j else SQ2)


# ---------------------------------------------------------------------- the values of one step


@dataclass(frozen=True)
class StepValues:
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


# Entries of A, one block per group of entries in pattern order; ``values`` gives them for a step.


@dataclass(frozen=True)
class _Const:
    """Entries that do not change from step to step."""

    v: np.ndarray

    def values(self, s: StepValues) -> np.ndarray:
        return self.v


@dataclass(frozen=True)
class _SocL:
    """2√β ℓ_s S[a, c] for (s, a, c): the L̃ columns of a ball group's rotated cone."""

    group: Group

    def values(self, s: StepValues) -> np.ndarray:
        g = self.group
        return (2.0 * g.sqrt_bound * s.ell[list(g.slots)][:, None, None] * s.S[None, :, :]).ravel()


@dataclass(frozen=True)
class _SocXi:
    """2 B S[a, c]: the L̃ columns of ξ's rotated cone."""

    def values(self, s: StepValues) -> np.ndarray:
        return (2.0 * s.B * s.S).ravel()


@dataclass(frozen=True)
class _Soc0:
    """2 ℓ₀ S[a, c]: the L̃ columns of the η₁ slot's cone."""

    def values(self, s: StepValues) -> np.ndarray:
        return (2.0 * float(s.ell[0]) * s.S).ravel()


@dataclass(frozen=True)
class _LmiL:
    """−L̃ ℓᵀ D in the LMI's off-diagonal block (``f`` the svec factors)."""

    f: np.ndarray
    lmi_slots: list[int]

    def values(self, s: StepValues) -> np.ndarray:
        return self.f * np.repeat(s.sc * s.ell[self.lmi_slots], NA)


@dataclass(frozen=True)
class _LmiXi:
    """ξ's column −B L̃ in the LMI (``per-rule``)."""

    f: np.ndarray

    def values(self, s: StepValues) -> np.ndarray:
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

    def values(self, s: StepValues) -> np.ndarray:
        return self.f * s.facts[self.m][self.gi, self.gj] * s.sc[self.li] * s.sc[self.lj] / s.kappa[self.c]


_ABlock = Union[_Const, _SocL, _SocXi, _Soc0, _LmiL, _LmiXi, _LmiTau]  # a runtime alias

# Rows of b that change per step (the others stay 0); ``fill`` writes them for a step.


@dataclass(frozen=True)
class _Rho:
    rows: list[int]
    sign: float = 1.0

    def fill(self, b: np.ndarray, s: StepValues) -> None:
        b[self.rows] = s.rho if self.sign > 0 else -s.rho


@dataclass(frozen=True)
class _SocPi0:
    """2√β Π₀[a, s] for (s, a): the constant part of a ball group's rotated cone."""

    rows: list[int]
    group: Group

    def fill(self, b: np.ndarray, s: StepValues) -> None:
        g = self.group
        b[self.rows] = (2.0 * g.sqrt_bound * s.pi0[0][:, list(g.slots)].T).ravel()


@dataclass(frozen=True)
class _LmiPi0:
    """S⁻¹ Π₀ D of LMI r in its off-diagonal block (``f`` the svec factors)."""

    rows: list[int]
    r: int
    f: np.ndarray
    lmi_slots: list[int]

    def fill(self, b: np.ndarray, s: StepValues) -> None:
        assert s.Sinv is not None  # an LMI block exists only with an LMI
        b[self.rows] = self.f * ((s.Sinv @ s.pi0[self.r][:, self.lmi_slots]) * s.sc).T.ravel()


_BBlock = Union[_Rho, _SocPi0, _LmiPi0]  # a runtime alias


# ---------------------------------------------------------------------- the pattern of a template key


@dataclass(frozen=True)
class Variables:
    """Column indices of the conic variables: P̃ (svec), per LMI L̃ and τ̂, the cone epigraphs t."""

    nv: int  # split variables (after all these) not included
    iP: list[int]
    iL: list[list[int]]
    iT: list[list[int]]
    iTt: list[int]
    groups: list[Group]  # the groups with a cone, in the order of their epigraphs iTt


@dataclass(frozen=True)
class Template:
    """The sparsity pattern and variable map of one template key; values are filled per step."""

    key: TemplateKey
    var: Variables
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
    def groups(self) -> list[Group]:
        return self.var.groups

    def fill(self, s: StepValues) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The step's entries of A (in csc order), b and q (:meth:`objective`): one call a solve."""
        values = np.concatenate([blk.values(s) for blk in self.a_blocks])
        b = np.zeros(self.n_rows)
        for blk in self.b_blocks:
            blk.fill(b, s)
        return values[self.order], b, self.objective(s.S)

    def objective(self, S: np.ndarray) -> np.ndarray:
        """q of trace(P_c) = trace(S P̃ Sᵀ) (with an LMI) plus Σ t (the cones' epigraphs)."""
        q = np.zeros(self.nv)
        if self.iP:
            q[self.iP] = (S.T @ S)[_P_I, _P_J] * _P_TRACE
        q[self.iTt] = 1.0
        return q


def build_template(red: Reduction, key: TemplateKey) -> Template:
    """The pattern of one template key: the cones in the order the rows hold them."""
    use_xi, slot0_cone = key
    asm = _Assembly(red, _variables(red, use_xi, slot0_cone))
    asm.xi_pin(use_xi)
    asm.nonneg(use_xi, slot0_cone)
    asm.group_cones()
    if slot0_cone:
        asm.slot0_cone(use_xi)
    lmi_rows, n = asm.lmis(use_xi) if red.lmi_slots else ([], 0)
    return asm.finish(key, lmi_rows, n)


def _variables(red: Reduction, use_xi: bool, slot0_cone: bool) -> Variables:
    """P̃ (svec, only with an LMI), per LMI L̃ (NA) and τ̂ (n_tau), then one epigraph t per cone."""
    nv = len(P_ENTRIES) if red.lmi_slots else 0
    iP = list(range(nv))
    iL, iT = [], []
    for _ in range(red.n_lmi):
        iL.append(list(range(nv, nv + NA)))
        nv += NA
        iT.append(list(range(nv, nv + red.n_tau)))
        nv += red.n_tau
    groups = red.cone_groups(use_xi)
    n_t = len(groups) + (1 if slot0_cone else 0)
    return Variables(nv + n_t, iP, iL, iT, list(range(nv, nv + n_t)), groups)


def _fact_entries(f: FactInfo) -> list[tuple[int, int]]:
    """The structural entries (i ≤ j, η slots) of a fact's Q: a ball's diagonal, a sector fact's φ row."""
    if f.kind == "ball":
        return [(0, 0)] + [(s, s) for s in f.slots]
    p = f.slots[0]
    return [(p, p)] + [(min(p, u), max(p, u)) for u in f.support if u != p]


class _Assembly:
    """Collects a template's A entries (rows × columns, one value block each), rows of b and cones."""

    def __init__(self, red: Reduction, var: Variables) -> None:
        self.red, self.var = red, var
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

    def xi_pin(self, use_xi: bool) -> None:
        """ξ's multiplier of a step without ξ is pinned to 0 (zero cone)."""
        xi, n_lmi = self.red.xi, self.red.n_lmi
        if xi is None or use_xi:
            return
        rr = self.newrows(n_lmi)
        self.put(_Const(np.ones(n_lmi)), rr, [self.var.iT[r][xi] for r in range(n_lmi)])
        self.cones.append(clarabel.ZeroConeT(n_lmi))

    def nonneg(self, use_xi: bool, slot0_cone: bool) -> None:
        """τ ≥ 0 and, for a pure SOCP whose η₁ column is zero, the budget Σ τ ≤ ρ (one nonnegative cone)."""
        red, iT = self.red, self.var.iT
        tcols = [iT[r][c] for r in range(red.n_lmi) for c in range(red.n_tau) if not (c == red.xi and not use_xi)]
        rr = self.newrows(len(tcols))
        self.put(_Const(-np.ones(len(tcols))), rr, tcols)
        n_nn = len(tcols)
        if red.closed_form and not slot0_cone:
            balls_c = red.balls_compact(use_xi)
            (r0,) = self.newrows(1)
            self.put(_Const(np.ones(len(balls_c))), [r0] * len(balls_c), [iT[0][c] for c in balls_c])
            self.b_blocks.append(_Rho([r0]))
            n_nn += 1
        self.cones.append(clarabel.NonnegativeConeT(n_nn))

    def group_cones(self) -> None:
        """Rotated cones β ‖Π_k(L)‖² ≤ t τ  ⇔  ‖(t − τ, 2√β Π_k)‖ ≤ t + τ, with L = S L̃, one per group."""
        var = self.var
        for k, g in enumerate(var.groups):
            r0, r1 = self.newrows(2)
            self.put(_Const(np.array([-1.0, -1.0, -1.0, 1.0])), [r0, r0, r1, r1], [var.iTt[k], var.iT[0][g.fact], var.iTt[k], var.iT[0][g.fact]])
            ns = max(len(g.slots), 1)
            xr = self.newrows(ns * NA)
            rr_ = np.repeat(np.asarray(xr), NA)  # (slot, a) rows × c columns of S
            cc_ = np.tile(np.asarray(var.iL[0]), ns * NA)
            self.put(_SocL(g) if g.slots else _SocXi(), rr_, cc_)
            if g.slots:
                self.b_blocks.append(_SocPi0(xr, g))
            self.cones.append(clarabel.SecondOrderConeT(2 + ns * NA))

    def slot0_cone(self, use_xi: bool) -> None:
        """ℓ₀² ‖L‖² ≤ t₀ λ₀ with λ₀ = ρ − Σ τ over the balls (a pure SOCP with ℓ₀ ≠ 0)."""
        var = self.var
        balls_c = self.red.balls_compact(use_xi)
        r0, r1 = self.newrows(2)
        t0 = var.iTt[-1]
        self.put(
            _Const(np.r_[-1.0, -1.0, np.ones(len(balls_c)), -np.ones(len(balls_c))]),
            [r0, r1] + [r0] * len(balls_c) + [r1] * len(balls_c),
            [t0, t0] + [var.iT[0][c] for c in balls_c] * 2,
        )
        self.b_blocks.append(_Rho([r0]))
        self.b_blocks.append(_Rho([r1], -1.0))
        xr = self.newrows(NA)
        self.put(_Soc0(), np.repeat(np.asarray(xr), NA), np.tile(np.asarray(var.iL[0]), NA))
        self.cones.append(clarabel.SecondOrderConeT(2 + NA))

    def lmis(self, use_xi: bool) -> tuple[list[int], int]:
        """LMIs [[P̃, Π̃_r], [Π̃_rᵀ, Ñ_r]] ⪰ 0, one PSD cone each or, decomposed, one per clique; returns the
        first row of each cone and the LMI size."""
        red = self.red
        xi_in_lmi = (not red.socp) and use_xi
        n = NA + len(red.lmi_slots) + (1 if xi_in_lmi else 0)
        lmi_rows: list[int] = []
        for r in range(red.n_lmi):
            vm = self._rows_whole(n, lmi_rows) if red.cliques is None else self._rows_cliques(n, red.cliques, lmi_rows)
            self._lmi_p(vm)
            self._lmi_pi(r, vm, n, xi_in_lmi)
            self._lmi_n(r, vm, n, xi_in_lmi)
            if red.cliques is None:
                self.cones.append(clarabel.PSDTriangleConeT(n))
        return lmi_rows, n

    def _rows_whole(self, n: int, lmi_rows: list[int]) -> np.ndarray:
        """One PSD cone: the LMI's svec entries on consecutive rows."""
        base = self.newrows(n * (n + 1) // 2)[0]
        lmi_rows.append(base)
        return np.arange(base, base + n * (n + 1) // 2)

    def _rows_cliques(self, n: int, cliques: list[list[int]], lmi_rows: list[int]) -> np.ndarray:
        """One PSD cone per clique; an entry held by several cliques gets free split variables (after all
        others) so that the cliques' matrices add up to the LMI."""
        vm = np.full(n * (n + 1) // 2, -1)
        owners: dict[int, list[int]] = {}
        for C in cliques:
            rr = self.newrows(len(C) * (len(C) + 1) // 2)
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
                col = self.var.nv + self.n_split
                self.put(_Const(np.array([-f, f])), [other, rws[-1]], [col, col])
                self.n_split += 1
        for C in cliques:
            self.cones.append(clarabel.PSDTriangleConeT(len(C)))
        return vm

    def _lmi_p(self, vm: np.ndarray) -> None:
        """The P̃ block (``vm``: svec entry of the LMI → row of A)."""
        pr, pf = zip(*[_tri(i, j) for i, j in P_ENTRIES])
        self.put(_Const(-np.asarray(pf)), vm[list(pr)], self.var.iP)

    def _lmi_pi(self, r: int, vm: np.ndarray, n: int, xi_in_lmi: bool) -> None:
        """Π̃ = S⁻¹Π₀ D − L̃ ℓᵀ D: L̃_a at (a, slot kk), S⁻¹Π₀ D in b; ξ's column −B L̃ when it is in the LMI."""
        lmi_slots, iL = self.red.lmi_slots, self.var.iL[r]
        lr, lc, lf = [], [], []
        for kk in range(len(lmi_slots)):
            for a in range(NA):
                ri, f = _tri(a, NA + kk)
                lr.append(int(vm[ri]))
                lc.append(iL[a])
                lf.append(f)
        self.put(_LmiL(np.asarray(lf), lmi_slots), lr, lc)
        self.b_blocks.append(_LmiPi0(lr, r, np.asarray(lf), lmi_slots))
        if xi_in_lmi:
            xr_, xf_ = zip(*[_tri(a, n - 1) for a in range(NA)])
            self.put(_LmiXi(np.asarray(xf_)), vm[list(xr_)], iL)

    def _lmi_n(self, r: int, vm: np.ndarray, n: int, xi_in_lmi: bool) -> None:
        """Ñ = ρ e₁e₁ᵀ − Σ τ̂ Q̂: the structural entries of each fact on the LMI slots; ρ in Ñ₁₁ (b), where
        the balls living in cones (and ξ) still cost their τ."""
        red, iT = self.red, self.var.iT[r]
        for c in red.lmi_facts:
            m = red.kept[c]
            ent = _fact_entries(red.lay.facts[m])
            gi = np.array([e[0] for e in ent])
            gj = np.array([e[1] for e in ent])
            li = np.array([red.lmi_pos[x] for x in gi])
            lj = np.array([red.lmi_pos[x] for x in gj])
            rr_, ff_ = zip(*[_tri(NA + x, NA + y) for x, y in zip(li, lj)])
            self.put(_LmiTau(m, gi, gj, li, lj, np.asarray(ff_), c), vm[list(rr_)], [iT[c]] * len(ent))
        r00 = int(vm[_tri(NA, NA)[0]])
        self.b_blocks.append(_Rho([r00]))
        extra = [g.fact for g in self.var.groups] if red.socp else []
        xi = red.xi if xi_in_lmi else None  # ξ is in the LMI only where balls were aggregated
        if xi is not None:
            extra.append(xi)
        if extra:
            self.put(_Const(np.ones(len(extra))), [r00] * len(extra), [iT[c] for c in extra])
        if xi is not None:
            self.put(_Const(-np.ones(1)), [int(vm[_tri(n - 1, n - 1)[0]])], [iT[xi]])

    def finish(self, key: TemplateKey, lmi_rows: list[int], n: int) -> Template:
        """The csc order of the entries (the pattern is fixed: data = values[order]) and the template."""
        nv = self.var.nv + self.n_split
        rows, cols = np.concatenate(self.rows), np.concatenate(self.cols)
        assert rows.min() >= 0 and all(min(b.rows) >= 0 for b in self.b_blocks), "an LMI entry outside every clique"
        order = np.lexsort((rows, cols))
        assert len(set(zip(rows.tolist(), cols.tolist()))) == len(order), "duplicate entries in the pattern"
        return Template(
            key=key,
            var=self.var,
            nv=nv,
            n_rows=self.n_rows,
            cones=self.cones,
            a_blocks=self.a_blocks,
            b_blocks=self.b_blocks,
            order=order,
            indices=rows[order].astype(np.int64),
            indptr=np.r_[0, np.cumsum(np.bincount(cols, minlength=nv))].astype(np.int64),
            lmi_rows=lmi_rows,
            lmi_n=n,
            decomposed=self.red.cliques is not None,
        )


__all__ = ["P_ENTRIES", "StepValues", "Template", "TemplateKey", "Variables", "build_template"]
