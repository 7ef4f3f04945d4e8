"""Issue 44's targets, part of ``netsetest bench --only widths``: what a node takes from its network (its in-neighbours'
published sets, the bounded readings; docs/network.md), measured against the central exact limit and against each
node's network limit (``netsetest exact --network``, docs/exact.md).

- *Faults at their bounds* (:func:`at_bounds`): paper6, paper6_max_faulty and paper6_reference, SAIM, worst-case
  signals, every faulty sensor's fault at ±F switching sign at δ a step (:func:`faults_at_bounds`): the published
  width over the central exact limit per node and coordinate, from step FROM_STEP; target ≤ :data:`CENTRAL_TARGET`.
- *Directed rings* (:func:`ring`): issue 44's 12-node rings, readings to out-neighbours only (netsetest_bench/
  topologies.py, ``near_reference`` and ``near_groups``), SAIM, worst-case signals: the published width over each
  node's network limit from step :data:`RING_FROM`, target ≤ :data:`NETWORK_TARGET`, the central limit beside it; the
  CPU the two limits took.
- *Declared bounds true and false* (:func:`declared_bounds`): paper6 SAIM, worst-case signals, every sensor's size and
  rate drawn at random, all true, or some false: violations (target 0) and whether every miss is attributed.
- *What it costs* (:func:`cost`): per node-step, the messages and bytes a node publishes and the deliveries they make,
  and the estimator's step, with the exchange and without it on the same topology (``neighbour_sets`` and
  ``bounded_readings`` off): replayed on the same inputs, CPU time, the two alternating; target ≤ +
  :data:`STEP_TARGET_MS` ms.
"""

from __future__ import annotations

import dataclasses
import math
import re
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from netsetest_bench.figures.network_sets import AtBounds, AtBoundsRun, Cost, Declared, Judged, Ratios, Ring, Sets, Sides, Step, Traffic, Wire
from netsetest_bench.figures.network_sets import load as load_sets
from netsetest_bench.render import fill
from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.config import BenchConfig

if TYPE_CHECKING:  # (the benchmark imports its parts lazily)
    from netsetest.analysis.exact import ExactBounds
    from netsetest.config.schema import Scenario
    from netsetest.records.record import Record
    from netsetest.records.summary import RunSummary

AT_BOUNDS = ("paper6", "paper6_max_faulty", "paper6_reference")
RINGS = ("near_reference", "near_groups")
RING_NODES, RING_FROM = 12, 12  # the rings' size, and the first step their target counts (the furthest data take up to 7 steps)
CENTRAL_TARGET, NETWORK_TARGET = 1.10, 1.10
STEP_TARGET_MS = 0.1
HOLD = 8  # steps a fault at its bound holds its sign before it switches (through 0, at δ a step)
COST_STEPS, COST_ROUNDS = 40, 5
COORDS = ("beta", "r", "f")
J = TypeVar("J", bound=Judged)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------- faults at their declared bounds


def _at_bound_points(size: float, rate: float, phase: int, steps: int) -> list[tuple[int, float]]:
    """A fault at ±size that holds for HOLD steps and switches sign at exactly ``rate`` a step (through 0 where
    2·size/rate steps are needed), starting at ``phase``."""
    moves = max(1, math.ceil(2 * size / rate - 1e-12))
    v, k, out = size if phase % 2 else -size, phase % (HOLD + moves) or HOLD + moves, []
    out.append((0, v))
    while k < steps + HOLD + moves:
        out.append((k, v))
        out.append((k + moves, -v))
        v, k = -v, k + moves + HOLD
    return out


def faults_at_bounds(directory: Path, topology: str, steps: int = 80) -> Path:
    """A copy of the bundled ``topology`` whose every sensor with a fault (the paper's sensors 1, 2, 4, 6) has it at
    ±F of its declared ``[fault_bound]`` switching at δ (:func:`_at_bound_points`, each sensor at its own phase); its
    node profiles written beside it."""
    nodes = TOPOLOGY_DIR.parent / "nodes"
    out = Path(directory) / f"{topology}_at_bounds"
    (out / "nodes").mkdir(parents=True, exist_ok=True)
    for prof in nodes.glob("*.toml"):
        text = prof.read_text()
        bound = re.search(r"\[fault_bound\][^\[]*?rate = ([0-9.]+)\s+size = ([0-9.]+)", text)
        if bound is not None and 'kind = "none"' not in text:
            rate, size = float(bound.group(1)), float(bound.group(2))
            points = _at_bound_points(size, rate, 3 * int(re.sub(r"\D", "", prof.stem) or 0), steps)
            text = text[: text.index("[fault]\n")] + '[fault]\nkind = "piecewise"\npoints = ' + str([[k, v] for k, v in points]) + "\n"
        (out / "nodes" / prof.name).write_text(text)
    topo = (TOPOLOGY_DIR / f"{topology}.toml").read_text()
    path = out / f"{topology}.toml"
    path.write_text(re.sub(r'node_dir = ".*"', 'node_dir = "nodes"', topo))
    return path


def _record(sc: Scenario, seed: int) -> tuple[Record, RunSummary]:
    from netsetest.records.record import record_from_parts
    from netsetest.runtime.inmemory import run_inmemory

    res = run_inmemory(sc, "worst", "scheduled", seed)
    assert res.parts is not None
    return record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary), res.summary


def _ratios(rec: Record, limit: ExactBounds, nodes: list[int], from_step: int) -> dict[int, list[float | None]]:
    """Per node, [β, r, f]: mean published width over ``limit``'s from ``from_step`` (None: a point limit, a reference's
    fault), and the intervals narrower than it (beyond exact.NARROWER_TOL, the last item; an end the k-of-N search left
    relaxed is no limit there, and not counted)."""
    from netsetest.analysis.exact import DEGENERATE_WIDTH, NARROWER_TOL

    relaxed = {(k.coordinate, k.node, k.step, k.side) for k in (limit.health.relaxed if limit.health is not None else ())}
    out: dict[int, list[float | None]] = {}
    for i in nodes:
        track = rec.nodes[i]
        row: list[float | None] = []
        narrower = 0
        for m, c in enumerate(COORDS):
            lo, hi = track.bounds(m)
            ex = limit.interval(c, i)[track.steps]  # type: ignore[arg-type]  # c is one of COORDINATES
            ok = np.isfinite(ex).all(axis=1)
            late = ok & (track.steps >= from_step)
            w, e = (hi - lo)[late], (ex[:, 1] - ex[:, 0])[late]
            row.append(float(w.mean() / e.mean()) if len(e) and e.mean() > DEGENERATE_WIDTH else None)
            slack = NARROWER_TOL * np.maximum(1.0, np.abs(ex))
            ends = ex.copy()
            for n, k in enumerate(track.steps.tolist()):
                for side in (0, 1):
                    if {(c, i, k, ("lo", "hi")[side]), (c, None, k, ("lo", "hi")[side])} & relaxed:
                        ends[n, side] = np.nan
            with np.errstate(invalid="ignore"):
                narrower += int(((lo > ends[:, 0] + slack[:, 0]) | (hi < ends[:, 1] - slack[:, 1]))[ok].sum())
        out[i] = [*row, float(narrower)]
    return out


def _worst(ratios: dict[int, list[float | None]]) -> float:
    return max((v for r in ratios.values() for v in r[:3] if v is not None), default=float("nan"))


def at_bounds(directory: Path, topology: str, seeds: list[int], steps: int = 80) -> AtBounds:
    """One bundled topology with faults at their bounds, SAIM, worst-case signals, per seed: the SDP's widths over the
    central exact limit (:func:`_ratios`, from step FROM_STEP), violations, covered node-steps."""
    from netsetest.analysis.exact import FROM_STEP, exact_bounds
    from netsetest.config.schema import load_topology

    sc = load_topology(faults_at_bounds(directory, topology, steps), "saim", steps)
    runs = []
    for seed in seeds:
        rec, summary = _record(sc, seed)
        central = exact_bounds(sc, rec)
        ratios = _ratios(rec, central, sc.ids, FROM_STEP)
        run = _judged(AtBoundsRun, summary, seed=seed, ratios=ratios, worst=_worst(ratios), narrower=sum(int(r[3] or 0) for r in ratios.values()))
        runs.append(run)
        _log(f"  {topology} at its bounds, seed {seed}: worst {run.worst:.3f} of central exact")
    return AtBounds(topology=topology, case="saim", signals="worst", from_step=FROM_STEP, target=CENTRAL_TARGET, runs=runs)


def _judged(kind: Callable[..., J], s: RunSummary, **figures: object) -> J:
    """A run's figures of ``kind`` (a :class:`~netsetest_bench.figures.network_sets.Judged`): its verdict from its
    summary, and ``figures``."""
    return kind(
        violations=s.violations_total,
        covered=s.node_steps_covered,
        evaluated=s.node_steps_evaluated,
        misses_attributed=s.misses_assumption_broken_total,
        misses=s.node_steps_evaluated - s.node_steps_contained,
        **figures,
    )


# ---------------------------------------------------------------- issue 44's directed rings


def ring(directory: Path, variant: str, seed: int, steps: int, budget_s: float | None = None) -> Ring:
    """One directed ring, SAIM, worst-case signals: the SDP's widths over each node's network limit and over the central
    limit from step RING_FROM, and the CPU seconds each limit took (in this process)."""
    from netsetest.analysis.exact import exact_bounds, network_limit
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology

    sc = load_topology(ring_topology(directory, RING_NODES, steps, "saim", variant=variant), "saim")  # type: ignore[arg-type]  # one of RINGS
    rec, summary = _record(sc, seed)
    t0 = time.process_time()
    central = exact_bounds(sc, rec)
    t1 = time.process_time()
    net = network_limit(sc, rec, central, budget_s=budget_s)  # (under k-of-N an end past the budget is relaxed: counted below)
    t2 = time.process_time()
    network = _ratios(rec, net, sc.ids, RING_FROM)
    out = _judged(
        Ring,
        summary,
        variant=variant,
        nodes=len(sc.ids),
        steps=steps,
        seed=seed,
        from_step=RING_FROM,
        target=NETWORK_TARGET,
        worst=_worst(network),
        furthest={i: max(sc.delays(i).values()) for i in sc.ids},
        network=network,
        central=_ratios(rec, central, sc.ids, RING_FROM),
        central_cpu_s=t1 - t0,
        network_cpu_s=t2 - t1,
        relaxed={k: None if e.health is None else len(e.health.relaxed) for k, e in (("central", central), ("network", net))},
    )
    _log(f"  ring {variant}, seed {seed}: worst {out.worst:.3f} of the network limit ({t2 - t1:.0f} s CPU), central beside it")
    return out


# ---------------------------------------------------------------- declared bounds true and false


def declared_bounds(seed: int, true: bool, steps: int) -> Declared:
    """paper6 SAIM, worst-case signals: every sensor's declared size and rate drawn at random (seed ``seed``): above
    its fault's largest size and step (``true``), or some of them below (a sensor with a fault, at random: false).
    The verdict (violations must be 0; every miss attributed) and which declarations were false."""
    from netsetest.config.schema import load_topology

    rng = np.random.default_rng(1000 * seed + true)
    sc = load_topology("paper6", "saim", steps)
    nodes, false = [], []
    faulty = [n.id for n in sc.nodes if any(n.fault(k) != 0.0 for k in range(steps + 1))]
    lying = set(rng.choice(faulty, size=rng.integers(1, len(faulty) + 1), replace=False).tolist()) if not true else set()
    for n in sc.nodes:
        f = np.array([n.fault(k) for k in range(steps + 1)])
        size, rate = float(np.abs(f).max()), float(np.abs(np.diff(f)).max())
        if n.id in lying:
            size_d, rate_d = size * rng.uniform(0.2, 0.9), max(rate, 1e-3) * rng.uniform(1.0, 2.0)
            false.append(n.id)
        else:
            size_d, rate_d = max(size, 0.01) * rng.uniform(1.0, 2.0), max(rate, 0.01) * rng.uniform(1.0, 2.0)
        nodes.append(dataclasses.replace(n, fault_size=size_d, fault_rate=rate_d))
    _, summary = _record(dataclasses.replace(sc, nodes=nodes), seed)
    return _judged(Declared, summary, seed=seed, declared="true" if true else "false", false_nodes=sorted(false))


# ---------------------------------------------------------------- what it costs


def _wire(sc: Scenario, steps: int) -> Wire:
    """One in-memory run: per node-step, the states and readings published, their bytes, and their deliveries (each
    state to its out-neighbours and the collector, each reading to the nodes that read it)."""
    from netsetest.bus.base import MemoryBus
    from netsetest.messages import encode
    from netsetest.runtime.inmemory import run_inmemory

    bus = MemoryBus()
    count: Counter[str] = Counter()
    size: Counter[str] = Counter()
    deliveries: Counter[str] = Counter()

    def seen(key: str, msg: object) -> None:
        kind = key.rsplit("/", 1)[-1]
        if kind in ("state", "reading"):
            node = int(key.rsplit("/", 2)[-2])
            count[kind] += 1
            size[kind] += len(encode(msg))  # type: ignore[arg-type]  # a Message: what the bus carries
            readers = sc.out_neighbours(node) + [0] if kind == "state" else [i for i in sc.ids if node in sc.reading_sources(i)]
            deliveries[kind] += len(readers)

    bus.subscribe("netsetest/**", seen)
    run_inmemory(sc, bus=bus, keep=False)
    node_steps = len(sc.ids) * (steps + 1)
    state, reading = (Traffic(messages=count[k] / node_steps, bytes=size[k] / node_steps, deliveries=deliveries[k] / node_steps) for k in ("state", "reading"))
    return Wire(state=state, reading=reading)


def _replay(sc_on: Scenario, sc_off: Scenario, rounds: int) -> Step:
    """The estimator's step per node-step (CPU ms), with the exchange and without, replayed on the same inputs (those
    of the run with it), the two alternating ``rounds`` times after one round each to warm up: every round's mean,
    the fastest and the median."""
    from netsetest.estimator.sdp import LocalEstimator
    from netsetest.runtime.inmemory import run_inmemory

    cases: list = []
    run_inmemory(sc_on, "paper", "scheduled", 0, observer=lambda est, prev, inp, res, ms: cases.append((est.node_id, prev, inp)), keep=False)

    def replay(estimators: dict) -> float:
        t0 = time.process_time()
        for i, prev, inp in cases:
            estimators[i].step(prev, inp)
        return 1e3 * (time.process_time() - t0) / len(cases)

    on = {i: LocalEstimator.for_node(sc_on, i) for i in sc_on.ids}
    off = {i: LocalEstimator.for_node(sc_off, i) for i in sc_off.ids}
    replay(on), replay(off)
    with_, without = [], []
    for _ in range(rounds):
        with_.append(replay(on))
        without.append(replay(off))
    return Step(
        with_ms=with_,
        without_ms=without,
        with_=min(with_),
        without=min(without),
        with_median=statistics.median(with_),
        without_median=statistics.median(without),
        over_ms=min(with_) - min(without),
        over_median_ms=statistics.median(with_) - statistics.median(without),
        met=min(with_) - min(without) <= STEP_TARGET_MS,
    )


def cost(directory: Path, label: str, topology: Path | str, case: str, steps: int = COST_STEPS, rounds: int = COST_ROUNDS) -> Cost:
    """The exchange's cost on one topology: the wire per node-step and the estimator's step, with it and without."""
    from netsetest.config.schema import load_topology

    on = load_topology(topology, case, steps)  # type: ignore[arg-type]  # one of the cases
    off = dataclasses.replace(on, neighbour_sets=False, bounded_readings=False)
    out = Cost(label=label, case=case, steps=steps, rounds=rounds, wire=Sides(with_=_wire(on, steps), without=_wire(off, steps)), step=_replay(on, off, rounds))
    _log(f"  cost {label} {case}: step {out.step.over_ms:+.3f} ms per node-step (fastest rounds)")
    return out


# ---------------------------------------------------------------- the part


def sets_figures(cfg: BenchConfig, tmp: Path) -> Sets:
    """Every figure of the module doc."""
    from netsetest_bench.topologies import ring_topology

    _log("issue 44: faults at their bounds (SAIM, worst-case signals), against the central exact limit")
    bounds = [at_bounds(tmp, t, cfg.sets_seeds) for t in AT_BOUNDS]
    _log("issue 44: directed rings, readings to out-neighbours only, against each node's network limit")
    rings = [ring(tmp, v, seed, cfg.sets_ring_steps, cfg.sets_network_budget_s) for v in RINGS for seed in cfg.sets_ring_seeds]
    _log("issue 44: declared bounds at random, true and false")
    declared = [declared_bounds(seed, true, cfg.sets_declared_steps) for true in (True, False) for seed in cfg.sets_seeds]
    _log("issue 44: what the exchange costs per node-step")
    costs = [cost(tmp, "paper6", "paper6", case) for case in ("nsnim", "saim")]
    costs += [cost(tmp, f"ring{RING_NODES} {v}", ring_topology(tmp, RING_NODES, COST_STEPS, "saim", variant=v), "saim") for v in RINGS]  # type: ignore[arg-type]  # v is one of RINGS, RingVariant's values
    return Sets(at_bounds=bounds, rings=rings, declared=declared, cost=costs, step_target_ms=STEP_TARGET_MS)


T = "network_sets"  # the tables' template (templates/network_sets.md)


def _f(v: float | None, spec: str = ".3f") -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def _cells(ratios: Ratios | None) -> str:
    """r / β / f per node (the worst of the three in brackets), compact."""
    return "; ".join(f"{i}: {'/'.join(_f(r[m]) for m in (1, 0, 2))}" for i, r in sorted((ratios or {}).items()))


def _narrower(ratios: Ratios | None) -> int:
    return sum(int(v[3] or 0) for v in (ratios or {}).values())


def _met(ok: bool) -> str:
    return fill(T, "yes" if ok else "no")


def sets_markdown(doc: dict | Sets) -> str:
    """Issue 44's tables: faults at their bounds, the directed rings, the declared bounds, the cost."""
    s = load_sets(doc) if isinstance(doc, dict) else doc
    return "\n".join([*_at_bounds_lines(s), *_ring_lines(s), *_declared_lines(s), *_cost_lines(s)]) + "\n"


def _at_bounds_lines(s: Sets) -> list[str]:
    lines = [fill(T, "at-bounds-head", from_step=s.at_bounds[0].from_step if s.at_bounds else 10)]
    for b in s.at_bounds:
        runs = b.runs
        worst = max(r.worst for r in runs)
        lines.append(
            fill(
                T,
                "at-bounds-row",
                b=b,
                seeds=",".join(str(r.seed) for r in runs),
                worst=_f(worst),
                per_seed=", ".join(_f(r.worst) for r in runs),
                narrower=sum(r.narrower for r in runs),
                violations=sum(r.violations for r in runs),
                covered=sum(r.covered for r in runs),
                evaluated=sum(r.evaluated for r in runs),
                met=_met(worst <= b.target and all(r.violations == 0 and r.narrower == 0 for r in runs)),
            )
        )
    return lines


def _ring_lines(s: Sets) -> list[str]:
    lines = [fill(T, "rings-head", from_step=RING_FROM)]
    for r in s.rings:
        narrower = (_narrower(r.network), _narrower(r.central))
        lines.append(
            fill(
                T,
                "ring-row",
                r=r,
                furthest=max((r.furthest or {}).values()),
                worst=_f(r.worst),
                network=_cells(r.network),
                central=_cells(r.central),
                narrower_network=narrower[0],
                narrower_central=narrower[1],
                central_cpu=_f(r.central_cpu_s, ".0f"),
                network_cpu=_f(r.network_cpu_s, ".0f"),
                relaxed=", ".join("–" if v is None else str(v) for v in (r.relaxed or {}).values()),
                met=_met(r.worst <= r.target and r.violations == 0 and narrower[0] == 0),
            )
        )
    return lines


def _declared_lines(s: Sets) -> list[str]:
    lines = [fill(T, "declared-head")]
    for kind in ("true", "false"):
        drawn = [d for d in s.declared if d.declared == kind]
        if drawn:
            lines.append(
                fill(
                    T,
                    "declared-row",
                    kind=kind,
                    seeds=",".join(str(d.seed) for d in drawn),
                    false_on="; ".join(",".join(map(str, d.false_nodes or [])) for d in drawn) or "–",
                    violations=sum(d.violations for d in drawn),
                    misses=sum(d.misses for d in drawn),
                    attributed=sum(d.misses_attributed for d in drawn),
                    covered=sum(d.covered for d in drawn),
                    evaluated=sum(d.evaluated for d in drawn),
                    met=_met(all(d.violations == 0 and d.misses_attributed == d.misses for d in drawn)),
                )
            )
    return lines


def _cost_lines(s: Sets) -> list[str]:
    lines = [fill(T, "cost-head", rounds=s.cost[0].rounds if s.cost else COST_ROUNDS, target=s.step_target_ms)]
    for c in s.cost:
        w, wo = c.wire.with_, c.wire.without
        states = " / ".join(fill(T, "traffic", t=x.state) for x in (w, wo))
        readings = " / ".join(fill(T, "traffic", t=x.reading) for x in (w, wo))
        lines.append(fill(T, "cost-row", c=c, case=c.case.upper(), states=states, readings=readings, s=c.step, met=_met(c.step.met)))
    return lines


__all__ = ["AT_BOUNDS", "RINGS", "at_bounds", "cost", "declared_bounds", "faults_at_bounds", "ring", "sets_figures", "sets_markdown"]
