"""The k-of-N health assumption in the exact limit: branch and bound over each step's pieces (docs/exact.md).

Under ``[network] max_faulty = m`` at least need = N − m sensors are healthy (|f_i,j| ≤ τ) at every step j
(with several ``[[network.health_groups]]``, in each group: one union per group and step, N and m the group's).
Every sensor measures t = uᵀx (C_i = s_i uᵀ, checked when the topology is loaded), so a healthy sensor's
measurement rows put t_j in its span I_i,j (the measured interval widened by |Ds_i|τ, over s_i).  Whether a
sensor's health is a condition on t_j alone depends on its fault variable:

- *untied*: f_i,j appears only in its own measurement rows (no declared bound, 0 < j, not the objective),
  or also in declared bounds that every healthy value meets whatever its neighbours (the caller decides), so
  some |f_i,j| ≤ τ meets them exactly when t_j ∈ I_i,j: health is t_j ∈ I_i,j;
- *tied*: f_i,j also enters a prior (j = 0), a declared fault bound a healthy value could break, or the
  objective: health is |f_i,j| ≤ τ itself.

The step's feasible set is then exactly the union of convex *pieces*: for each set Q of tied sensors
assumed healthy (|Q| ≤ need), a maximal interval of t_j inside ∩_{q∈Q} I_q that at least need − |Q|
untied spans cover, with |f_q,j| ≤ τ for q ∈ Q.  :func:`minimise` is a best-first branch and bound over
them: the relaxation leaves every unchosen step's union out, a node whose minimiser meets every step's
union is optimal (it has the least bound of all open nodes), otherwise it branches into the pieces of one
violated step; before it, one *dive* tries the pieces the same end chose at the previous horizon, all at once
(one solve where the search would branch once per union), a child whose piece's interval bounds the objective
past the incumbent is never solved, and a minimiser that misses a union only by tied faults is mended, not branched
on (:func:`_repaired`: the faults clipped to τ where every row still holds; its value is then proven).  Before the
root, :func:`guided` solves once with the previous horizon's pieces and proves the end by the duals of their rows
where it can (one solve where the root and the dive take two).  Past the
budget of solves, or past the run's deadline (CPU time), it stops with the least open bound: an outer bound
(sound), reported as relaxed.  The solvers of the nodes are kept for the
other ends of the same program (the same rows, another objective), at most :data:`MAX_SOLVERS` of them (least
recently used out): what the search keeps is bounded, whatever the number of branches.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
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
    healthy: tuple[int, ...]  # sensor positions (in its group) of tied faults assumed healthy
    group: int = 0  # the k-of-N group it belongs to: pieces of different groups are different constraints

    def within(self, other: Piece) -> bool:
        return set(other.healthy) <= set(self.healthy) and other.lo <= self.lo and self.hi <= other.hi


Path = tuple[tuple[int, Piece], ...]  # the (step, piece) a node chose, in order

RETRY_REGULARIZATION = 1e-7  # a branch the solver stopped on (NumericalError) is solved once more with this static regularization (default 1e-8)
MAX_SOLVERS = 64  # branch solvers kept per program: each holds its KKT factorisation (~1 MB at 80 steps, 12 nodes)


class Solvers:
    """A node's solver by its path (the same rows for every end of one program, only q changes), at most
    ``size`` of them, the least recently used dropped first: unbounded, this cache held every branch of every
    end of a horizon and grew by about 1 GB a minute on a 12-node ring with two groups (issue 34)."""

    def __init__(self, size: int = MAX_SOLVERS) -> None:
        self.size = size
        self._kept: OrderedDict[tuple, clarabel.DefaultSolver] = OrderedDict()
        self.built = 0  # solvers made (the others were reused)

    def get(self, path: tuple) -> clarabel.DefaultSolver | None:
        solver = self._kept.get(path)
        if solver is not None:
            self._kept.move_to_end(path)
        return solver

    def put(self, path: tuple, solver: clarabel.DefaultSolver) -> None:
        self.built += 1
        self._kept[path] = solver
        if len(self._kept) > self.size:
            self._kept.popitem(last=False)

    def __len__(self) -> int:
        return len(self._kept)


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


def interval_rows(terms: dict[int, float], span: Span) -> list[Row]:
    """lo ≤ Σ terms[c]·z[c] ≤ hi as rows a·z ≤ b; an infinite side gives none."""
    lo, hi = span
    return ([(dict(terms), hi)] if math.isfinite(hi) else []) + ([({c: -v for c, v in terms.items()}, -lo)] if math.isfinite(lo) else [])


def _clip(parts: list[Span], lo: float, hi: float) -> list[Span]:
    return [(max(a, lo), min(b, hi)) for a, b in parts if max(a, lo) <= min(b, hi)]


def step_pieces(spans: Sequence[Span], tied: Sequence[bool], allowed: Sequence[bool], need: int, window: Span, group: int = 0) -> list[Piece] | None:
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
        for healthy in itertools.combinations(candidates, q):
            lo = max([window[0], *(spans[n][0] for n in healthy)])
            hi = min([window[1], *(spans[n][1] for n in healthy)])
            pieces += [Piece(a, b, healthy, group) for a, b in _clip(covered(untied, need - q), lo, hi)]
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
    t_before: dict[int, float] | None = None  # t_(j−1) = Σ t_before[c]·z[c], the same direction a step earlier (None at step 0)

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
        out = interval_rows(self.t, (piece.lo, piece.hi))
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

    @cached_property
    def position(self) -> dict[int, int]:
        """Global column → position in ``cols``."""
        return {int(c): m for m, c in enumerate(self.cols)}

    def with_rows(self, rows: Sequence[Row], equal: Sequence[Row] = ()) -> Conic:
        """The same program with ``rows`` (a·z ≤ b) added as one more non-negative cone, then ``equal`` (a·z = b) as
        a zero cone."""
        if not rows and not equal:
            return self
        position = self.position
        data, ri, ci = [], [], []
        for r, (terms, _) in enumerate([*rows, *equal]):
            for c, v in terms.items():
                ri.append(r)
                ci.append(position[c])
                data.append(v)
        extra = sparse.csc_matrix((data, (ri, ci)), shape=(len(rows) + len(equal), len(self.cols)))
        b = np.r_[self.b, [rhs for _, rhs in [*rows, *equal]]]
        cones = [*self.cones, *([clarabel.NonnegativeConeT(len(rows))] if rows else []), *([clarabel.ZeroConeT(len(equal))] if equal else [])]
        return Conic(self.cols, sparse.vstack([self.A, extra], format="csc"), b, cones, self.settings)

    @cached_property
    def _cone_of_row(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row: its cone's kind (0 zero, 1 non-negative, 2 second-order, 3 other), first row and dimension."""
        kinds = {clarabel.ZeroConeT: 0, clarabel.NonnegativeConeT: 1, clarabel.SecondOrderConeT: 2}
        kind, first, dim, at = [], [], [], 0
        for cone in self.cones:
            kind += [kinds.get(type(cone), 3)] * cone.dim
            first += [at] * cone.dim
            dim += [cone.dim] * cone.dim
            at += cone.dim
        return np.array(kind), np.array(first), np.array(dim)

    def violation(self, s: np.ndarray, rows: np.ndarray | None = None) -> float:
        """How far the slacks ``s`` = b − A·x are from their cones over ``rows`` (their cones; default every row):
        the largest residual of an equality, shortfall of an inequality or of a second-order cone (0: none)."""
        kind, first, dim = self._cone_of_row
        rows = np.arange(len(s)) if rows is None else rows
        k: np.ndarray = kind[rows]  # (typed once: mypy spent over a second resolving numpy's overloads on kind[rows] inferred four times)
        worst = float(np.abs(s[rows[k == 0]]).max(initial=0.0))
        worst = max(worst, float(-s[rows[k == 1]].min(initial=0.0)))
        for start in np.unique(first[rows[k == 2]]):
            part = s[start : start + dim[start]]
            worst = max(worst, float(np.linalg.norm(part[1:]) - part[0]))
        return math.inf if np.any(k == 3) else worst

    def moved(self, s: np.ndarray, cols: Sequence[int], delta: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """The slacks after x[cols] += delta (positions in ``cols`` of the program), and the rows that changed."""
        out, rows = s.copy(), []
        for c, d in zip(cols, delta):
            span = slice(self.A.indptr[c], self.A.indptr[c + 1])
            out[self.A.indices[span]] -= self.A.data[span] * d
            rows.append(self.A.indices[span])
        return out, np.concatenate(rows) if rows else np.zeros(0, dtype=int)

    def solver(self, q: np.ndarray, regularization: float | None = None) -> clarabel.DefaultSolver:
        """A solver of min q·z (``regularization``: Clarabel's static regularization for this one, else the settings')."""
        n = len(self.cols)
        if regularization is None:
            return clarabel.DefaultSolver(sparse.csc_matrix((n, n)), q, self.A, self.b, self.cones, self.settings)
        usual, self.settings.static_regularization_constant = self.settings.static_regularization_constant, regularization
        try:
            return clarabel.DefaultSolver(sparse.csc_matrix((n, n)), q, self.A, self.b, self.cones, self.settings)
        finally:
            self.settings.static_regularization_constant = usual


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
    guided: bool = False  # settled by :func:`guided`'s one solve, not from the root


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


Guide = tuple[int, np.ndarray]  # an earlier horizon's last step and its minimiser of the same end (global columns)
DIVE_ROUNDS = 3  # pieces added at most three times in the dive: a guide that misses costs at most three solves
GAP_TOL = 1e-9  # relative: the search stops once the best trajectory found is within this of the least open bound


@dataclass(order=True)
class _Node:
    """An open node: its bound (a lower bound of q·z over its region), unsolved (``lazy``: the parent's bound)
    or solved; at equal bounds a solved node comes first and then the order the children were made in."""

    bound: float
    lazy: bool
    order: int
    chosen: frozenset[int] = field(compare=False)  # unions (by position in the list) whose piece is fixed
    rows: tuple[Row, ...] = field(compare=False)
    z: np.ndarray | None = field(compare=False, default=None)  # the minimiser (global columns); None: unbounded or lazy
    path: Path = field(compare=False, default=())


def _repaired(conic: Conic, unions: Sequence[StepUnion], node: _Node, objective: int) -> np.ndarray | None:
    """A solved node's minimiser moved into the unions it violates only by tied faults: for each, the first piece
    (nearest first) whose interval holds its t_j, with that piece's tied faults clipped to [−τ, τ], where the
    program's rows hold as well as at the solver's minimiser (:meth:`Conic.violation`).  The objective's column
    is never moved, so the point reaches the node's value: a trajectory that proves it without a solve.  An
    interior-point minimiser lies in the middle of its optimal face, so where the end does not care about a tied
    fault (step 0's, tied by the priors: every root of paper6_max_faulty SAIM missed that union) it leaves the
    fault off zero.  None if some union is not mended (a t_j between pieces needs a solve: the dive's)."""
    assert node.z is not None
    z = node.z
    missed = [union for m, union in enumerate(unions) if m not in node.chosen and not union.holds(z)]
    ts = [sum(v * z[c] for c, v in union.t.items()) for union in missed]
    if not all(any(p.lo - HEALTH_TOL <= t <= p.hi + HEALTH_TOL for p in union.pieces) for union, t in zip(missed, ts)):
        return None  # a t_j between pieces: no clipping of faults mends it
    slack = conic.b - conic.A @ z[conic.cols]
    allowed = conic.violation(slack)  # the solver's own precision: mending may not make it worse
    for union, t in zip(missed, ts):
        mended = _mended(conic, union, t, z, slack, allowed, objective)
        if mended is None:
            return None
        z, slack = mended
    return z


def _mended(conic: Conic, union: StepUnion, t: float, z: np.ndarray, slack: np.ndarray, allowed: float, objective: int) -> tuple[np.ndarray, np.ndarray] | None:
    """One union :func:`_repaired` mends: the point and the rows' slack with the first piece (nearest first) holding
    t whose tied faults clipped to [−τ, τ] meet the union, the rows no worse than ``allowed``; None if no piece does."""
    for piece in sorted(union.pieces, key=lambda p: _distance(union, p, z)):
        cols = [c for c in (union.f_col[n] for n in piece.healthy) if c is not None]
        if not piece.lo - HEALTH_TOL <= t <= piece.hi + HEALTH_TOL or objective in cols:
            continue
        trial = z.copy()
        trial[cols] = np.clip(trial[cols], -union.tolerance, union.tolerance)
        moved, rows = conic.moved(slack, [conic.position[c] for c in cols], trial[cols] - z[cols])
        if union.holds(trial) and conic.violation(moved, rows) <= allowed:
            return trial, moved
    return None


def _branch_on(unions: Sequence[StepUnion], node: _Node) -> int | None:
    """The union to branch on: the latest step the minimiser violates; for an unbounded relaxation (no
    minimiser) the latest one not yet chosen.  None: the node's minimiser meets every union (or, unbounded,
    every union is chosen: its relaxation is exact)."""
    for m in range(len(unions) - 1, -1, -1):
        if m not in node.chosen and (node.z is None or not unions[m].holds(node.z)):
            return m
    return None


def _distance(union: StepUnion, piece: Piece, z: np.ndarray | None) -> float:
    """How far the parent's minimiser is from the piece: the child to solve first is the nearest."""
    if z is None:
        return 0.0
    t = sum(v * z[c] for c, v in union.t.items())
    out = max(0.0, piece.lo - t, t - piece.hi)
    return out + sum(max(0.0, abs(z[c]) - union.tolerance) for c in (union.f_col[n] for n in piece.healthy) if c is not None)


@dataclass
class _Search:
    """Best-first branch and bound of one end (see :func:`minimise`)."""

    conic: Conic
    q: np.ndarray
    nz: int
    unions: Sequence[StepUnion]
    budget: int
    deadline: float = math.inf  # time.process_time() past which no node is solved
    objective: tuple[int, float] = (-1, 0.0)  # q·z = sign·z[col] (global column): every end's objective
    heap: list[_Node] = field(default_factory=list)
    solves: int = 0
    dead: list[tuple[int, Piece]] = field(default_factory=list)
    best: tuple[float, np.ndarray] | None = None  # the least q·z of a minimiser that meets every union
    order: itertools.count = field(default_factory=itertools.count)
    solvers: Solvers = field(default_factory=Solvers)

    def result(self, status: Literal["solved", "unbounded", "infeasible"], value: float, exact: bool) -> EndResult:
        z = self.best[1] if exact and self.best is not None else None
        return EndResult(status, value, z, exact, self.solves, tuple(self.dead))

    def solve(self, node: _Node) -> tuple[Literal["solved", "unbounded", "infeasible", "other"], _Node | None]:
        """Solve a lazy node: its kind and, solved or unbounded, the node with its bound and minimiser."""
        solver = self.solvers.get(node.path)
        if solver is None:
            solver = self.conic.with_rows(node.rows).solver(self.q)
            self.solvers.put(node.path, solver)
        else:
            solver.update(q=self.q)
        sol = solver.solve()
        if settle(str(sol.status)) == "other":  # e.g. NumericalError on a piece that barely meets the program: once more, regularized
            sol = self.conic.with_rows(node.rows).solver(self.q, RETRY_REGULARIZATION).solve()
            self.solves += 1
        status, x = str(sol.status), np.asarray(sol.x) if str(sol.status) in _SOLVED else None
        self.solves += 1
        kind = settle(status)
        if kind == "infeasible" and len(node.path) == 1:  # the root's program and one piece: no trajectory in any later horizon either
            self.dead.append(node.path[0])
        if kind in ("other", "infeasible"):
            return kind, None
        z = None if x is None else _expand(self.conic, x, self.nz)
        value = -math.inf if x is None else float(self.q @ x)
        # a child no worse than its parent to the gap keeps the parent's bound: it is then explored before its siblings
        bound = node.bound if value <= node.bound + GAP_TOL * max(1.0, abs(node.bound)) else value
        return kind, _Node(bound, False, next(self.order), node.chosen, node.rows, z, node.path)

    def keep(self, solved: _Node) -> bool:
        """A solved node's minimiser that meets every union, or mended to (:func:`_repaired`), is a trajectory (the
        incumbent if the best): True."""
        z = solved.z if solved.z is None or _branch_on(self.unions, solved) is None else _repaired(self.conic, self.unions, solved, self.objective[0])
        if z is None:
            return False
        if self.best is None or solved.bound < self.best[0]:
            self.best = (solved.bound, z)
        return True

    def settle_node(self, node: _Node) -> bool:
        """Solve a lazy node and keep it (or the trajectory it found); False if the solver could not settle it."""
        kind, solved = self.solve(node)
        if solved is not None and not self.keep(solved):
            heapq.heappush(self.heap, solved)
        return kind != "other"

    def spent(self) -> bool:
        return self.solves >= self.budget or time.process_time() >= self.deadline

    def dive(self, root: _Node, guide: Guide | None) -> None:
        """One path tried before the search, all its pieces at once: for each union the minimiser violates, the
        piece nearest the guide (a trajectory of an earlier horizon, for its steps) or else the minimiser.  A
        trajectory found is only an incumbent (the search still proves the end); when the relaxation's minimiser
        lands between pieces only because the objective does not care, it reaches the root's bound in one solve
        where the search would branch once per union (docs/exact.md, measured)."""
        node = root
        for _ in range(DIVE_ROUNDS):
            violated = [m for m in range(len(self.unions)) if m not in node.chosen and (node.z is None or not self.unions[m].holds(node.z))]
            if not violated or self.spent() or any(not self.unions[m].pieces for m in violated):
                return  # a union with no piece left: the search proves the end infeasible
            rows, path = node.rows, node.path
            for m in violated:
                union = self.unions[m]
                ref = guide[1] if guide is not None and union.step <= guide[0] else node.z
                piece = min(union.pieces, key=lambda p: _distance(union, p, ref))
                rows, path = rows + tuple(union.rows(piece)), (*path, (union.step, piece))
            kind, solved = self.solve(_Node(node.bound, True, next(self.order), node.chosen | set(violated), rows, None, path))
            if solved is None or self.keep(solved):
                return
            node = solved

    def branch(self, node: _Node, m: int) -> None:
        union = self.unions[m]
        for piece in sorted(union.pieces, key=lambda p: _distance(union, p, node.z)):
            path = (*node.path, (union.step, piece))
            bound = max(node.bound, self.piece_bound(union, piece))  # a child its interval puts past the incumbent is never solved
            heapq.heappush(self.heap, _Node(bound, True, next(self.order), node.chosen | {m}, node.rows + tuple(union.rows(piece)), None, path))

    def piece_bound(self, union: StepUnion, piece: Piece) -> float:
        """A lower bound of the objective over a piece, without solving: where the objective is a multiple of t_j
        (the yaw rate of the piece's step) its interval bounds it, and a tied fault assumed healthy by τ."""
        col, sign = self.objective
        if len(union.t) == 1 and col in union.t:
            a = sign / union.t[col]  # objective = a·t_j
            return min(a * piece.lo, a * piece.hi)  # a ≠ 0: an infinite side gives −inf only where it is the minimum
        if any(union.f_col[n] == col for n in piece.healthy):
            return -abs(sign) * union.tolerance
        return -math.inf

    def run(self, root: _Node, guide: Guide | None = None) -> EndResult:
        if self.best is None:  # else a trajectory is known already (:func:`guided`'s): the dive would look for one
            self.dive(root, guide)
        heapq.heappush(self.heap, root)
        while self.heap:
            node = heapq.heappop(self.heap)
            if self.best is not None and self.best[0] <= node.bound + GAP_TOL * max(1.0, abs(node.bound)):
                return self.result("solved", min(self.best[0], node.bound), True)  # the end to the gap, on the sound side
            status: Literal["solved", "unbounded"] = "unbounded" if node.bound == -math.inf else "solved"
            if node.lazy:
                if self.spent() or not self.settle_node(node):
                    return self.result(status, node.bound, False)  # the least open bound: an outer bound
                continue
            m = _branch_on(self.unions, node)
            if m is None:  # an unbounded relaxation with every union chosen: exact
                return self.result("unbounded", -math.inf, True)
            self.branch(node, m)
        return self.result("solved", self.best[0], True) if self.best is not None else self.result("infeasible", math.nan, True)


POINT_WIDTH = 1e-9  # relative: a piece this narrow is its midpoint (one equality), not two rows whose multipliers split


def _certified_below(union: StepUnion, piece: Piece, duals: np.ndarray) -> float:
    """What the piece's rows can take off the dual bound over the union: the least of Σ y·(b − a·z) for t_j in the
    union's hull (every trajectory meeting the union has its t_j in one of its pieces).  Rows: lo ≤ t_j ≤ hi (the
    order of :func:`interval_rows`, the upper side first; duals y ≥ 0), giving y_hi·(hi − t) + y_lo·(t − lo); or, for
    a point piece, t_j = its midpoint c (one dual of either sign), giving y·(c − t).  −inf where the hull is
    unbounded on a side the duals reward."""
    lo_hull, hi_hull = min(p.lo for p in union.pieces), max(p.hi for p in union.pieces)
    if _is_point(piece):
        (y,) = duals
        y_hi, y_lo, hi, lo = y, 0.0, _midpoint(piece), 0.0
    else:
        rest = iter(duals)
        y_hi = next(rest) if math.isfinite(piece.hi) else 0.0
        y_lo = next(rest) if math.isfinite(piece.lo) else 0.0
        hi, lo = piece.hi, piece.lo
    slope = y_lo - y_hi  # d/dt of y_hi·(hi − t) + y_lo·(t − lo)
    at = lo_hull if slope >= 0 else hi_hull  # the least of a linear function on the hull: the end its slope points from
    if not math.isfinite(at):
        return 0.0 if slope == 0 else -math.inf
    return (y_hi * (hi - at) if y_hi else 0.0) + (y_lo * (at - lo) if y_lo else 0.0)


def _is_point(piece: Piece) -> bool:
    return math.isfinite(piece.lo) and math.isfinite(piece.hi) and piece.hi - piece.lo <= POINT_WIDTH * max(1.0, abs(piece.lo))


def _midpoint(piece: Piece) -> float:
    return 0.5 * (piece.lo + piece.hi)


@dataclass(frozen=True)
class GuidedStart:
    """What :func:`guided` found: the end settled in one solve, or else the trajectory it found (its q·z and the
    point), which the search then starts from instead of diving (:meth:`_Search.dive`); and the solves spent."""

    end: EndResult | None
    solves: int
    incumbent: tuple[float, np.ndarray] | None = None


def _guided_pieces(unions: Sequence[StepUnion], guide: Guide) -> tuple[list[tuple[StepUnion, Piece]], list[StepUnion]]:
    """:func:`guided`'s pieces: (union, piece) for every union of several pieces the guide covers (at an earlier step
    the piece nearest its minimiser, at the current one the piece nearest its last t) where that piece has a tied
    fault, and the unions of one piece."""
    last, ref = guide
    chosen = []  # (union, piece) whose rows the duals answer for over the union's hull
    convex = []  # unions of one piece: every trajectory meets its rows, so their duals take nothing off the bound
    for union in unions:
        if len(union.pieces) == 1:
            convex.append(union)
            continue
        if not union.pieces or union.step > last + 1:
            continue
        if union.step <= last:
            piece = min(union.pieces, key=lambda p: _distance(union, p, ref))
        elif union.t_before is not None:  # the current step: nearest the guide's t at its last step (t changes little in a step)
            t_last = sum(v * ref[c] for c, v in union.t_before.items())
            piece = min(union.pieces, key=lambda p: max(0.0, p.lo - t_last, t_last - p.hi))
        else:
            continue
        if not piece.healthy:
            chosen.append((union, piece))
    return chosen, convex


def guided(conic: Conic, q: np.ndarray, nz: int, unions: Sequence[StepUnion], guide: Guide, solvers: Solvers) -> GuidedStart:
    """One solve that may settle an end before its root relaxation: the program with, for every earlier step the guide
    (the same end's minimiser of the previous horizon) covers, the piece of t_j it chose, and for the current step the
    piece nearest the guide's last t (t changes little from one step to the next); pieces of t_j alone: a tied fault's
    pair of rows |f| ≤ τ = 0 splits its multipliers and certifies nothing (docs/exact.md), and a point piece is one
    equality for the same reason.  Its minimiser, where it meets every union (or is mended to, :func:`_repaired`), is a
    trajectory: an upper bound.  Its duals y give a lower bound of the end over every union by weak duality: for any z
    of the root's program, q·z ≥ −b·y + Σ_piece rows y·(b − a·z), the last term bounded below over the union's hull of
    t_j (:func:`_certified_below`).  When the two meet to :data:`GAP_TOL` the end is the lower one, exact, in one solve
    where the root and the dive take two; otherwise the caller searches from the root, with that trajectory if any."""
    chosen, convex = _guided_pieces(unions, guide)
    settled = [row for union in convex for row in union.rows(union.pieces[0])]
    rows = settled + [row for union, piece in chosen if not _is_point(piece) for row in union.rows(piece)]
    equal = [(dict(union.t), _midpoint(piece)) for union, piece in chosen if _is_point(piece)]
    if not rows and not equal:
        return GuidedStart(None, 0)
    path: Path = tuple((union.step, union.pieces[0]) for union in convex) + tuple((union.step, piece) for union, piece in chosen)
    key = (len(convex), *path)  # a one-piece union brings all its rows, a chosen point an equality: the count says which
    solver = solvers.get(key)
    program = conic.with_rows(rows, equal)
    if solver is None:
        solver = program.solver(q)
        solvers.put(key, solver)
    else:
        solver.update(q=q)
    sol = solver.solve()
    if settle(str(sol.status)) != "solved":
        return GuidedStart(None, 1)
    x, y = np.asarray(sol.x), np.asarray(sol.z)
    below = -float(program.b @ y)  # the dual objective: a lower bound of q·z over the program without the pieces' rows, once
    at, at_equal = len(conic.b) + len(settled), len(conic.b) + len(rows)  # after the one-piece unions' rows, the chosen pieces', then the points
    for union, piece in chosen:
        if _is_point(piece):
            below += _certified_below(union, piece, y[at_equal : at_equal + 1])
            at_equal += 1
        else:
            n = math.isfinite(piece.hi) + math.isfinite(piece.lo)
            below += _certified_below(union, piece, y[at : at + n])
            at += n
    node = _Node(float(q @ x), False, 0, frozenset(), tuple(rows + equal), _expand(conic, x, nz), path)
    (col,) = conic.cols[np.flatnonzero(q)]
    z = node.z if _branch_on(unions, node) is None else _repaired(program, unions, node, int(col))
    if z is None:
        return GuidedStart(None, 1)
    if not (math.isfinite(below) and node.bound <= below + GAP_TOL * max(1.0, abs(below))):  # a bound −inf or NaN proves nothing
        return GuidedStart(None, 1, (node.bound, z))
    return GuidedStart(EndResult("solved", min(node.bound, below), z, True, 1), 1)


def minimise(
    conic: Conic,
    q: np.ndarray,
    nz: int,
    unions: Sequence[StepUnion],
    root: tuple[str, np.ndarray | None],
    budget: int,
    solvers: Solvers | None = None,
    deadline: float = math.inf,
    guide: Guide | None = None,
    incumbent: tuple[float, np.ndarray] | None = None,
) -> EndResult:
    """min q·z over the program and every union (module doc), from the root relaxation ``root`` (its status and
    minimiser over the global columns).  At most ``budget`` solves; past it the least open bound, not exact.
    ``solvers``: the nodes' solvers by path, shared by the ends of one program (a path's rows are the same for
    every end, only q changes); ``deadline``: a time.process_time() past which no more nodes are solved (relaxed);
    ``guide``: (its last step, a minimiser over the global columns) of the same end at an earlier horizon, whose
    pieces are tried first (:meth:`_Search.dive`); ``incumbent``: a trajectory known already (its q·z, the point), then
    no dive."""
    kind = settle(root[0])
    assert kind != "other", root[0]  # the caller reports a root the solver could not settle
    if kind == "infeasible":
        return EndResult("infeasible", math.nan, None, True, 0)
    z = root[1]
    node = _Node(-math.inf if z is None else float(q @ z[conic.cols]), False, 0, frozenset(), (), z)
    (at,) = np.flatnonzero(q)  # one coordinate's end
    if z is not None:
        mended = z if _branch_on(unions, node) is None else _repaired(conic, unions, node, int(conic.cols[at]))
        if mended is not None:
            return EndResult("solved", node.bound, mended, True, 0)
    search = _Search(conic, q, nz, unions, budget, deadline, (int(conic.cols[at]), float(q[at])), order=itertools.count(1))
    search.solvers = Solvers() if solvers is None else solvers
    search.best = incumbent
    return search.run(node, guide)


__all__ = [
    "HEALTH_TOL",
    "MAX_SOLVERS",
    "Conic",
    "EndResult",
    "Guide",
    "Piece",
    "Path",
    "Row",
    "Solvers",
    "Span",
    "StepUnion",
    "covered",
    "GuidedStart",
    "guided",
    "interval_rows",
    "minimise",
    "settle",
    "step_pieces",
]
