"""The exact limit: the tightest intervals any guaranteed estimator could publish from a run's data.

For every step k and node i, :func:`exact_bounds` computes the smallest and largest value of f_i,k, β_k
and r_k over every trajectory that meets the run's assumptions and reproduces every measurement of
steps 0..k of every node (centralized: no networked estimator can be tighter).  Decision variables are
z = [x_0, w_0..w_{k−1}, f_i,0..k (every node i)]; the state is affine in z through the known scheduled
dynamics x_{j+1} = Ā_j x_j + B̄_j u_j + D̄_j w_j + e_j (α_j from the recorded speed; e_j ≡ 0 unless the topology
declares a ``[model_uncertainty]``, docs/plant.md), and the noise is eliminated:

    node i's prior:        ‖P0_i^{-½}([x_0; f_i,0] − x̂0_i)‖ ≤ √ρ_i                  (second-order cone)
    wind:                  |w_j| ≤ √W
    model mismatch:        e_j in the declared box (linear) or ellipsoid (SOC(3)), where one is declared
    measurement (i, j):    σ(C̄_i x̄_i,j) ∈ [(ỹ − |Dv|√R)/γ, (ỹ + |Dv|√R)/γ]  ⇔  C̄_i x̄_i,j ∈ [lo, hi]
                           (only where node i has a reading at step j: a recorded drive's gap has no row)
    declared fault bounds: |f_i,j+1 − f_i,j| ≤ δ_i,  |f_i,j| ≤ F_i   (where ``fault_bounds`` applies them)

σ is the identity in NSNIM; in SAIM it is the saturation sign(r)·min(r_max, |r|), monotone and the
identity on [−r_max, r_max], so its preimage of an interval is an interval whose side is open (±∞) where
the measured interval reaches ±r_max.  Every constraint is linear or a cone, so each bound is one
Clarabel solve (an SOCP); the solves of one horizon share one factorisation structure (only the
objective changes).  The solver's argument at each bound is a *witness*: a trajectory reaching it.
Derivation and measured figures: docs/exact.md.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Literal

import math
import time

import clarabel
import numpy as np
from scipy import sparse

from netsetest.analysis.errors import ExactError
from netsetest.analysis.kofn import (
    Conic,
    EndResult,
    Guide,
    GuidedStart,
    Piece,
    Row,
    Solvers,
    Span,
    StepUnion,
    guided,
    interval_rows,
    minimise,
    settle,
    step_pieces,
)
from netsetest.config.schema import FaultBoundsMode, NodeConfig, Scenario
from netsetest.estimator.health import HealthModel
from netsetest.records.record import Record

Coordinate = Literal["beta", "r", "f"]
COORDINATES: tuple[Coordinate, ...] = ("beta", "r", "f")
Side = Literal["lo", "hi"]

FROM_STEP = 10  # ratios "from step 10" leave out the start-up transient of the estimators
DEGENERATE_WIDTH = 1e-6  # a mean exact width below it is a point (a declared zero), not an interval to compare
NARROWER_TOL = 1e-8  # solver precision of the exact ends (measured ≤ 2e-9 over 80 steps) with margin
PIECE_MARGIN = 1e-12  # relative widening of each k-of-N interval: ~10⁴ ulps, far below what the witnesses are checked to (1e-8)
SOLVER_TOL = 1e-10  # Clarabel gap and feasibility tolerances: witnesses meet every constraint to ~1e-9
HEALTH_BUDGET = 400  # solves per interval end for the k-of-N branch and bound; past it the end is relaxed
GUIDED_RETRY = 8  # horizons an end's guided solve is not tried after it failed (kofn.guided)
CUT_MARGIN = 1e-8  # a past step's end is loosened by this (relative) before it bounds later horizons: solver precision


@dataclass(frozen=True)
class RecordedStep:
    """What every node knows at step k (the vehicle publishes it): u_k, Vx_k, and each ỹ_i,k, γ_i,k; a node in
    ``no_reading`` (a recorded drive's gap, docs/your-log.md) has no ỹ_i,k: its measurement constraint is absent."""

    step: int
    u: float
    vx: float
    y: dict[int, float]
    gamma: dict[int, float]
    no_reading: tuple[int, ...] = ()


@dataclass(frozen=True)
class Witness:
    """A trajectory reaching one end of an exact interval: x_0, w_0..w_{k−1}, f_i,0..k of every node."""

    x0: np.ndarray  # (2,)
    w: np.ndarray  # (k,)
    f: dict[int, np.ndarray]  # node → (k+1,)
    e: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (k, 2) model mismatch (declared bound only)


@dataclass(frozen=True)
class WitnessKey:
    coordinate: Coordinate
    node: int | None  # None for the state coordinates β, r (shared by every node)
    step: int
    side: Side


@dataclass(frozen=True)
class HealthSearch:
    """How :func:`exact_bounds` applied ``[network] max_faulty`` (branch and bound, docs/exact.md): every end
    is exact but those in ``relaxed``, where the budget ran out and the end is the least bound proven (an outer
    bound of the exact one, at worst the program without the assumption)."""

    declared: str  # the declaration (Scenario.health_label)
    need: tuple[int, ...]  # per group, sensors healthy at every step: |S| − m of the program's nodes S in it
    nodes: tuple[tuple[int, ...], ...]  # per group, those nodes S (the group's within the nodes the program has)
    budget: int  # solves per end
    ends: int
    exact_ends: int
    relaxed: tuple[WitnessKey, ...]
    solves: int
    budget_s: float | None = None  # the whole computation's time budget (CPU seconds of this process; None: none)
    out_of_time: int | None = None  # the step during which it ran out: the search of every later end was cut short


@dataclass(frozen=True)
class ExactBounds:
    """Per step: the exact intervals of β, r (all nodes) and of each node's fault; ±inf where unbounded.

    ``infeasible_steps``: steps whose data contradict the assumptions (no trajectory exists; NaN bounds).
    """

    steps: np.ndarray  # (K,)
    beta: np.ndarray  # (K, 2) lower, upper
    r: np.ndarray  # (K, 2)
    fault: dict[int, np.ndarray]  # node → (K, 2)
    fault_bounds: FaultBoundsMode
    bounded_nodes: tuple[int, ...]  # nodes whose declared fault bounds were applied
    infeasible_steps: tuple[int, ...]
    witnesses: dict[WitnessKey, Witness] = field(default_factory=dict)
    # declared assumptions the program leaves out: the limit is then an outer bound of the exact one, and a
    # node that uses them may be narrower than it (the k-of-N health when not applied: ``health=False``)
    omitted: tuple[str, ...] = ()
    health: HealthSearch | None = None  # the k-of-N branch and bound, where applied
    # the network limit (exact_bounds(network=True)): node → its own β and r (K, 2) each; ``beta`` and ``r`` are then
    # unused (NaN), and ``fault[i]`` is node i's own network limit
    by_node: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    # (node, step) of the program's nodes without a reading (a recorded drive's gaps): no measurement row there
    no_reading: tuple[tuple[int, int], ...] = ()

    @property
    def network(self) -> bool:
        """Whether these are network limits (one per node) rather than the central one."""
        return bool(self.by_node)

    @property
    def label(self) -> str:
        """The reference in a few words: the fault-bounds mode and what else was applied or left out."""
        applied = (" network" if self.by_node else "") + (" with k-of-N health" if self.health is not None else "")
        relaxed = f" ({len(self.health.relaxed)} ends relaxed)" if self.health is not None and self.health.relaxed else ""
        return self.fault_bounds + applied + relaxed + "".join(f" without {o}" for o in self.omitted)

    def interval(self, coordinate: Coordinate, node: int | None = None) -> np.ndarray:
        """(K, 2) bounds of one coordinate (``node`` is needed for the fault)."""
        if coordinate == "f":
            if node is None:
                raise ValueError("the fault interval needs a node id")
            return self.fault[node]
        if self.by_node:
            if node is None:
                raise ValueError("a network limit's β and r are a node's: give its id")
            return self.by_node[node][0 if coordinate == "beta" else 1]
        return self.beta if coordinate == "beta" else self.r


# ---------------------------------------------------------------- data


def step_data(record: Record) -> list[RecordedStep]:
    """The data of steps 0..K from the record's truth entries (u, Vx, ỹ, γ: what the nodes see)."""
    out = []
    try:
        for k, t in enumerate(sorted(record.truth, key=lambda t: t["step"])):
            if t["step"] != k:
                raise ExactError(f"{record.path}: truth entries are not the contiguous steps 0..K (step {k} missing)")
            out.append(
                RecordedStep(
                    step=k,
                    u=float(t["u"]),
                    vx=float(t["vx"]),
                    y={i: float(v) for i, v in t["y"].items()},
                    gamma={i: float(v) for i, v in t["gamma"].items()},
                    no_reading=tuple(sorted(int(i) for i in t.get("no_reading", ()))),
                )
            )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ExactError(f"{record.path}: malformed truth entry ({type(exc).__name__}: {exc})") from None
    if not out:
        raise ExactError(f"{record.path}: the record has no truth entries")
    return out


# ---------------------------------------------------------------- the program


class _Program:
    """Every constraint of the full horizon 0..K, each row tagged with the last step it involves.

    Columns: x_0..x_K (2 each), w_0..w_{K−1}, e_0..e_{K−1} (2 each, only with a declared model-mismatch
    bound), then f_i,0..K per node; the dynamics are equality rows, so every row is sparse.  The horizon-k program keeps the rows of steps ≤ k and the columns of steps
    ≤ k (the others appear in no kept row).
    """

    def __init__(self, scenario: Scenario, data: list[RecordedStep], bounded: tuple[int, ...], viewer: int | None = None) -> None:
        self.sc, self.data, self.bounded = scenario, data, bounded
        self.ids = scenario.ids
        self.K = K = len(data) - 1
        # the network limit of node ``viewer``: node j's data of step s is in the horizon-k program iff s ≤ k − d(j→i)
        # (Scenario.delays; a node whose data never reach the viewer is absent); None: centralized, every datum
        self.viewer = viewer
        self.delay: dict[int, int] = scenario.delays(viewer) if viewer is not None else dict.fromkeys(self.ids, 0)
        self.first: dict[int, int] = scenario.delays(viewer, first=True) if viewer is not None else self.delay  # step 0's: no reading carries it
        self.hold: set[int] = set()  # nodes whose faults stay in the program where not yet measured (kofn: tied health)
        self.ne = 2 if scenario.uncertainty is not None else 0  # e_j columns per step
        self.nz = 2 * (K + 1) + K + self.ne * K + len(self.ids) * (K + 1)
        # the measured intervals of the readings there are (a node without one at a step: no measurement row there)
        self.intervals = {
            (node.id, j): node.sensor.measured_interval(dj.y[node.id], dj.gamma[node.id])
            for node in scenario.nodes
            for j, dj in enumerate(data)
            if node.id in dj.y
        }
        lin = _Rows()  # a z ≤ b
        self._wind_rows(lin)
        self._sensor_rows(lin)
        esoc = self._mismatch_rows(lin)
        self.eq, self.lin, self.soc = self._dynamics_rows().build(self.nz), lin.build(self.nz), self._prior_rows().build(self.nz)
        self.esoc = esoc.build(self.nz)
        for block in (self.lin, self.soc):  # the delay of each row's datum (never: past any horizon)
            block.delay[:] = [0 if i < 0 else (self.first if s == 0 else self.delay).get(int(i), 2 * (K + 1)) for i, s in zip(block.node, block.step)]

    def _dynamics_rows(self) -> _Rows:
        """x_{j+1} − Ā_j x_j − D̄_j w_j − e_j = B̄_j u_j."""
        eq, sc, data = _Rows(), self.sc, self.data
        for j in range(self.K):
            a, b, d = sc.model.blend(sc.model.weights(data[j].vx))
            for row in range(2):
                terms = {self._x(j + 1, row): 1.0, self._w(j): -d[row, 0]}
                terms.update({self._x(j, c): -a[row, c] for c in range(2)})
                if self.ne:
                    terms[self._e(j, row)] = -1.0
                eq.add(terms, b[row, 0] * data[j].u, j + 1)
        return eq

    def _wind_rows(self, lin: _Rows) -> None:
        """|w_j| ≤ √W."""
        sqrt_w = np.sqrt(self.sc.W)
        for j in range(self.K):
            lin.add({self._w(j): 1.0}, sqrt_w, j + 1)
            lin.add({self._w(j): -1.0}, sqrt_w, j + 1)

    def _sensor_rows(self, lin: _Rows) -> None:
        """lo ≤ C̄_i x̄_i,j ≤ hi (the measured interval) where node i has a reading at step j, and the declared fault
        bounds of the bounded nodes at every step (a step without the reading keeps them: the fault is still there)."""
        K = self.K
        for n, node in enumerate(self.sc.nodes):
            free = node.id not in self.bounded
            c, ds = node.sensor.C, node.sensor.Ds
            for j in range(K + 1):
                if (node.id, j) not in self.intervals:
                    continue  # no reading (a recorded drive's gap): no measurement constraint, never an invented one
                lo, hi = self.intervals[node.id, j]
                r = {self._x(j, 0): c[0], self._x(j, 1): c[1], self._f(n, j): ds}  # r = C̄_i x̄_i,j
                if np.isfinite(hi):
                    lin.add(r, hi, j, j if free else -1, node.id)
                if np.isfinite(lo):
                    lin.add({col: -v for col, v in r.items()}, -lo, j, j if free else -1, node.id)
            if free:
                continue
            for j in range(K + 1):
                if node.fault_size is not None:
                    lin.add({self._f(n, j): 1.0}, node.fault_size, j)
                    lin.add({self._f(n, j): -1.0}, node.fault_size, j)
                if node.fault_rate is not None and j > 0:
                    lin.add({self._f(n, j): 1.0, self._f(n, j - 1): -1.0}, node.fault_rate, j)
                    lin.add({self._f(n, j): -1.0, self._f(n, j - 1): 1.0}, node.fault_rate, j)

    def _mismatch_rows(self, lin: _Rows) -> _Rows:
        """The declared bound on e_j: a box as linear rows, an ellipsoid as s = [1; G⁻¹ e_j] ∈ SOC(3) (returned)."""
        esoc, unc = _Rows(), self.sc.uncertainty
        if unc is not None and unc.kind == "box":
            for j in range(self.K):
                for row in range(2):
                    lin.add({self._e(j, row): 1.0}, unc.G[row, row], j + 1)
                    lin.add({self._e(j, row): -1.0}, unc.G[row, row], j + 1)
        elif unc is not None:
            g_inv = np.linalg.inv(unc.G)
            for j in range(self.K):
                esoc.add({}, 1.0, j + 1)
                for row in range(2):
                    esoc.add({self._e(j, c): -g_inv[row, c] for c in range(2)}, 0.0, j + 1)
        return esoc

    def _prior_rows(self) -> _Rows:
        """The priors: s = b − A z = [√ρ; L⁻¹([x_0; f_i,0] − x̂0)] ∈ SOC(4), P0 = L Lᵀ."""
        soc = _Rows()
        for n, node in enumerate(self.sc.nodes):
            li = np.linalg.inv(np.linalg.cholesky(node.P0))
            prior_cols = (self._x(0, 0), self._x(0, 1), self._f(n, 0))
            soc.add({}, np.sqrt(node.rho), 0, node=node.id)
            centre = li @ node.x0_hat
            for row in range(3):
                soc.add({col: -li[row, m] for m, col in enumerate(prior_cols) if li[row, m] != 0}, -centre[row], 0, node=node.id)
        return soc

    def _x(self, j: int, comp: int) -> int:
        return 2 * j + comp

    def _w(self, j: int) -> int:
        return 2 * (self.K + 1) + j

    def _e(self, j: int, comp: int) -> int:
        return 2 * (self.K + 1) + self.K + 2 * j + comp

    def _f(self, n: int, j: int) -> int:
        return 2 * (self.K + 1) + self.K + self.ne * self.K + n * (self.K + 1) + j

    def _eliminated(self, n: int, j: int, k: int, eliminate: bool) -> bool:
        """Whether f_i,j leaves the horizon-k program: a fault without declared bounds at 0 < j < k
        appears only in its own measurement rows, and some f_i,j meets them for every x_j (Ds ≠ 0, the
        measured interval is not empty), so dropping the variable with its rows is exact.  (The network limit
        bounds the viewer's fault alone: there every other node's is eliminated at k too, :meth:`matrices`.)"""
        return eliminate and self.ids[n] not in self.bounded and 0 < j < k

    def available(self, node: int, j: int, k: int) -> bool:
        """Whether node ``node``'s data of step j (its measurement; at j = 0 also its prior) are in the horizon-k program."""
        d = (self.first if j == 0 else self.delay).get(node)
        return d is not None and j <= k - d

    def holds(self, other: _Program, h: int, k: int) -> bool:
        """Whether this program's horizon k has every datum ``other``'s horizon h has (both of one scenario and record):
        then the same assumptions over at least those data, so whatever that horizon proved holds here (and later)."""
        for j in self.ids:
            if other.available(j, 0, h) and not self.available(j, 0, k):
                return False
            last = h - other.delay[j] if j in other.delay else 0  # its data of steps 1..last (a threshold in the step)
            if last >= 1 and not (j in self.delay and last <= k - self.delay[j]):
                return False
        return True

    def _available_rows(self, block: _RowBlock, k: int) -> np.ndarray:
        """The rows of ``block`` whose data the horizon-k program has (a row of no node's data: always)."""
        return block.step <= k - block.delay

    def columns(self, k: int, eliminate: bool) -> np.ndarray:
        """Columns of the horizon-k program: x_0..x_k, w_0..w_{k−1}, e_0..e_{k−1}, the f_i,0..k not eliminated (and, in a
        network limit, measured by the horizon: a fault the viewer knows no datum of is free but for its declared
        bounds, which some value within them always meets; kept where a k-of-N group ties its health, ``hold``)."""
        cols = [np.arange(2 * (k + 1)), self._w(0) + np.arange(k)]
        if self.ne:
            cols.append(self._e(0, 0) + np.arange(2 * k))
        for n, i in enumerate(self.ids):
            own = self.viewer is None or i == self.viewer
            cols.append(
                np.array(
                    [
                        self._f(n, j)
                        for j in range(k + 1)
                        if not self._eliminated(n, j, k, eliminate)
                        and (self.available(i, j, k) or (i in self.hold and i in self.bounded))
                        and (own or not eliminate or i in self.bounded or j == 0)
                    ],
                    dtype=int,
                )
            )
        return np.concatenate(cols).astype(int)

    def matrices(self, k: int, eliminate: bool) -> tuple[np.ndarray, sparse.csc_matrix, np.ndarray, list]:
        """Columns, A, b and cones of the horizon-k program (A z + s = b, s in the cones)."""
        cols = self.columns(k, eliminate)
        keep_eq = self.eq.step <= k
        keep_lin = (self.lin.step <= k) & self._available_rows(self.lin, k)
        if eliminate:
            free_ok = self.lin.free == k
            if self.viewer is not None:  # the viewer's own fault is the only one bounded at k
                free_ok &= self.lin.node == self.viewer
            keep_lin &= (self.lin.free <= 0) | free_ok
        keep_soc = self._available_rows(self.soc, k)
        keep_esoc = self.esoc.step <= k
        lin = self.lin.A[keep_lin]
        if self.viewer is not None:  # a row on a fault that left the program (a declared bound of a fault not yet measured): out
            inside = np.zeros(self.nz, dtype=bool)
            inside[cols] = True
            outside = np.asarray(lin[:, ~inside].getnnz(axis=1)).ravel() > 0
            keep_lin[np.flatnonzero(keep_lin)[outside]] = False
            lin = self.lin.A[keep_lin]
        A = sparse.vstack(
            [self.eq.A[keep_eq][:, cols], lin[:, cols], self.soc.A[keep_soc][:, cols], self.esoc.A[keep_esoc][:, cols]],
            format="csc",
        )
        b = np.r_[self.eq.b[keep_eq], self.lin.b[keep_lin], self.soc.b[keep_soc], self.esoc.b[keep_esoc]]
        cones = [clarabel.ZeroConeT(int(keep_eq.sum())), clarabel.NonnegativeConeT(int(keep_lin.sum()))]
        cones += [clarabel.SecondOrderConeT(4)] * (int(keep_soc.sum()) // 4)
        cones += [clarabel.SecondOrderConeT(3)] * (int(keep_esoc.sum()) // 3)
        return cols, A, b, cones

    def objectives(self, k: int) -> list[tuple[Coordinate, int | None, int]]:
        """(coordinate, node, column) of every bounded quantity at step k (a network limit: β, r and the viewer's fault)."""
        out: list[tuple[Coordinate, int | None, int]] = [("beta", None, self._x(k, 0)), ("r", None, self._x(k, 1))]
        return out + [("f", i, self._f(n, k)) for n, i in enumerate(self.ids) if self.viewer is None or i == self.viewer]

    def witness(self, z: np.ndarray, k: int, eliminate: bool) -> Witness:
        """The trajectory of a solution; an eliminated fault takes the value nearest 0 that meets its
        measurement (C̄_i x̄_i,j in the measured interval; 0 at a step without a reading, where no row holds it)."""
        f = {}
        for n, node in enumerate(self.sc.nodes):
            fi = z[self._f(n, 0) : self._f(n, k) + 1].copy()
            for j in range(k + 1):
                if self._eliminated(n, j, k, eliminate):
                    cx = float(node.sensor.C @ z[self._x(j, 0) : self._x(j, 1) + 1])
                    lo, hi = self.intervals.get((node.id, j), (-math.inf, math.inf))
                    ends = sorted(((lo - cx) / node.sensor.Ds, (hi - cx) / node.sensor.Ds))
                    fi[j] = float(np.clip(0.0, ends[0], ends[1]))
            f[node.id] = fi
        e = z[self._e(0, 0) : self._e(0, 0) + 2 * k].reshape(k, 2).copy() if self.ne else np.zeros((k, 2))
        return Witness(x0=z[:2].copy(), w=z[self._w(0) : self._w(0) + k].copy(), f=f, e=e)


class _Rows:
    """Sparse constraint rows with the step each belongs to (and, for a free fault's measurement, its step)."""

    def __init__(self) -> None:
        self.entries: list[tuple[dict[int, float], float, int, int, int]] = []

    def add(self, terms: dict[int, float], rhs: float, step: int, free: int = -1, node: int = -1) -> None:
        """``node``: whose datum of ``step`` the row is (a measurement, a prior; −1: an assumption of the model)."""
        self.entries.append((terms, float(rhs), step, free, node))

    def build(self, nz: int) -> _RowBlock:
        data, ri, ci = [], [], []
        for r, (terms, *_rest) in enumerate(self.entries):
            for c, v in terms.items():
                ri.append(r)
                ci.append(c)
                data.append(float(v))
        A = sparse.csr_matrix((data, (ri, ci)), shape=(len(self.entries), nz))
        return _RowBlock(
            A=A,
            b=np.array([e[1] for e in self.entries]),
            step=np.array([e[2] for e in self.entries], dtype=int),
            free=np.array([e[3] for e in self.entries], dtype=int),
            node=np.array([e[4] for e in self.entries], dtype=int),
            delay=np.zeros(len(self.entries), dtype=int),
        )


@dataclass(frozen=True)
class _RowBlock:
    A: sparse.csr_matrix
    b: np.ndarray
    step: np.ndarray
    free: np.ndarray
    node: np.ndarray  # whose datum the row is (−1: none)
    delay: np.ndarray  # the steps that datum takes to the viewer (_Program sets it)


def _settings() -> clarabel.DefaultSettings:
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.presolve_enable = False  # keep every row: the objective is updated in place between solves
    st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = SOLVER_TOL
    st.tol_ktratio = 1e-8
    st.max_iter = 200
    return st


class _HealthPlan:
    """The k-of-N unions of one program's steps (netsetest/analysis/kofn.py), and what each finished horizon j
    proved about step j: the interval of t_j = uᵀx_j and the range of every tied fault, loosened by
    :data:`CUT_MARGIN`.  They hold in every later horizon (it only adds constraints), so they become rows of
    its program; a step left with one piece inside them is convex there and joins those rows.

    In a network limit a member's reading of step j may reach the viewer only at a later horizon: until then it is
    a sensor that may be healthy with any value (its span the whole line, untied), and the union of step j is built
    again at every horizon until every member's datum of j is in (``pending``); then it is kept like any other."""

    def __init__(self, prog: _Program, model: HealthModel, group: int = 0) -> None:
        self.prog, self.model, self.group = prog, model, group
        self.members = [(n, node) for n, node in enumerate(prog.sc.nodes) if node.id in model.sensors]  # (program position, node)
        self.cuts: list[Row] = []  # rows valid in every later horizon
        self.unions: list[StepUnion] = []  # past steps with several pieces
        self.pending: dict[int, tuple[list[bool], Span]] = {}  # past steps whose data are not all in yet: allowed, window
        self.incomplete = False  # a past step's pieces were too many to enumerate: later ends are relaxed
        self.dead: dict[int, list[Piece]] = {}  # pending steps' pieces some horizon found without a trajectory (drop)

    def _t(self, j: int) -> dict[int, float]:
        return {self.prog._x(j, c): float(self.model.u[c]) for c in range(2) if self.model.u[c] != 0}

    def _measured(self, node: NodeConfig, j: int, k: int) -> bool:
        return self.prog.available(node.id, j, k)

    def _complete(self, j: int, k: int) -> bool:
        """Whether the horizon-k program has every member's datum of step j that will ever reach the viewer."""
        return all(self._measured(node, j, k) or node.id not in self.prog.delay for _, node in self.members)

    def _spans(self, j: int, k: int) -> tuple[Span, ...]:
        """Per node: the interval of t_j its measurement gives with |f| ≤ τ (C_i = s_i uᵀ), widened by
        :data:`PIECE_MARGIN` for rounding: with worst-case signals two healthy sensors' noises sit at opposite
        bounds, their intervals meet in the truth's one point, and an ulp apart they would not.  A measurement the
        horizon-k program does not have: the whole line."""
        out = []
        for _, node in self.members:
            if not self._measured(node, j, k) or (node.id, j) not in self.prog.intervals:  # (none: a recorded drive's gap)
                out.append((-math.inf, math.inf))
                continue
            lo, hi = self.prog.intervals[node.id, j]
            sensor = node.sensor
            pad = PIECE_MARGIN * (abs(sensor.Dv) * math.sqrt(sensor.R) + max((abs(v) for v in (lo, hi) if math.isfinite(v)), default=0.0))
            slack, s = abs(sensor.Ds) * self.model.tolerance + pad, float(sensor.C @ self.model.u)
            a, b = (lo - slack) / s, (hi + slack) / s
            out.append((min(a, b), max(a, b)))
        return tuple(out)

    def _union(self, j: int, tied: list[bool], allowed: list[bool], window: Span, k: int) -> StepUnion | None:
        spans = self._spans(j, k)
        pieces = step_pieces(spans, tied, allowed, self.model.need, window, self.group)
        if pieces is None:
            return None
        f_col = tuple(self.prog._f(n, j) if t else None for (n, _), t in zip(self.members, tied))
        return StepUnion(j, self._t(j), spans, f_col, self.model.tolerance, self.model.need, tuple(pieces), self._t(j - 1) if j > 0 else None)

    def _tied(self, j: int, k: int) -> list[bool]:
        """A fault tied to more than its measurement in every horizon after j: by a prior (j = 0), or by a declared
        bound that a healthy value could break (:func:`_bound_admits_health`).  Not yet measured (a network limit):
        tied only where such a bound keeps its fault in the program (``_Program.hold``)."""
        tol, prog = self.model.tolerance, self.prog
        out = []
        for _, node in self.members:
            strict = node.id in prog.bounded and not _bound_admits_health(node, tol)
            out.append((j == 0 or strict) if self._measured(node, j, k) else (strict and node.id in prog.hold))
        return out

    def window(self, j: int, beta: np.ndarray, r: np.ndarray) -> Span:
        """The interval of t_j = uᵀx_j over the box of β_j, r_j (loosened), or the whole line."""
        ends = [sorted((u * lo, u * hi)) for u, (lo, hi) in zip(self.model.u, (beta, r))]
        lo, hi = sum(e[0] for e in ends), sum(e[1] for e in ends)
        return (-np.inf, np.inf) if np.isnan(lo) or np.isnan(hi) else _loosened(lo, hi)

    def unions_at(self, k: int, objective: int, window: Span) -> tuple[list[StepUnion], bool]:
        """The unions of horizon k for one objective column, and whether they are complete (exact ends)."""
        tied = [t or self.prog._f(n, k) == objective for (n, _), t in zip(self.members, self._tied(k, k))]
        last = self._union(k, tied, [True] * len(tied), window, k)
        again = [self._alive(self._union(j, self._tied(j, k), allowed, w, k)) for j, (allowed, w) in sorted(self.pending.items())]
        complete = last is not None and None not in again and not self.incomplete
        return [*self.unions, *(u for u in again if u is not None), *([last] if last is not None else [])], complete

    def narrow(self, horizon: _Horizon) -> int:
        """Drop every past step's piece outside the range of its t_j in this horizon's program without the unions
        (min and max of t_j, loosened by :data:`CUT_MARGIN`): the root plus such a piece has no trajectory, here and
        in every later horizon (each adds constraints).  Without it only the pieces a root's search happened to try
        were found dead, and the unions of a run whose ends settle without their roots (:func:`kofn.guided`) kept
        them all.  The solves spent."""
        solves = 0
        first = 0 if self.prog.viewer is None else -1  # step 0's (the priors tie it) is cut by its own horizon, where that has its data
        for union in [u for u in self.unions if len(u.pieces) > 1 and u.step > first]:
            ends = []
            for sign in (1.0, -1.0):
                q = horizon.objective({c: sign * v for c, v in union.t.items()})
                status, z = horizon.solve(q)
                solves += 1
                if z is None:
                    break
                ends.append(sign * float(q @ z[horizon.conic.cols]))
            if len(ends) == 2:
                lo, hi = _loosened(*ends)
                self.drop([(union.step, p) for p in union.pieces if p.hi < lo or p.lo > hi])
        return solves

    def tighten(self, j: int, window: Span) -> None:
        """Step j's t_j lies in ``window`` in this horizon and every later one (another program proved it, :class:`_Ledger`):
        a pending union is built inside it from now on, a kept one loses the pieces outside it (one piece left: convex,
        its rows join the cuts)."""
        if j in self.pending:
            allowed, w = self.pending[j]
            self.pending[j] = (allowed, (max(w[0], window[0]), min(w[1], window[1])))
        self.drop([(j, p) for u in self.unions if u.step == j for p in u.pieces if p.hi < window[0] or p.lo > window[1]])
        for u in [u for u in self.unions if u.step == j and len(u.pieces) == 1]:
            self.cuts += u.rows(u.pieces[0])
            self.unions.remove(u)

    def _alive(self, union: StepUnion | None) -> StepUnion | None:
        """A pending step's union built again without the pieces inside one found dead (:meth:`drop`)."""
        if union is None or not self.dead.get(union.step):
            return union
        return replace(union, pieces=tuple(p for p in union.pieces if not any(p.within(d) for d in self.dead[union.step])))

    def drop(self, dead: Sequence[tuple[int, Piece]]) -> None:
        """Pieces that admit no trajectory in some horizon admit none in any later one (it adds constraints); nor does
        any piece inside one (its interval of t_j within, at least its tied sensors healthy), which is how a pending
        step's union, built again at every horizon, forgets them."""
        for step, piece in dead:
            if step in self.pending and piece.group == self.group:
                self.dead.setdefault(step, []).append(piece)
            self.unions = [replace(u, pieces=tuple(p for p in u.pieces if p != piece)) if u.step == step else u for u in self.unions]

    def learn(self, k: int, beta: np.ndarray, r: np.ndarray, fault: dict[int, np.ndarray]) -> None:
        """Horizon k is done: its ends of t_k and of the tied faults bound step k in every later horizon (a fault this
        program did not bound, NaN, bounds nothing), and the union of step k, or of a pending step whose data are all
        in from horizon k + 1 on, holds in every later horizon."""
        window, tied = self.window(k, beta, r), self._tied(k, k)
        self.cuts += interval_rows(self._t(k), window)
        allowed = []
        for (n, node), is_tied in zip(self.members, tied):
            lo, hi = _loosened(*fault[node.id]) if node.id in fault and not np.isnan(fault[node.id]).any() else (-np.inf, np.inf)
            allowed.append(bool(lo <= self.model.tolerance and hi >= -self.model.tolerance))
            if is_tied and math.isfinite(lo) and math.isfinite(hi):
                self.cuts += interval_rows({self.prog._f(n, k): 1.0}, (lo, hi))
        self.pending[k] = (allowed, window)
        for j in [j for j in sorted(self.pending) if self._complete(j, k + 1)]:  # every datum of step j is in from k + 1 on
            allowed_j, window_j = self.pending.pop(j)
            union = self._alive(self._union(j, self._tied(j, k + 1), allowed_j, window_j, k + 1))
            self.dead.pop(j, None)
            if union is None:
                self.incomplete = True
            else:
                self.unions.append(union)
        self.unions.sort(key=lambda u: u.step)
        for u in [u for u in self.unions if len(u.pieces) == 1]:  # convex: one more row set of every later horizon
            self.cuts += u.rows(u.pieces[0])
            self.unions.remove(u)


def _loosened(lo: float, hi: float) -> Span:
    """An interval proven by a solve, widened by :data:`CUT_MARGIN` (relative) for the solver's precision."""
    return lo - CUT_MARGIN * max(1.0, abs(lo)), hi + CUT_MARGIN * max(1.0, abs(hi))


def _bound_admits_health(node: NodeConfig, tolerance: float) -> bool:
    """Whether any |f_j| ≤ τ meets node's declared bounds whatever its neighbours f_j±1 (themselves within them):
    τ ≤ F and F + τ ≤ δ (paper6: F = δ, τ = 0).  Then replacing f_j by the healthy value its measurement allows
    keeps every row, so its health is t_j in its span, as for a fault without bounds (docs/exact.md)."""
    size_ok = node.fault_size is None or tolerance <= node.fault_size
    rate_ok = node.fault_rate is None or (node.fault_size is not None and node.fault_size + tolerance <= node.fault_rate)
    return size_ok and rate_ok


class _Horizon:
    """One horizon's program and its solver, shared by the root relaxations of every end (only q changes)."""

    def __init__(self, conic: Conic, nz: int) -> None:
        self.conic, self.nz = conic, nz
        self.solver: clarabel.DefaultSolver | None = None
        self.branches = Solvers()  # the branch and bound's, shared by the horizon's ends (bounded: kofn.MAX_SOLVERS)
        self.guided = Solvers()  # kofn.guided's (a point piece is an equality there: not a branch's rows)

    def objective(self, terms: dict[int, float]) -> np.ndarray:
        """q of Σ terms[c]·z[c] over the program's columns."""
        q = np.zeros(len(self.conic.cols))
        for c, v in terms.items():
            q[self.conic.position[c]] = v
        return q

    def solve(self, q: np.ndarray) -> tuple[str, np.ndarray | None]:
        """The solver's status and its minimiser (over every column of the program) of q·z, without the unions."""
        if self.solver is None:
            self.solver = self.conic.solver(q)
        else:
            self.solver.update(q=q)
        sol = self.solver.solve()
        status = str(sol.status)
        if settle(status) != "solved":
            return status, None
        z = np.zeros(self.nz)
        z[self.conic.cols] = np.asarray(sol.x)
        return status, z

    def root(self, col: int, sign: float, what: str) -> tuple[np.ndarray, str, np.ndarray | None]:
        """q, the solver's status and its minimiser of sign·z[col]; a status that settles nothing is an error (``what``
        names the end)."""
        q = self.objective({col: sign})
        status, z = self.solve(q)
        if settle(status) == "other":
            raise ExactError(f"{what}: the solver stopped with status {status}")
        return q, status, z

    def end(self, col: int, sign: float, what: str) -> EndResult:
        """min sign·z[col] over the program: one solve (no k-of-N health)."""
        q, status, z = self.root(col, sign, what)
        kind = settle(status)
        value = {"solved": float(q @ z[self.conic.cols]) if z is not None else np.nan, "unbounded": -np.inf, "infeasible": np.nan}[kind]
        return EndResult(kind, value, z, True, 1)  # type: ignore[arg-type]  # kind is not "other": root raised


class _Guides:
    """Per end (coordinate, node, side): its last minimiser (the next horizon's search tries its pieces first, and
    :func:`kofn.guided` solves with them), and the horizon its guided solve last failed at.  An end whose guided solve
    failed is not guided again for :data:`GUIDED_RETRY` horizons: on a 12-node ring with two groups most guided solves
    are not proven and each is one solve more than the search from the root (docs/exact.md, measured)."""

    def __init__(self) -> None:
        self.last: dict[tuple[Coordinate, int | None, Side], Guide] = {}  # one vector each
        self.failed: dict[tuple[Coordinate, int | None, Side], int] = {}

    def get(self, key: tuple[Coordinate, int | None, Side], k: int) -> tuple[Guide | None, bool]:
        """The guide, and whether to try a guided solve first at horizon k."""
        return self.last.get(key), k - self.failed.get(key, -GUIDED_RETRY) >= GUIDED_RETRY

    def learn(self, key: tuple[Coordinate, int | None, Side], k: int, result: EndResult, tried: bool) -> None:
        if result.z is not None:
            self.last[key] = (k, result.z)
        if tried and not result.guided:
            self.failed[key] = k


@dataclass
class _HealthTally:
    """What the k-of-N search spent and settled over every program of one computation, and its one deadline (CPU
    seconds of this process, :func:`time.process_time`; past it no branch is solved any more)."""

    deadline: float
    ends: int = 0
    exact: int = 0
    solves: int = 0
    relaxed: list[WitnessKey] = field(default_factory=list)
    out_of_time: int | None = None  # the horizon during which the deadline passed

    def count(self, key: WitnessKey, end: EndResult) -> None:
        self.ends += 1
        self.exact += end.exact
        self.solves += end.solves
        if not end.exact:
            self.relaxed.append(key)

    def in_time(self) -> bool:
        return time.process_time() < self.deadline

    def clock(self, k: int) -> None:
        """Horizon k is done: note it if the deadline passed during it."""
        if self.out_of_time is None and not self.in_time():
            self.out_of_time = k


@dataclass
class _Ledger:
    """The programs of one computation and where their ends go (a network limit: one per node): a horizon of one program
    holds in a horizon of another whose data it holds (:meth:`_Program.holds`), so each search imports what the others
    proved about the states of past steps (:meth:`KofNSearch._import`): rows that leave its limit as it is and cut its
    relaxations and pieces (docs/exact.md, *The network limit*)."""

    entries: list[tuple[_Program, _Limits]] = field(default_factory=list)


class KofNSearch:
    """A declared ``[network] max_faulty`` applied to one program by branch and bound (analysis/kofn.py, docs/exact.md).

    Its state: the plans (per k-of-N group: the unions of the past steps and what the past horizons proved about them),
    the guides (each end's last minimiser), and the tally and deadline it shares with the other programs of the same
    computation (each node's network limit is a program of its own).  The exact step loop (:class:`_StepLoop`) asks it
    for each horizon's program (:meth:`horizon`) and each end (:meth:`end`), and tells it when a horizon is done
    (:meth:`learn`); without it the loop solves each end once.
    """

    def __init__(self, prog: _Program, plans: list[_HealthPlan], tally: _HealthTally, budget: int, ledger: _Ledger | None = None) -> None:
        self.prog, self.plans, self.tally, self.budget = prog, plans, tally, budget
        self.guides = _Guides()
        self.ledger = ledger if ledger is not None else _Ledger()
        self.box: dict[int, list[float]] = {}  # step → [β lo, β hi, r lo, r hi]: the tightest proven of it (own horizons, imports)
        self.upto: dict[int, int] = {}  # per other program of the ledger (its position): the last of its horizons imported

    @classmethod
    def of(cls, prog: _Program, scenario: Scenario, health: bool, tally: _HealthTally, budget: int, ledger: _Ledger | None = None) -> KofNSearch | None:
        """The search of ``prog`` where ``health`` applies a declared group its nodes say something about; else None."""
        plans = _plans(prog, scenario, health)
        return cls(prog, plans, tally, budget, ledger) if plans else None

    def horizon(self, conic: Conic, k: int) -> _Horizon:
        """Horizon k's program with what the past horizons proved (the plans' cuts; in a network limit the box of β_j, r_j
        of every past step, its own horizons' and the other programs' of the ledger whose data this horizon holds), its
        unions' pieces outside the program's range dropped before the deadline (:meth:`_HealthPlan.narrow`, the solves
        counted)."""
        self._import(k)
        rows = [row for p in self.plans for row in p.cuts]
        for j, (b_lo, b_hi, r_lo, r_hi) in sorted(self.box.items()):
            rows += interval_rows({self.prog._x(j, 0): 1.0}, _loosened(b_lo, b_hi)) + interval_rows({self.prog._x(j, 1): 1.0}, _loosened(r_lo, r_hi))
        horizon = _Horizon(conic.with_rows(rows), self.prog.nz)
        if self.tally.in_time():
            self.tally.solves += sum(p.narrow(horizon) for p in self.plans)
        return horizon

    def end(self, horizon: _Horizon, key: WitnessKey, col: int, sign: float, limits: _Limits) -> EndResult:
        """min sign·z[col] over horizon ``key.step`` and every group's unions; a feasible end is counted, its minimiser
        guides the same end at the next horizon, and the pieces it found dead leave the plans."""
        k = key.step
        unions, complete = self._unions(k, col, limits.window(k) if key.coordinate == "f" else None)
        which = (key.coordinate, key.node, key.side)
        guide, try_guided = self.guides.get(which, k)
        result = self._search(horizon, col, sign, (unions, complete), guide, try_guided, f"step {k}: the {key.coordinate} bound")
        if result.status != "infeasible":
            self.tally.count(key, result)
            self.guides.learn(which, k, result, guide is not None and try_guided)
            for p in self.plans:
                p.drop([d for d in result.dead if d[0] < k])
        return result

    def learn(self, k: int, limits: _Limits) -> None:
        """Horizon k is done and feasible: its ends bound step k in every later horizon (:meth:`_HealthPlan.learn`)."""
        for p in self.plans:
            p.learn(k, limits.beta[k], limits.r[k], {i: f[k] for i, f in limits.fault.items()})
        if self.prog.viewer is not None:  # (the central program's own boxes: no fewer solves, one end relaxed on a ring, measured)
            self._proved(k, limits.beta[k], limits.r[k])

    def _import(self, k: int) -> None:
        """Every horizon h ≤ k of the ledger's other programs whose data horizon k holds (:meth:`_Program.holds`; a
        threshold in h) and not imported yet: its β_h, r_h ends bound step h here."""
        for n, (prog, limits) in enumerate(self.ledger.entries):
            if prog is self.prog:
                continue
            h = self.upto.get(n, -1) + 1
            while h <= min(k, limits.done) and self.prog.holds(prog, h, k):
                self._proved(h, limits.beta[h], limits.r[h])
                h += 1
            self.upto[n] = h - 1

    def _proved(self, j: int, beta: np.ndarray, r: np.ndarray) -> None:
        """β_j and r_j lie in these ends (loosened where they become rows) in every later horizon: the box of step j
        narrows, and so do the unions' windows of t_j (:meth:`_HealthPlan.tighten`)."""
        old = self.box.get(j, [-math.inf, math.inf, -math.inf, math.inf])
        ends = [float(v) if not math.isnan(v) else d for v, d in zip((beta[0], beta[1], r[0], r[1]), old)]
        new = [max(old[0], ends[0]), min(old[1], ends[1]), max(old[2], ends[2]), min(old[3], ends[3])]
        if new == old or new[0] > new[1] or new[2] > new[3]:
            return  # nothing new (or two programs disagree: the rows would leave no trajectory, so none are added)
        self.box[j] = new
        for p in self.plans:
            p.tighten(j, p.window(j, np.array(new[:2]), np.array(new[2:])))

    def summary(self, declared: str, budget_s: float | None) -> HealthSearch:
        """How the computation applied the assumption (its tally is every program's)."""
        t = self.tally
        needs = tuple(p.model.need for p in self.plans)
        groups = tuple(tuple(p.model.sensors) for p in self.plans)
        return HealthSearch(declared, needs, groups, self.budget, t.ends, t.exact, tuple(t.relaxed), t.solves, budget_s, t.out_of_time)

    def _unions(self, k: int, col: int, box: tuple[np.ndarray, np.ndarray] | None) -> tuple[list[StepUnion], bool]:
        """Every group's unions of horizon k for one objective column, by step, and whether all are complete; a fault's
        window of t_k (a group's direction u) from the horizon's β, r ends (``box``), which come before the faults'."""
        unions: list[StepUnion] = []
        complete = True
        for p in self.plans:
            got, done = p.unions_at(k, col, p.window(k, *box) if box is not None else (-np.inf, np.inf))
            unions += got
            complete = complete and done
        return sorted(unions, key=lambda u: u.step), complete

    def _search(
        self, horizon: _Horizon, col: int, sign: float, unions: tuple[list[StepUnion], bool], guide: Guide | None, try_guided: bool, what: str
    ) -> EndResult:
        """With a ``guide`` (and ``try_guided``), first one solve with its pieces that may settle the end alone
        (:func:`kofn.guided`); else the root relaxation, then the branch and bound over the unions (``unions``: they
        and whether they are complete, i.e. the end can be exact)."""
        first = GuidedStart(None, 0)
        if guide is not None and try_guided and self.tally.in_time():
            first = guided(horizon.conic, horizon.objective({col: sign}), horizon.nz, unions[0], guide, horizon.guided)
            if first.end is not None:
                return replace(first.end, exact=unions[1], guided=True)
        q, status, z = horizon.root(col, sign, what)
        result = minimise(horizon.conic, q, horizon.nz, unions[0], (status, z), self.budget, horizon.branches, self.tally.deadline, guide, first.incumbent)
        return replace(result, exact=result.exact and unions[1], solves=result.solves + 1 + first.solves)


def _plans(prog: _Program, scenario: Scenario, health: bool) -> list[_HealthPlan]:
    """The k-of-N plan of every declared group the program's nodes say something about (a group they leave out, or
    all but m of it, says nothing); a group's members whose declared bound ties their health stay in the program where
    not yet measured (a network limit: ``_Program.hold``)."""
    models = [HealthModel.of_group(scenario, g) for g in scenario.health_groups] if health and scenario.health_declared else []
    plans = [_HealthPlan(prog, m, k) for k, m in enumerate(models) if m is not None and m.need > 0]
    prog.hold = {node.id for p in plans for _, node in p.members if not _bound_admits_health(node, p.model.tolerance)}
    return plans


def exact_bounds(
    scenario: Scenario,
    record: Record,
    fault_bounds: FaultBoundsMode = "used",
    keep_witnesses: bool = False,
    eliminate_free_faults: bool = True,
    nodes: Sequence[int] | None = None,
    progress: Callable[[int, int], None] | None = None,
    health: bool = True,
    health_budget: int = HEALTH_BUDGET,
    budget_s: float | None = None,
    network: bool = False,
    central: ExactBounds | None = None,
) -> ExactBounds:
    """The exact intervals of every step of ``record`` under ``scenario``'s assumptions (module doc).

    ``progress(k, K)``: called after each step's programs (a SAIM record takes seconds).

    ``nodes``: use only these nodes' priors and measurements (e.g. one node: the limit of a purely
    local estimator); default every node (centralized).  ``eliminate_free_faults`` drops the past
    faults that no declared bound ties (exact, see :meth:`_Program._eliminated`; False keeps the
    whole program, for checking that).  ``health``: apply a declared ``[network] max_faulty`` by branch
    and bound (at most ``health_budget`` solves per end, docs/exact.md: :class:`KofNSearch`); False leaves it out (an
    outer bound).  ``budget_s``: CPU seconds of this process for the whole computation (its wall time on an idle core;
    CPU, so that which ends are exact does not depend on what else the machine runs); past them no branch is solved any
    more, and every end its relaxation does not settle is relaxed (sound, labelled: ``HealthSearch.out_of_time``).
    None: no limit.  ``network``: each node's network limit instead of the central one (docs/exact.md, *The network
    limit*): its β, r (``ExactBounds.by_node``) and its fault from its own data and node j's data up to step
    k − d(j→i) (:meth:`Scenario.delays`), one program per node (one for all where every datum reaches every node in
    its step: the central program); the witnesses' faults of other nodes are not checked there (a fault the viewer
    has no datum of is left at 0).  ``central``: the central limit of the same record and assumptions, where it is at
    hand (``exact --network`` computes it first): each node's program takes its box of every step whose data it holds
    (:class:`_Ledger`), which leaves the limits as they are and spares solves.
    """
    data = step_data(record)
    scenario, bounded = _program_nodes(scenario, record, data, fault_bounds, nodes, network)
    K1 = len(data)
    beta, r = np.full((K1, 2), np.nan), np.full((K1, 2), np.nan)
    fault = {i: np.full((K1, 2), np.nan) for i in scenario.ids}
    by_node: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    loop = _StepLoop(keep_witnesses, eliminate_free_faults)
    tally = _HealthTally(math.inf if budget_s is None else time.process_time() + budget_s)
    searches: list[KofNSearch] = []
    infeasible: set[int] = set()
    shared = network and everywhere(scenario)
    viewers: list[int | None] = list(scenario.ids) if network and not shared else [None]
    ledger = _Ledger()
    if network and not shared and central is not None and _same_assumptions(central, fault_bounds, health, scenario):
        ledger.entries.append((_Program(scenario, data, bounded), _Limits(central.beta, central.r, central.fault, done=K1 - 1)))
    runs = []
    for n, viewer in enumerate(viewers):
        prog = _Program(scenario, data, bounded, viewer)
        kofn = KofNSearch.of(prog, scenario, health, tally, health_budget, ledger)
        searches += [kofn] if kofn is not None else []
        if viewer is None:
            limits = _Limits(beta, r, fault)
        else:
            limits = _Limits(np.full((K1, 2), np.nan), np.full((K1, 2), np.nan), {viewer: fault[viewer]})
            by_node[viewer] = (limits.beta, limits.r)
        ledger.entries.append((prog, limits))

        def step_progress(k: int, total: int, n: int = n) -> None:
            if progress is not None:
                progress(k * len(viewers) + n, total * len(viewers))

        runs.append(loop.horizons(prog, limits, kofn, step_progress))
    for horizon in zip(*runs):  # side by side, horizon by horizon: each program imports what the others proved so far
        infeasible |= {k for k, feasible in horizon if not feasible}
    if shared:  # every node has every datum in its step: each node's program is the central one
        by_node = {i: (beta.copy(), r.copy()) for i in scenario.ids}
        beta[:], r[:] = np.nan, np.nan
    return ExactBounds(
        steps=np.arange(K1),
        beta=beta,
        r=r,
        fault=fault,
        fault_bounds=fault_bounds,
        bounded_nodes=bounded,
        infeasible_steps=tuple(sorted(infeasible)),
        witnesses=loop.witnesses,
        omitted=omitted_assumptions(scenario, health),
        health=searches[0].summary(scenario.health_label, budget_s) if searches else None,
        by_node=by_node,
        no_reading=_no_reading(data, scenario),
    )


def _same_assumptions(central: ExactBounds, fault_bounds: FaultBoundsMode, health: bool, scenario: Scenario) -> bool:
    """Whether ``central`` is the central limit under the assumptions a network limit is asked for (else it bounds
    nothing there and is not used)."""
    applied = health and scenario.health_declared
    return not central.network and central.fault_bounds == fault_bounds and (central.health is not None) == applied and not central.infeasible_steps


def _no_reading(data: list[RecordedStep], scenario: Scenario) -> tuple[tuple[int, int], ...]:
    """(node, step) of the program's nodes without a reading (a recorded drive's gaps)."""
    return tuple((i, d.step) for d in data for i in d.no_reading if i in scenario.ids)


def _program_nodes(
    scenario: Scenario, record: Record, data: list[RecordedStep], fault_bounds: FaultBoundsMode, nodes: Sequence[int] | None, network: bool
) -> tuple[Scenario, tuple[int, ...]]:
    """The scenario of the program's nodes (``nodes``, default all) and the nodes whose declared fault bounds it applies;
    a record or a node subset that does not fit the topology is refused (ExactError)."""
    for d in data:
        if set(d.y) | set(d.no_reading) != set(scenario.ids) or set(d.y) & set(d.no_reading) or set(d.gamma) != set(scenario.ids):
            without = f" and none of nodes {list(d.no_reading)}" if d.no_reading else ""
            raise ExactError(f"{record.path}: step {d.step} has measurements of nodes {sorted(d.y)}{without}, the topology has nodes {scenario.ids}")
    if nodes is None:
        return scenario, scenario.fault_bounded(fault_bounds)
    unknown = sorted(set(nodes) - set(scenario.ids))
    if unknown or not nodes:
        raise ExactError(f"nodes {list(nodes)}: not a non-empty subset of the topology's nodes {scenario.ids}")
    if network:
        raise ExactError("the network limit is over every node of the topology: give no node subset")
    # (the bounds the whole network's estimators rely on: a node's own bound is relied on where others read its reading)
    relied = scenario.fault_bounded(fault_bounds)
    scenario = replace(scenario, nodes=[n for n in scenario.nodes if n.id in set(nodes)])
    return scenario, tuple(i for i in relied if i in scenario.ids)


@dataclass
class _Limits:
    """Where one program's ends go: β, r (K, 2) and the faults it bounds (node → (K, 2))."""

    beta: np.ndarray
    r: np.ndarray
    fault: dict[int, np.ndarray]
    done: int = -1  # the last horizon whose ends are in (the programs of a network limit run side by side)

    def target(self, coordinate: Coordinate, node: int | None) -> np.ndarray:
        return self.fault[node] if node is not None else (self.beta if coordinate == "beta" else self.r)

    def window(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Step k's β and r ends so far (a horizon bounds them before the faults)."""
        return self.beta[k], self.r[k]


SIDES: tuple[tuple[Side, float], ...] = (("lo", 1.0), ("hi", -1.0))  # an end and the sign of its objective: lo = min z, hi = −min −z


@dataclass
class _StepLoop:
    """The exact program's horizons, one after another: at each step k the horizon-k program, and per bounded quantity
    (β, r, each fault) two solves, its least and its greatest value; a :class:`KofNSearch` (where the k-of-N health is
    applied) makes the horizon's program and each end."""

    keep_witnesses: bool
    eliminate: bool
    witnesses: dict[WitnessKey, Witness] = field(default_factory=dict)

    def run(self, prog: _Program, limits: _Limits, kofn: KofNSearch | None, progress: Callable[[int, int], None]) -> set[int]:
        """Every horizon of ``prog`` (its ends into ``limits``); the infeasible steps."""
        return {k for k, feasible in self.horizons(prog, limits, kofn, progress) if not feasible}

    def horizons(self, prog: _Program, limits: _Limits, kofn: KofNSearch | None, progress: Callable[[int, int], None]) -> Iterator[tuple[int, bool]]:
        """The horizons of ``prog`` one at a time (each step k and whether it has a trajectory), so that the programs of a
        network limit can run side by side, each importing what the others proved (:class:`_Ledger`)."""
        K1 = len(prog.data)
        st = _settings()
        infeasible = False
        for k in range(K1):
            progress(k, K1)
            if kofn is not None and infeasible:  # a later horizon only adds constraints: no trajectory either
                limits.done = k
                yield k, False
                continue
            conic = Conic(*prog.matrices(k, self.eliminate), st)
            horizon = kofn.horizon(conic, k) if kofn is not None else _Horizon(conic, prog.nz)
            feasible = self._ends(prog, k, horizon, limits, kofn)
            del horizon  # (its solvers: a suspended program keeps none)
            if feasible and kofn is not None:
                kofn.learn(k, limits)
            if kofn is not None:
                kofn.tally.clock(k)
            infeasible = infeasible or not feasible
            limits.done = k
            yield k, feasible

    def _ends(self, prog: _Program, k: int, horizon: _Horizon, limits: _Limits, kofn: KofNSearch | None) -> bool:
        """Every end of horizon k; False if the step has no trajectory."""
        feasible = True
        for coord, node, col in prog.objectives(k):
            target = limits.target(coord, node)  # node: the fault's only
            who = node if node is not None else prog.viewer  # a network limit's β and r are its viewer's
            for end, (side, sign) in enumerate(SIDES):
                key = WitnessKey(coord, who, k, side)
                result = kofn.end(horizon, key, col, sign, limits) if kofn is not None else horizon.end(col, sign, f"step {k}: the {coord} bound")
                if result.status == "infeasible":
                    feasible = False
                    continue
                target[k, end] = sign * result.value
                if self.keep_witnesses and result.z is not None and result.status == "solved":
                    self.witnesses[key] = prog.witness(result.z, k, self.eliminate)
        return feasible


def everywhere(scenario: Scenario) -> bool:
    """Whether every node has every node's data in its step, step 0's too (every d(j→i) = 0: one node alone, since a
    neighbour's step-0 data come with its state, a step late): then each node's network limit is the central one."""
    return all(len(d) == len(scenario.ids) and not any(d.values()) for i in scenario.ids for d in (scenario.delays(i), scenario.delays(i, first=True)))


def network_limit(scenario: Scenario, record: Record, central: ExactBounds, **kw: object) -> ExactBounds:
    """Each node's network limit (:func:`exact_bounds` with ``network=True``, the same ``fault_bounds`` and health as
    ``central``); where every datum reaches every node in its step, ``central`` itself as every node's (no program
    solved again).  ``kw``: exact_bounds' other options (budget, progress)."""
    if everywhere(scenario):
        nan = np.full_like(central.beta, np.nan)
        return replace(central, beta=nan, r=nan.copy(), by_node={i: (central.beta, central.r) for i in scenario.ids})
    health = central.health is not None or not scenario.health_declared
    return exact_bounds(scenario, record, central.fault_bounds, health=health, network=True, central=central, **kw)  # type: ignore[arg-type]  # kw: exact_bounds' keyword options, passed through


def eta_s(elapsed: float, done: int, total: int, budget_s: float | None) -> float | None:
    """Seconds left after ``done`` of ``total`` steps in ``elapsed`` s: a step costs about its horizon's length
    (every program grows with it), so the time so far grows as done².  Before the budget, at most what is left of
    it (the search stops there; the steps after it cost one solve an end, not counted); past it, that pace (an
    overestimate: the later steps have no search).  None before the first step is done."""
    if done <= 0:
        return None
    left = elapsed * (total**2 - done**2) / done**2
    return left if budget_s is None or elapsed >= budget_s else min(left, budget_s - elapsed)


def _ids(nodes: tuple[int, ...]) -> str:
    return ", ".join(map(str, nodes))


def health_line(h: HealthSearch) -> str:
    """One line on the k-of-N branch and bound: what was applied and how many ends are exact."""
    line = (
        f"applied: k-of-N health ({h.declared}: at least "
        f"{' and '.join(f'{n} of sensors {_ids(g)}' for n, g in zip(h.need, h.nodes))} healthy at every step) by branch and bound, "
        f"{h.exact_ends} of {h.ends} ends exact ({h.solves} solves, at most {h.budget} per end"
        + ("" if h.budget_s is None else f", {h.budget_s:g} s of CPU in all")
        + ")"
    )
    if h.out_of_time is not None:
        line += f"; the time budget ran out at step {h.out_of_time}: later ends are relaxed where one solve does not settle them"
    if not h.relaxed:
        return line
    shown = ", ".join(f"{k.coordinate}{'' if k.node is None else k.node} {k.side} at step {k.step}" for k in h.relaxed[:8])
    more = f" and {len(h.relaxed) - 8} more" if len(h.relaxed) > 8 else ""
    return f"{line}; relaxed (the least bound proven, an outer bound): {shown}{more}"


# the record's meta fields its topology determines: another topology with other values is not the record's
TOPOLOGY_FIELDS = ("node_ids", "tau_s", "C", "h1", "r_max", "in_weights", "plant", "model_uncertainty")


def topology_mismatch(scenario: Scenario, record: Record) -> str | None:
    """What differs between the record's meta and the meta ``scenario`` would write (None: nothing), over
    :data:`TOPOLOGY_FIELDS`; an empty map or list (a field an older record lacks) is not compared."""
    from netsetest.runtime.inmemory import run_meta  # the one place a scenario's meta is built

    m = record.meta
    mine = run_meta(scenario, m.mode or "", m.clock or "", m.signals or "", m.variant or "", m.seed, m.run_id or "")
    diffs = [
        f"{name} (record {getattr(m, name)!r:.80}, topology {getattr(mine, name)!r:.80})"
        for name in TOPOLOGY_FIELDS
        if getattr(m, name) != getattr(mine, name) and getattr(m, name) not in ({}, [])
    ]
    if not diffs and None not in (m.settings_digest, mine.settings_digest) and m.settings_digest != mine.settings_digest:
        diffs.append(
            "its other values (vehicle, speed, steering, noise, disturbance or fault bounds, priors, faults, losses or "
            f"k-of-N groups: settings digest {mine.settings_digest}, the record's {m.settings_digest})"
        )
    return "; ".join(diffs) or None


def omitted_assumptions(scenario: Scenario, health: bool = True) -> tuple[str, ...]:
    """The declared assumptions :func:`exact_bounds` does not apply (docs/exact.md): the k-of-N health
    unless it is applied (``health``)."""
    return (f"k-of-N health ({scenario.health_label})",) if scenario.health_declared and not health else ()


# ---------------------------------------------------------------- a record against the exact limit


@dataclass(frozen=True)
class CoordinateRatio:
    """One node's published intervals of one coordinate against the exact ones.

    ``width_ratio``: mean published width / mean exact width over the steps ≥ FROM_STEP;
    ``width_ratio_all``: the same over every step; ``rms_radius_rel``: Althoff & Rath's relative RMS
    radius (their eq. (9)) with the exact limit as the reference observer: √(mean r²_published) /
    √(mean r²_exact) over every step, r the interval's half-width (1 = exact).  Steps where the exact
    interval is unbounded or empty are left out and counted in ``left_out``.  ``narrower``: steps where
    the published interval does not contain the exact one (beyond NARROWER_TOL): the estimator relied
    on more than these assumptions there, or one of the two is wrong.  Where the exact interval is a point
    (mean width ≤ DEGENERATE_WIDTH: a reference sensor's declared zero fault) no ratio exists (NaN):
    ``width_excess`` (``_all``) is then the mean published width minus the mean exact width, absolute.
    """

    coordinate: Coordinate
    width_ratio: float
    width_ratio_all: float
    rms_radius_rel: float
    steps: int
    left_out: int
    narrower: int
    width_excess: float | None = None
    width_excess_all: float | None = None


@dataclass(frozen=True)
class NodeRatios:
    node: int
    ratios: dict[Coordinate, CoordinateRatio]


@dataclass(frozen=True)
class ExactComparison:
    """Per node and coordinate ratios, their mean over nodes per coordinate, and the overall mean."""

    nodes: tuple[NodeRatios, ...]
    mean_width_ratio: dict[Coordinate, float]
    mean_rms_radius_rel: dict[Coordinate, float]
    overall_width_ratio: float
    mean_width_ratio_all: dict[Coordinate, float]  # over all steps (mean_width_ratio: steps ≥ 10)
    overall_rms_radius_rel: float


def _ratio(num: np.ndarray, den: np.ndarray) -> float:
    """mean(num) / mean(den); NaN where den is empty or a point (no ratio to a zero width: :func:`_excess`)."""
    return float(num.mean() / den.mean()) if len(num) and den.mean() > DEGENERATE_WIDTH else float("nan")


def _excess(width: np.ndarray, exact_width: np.ndarray) -> float | None:
    """mean(width) − mean(exact_width) where the exact interval is a point (no ratio), else None."""
    return float(width.mean() - exact_width.mean()) if len(width) and not exact_width.mean() > DEGENERATE_WIDTH else None


def compare_record(record: Record, exact: ExactBounds) -> ExactComparison:
    """The record's published intervals against ``exact`` (see :class:`CoordinateRatio`)."""
    rows = []
    for i in sorted(record.nodes):
        if i not in exact.fault:
            raise ExactError(f"{record.path}: node {i} is not in the exact bounds (nodes {sorted(exact.fault)})")
        track = record.nodes[i]
        ratios = {}
        for idx, coord in enumerate(COORDINATES):
            lo, hi = track.bounds(idx)
            ex = exact.interval(coord, i)[track.steps]
            ok = np.isfinite(ex).all(axis=1)
            width, ex_width = (hi - lo)[ok], (ex[:, 1] - ex[:, 0])[ok]
            late = track.steps[ok] >= FROM_STEP
            slack = NARROWER_TOL * np.maximum(1.0, np.abs(ex))
            with np.errstate(invalid="ignore"):
                narrower = (lo > ex[:, 0] + slack[:, 0]) | (hi < ex[:, 1] - slack[:, 1])
            ratios[coord] = CoordinateRatio(
                coordinate=coord,
                width_ratio=_ratio(width[late], ex_width[late]),
                width_ratio_all=_ratio(width, ex_width),
                rms_radius_rel=float(np.sqrt(_ratio((width / 2) ** 2, (ex_width / 2) ** 2))),
                steps=int(ok.sum()),
                left_out=int((~ok).sum()),
                narrower=int(narrower.sum()),
                width_excess=_excess(width[late], ex_width[late]),
                width_excess_all=_excess(width, ex_width),
            )
        rows.append(NodeRatios(i, ratios))

    def mean(attr: str, coord: Coordinate) -> float:
        return _nanmean([getattr(n.ratios[coord], attr) for n in rows])

    return ExactComparison(
        nodes=tuple(rows),
        mean_width_ratio={c: mean("width_ratio", c) for c in COORDINATES},
        mean_rms_radius_rel={c: mean("rms_radius_rel", c) for c in COORDINATES},
        overall_width_ratio=_nanmean([n.ratios[c].width_ratio for n in rows for c in COORDINATES]),
        overall_rms_radius_rel=_nanmean([n.ratios[c].rms_radius_rel for n in rows for c in COORDINATES]),
        mean_width_ratio_all={c: mean("width_ratio_all", c) for c in COORDINATES},
    )


@dataclass(frozen=True)
class LocalLimit:
    """What the network could buy node i at best: its exact limit from its own data alone (``local``) over
    the exact limit from every node's data (``central``), mean width ratio from step FROM_STEP (docs/network.md);
    the same for its network limit (what the topology carries to it: :func:`limit_ratios`)."""

    node: int
    fault_ratio: float  # node i's own fault
    r_ratio: float
    beta_ratio: float


def limit_ratios(limit: ExactBounds, central: ExactBounds, nodes: Sequence[int]) -> list[LocalLimit]:
    """Per node: ``limit``'s mean width over ``central``'s from step FROM_STEP, per coordinate; NaN where the central
    width is solver precision (a reference sensor's own fault is 0)."""
    keep = central.steps >= FROM_STEP
    out = []
    for i in nodes:

        def ratio(coord: Coordinate, i: int = i) -> float:
            a, b = limit.interval(coord, i)[keep], central.interval(coord, i)[keep]
            ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
            wa, wb = (a[:, 1] - a[:, 0])[ok], (b[:, 1] - b[:, 0])[ok]
            return _ratio(wa, wb) if len(wb) and wb.mean() > DEGENERATE_WIDTH else float("nan")

        out.append(LocalLimit(i, ratio("f"), ratio("r"), ratio("beta")))
    return out


def local_limits(
    scenario: Scenario,
    record: Record,
    fault_bounds: FaultBoundsMode = "used",
    central: ExactBounds | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[LocalLimit]:
    """Per node: the one-node exact limit against the whole network's (``central``: computed unless given)."""
    central = central or exact_bounds(scenario, record, fault_bounds)
    out = []
    for n, i in enumerate(scenario.ids):
        out += limit_ratios(exact_bounds(scenario, record, fault_bounds, nodes=[i]), central, [i])
        if progress is not None:
            progress(n + 1, len(scenario.ids))
    return out


def _nanmean(values: list[float]) -> float:
    """The mean of the values that are not NaN; NaN (quietly) when none is (e.g. a record shorter than the
    steps the ratios skip)."""
    finite = [v for v in values if not np.isnan(v)]
    return float(np.mean(finite)) if finite else float("nan")


EXACT_FORMAT_VERSION = 3  # 3: health has relaxed_ends, budget_s, out_of_time; 2: {declared, need and nodes per group} instead of {max_faulty, need}


def _finite_or_none(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _health_document(h: HealthSearch | None) -> dict | None:
    if h is None:
        return None
    relaxed = [{"coordinate": k.coordinate, "node": k.node, "step": k.step, "side": k.side} for k in h.relaxed]
    return {
        "declared": h.declared,
        "need": list(h.need),
        "nodes": [list(g) for g in h.nodes],
        "budget": h.budget,
        "ends": h.ends,
        "exact_ends": h.exact_ends,
        "relaxed_ends": len(h.relaxed),
        "solves": h.solves,
        "budget_s": h.budget_s,
        "out_of_time": h.out_of_time,
        "relaxed": relaxed,
    }


def limit_ratios_document(limits: list[LocalLimit]) -> list[dict]:
    """Per node, its LocalLimit as JSON (NaN: null)."""
    return [{k: None if isinstance(v, float) and math.isnan(v) else v for k, v in asdict(lim).items()} for lim in limits]


def network_document(scenario: Scenario, network: ExactBounds, comparison: ExactComparison, central: ExactBounds) -> dict:
    """``exact --network --json``'s ``network`` object: per node the steps each node's data take to it (``delays``:
    node → {j: d(j→i)}), its network limit's intervals (``exact``: node → beta, r, fault, per step [lower, upper],
    null = unbounded), the record's ratios against it (``ratios``, the form of the document's own) and the limit over
    the central one (``over_central``: node, fault_ratio, r_ratio, beta_ratio)."""

    def intervals(a: np.ndarray) -> list[list[float | None]]:
        return [[_finite_or_none(lo), _finite_or_none(hi)] for lo, hi in a]

    ids = sorted(network.fault)
    return {
        "label": network.label,
        "delays": {str(i): {str(j): d for j, d in scenario.delays(i).items()} for i in ids},
        "health": _health_document(network.health),
        "exact": {str(i): {c: intervals(network.interval(c, i)) for c in ("beta", "r")} | {"fault": intervals(network.fault[i])} for i in ids},
        "ratios": _ratios_document(comparison),
        "over_central": limit_ratios_document(limit_ratios(network, central, ids)),
    }


def _ratios_document(comparison: ExactComparison) -> dict:
    def ratio(c: CoordinateRatio) -> dict:
        return {
            "width_ratio": _finite_or_none(c.width_ratio),
            "width_ratio_all": _finite_or_none(c.width_ratio_all),
            "rms_radius_rel": _finite_or_none(c.rms_radius_rel),
            "steps": c.steps,
            "left_out": c.left_out,
            "narrower": c.narrower,
            "width_excess": c.width_excess,
            "width_excess_all": c.width_excess_all,
        }

    return {
        "nodes": {str(n.node): {c: ratio(n.ratios[c]) for c in COORDINATES} for n in comparison.nodes},
        "mean_width_ratio": {c: _finite_or_none(v) for c, v in comparison.mean_width_ratio.items()},
        "mean_rms_radius_rel": {c: _finite_or_none(v) for c, v in comparison.mean_rms_radius_rel.items()},
        "overall_width_ratio": _finite_or_none(comparison.overall_width_ratio),
        "overall_rms_radius_rel": _finite_or_none(comparison.overall_rms_radius_rel),
    }


def exact_document(record: Record, exact: ExactBounds, comparison: ExactComparison) -> dict:
    """The ``--json`` document: per step exact intervals (null: unbounded on that side, or no
    trajectory at an infeasible step) and the record's ratios."""

    def intervals(a: np.ndarray) -> list[list[float | None]]:
        return [[_finite_or_none(lo), _finite_or_none(hi)] for lo, hi in a]

    return {
        "format": "netsetest-exact",
        "version": EXACT_FORMAT_VERSION,
        "record": record.path,
        "fault_bounds": exact.fault_bounds,
        "bounded_nodes": list(exact.bounded_nodes),
        "from_step": FROM_STEP,
        "steps": [int(k) for k in exact.steps],
        "infeasible_steps": list(exact.infeasible_steps),
        "no_reading": [list(p) for p in exact.no_reading],
        "omitted": list(exact.omitted),
        "health": _health_document(exact.health),
        "exact": {
            "beta": intervals(exact.beta),
            "r": intervals(exact.r),
            "fault": {str(i): intervals(a) for i, a in exact.fault.items()},
        },
        "ratios": _ratios_document(comparison),
    }
