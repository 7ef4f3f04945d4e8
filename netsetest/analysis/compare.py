"""``netsetest compare``: every guaranteed estimator on the same vehicle, network and data.

For each (case, signals, seed) the network runs in memory once per real-time estimator, every node
running it (the ``sdp`` row: this project's ellipsoidal SDP; the others of estimator/registry.py as
node estimators, each node keeping the SDP where a method refuses it; the vehicle's truth and
measurements are the same in every run of a seed), exactly as ``netsetest run`` runs them; the exact
limit (analysis/exact.py, centralized, declared fault bounds where a saturating sensor needs them) is
the reference and the ``exact`` row (not real time: its ms is the offline solve time per node-step).

Per row: containment — the published set is checked against the truth at every node-step; every node
row is judged by the run's collector (its one-step dependency cone, docs/coverage.md: a miss where the
cone held is a ``violation``, other misses are attributed to the cause the collector names), so a row
here is what a user's run of that estimator reports.  The exact rows use every datum of the horizon, so
their cone is the whole history: the prior at step 0, the noise bound at every step ≤ k, the wind bound
at every step < k, the declared fault bound at every step ≤ k where applied (roles/judge.py,
:func:`~netsetest.roles.judge.history_cone`).
``covered`` counts the node-steps whose cone held.  Widths are per-coordinate interval-hull widths,
mean over nodes and the steps ≥ FROM_STEP; ``ratio_exact`` is the mean fault width over the exact
one's (same steps, bounded exact intervals only), ``ratio_exact_state`` the same for β and r, each
against the exact limit under the row's own assumptions: a method that relies on the declared fault
bound of a node where the ``exact`` row does not (every non-saturating node) is compared with the exact
limit with every declared bound (``exact_reference`` "all");
``narrower`` counts the intervals (node-step and coordinate) narrower than the exact one where the
node-step's cone held (beyond exact.NARROWER_TOL; an end the k-of-N search left relaxed is not the limit and
is left out): a sound set never is;
``rests_on`` says in words what the row's sets rest on (the declared fault bound at which nodes: the SDP and the
exact row where the SDP relies on it, strip and setprop at every node), and :func:`assumptions_notes` what that means
for the widths: a row resting on more than the ``exact`` row (the limit under the SDP's assumptions) may be narrower
than it, never than the limit under its own;
``rms_radius_rel`` is Althoff & Rath's relative-RMS radius (their eq. (9)) with the exact limit as the
reference observer, mean over nodes and the three coordinates; ms are per node-step.
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from netsetest.analysis.exact import COORDINATES, DEGENERATE_WIDTH, FROM_STEP, NARROWER_TOL, ExactBounds, exact_bounds, network_limit, step_data
from netsetest.config.schema import Case, ConfigError, Scenario, load_topology
from netsetest.analysis.errors import CompareError
from netsetest.estimator.names import DEFAULT_COMPARE, ESTIMATOR_NAMES, EXACT, SDP
from netsetest.estimator.registry import node_set_estimator
from netsetest.logs.drive import with_log_steps
from netsetest.models.signals import SignalKind
from netsetest.records.record import Record, record_from_parts
from netsetest.roles.judge import HEALTH, history_cone
from netsetest.runtime.inmemory import run_inmemory

CONTAIN_TOL = 1e-8  # the sets' own membership slack (sets.MEMBERSHIP_TOL) plus float sums of the bounds
EXACT_PINNED = 1e-9  # an exact half-width below this is a coordinate pinned by a declaration (no ratio to it)
_COLLECTOR: tuple[str, ...] = ("dependency cone (collector)",)  # a node row: judged by the run's collector
SDP_ALONE, EXACT_LOCAL = "sdp-alone", "exact-local"  # compare(alone=True): the nodes alone, each node's exact local limit
EXACT_NETWORK = "exact-network"  # compare(alone=True): each node's network limit (what the topology carries to it)
SDP_ELLIPSOID = "sdp-ellipsoid"  # the SDP's published ellipsoid alone (the paper's own set), scored from the same run as ``sdp``
ALONE_ROWS = (SDP_ALONE, EXACT_LOCAL, EXACT_NETWORK)
OFFLINE = (EXACT, EXACT_LOCAL, EXACT_NETWORK)  # the rows that are limits, not estimators


@dataclass
class _Accumulator:
    """One estimator's samples over every run, node and step."""

    node_steps: int = 0
    covered: int = 0
    violations: int = 0
    attributed: Counter = field(default_factory=Counter)
    widths: list[np.ndarray] = field(default_factory=list)  # (3,) per late node-step with a bounded exact
    exact_widths: list[np.ndarray] = field(default_factory=list)
    # node → (published, exact) mean widths (3,) over its late steps: the per-node ratios, and the coordinates
    # whose exact interval is a point (a reference's declared fault), which get the absolute excess, no ratio
    per_node: dict[int, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    rms: list[float] = field(default_factory=list)  # relative-RMS radius per run, node and coordinate
    narrower: int = 0  # published intervals not holding the exact one on a covered node-step (must stay 0)
    compared: int = 0  # the intervals that count was taken over (covered node-steps, exact ends not relaxed)
    ms: list[float] = field(default_factory=list)
    fallbacks: int = 0
    refused: list[str] = field(default_factory=list)
    assumptions: set[str] = field(default_factory=set)
    references: set[str] = field(default_factory=set)  # fault-bounds modes of the exact limits compared with
    # node → (published, network limit) mean widths (3,) over its late steps: the ratios to what the topology carries
    per_node_network: dict[int, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    # what the row's sets rest on, for its ``rests_on``: the nodes scored, those where it relies on the declared fault
    # bound (|f_k+1 − f_k| ≤ δ, |f_k| ≤ F), and whether on the k-of-N health
    nodes: set[int] = field(default_factory=set)
    fault_bound_nodes: set[int] = field(default_factory=set)
    health: bool = False

    def rests_on(self, node: int, fault_bound: bool, health: bool) -> None:
        """Node ``node``'s sets in this row rest on the base assumptions, and on the declared fault bound and the
        k-of-N health where told."""
        self.nodes.add(node)
        if fault_bound:
            self.fault_bound_nodes.add(node)
        self.health |= health


@dataclass(frozen=True)
class CompareRow:
    estimator: str
    real_time: bool
    assumptions: list[str]
    node_steps: int
    covered: int
    violations: int
    misses_attributed: dict[str, int]
    fault_width_mean: float | None
    beta_width_mean: float | None
    r_width_mean: float | None
    ratio_exact: float | None
    ratio_exact_state: list[float | None]
    ratio_exact_by_node: dict[int, list[float | None]]  # node → [β, r, f] mean published width / exact (None: a point exact interval)
    pinned_excess: float | None  # mean published width − exact width over (node, coordinate)s whose exact interval is a point
    narrower: int  # intervals narrower than exact where the assumptions held (beyond NARROWER_TOL; a relaxed exact end left out)
    compared: int  # the intervals checked for it
    rms_radius_rel: float | None
    ms_median: float | None
    ms_p95: float | None
    fallbacks: int
    refused: list[str]
    exact_reference: list[str]  # fault-bounds modes of the exact limit its ratios are against
    # the same mean widths over each node's network limit (compare(network=True): what the topology carries to the node;
    # docs/exact.md), [β, r, f] pooled over nodes and per node; None where not computed or a point
    ratio_network: list[float | None] = field(default_factory=lambda: [None, None, None])
    ratio_network_by_node: dict[int, list[float | None]] = field(default_factory=dict)
    rests_on: str = ""  # the assumptions its sets rest on, in words (:func:`_rests_on_text`)
    fault_bound_nodes: list[int] = field(default_factory=list)  # the nodes where it relies on the declared fault bound


@dataclass(frozen=True)
class Comparison:
    topology: str
    runs: list[str]  # case/signals/seed of each run
    steps: int
    tau_s: float
    rows: list[CompareRow]
    bounds: dict[str, dict[int, np.ndarray]]  # first run: estimator → node → (K, 3, 2)
    truth_fault: dict[int, np.ndarray]  # first run: node → (K,)
    plant: str = "ts"  # what generated the truth (Scenario.plant_label)


def _centralized_cones(sc: Scenario, rec: Record, ex: ExactBounds) -> dict[int, str | None]:
    """Per step: the exact limit rests on every node's whole history (with the fault bound where applied, and
    the k-of-N health of every step where applied)."""
    truth = sorted(rec.truth, key=lambda t: t["step"])
    per_node = {i: history_cone(sc, truth, i, i in ex.bounded_nodes) for i in sc.ids}
    cones = {k: next((per_node[i][k] for i in sc.ids if per_node[i][k] is not None), None) for k in range(len(truth))}
    if ex.health is not None:
        broke = next((k for k, t in enumerate(truth) if not t.get("health_ok", True)), len(truth))
        cones.update({k: cones[k] or HEALTH for k in range(broke, len(truth))})
    return cones


def _record_bounds(rec: Record, i: int, ellipsoid: bool = False) -> np.ndarray:
    """(K, 3, 2) node i's published set's bounds (``ellipsoid``: its published ellipsoid's alone)."""
    tr = rec.nodes[i]
    of = tr.ellipsoid_bounds if ellipsoid else tr.bounds
    return np.stack([np.stack(of(c), axis=1) for c in range(3)], axis=1)


def _exact_array(ex: ExactBounds, i: int) -> np.ndarray:
    return np.stack([ex.interval("beta", i), ex.interval("r", i), ex.fault[i]], axis=1)


def _limit_ends(ex: ExactBounds, i: int) -> np.ndarray:
    """:func:`_exact_array` with every end the k-of-N search relaxed set to NaN: the ends that are the limit."""
    out = _exact_array(ex, i).copy()
    for key in ex.health.relaxed if ex.health is not None else ():
        if key.node in (None, i):
            out[key.step, COORDINATES.index(key.coordinate), 0 if key.side == "lo" else 1] = np.nan
    return out


def _score(
    acc: _Accumulator,
    node: int,
    bounds: np.ndarray,
    steps: np.ndarray,
    truth: np.ndarray,
    reference: ExactBounds,
    broken: list[str | None],
    network: ExactBounds | None = None,
) -> None:
    """Add node ``node``'s run: bounds (K, 3, 2) at ``steps``, truth (K, 3), against the exact limit ``reference`` (and
    its widths against the node's ``network`` limit)."""
    if network is not None:
        net = _exact_array(network, node)[steps]
        keep = np.isfinite(net).all(axis=(1, 2)) & (steps >= FROM_STEP)
        if keep.any():
            acc.per_node_network.setdefault(node, []).append(
                (np.diff(bounds[keep], axis=2)[..., 0].mean(axis=0), np.diff(net[keep], axis=2)[..., 0].mean(axis=0))
            )
    ex = _exact_array(reference, node)[steps]
    limit = _limit_ends(reference, node)[steps]
    held = np.array([b is None for b in broken], dtype=bool)
    slack = NARROWER_TOL * np.maximum(1.0, np.abs(limit))
    with np.errstate(invalid="ignore"):  # (NaN: an unbounded, infeasible or relaxed end, not compared)
        narrower = (bounds[..., 0] > limit[..., 0] + slack[..., 0]) | (bounds[..., 1] < limit[..., 1] - slack[..., 1])
    acc.narrower += int(narrower[held].sum())
    acc.compared += int(np.isfinite(limit[held]).any(axis=-1).sum())
    for n in range(len(steps)):
        acc.node_steps += 1
        inside = bool(np.all(bounds[n, :, 0] <= truth[n] + CONTAIN_TOL) and np.all(truth[n] <= bounds[n, :, 1] + CONTAIN_TOL))
        if broken[n] is None:
            acc.covered += 1
            acc.violations += not inside
        elif not inside:
            acc.attributed[broken[n]] += 1
    ok = np.isfinite(ex).all(axis=(1, 2))
    late = ok & (steps >= FROM_STEP)
    acc.widths += list(np.diff(bounds[late], axis=2)[..., 0])
    acc.exact_widths += list(np.diff(ex[late], axis=2)[..., 0])
    if late.any():
        acc.per_node.setdefault(node, []).append((np.diff(bounds[late], axis=2)[..., 0].mean(axis=0), np.diff(ex[late], axis=2)[..., 0].mean(axis=0)))
    if ok.any():
        half, ex_half = np.diff(bounds[ok], axis=2)[..., 0] / 2, np.diff(ex[ok], axis=2)[..., 0] / 2
        ex_ms = (ex_half**2).mean(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):  # a coordinate the exact limit pins (a reference's declared fault): no ratio
            acc.rms += list(np.where(ex_ms > EXACT_PINNED**2, np.sqrt((half**2).mean(axis=0) / ex_ms), np.nan))


BASE_WORDS = "prior, noise, disturbance"  # estimator/base.py BASE_ASSUMPTIONS: x̄_0 in the prior, v² ≤ R, w² ≤ W (and e_k where declared)


def _rests_on_text(acc: _Accumulator) -> str:
    """The row's assumptions in words: the base ones, the declared fault bound at which nodes, the k-of-N health."""
    words = [BASE_WORDS]
    bound = sorted(acc.fault_bound_nodes)
    if bound:
        where = "every node" if acc.nodes <= acc.fault_bound_nodes else f"node{'s' if len(bound) > 1 else ''} {', '.join(map(str, bound))}"
        words.append(f"declared fault bound at {where}")
    if acc.health:
        words.append(HEALTH)
    return ", ".join(words)


def _row(name: str, acc: _Accumulator, real_time: bool) -> CompareRow:
    def num(v: float) -> float | None:
        return float(v) if np.isfinite(v) else None

    w = np.array(acc.widths).reshape(-1, 3)
    mean = w.mean(axis=0) if len(w) else np.full(3, np.nan)
    by_node = {i: (np.mean([w for w, _ in runs], axis=0), np.mean([e for _, e in runs], axis=0)) for i, runs in sorted(acc.per_node.items())}
    pinned = {i: e <= DEGENERATE_WIDTH for i, (_, e) in by_node.items()}  # a point exact interval: no ratio to it
    if by_node:  # pooled over the nodes, without the (node, coordinate)s the exact limit pins
        keep = np.array([~pinned[i] for i in by_node])
        w_all, e_all = np.array([w for w, _ in by_node.values()]), np.array([e for _, e in by_node.values()])
        with np.errstate(invalid="ignore"):
            ratio = np.where(keep, w_all, 0.0).sum(axis=0) / np.where(keep, e_all, 0.0).sum(axis=0)
        excess = [float(w[m] - e[m]) for i, (w, e) in by_node.items() for m in range(3) if pinned[i][m]]
    else:
        ratio, excess = np.full(3, np.nan), []
    ms = np.array(acc.ms)
    net_ratio, net_by_node = _network_ratios(acc.per_node_network)
    return CompareRow(
        estimator=name,
        real_time=real_time,
        assumptions=sorted(acc.assumptions),
        node_steps=acc.node_steps,
        covered=acc.covered,
        violations=acc.violations,
        misses_attributed=dict(acc.attributed),
        fault_width_mean=num(mean[2]),
        beta_width_mean=num(mean[0]),
        r_width_mean=num(mean[1]),
        ratio_exact=num(ratio[2]),
        ratio_exact_state=[num(ratio[0]), num(ratio[1])],
        ratio_exact_by_node={i: [None if pinned[i][m] else num(float(w[m] / e[m])) for m in range(3)] for i, (w, e) in by_node.items()},
        pinned_excess=float(np.mean(excess)) if excess else None,
        narrower=acc.narrower,
        compared=acc.compared,
        rms_radius_rel=num(float(np.nanmean(acc.rms))) if acc.rms else None,
        ms_median=num(float(np.median(ms))) if len(ms) else None,
        ms_p95=num(float(np.percentile(ms, 95))) if len(ms) else None,
        fallbacks=acc.fallbacks,
        refused=acc.refused[:3],
        exact_reference=sorted(acc.references),
        ratio_network=net_ratio,
        ratio_network_by_node=net_by_node,
        rests_on=_rests_on_text(acc),
        fault_bound_nodes=sorted(acc.fault_bound_nodes),
    )


def _network_ratios(per_node: dict[int, list[tuple[np.ndarray, np.ndarray]]]) -> tuple[list[float | None], dict[int, list[float | None]]]:
    """[β, r, f] mean published width over the network limit's, pooled over the nodes and per node (None: a point)."""
    if not per_node:
        return [None, None, None], {}
    means = {i: (np.mean([w for w, _ in runs], axis=0), np.mean([e for _, e in runs], axis=0)) for i, runs in sorted(per_node.items())}
    keep = {i: e > DEGENERATE_WIDTH for i, (_, e) in means.items()}
    w_all = sum(np.where(keep[i], w, 0.0) for i, (w, _) in means.items())
    e_all = sum(np.where(keep[i], e, 0.0) for i, (_, e) in means.items())
    pooled = [float(a / b) if b > 0 else None for a, b in zip(w_all, e_all)]  # type: ignore[arg-type]  # sums of (3,) arrays
    return pooled, {i: [float(w[m] / e[m]) if keep[i][m] else None for m in range(3)] for i, (w, e) in means.items()}


def _check_lists(estimators: tuple[str, ...], cases: tuple[Case | None, ...], signals: tuple[SignalKind, ...], seeds: tuple[int, ...]) -> None:
    """CompareError where ``compare``'s lists name an unknown estimator, one twice, or leave nothing to compare."""
    unknown = [e for e in estimators if e not in ESTIMATOR_NAMES]
    if unknown:
        raise CompareError(f"unknown estimator {unknown[0]!r}; choose from {', '.join(ESTIMATOR_NAMES)}")
    if len(set(estimators)) != len(estimators):
        raise CompareError(f"estimator list {','.join(estimators)} names one twice")
    if not estimators or not cases or not signals or not seeds:
        raise CompareError("nothing to compare: give at least one estimator, case, signal kind and seed")


def compare(
    topology: str | Path,
    estimators: tuple[str, ...] = DEFAULT_COMPARE,
    cases: tuple[Case | None, ...] = (None,),
    signals: tuple[SignalKind, ...] = ("paper",),
    seeds: tuple[int, ...] = (0,),
    steps: int | None = None,
    progress: Callable[[int, int, str], None] | None = None,
    alone: bool = False,
    network: bool = False,
) -> Comparison:
    """Run every (case, signals, seed) and score every estimator (module doc); ``progress(done, total,
    what)`` after each run and each estimator's scoring (a comparison takes tens of seconds).

    ``alone``: three more rows, what the network is worth: ``sdp-alone``, the same nodes run on their own (a
    self-loop only, no reading: :meth:`Scenario.alone`), ``exact-local``, each node's exact limit from
    its own data (the best any node alone can do), and ``exact-network``, each node's limit from what the topology
    carries to it (docs/exact.md); all against the central exact limit, like every row.  ``network`` (implied by
    ``alone``): every row's widths over each node's network limit too (``ratio_network``, ``ratio_network_by_node``)."""
    _check_lists(estimators, cases, signals, seeds)
    names = [r for e in estimators for r in ((e, SDP_ELLIPSOID) if e == SDP else (e,))]  # the paper's own set right after sdp
    acc = {e: _Accumulator() for e in (*names, *(ALONE_ROWS if alone else ()))}
    runs: list[str] = []
    first_bounds: dict[str, dict[int, np.ndarray]] = {}
    truth_fault: dict[int, np.ndarray] = {}
    sc = None
    total = len(cases) * len(signals) * len(seeds) * (1 + len(estimators) + len(ALONE_ROWS) * alone)  # a run, then each row's scoring
    done = [0]

    def report(what: str) -> None:
        done[0] += 1
        if progress is not None:
            progress(done[0], total, what)

    for case in cases:
        # the run (row sdp) is all-SDP, whatever the file's nodes say; a recorded drive's steps decided against its log, as run's
        sc = with_log_steps(load_topology(topology, case, steps, SDP))
        for sig in signals:
            for seed in seeds:
                rec = _run_record(sc, sig, seed)
                report(f"run {sc.case}/{sig}/{seed}")
                ex, net = _score_run(sc, rec, sig, seed, estimators, acc, first_bounds if not runs else None, report, network or alone)
                if alone:
                    assert net is not None
                    _score_alone(sc, rec, _run_record(sc.alone(), sig, seed), ex, net, acc, first_bounds if not runs else None, report)
                runs.append(f"{sc.case}/{sig}/{seed}")
                if len(runs) == 1:
                    truth_fault = {i: np.array([t["faults"][i] for t in sorted(rec.truth, key=lambda t: t["step"])]) for i in sc.ids}
    assert sc is not None
    rows = [_row(e, a, e not in OFFLINE) for e, a in acc.items()]
    return Comparison(str(topology), runs, sc.steps, sc.tau_s, rows, first_bounds, truth_fault, sc.plant_label)


def _node_track(rec: Record, i: int, a: _Accumulator, ellipsoid: bool = False) -> tuple[np.ndarray, np.ndarray, list[str | None]]:
    """Node i's published bounds in a run's record (``ellipsoid``: its ellipsoid's alone), its steps, and per
    step None (covered) or the cause the collector named; its solve times and fallbacks go to ``a``."""
    track = rec.nodes[i]
    bounds, steps = _record_bounds(rec, i, ellipsoid), track.steps.astype(int)
    a.ms += [float(m) for m, s, k in zip(track.solve_ms, track.status, steps) if s in ("ok", "fallback") and k > 0]
    a.fallbacks += sum(s == "fallback" for s in track.status)
    a.assumptions.update(_COLLECTOR)
    causes = [e.get("not_covered_cause") or "dependency cone" for e in rec.raw_nodes[str(i)]]
    return bounds, steps, [None if ok else why for ok, why in zip(track.assumptions_ok, causes)]


def _network_of(sc: Scenario, name: str) -> tuple[Scenario, dict[int, tuple[str, ...]], list[str]]:
    """The scenario with every node running set estimator ``name`` where it accepts the node (the others keep
    the SDP and are left out of the row), the accepted nodes' declared assumptions, and the refusals."""
    trial = dataclasses.replace(sc, nodes=[dataclasses.replace(n, estimator=name) for n in sc.nodes])
    accepted: dict[int, tuple[str, ...]] = {}
    refused: list[str] = []
    for n in sc.nodes:
        try:
            accepted[n.id] = tuple(node_set_estimator(trial, n.id).assumptions)
        except ConfigError as exc:
            refused.append(str(exc))
    run = dataclasses.replace(sc, nodes=[dataclasses.replace(n, estimator=name) if n.id in accepted else n for n in sc.nodes])
    return run, accepted, refused


def _score_alone(
    sc: Scenario,
    rec: Record,
    rec_alone: Record,
    ex: ExactBounds,
    net: ExactBounds,
    acc: dict[str, _Accumulator],
    keep: dict[str, dict[int, np.ndarray]] | None,
    report: Callable[[str], None],
) -> None:
    """The rows of ``compare(alone=True)``: the nodes run alone (``rec_alone``, the same truth and
    measurements), each node's exact local limit and each node's network limit ``net``, against the central exact
    limit ``ex``."""
    cones = _centralized_cones(sc, rec, net)  # (the network limit rests on what reaches the node: a subset of this)
    truth = sorted(rec.truth, key=lambda t: t["step"])
    for name in ALONE_ROWS:
        a = acc[name]
        if keep is not None:
            keep[name] = {}
        for i in sc.ids:
            tr_i = np.array([np.r_[t["x"], t["faults"][i]] for t in truth])
            if name == SDP_ALONE:
                bounds, steps, broken = _node_track(rec_alone, i, a)
                a.rests_on(i, i in ex.bounded_nodes, False)  # alone: no reading, so no k-of-N pin
            elif name == EXACT_NETWORK:
                bounds, steps = _exact_array(net, i), np.arange(len(truth))
                broken = [cones[int(k)] for k in steps]
                a.assumptions.update(("prior", "noise", "disturbance", *(("fault_bound",) if net.bounded_nodes else ()), *((HEALTH,) if net.health else ())))
                a.rests_on(i, i in net.bounded_nodes, net.health is not None)
            else:
                t0 = time.perf_counter()
                local = exact_bounds(sc, rec, "used", nodes=[i])
                bounds, steps = _exact_array(local, i), np.arange(len(truth))
                a.ms += [1000 * (time.perf_counter() - t0) / len(steps)] * len(steps)
                broken = history_cone(sc, truth, i, i in local.bounded_nodes)
                a.assumptions.update(("prior", "noise", "disturbance", *(("fault_bound",) if local.bounded_nodes else ())))
                a.rests_on(i, i in local.bounded_nodes, local.health is not None)
            a.references.add(ex.label)
            _score(a, i, bounds, steps, tr_i[steps], ex, broken, net)
            if keep is not None:
                keep[name][i] = bounds
        report(name)


def _run_record(sc: Scenario, signals: SignalKind, seed: int) -> Record:
    """One in-memory run, as ``netsetest run --mode inmemory`` makes it, kept in memory as a record."""
    res = run_inmemory(sc, signals, "scheduled", seed)
    assert res.parts is not None  # kept in memory (run_inmemory's default)
    return record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)


def _score_run(
    sc: Scenario,
    rec: Record,
    signals: SignalKind,
    seed: int,
    estimators: tuple[str, ...],
    acc: dict[str, _Accumulator],
    keep: dict[str, dict[int, np.ndarray]] | None,
    report: Callable[[str], None],
    network: bool = False,
) -> tuple[ExactBounds, ExactBounds | None]:
    """Score every estimator on one (case, signals, seed): ``rec`` is the SDP network's run; each set
    estimator runs as the network's nodes on the same seed.  Returns the central exact limit (what every
    row is measured against) and, with ``network``, each node's network limit (every row's widths over it too)."""
    data = step_data(rec)
    t0 = time.perf_counter()
    ex = exact_bounds(sc, rec, "used")
    net = network_limit(sc, rec, ex) if network else None
    exact_ms = 1000 * (time.perf_counter() - t0) / (len(data) * len(sc.ids))
    ex_all: ExactBounds | None = None  # the exact limit with every declared fault bound, if a row uses more
    truth = sorted(rec.truth, key=lambda t: t["step"])
    all_steps = np.arange(len(data))
    for name in estimators:
        a = acc[name]
        if keep is not None:
            keep[name] = {}
        accepted: dict[int, tuple[str, ...]]
        if name in (SDP, EXACT):
            run, accepted = rec, {i: () for i in sc.ids}
        else:
            sc_run, accepted, refused = _network_of(sc, name)
            a.refused += refused
            run = _run_record(sc_run, signals, seed)
        for i in accepted:
            tr_i = np.array([np.r_[t["x"], t["faults"][i]] for t in truth])
            reference = ex
            if name == EXACT:
                bounds, steps = _exact_array(ex, i), all_steps
                cones = _centralized_cones(sc, rec, ex)
                broken = [cones[int(k)] for k in steps]
                a.ms += [exact_ms] * len(steps)
                a.assumptions.update(("prior", "noise", "disturbance", *(("fault_bound",) if ex.bounded_nodes else ()), *((HEALTH,) if ex.health else ())))
                a.rests_on(i, i in ex.bounded_nodes, ex.health is not None)  # the SDP's assumptions ("used")
            else:
                bounds, steps, broken = _node_track(run, i, a)
                # the SDP relies on a node's declared bound where "used" applies it; a set estimator where it says so
                a.rests_on(i, i in ex.bounded_nodes if name == SDP else "fault_bound" in accepted[i], ex.health is not None)
                if "fault_bound" in accepted[i] and i not in ex.bounded_nodes:
                    ex_all = ex_all or exact_bounds(sc, rec, "all")
                    reference = ex_all
            a.references.add(reference.label)
            _score(a, i, bounds, steps, tr_i[steps], reference, broken, net)
            if keep is not None:
                keep[name][i] = bounds
            if name == SDP:  # the paper's own set, the published ellipsoid alone, from the same run
                e_bounds, _, _ = _node_track(run, i, acc[SDP_ELLIPSOID], ellipsoid=True)
                acc[SDP_ELLIPSOID].rests_on(i, i in ex.bounded_nodes, ex.health is not None)
                acc[SDP_ELLIPSOID].references.add(reference.label)
                _score(acc[SDP_ELLIPSOID], i, e_bounds, steps, tr_i[steps], reference, broken, net)
        report(name)
    return ex, net


def comparison_document(c: Comparison) -> list[dict]:
    """The ``--json`` document: one object per row."""
    return [asdict(r) | {"plant": c.plant} for r in c.rows]


def _fmt(v: float | None, spec: str = ".4f") -> str:
    return "–" if v is None else format(v, spec)


TABLE_HEADER = (
    "estimator",
    "plant",
    "violations",
    "misses (broken assumption)",
    "covered",
    "fault width",
    "β width",
    "r width",
    "fault/exact",
    "β, r / exact",
    "exact with fault bounds",
    "β, r, f / network",
    "rms radius rel.",
    "ms median",
    "ms p95",
    "fallbacks",
    "rests on",
)


def table_rows(c: Comparison) -> list[tuple[str, ...]]:
    out: list[tuple[str, ...]] = []
    for r in c.rows:
        broken = ", ".join(f"{k} {v}" for k, v in sorted(r.misses_attributed.items())) or "0"
        name = r.estimator + ("" if r.real_time else " (offline)") + (" [refused some nodes]" if r.refused else "")
        out.append(
            (
                name,
                c.plant,
                str(r.violations),
                broken,
                f"{r.covered}/{r.node_steps}",
                _fmt(r.fault_width_mean),
                _fmt(r.beta_width_mean),
                _fmt(r.r_width_mean),
                _fmt(r.ratio_exact, ".3f"),
                "/".join(_fmt(v, ".3f") for v in r.ratio_exact_state),
                ",".join(r.exact_reference),
                "/".join(_fmt(v, ".3f") for v in r.ratio_network),
                _fmt(r.rms_radius_rel, ".3f"),
                _fmt(r.ms_median, ".3f"),
                _fmt(r.ms_p95, ".3f"),
                str(r.fallbacks),
                r.rests_on,
            )
        )
    return out


def assumptions_notes(c: Comparison) -> list[str]:
    """What the rows' assumptions mean for their widths, under every table (terminal, Markdown, page): the ``exact``
    row is the limit under the SDP's assumptions; a row resting on a declared fault bound where the SDP does not
    (strip, setprop: their fault model) may be narrower than that row, and is measured against the limit under its own."""
    by = {r.estimator: r for r in c.rows}
    sdp_like = by.get(EXACT) or by.get(SDP)
    notes = [
        "rests on: the assumptions a row's sets are guaranteed under (docs/comparison.md); its ratios are against the exact "
        "limit under the same ('exact with fault bounds': used = where the SDP relies on a declared fault bound, all = every declared bound)."
    ]
    if EXACT in by:
        notes.append(f"The exact row is the limit under the SDP's assumptions ({by[EXACT].rests_on}): no estimator resting on no more can be narrower.")
    if sdp_like is not None:
        more = [r.estimator for r in c.rows if r.estimator not in ALONE_ROWS and not set(r.fault_bound_nodes) <= set(sdp_like.fault_bound_nodes)]
        if more:
            its = "its" if len(more) == 1 else "their"
            notes.append(
                f"{', '.join(more)} rest{'s' if len(more) == 1 else ''} on a declared fault bound (|f_k+1 − f_k| ≤ δ, |f_k| ≤ F) where the SDP "
                f"does not: more than the exact row assumes, so {its} widths may be narrower than that row's and still sound, though never "
                f"narrower than the exact limit under {its} own assumptions, which {its} ratios are against."
            )
    return notes


def node_ratio_lines(c: Comparison) -> list[str]:
    """Per estimator and node: mean published width / exact of r, β and f from step FROM_STEP; a coordinate the
    exact limit pins to a point (a reference's declared fault) shows the absolute width over it instead."""
    nodes = sorted({i for r in c.rows for i in r.ratio_exact_by_node})
    lines = [f"per node, r / β / f width over exact (steps ≥ {FROM_STEP}; '–': the exact interval is a point, see 'pinned')"]
    lines.append(f"{'estimator':<22}" + "".join(f"{'node ' + str(i):>20}" for i in nodes) + "  pinned +width")
    for r in c.rows:
        cells = []
        for i in nodes:
            v = r.ratio_exact_by_node.get(i)
            cells.append(f"{'' if v is None else '/'.join(_fmt(v[m], '.3f') for m in (1, 0, 2)):>20}")
        lines.append(f"{r.estimator:<22}" + "".join(cells) + f"  {_fmt(r.pinned_excess, '.1e')}")
    if any(r.ratio_network_by_node for r in c.rows):
        lines.append(f"per node, r / β / f width over the node's network limit (steps ≥ {FROM_STEP}; docs/exact.md)")
        lines.append(f"{'estimator':<22}" + "".join(f"{'node ' + str(i):>20}" for i in nodes))
        for r in c.rows:
            cells = []
            for i in nodes:
                v = r.ratio_network_by_node.get(i)
                cells.append(f"{'' if v is None else '/'.join(_fmt(v[m], '.3f') for m in (1, 0, 2)):>20}")
            lines.append(f"{r.estimator:<22}" + "".join(cells))
    return lines


def markdown_table(c: Comparison) -> str:
    lines = [f"Comparison on {c.topology}, runs {', '.join(c.runs)} ({c.steps} steps); widths mean over nodes and steps ≥ {FROM_STEP}.", ""]
    lines.append("| " + " | ".join(TABLE_HEADER) + " |")
    lines.append("|" + "---|" * len(TABLE_HEADER))
    lines += ["| " + " | ".join(row) + " |" for row in table_rows(c)]
    lines += ["", *assumptions_notes(c)]
    return "\n".join(lines) + "\n"


def plot_fault_bounds(c: Comparison, out_dir: str | Path) -> list[Path]:
    """One figure per node: every estimator's fault bounds (first run) with the true fault."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, truth in sorted(c.truth_fault.items()):
        fig, ax = plt.subplots(figsize=(8, 4))
        t = np.arange(len(truth)) * c.tau_s
        ax.plot(t, truth, "k-", lw=2, label="true f")
        for n, (name, per_node) in enumerate(c.bounds.items()):
            if i not in per_node:
                continue
            b = per_node[i]
            tt = np.arange(len(b)) * c.tau_s
            color = f"C{n}"
            ax.plot(tt, b[:, 2, 0], color=color, lw=1, label=name)
            ax.plot(tt, b[:, 2, 1], color=color, lw=1)
        truth_span = float(np.ptp(truth)) or 0.1
        ax.set_ylim(float(truth.min()) - 2 * truth_span, float(truth.max()) + 2 * truth_span)
        ax.set_xlabel("t [s]")
        ax.set_ylabel(f"f_{i} [rad/s]")
        ax.set_title(f"node {i}: fault bounds of every estimator ({c.runs[0]})")
        ax.legend(fontsize=7, ncol=2)
        path = out / f"compare_fault_node{i}.png"
        fig.savefig(path, dpi=100, bbox_inches="tight")
        plt.close(fig)
        paths.append(path)
    return paths
