"""The k-of-N health assumption in the exact limit: branch and bound over each step's pieces (docs/exact.md).

Under ``[network] max_faulty = m`` at least need = N − m sensors are healthy (|f_i,j| ≤ τ) at every step j.
Every sensor measures t = uᵀx (C_i = s_i uᵀ, checked when the topology is loaded), so a healthy sensor's
measurement rows put t_j in its span I_i,j (the measured interval widened by |Ds_i|τ, over s_i).  Whether a
sensor's health is a condition on t_j alone depends on its fault variable:

- *untied*: f_i,j appears only in its own measurement rows (no declared bound, 0 < j, not the objective),
  so some |f_i,j| ≤ τ meets them exactly when t_j ∈ I_i,j: health is t_j ∈ I_i,j;
- *tied*: f_i,j also enters a prior (j = 0), a declared fault bound, or the objective: health is
  |f_i,j| ≤ τ itself.

The step's feasible set is then exactly the union of convex *pieces*: for each set Q of tied sensors
assumed healthy (|Q| ≤ need), a maximal interval of t_j inside ∩_{q∈Q} I_q that at least need − |Q|
untied spans cover, with |f_q,j| ≤ τ for q ∈ Q.  :func:`minimise` is a best-first branch and bound over
them: the relaxation leaves every unchosen step's union out, a node whose minimiser meets every step's
union is optimal (it has the least bound of all open nodes), otherwise it branches into the pieces of one
violated step.  Past the budget of solves it stops with the least open bound: an outer bound (sound),
reported as relaxed.
"""

from __future__ import annotations

import heapq
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import clarabel
import numpy as np
from scipy import sparse

Span = tuple[float, float]
Row = tuple[dict[int, float], float]  # a·z ≤ b over the program's columns (global indices)

HEALTH_TOL = 1e-9  # a minimiser this close to a piece counts as in it: that can only widen an end (sound side)
_SOLVED = ("Solved", "AlmostSolved")
_UNBOUNDED = ("DualInfeasible", "AlmostDualInfeasible")
_INFEASIBLE = ("PrimalInfeasible", "AlmostPrimalInfeasible")


@dataclass(frozen=True)
class Piece:
    """One convex branch of a step's union: t_j ∈ [lo, hi] and |f_q,j| ≤ τ for every sensor q in ``healthy``."""

    lo: float
    hi: float
    healthy: tuple[int, ...]  # sensor positions of tied faults assumed healthy

    def within(self, other: Piece) -> bool:
        return set(other.healthy) <= set(self.healthy) and other.lo <= self.lo and self.hi <= other.hi


def covered(spans: Sequence[Span], need: int) -> list[Span]:
    """The points in at least ``need`` of the closed ``spans``, as disjoint closed intervals in order."""
    if need <= 0:
        return [(-math.inf, math.inf)]
    # opening events sort before closing ones at the same point: closed intervals that touch do overlap
    events = sorted([(lo, 0) for lo, _ in spans] + [(hi, 1) for _, hi in spans])
    out, count, start = [], 0, -math.inf
    for t, kind in events:
        if kind == 0:
            count += 1
            if count == need:
                start = t
        else:
            if count == need:
                out.append((start, t))
            count -= 1
    return out


def _clip(parts: list[Span], lo: float, hi: float) -> list[Span]:
    return [(max(a, lo), min(b, hi)) for a, b in parts if max(a, lo) <= min(b, hi)]


def step_pieces(spans: Sequence[Span], tied: Sequence[bool], allowed: Sequence[bool], need: int, window: Span) -> list[Piece] | None:
    """Every piece of one step (module doc) inside ``window`` (an interval known to hold t_j), none contained
    in another; ``allowed``: tied sensors that may be healthy (their fault's known range meets [−τ, τ]).
    None if there are more than :data:`MAX_PIECE_SETS` sets Q to try (the caller relaxes the step)."""
    untied = [sp for sp, t in zip(spans, tied) if not t]
    candidates = [n for n, (t, ok) in enumerate(zip(tied, allowed)) if t and ok]
    sizes = range(max(0, need - len(untied)), min(need, len(candidates)) + 1)
    if sum(math.comb(len(candidates), q) for q in sizes) > MAX_PIECE_SETS:
        return None
    pieces: list[Piece] = []
    for q in sizes:
        for group in itertools.combinations(candidates, q):
            lo = max([window[0], *(spans[n][0] for n in group)])
            hi = min([window[1], *(spans[n][1] for n in group)])
            pieces += [Piece(a, b, group) for a, b in _clip(covered(untied, need - q), lo, hi)]
    return [p for m, p in enumerate(pieces) if not any(p.within(o) and (not o.within(p) or n < m) for n, o in enumerate(pieces) if n != m)]


MAX_PIECE_SETS = 2000  # sets Q of tied sensors enumerated at one step: C(N, need) grows fast with N


@dataclass(frozen=True)
class StepUnion:
    """The k-of-N constraint of one step: t_j = Σ t[c]·z[c], the sensors' spans, and per sensor the column
    of its tied fault (None: untied, its health is t_j ∈ its span); ``pieces``: the union, branch by branch."""

    step: int
    t: dict[int, float]
    spans: tuple[Span, ...]
    f_col: tuple[int | None, ...]
    tolerance: float
    need: int
    pieces: tuple[Piece, ...]

    def holds(self, z: np.ndarray) -> bool:
        """Whether the point meets the union: at least ``need`` sensors healthy (to :data:`HEALTH_TOL`)."""
        t = sum(v * z[c] for c, v in self.t.items())
        healthy = 0
        for (lo, hi), col in zip(self.spans, self.f_col):
            if col is None:
                healthy += lo - HEALTH_TOL <= t <= hi + HEALTH_TOL
            else:
                healthy += abs(z[col]) <= self.tolerance + HEALTH_TOL
        return healthy >= self.need

    def rows(self, piece: Piece) -> list[Row]:
        """The piece as rows a·z ≤ b (a side at ±inf gives none)."""
        out: list[Row] = []
        if math.isfinite(piece.hi):
            out.append((dict(self.t), piece.hi))
        if math.isfinite(piece.lo):
            out.append(({c: -v for c, v in self.t.items()}, -piece.lo))
        for n in piece.healthy:
            col = self.f_col[n]
            assert col is not None  # only tied sensors are assumed healthy by a row
            out += [({col: 1.0}, self.tolerance), ({col: -1.0}, self.tolerance)]
        return out


@dataclass(frozen=True)
class Conic:
    """One horizon's program, A z + s = b with s in ``cones``, over the columns ``cols`` (global indices)."""

    cols: np.ndarray
    A: sparse.csc_matrix
    b: np.ndarray
    cones: list
    settings: clarabel.DefaultSettings

    def with_rows(self, rows: Sequence[Row]) -> Conic:
        """The same program with ``rows`` (a·z ≤ b) added as one more non-negative cone."""
        if not rows:
            return self
        position = {int(c): m for m, c in enumerate(self.cols)}
        data, ri, ci = [], [], []
        for r, (terms, _) in enumerate(rows):
            for c, v in terms.items():
                ri.append(r)
                ci.append(position[c])
                data.append(v)
        extra = sparse.csc_matrix((data, (ri, ci)), shape=(len(rows), len(self.cols)))
        b = np.r_[self.b, [rhs for _, rhs in rows]]
        return Conic(self.cols, sparse.vstack([self.A, extra], format="csc"), b, [*self.cones, clarabel.NonnegativeConeT(len(rows))], self.settings)

    def solver(self, q: np.ndarray) -> clarabel.DefaultSolver:
        n = len(self.cols)
        return clarabel.DefaultSolver(sparse.csc_matrix((n, n)), q, self.A, self.b, self.cones, self.settings)

    def solve(self, q: np.ndarray, rows: Sequence[Row]) -> tuple[str, np.ndarray | None]:
        """Minimise q·z with ``rows`` added: (status, minimiser over ``cols`` or None)."""
        sol = self.with_rows(rows).solver(q).solve()
        return str(sol.status), np.asarray(sol.x) if str(sol.status) in _SOLVED else None


@dataclass(frozen=True)
class EndResult:
    """One end's minimum of q·z over the union: ``value`` (−inf unbounded, NaN infeasible), the minimiser
    (over the global columns; None unless solved exactly), whether it is exact, and the solves spent."""

    status: Literal["solved", "unbounded", "infeasible"]
    value: float
    z: np.ndarray | None
    exact: bool
    solves: int
    dead: tuple[tuple[int, Piece], ...] = ()  # (step, piece) with no trajectory: the root program plus the piece is infeasible


def settle(status: str) -> Literal["solved", "unbounded", "infeasible", "other"]:
    if status in _SOLVED:
        return "solved"
    if status in _UNBOUNDED:
        return "unbounded"
    return "infeasible" if status in _INFEASIBLE else "other"


def _expand(conic: Conic, x: np.ndarray, nz: int) -> np.ndarray:
    z = np.zeros(nz)
    z[conic.cols] = x
    return z


@dataclass(order=True)
class _Node:
    bound: float
    order: int
    chosen: frozenset[int]  # unions (by position in the list) whose piece is fixed
    rows: tuple[Row, ...]
    z: np.ndarray | None  # the relaxation's minimiser (global columns); None: unbounded


def _branch_on(unions: Sequence[StepUnion], node: _Node) -> int | None:
    """The union to branch on: the latest step the minimiser violates; for an unbounded relaxation (no
    minimiser) the latest one not yet chosen.  None: the node is a leaf (its relaxation is exact)."""
    for m in range(len(unions) - 1, -1, -1):
        if m not in node.chosen and (node.z is None or not unions[m].holds(node.z)):
            return m
    return None


def minimise(conic: Conic, q: np.ndarray, nz: int, unions: Sequence[StepUnion], root: tuple[str, np.ndarray | None], budget: int) -> EndResult:
    """min q·z over the program and every union (module doc), from the root relaxation ``root`` (its status and
    minimiser over the global columns).  At most ``budget`` solves; past it the least open bound, not exact."""
    kind = settle(root[0])
    assert kind != "other", root[0]  # the caller reports a root the solver could not settle
    if kind == "infeasible":
        return EndResult("infeasible", math.nan, None, True, 0)
    counter = itertools.count()
    z0 = root[1]
    heap = [_Node(-math.inf if z0 is None else float(q @ z0[conic.cols]), next(counter), frozenset(), (), z0)]
    solves, dead = 0, list[tuple[int, Piece]]()
    while heap:
        node = heapq.heappop(heap)
        m = _branch_on(unions, node)
        if m is None:  # every step's union holds at the least bound of all open nodes: the minimum
            if node.z is None:
                return EndResult("unbounded", -math.inf, None, True, solves, tuple(dead))
            return EndResult("solved", node.bound, node.z, True, solves, tuple(dead))
        pieces = unions[m].pieces
        if solves + len(pieces) > budget:
            return EndResult("unbounded" if node.z is None else "solved", node.bound, None, False, solves, tuple(dead))
        for piece in pieces:
            rows = node.rows + tuple(unions[m].rows(piece))
            status, x = conic.solve(q, rows)
            solves += 1
            kind = settle(status)
            if kind == "other":  # a child the solver could not settle cannot be pruned: stop at the least bound
                return EndResult("unbounded" if node.z is None else "solved", node.bound, None, False, solves, tuple(dead))
            if kind == "infeasible":
                if not node.chosen:
                    dead.append((unions[m].step, piece))
                continue
            z = None if x is None else _expand(conic, x, nz)
            heapq.heappush(heap, _Node(-math.inf if z is None else float(q @ x), next(counter), node.chosen | {m}, rows, z))
    return EndResult("infeasible", math.nan, None, True, solves, tuple(dead))


__all__ = ["HEALTH_TOL", "Conic", "EndResult", "Piece", "Row", "Span", "StepUnion", "covered", "minimise", "settle", "step_pieces"]
