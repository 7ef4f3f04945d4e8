"""The benchmark's network figures (docs/network.md): what the exchange between nodes buys.

Per scenario, case and signals:

- at best: each node's exact limit from its own data alone over the exact limit from every node's data
  (``netsetest exact --local``), mean width from step 10, for its own fault and the yaw rate;
- today: each node's SDP fault width run alone (a self-loop only, no reference's reading) over the same
  node in the network (neighbours' states and, with a reference, its same-step readings), the network's
  over the exact central limit, and the detection delays in the network and alone;
- containment over seeds 0–9, in memory (:func:`containment_sweep`): violations, coverage, false detections,
  and a false health declaration's misses, all where an assumption broke;
- the same-step phase's cost: ``netsetest run`` of ``paper6_reference`` over Zenoh (secured, lockstep,
  as users start it) with the readings and with ``[network] readings = false``, time per step.

``paper6``: the paper's assumptions (every fault free at every step); ``paper6_reference``: sensor 3
declared fault-free; ``paper6_max_faulty``: at most 4 of the 6 sensors faulty at once (the exact central
limit with the k-of-N assumption, docs/exact.md; no one-node limit: one sensor's data alone cannot use it).
"""

from __future__ import annotations

import math
import statistics
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

from netsetest.config.schema import Scenario
from netsetest_bench.figures.network import NetworkRun
from netsetest_bench.figures.network import load as load_network
from netsetest_bench.render import figure, fill
from netsetest.records.record import Record
from netsetest.roles.judge import HEALTH
from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.config import BenchConfig

SCENARIOS = ("paper6", "paper6_reference", "paper6_max_faulty")


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _sdp_figures(sc: Scenario, sig: str, seed: int, path: Path) -> tuple[dict, Record]:
    """Per node: the SDP's mean fault width from step FROM_STEP and its detection delay (docs/fdi.md); and
    the run's record."""
    import numpy as np

    from netsetest.analysis.exact import FROM_STEP
    from netsetest.records.record import load_record
    from netsetest.runtime.inmemory import run_inmemory

    res = run_inmemory(sc, sig, "scheduled", seed, record=str(path), keep=False)  # type: ignore[arg-type]  # paper or worst
    rec = load_record(str(path))
    out = {}
    for row in res.summary.nodes:
        node = rec.nodes[row.id]
        late = node.steps >= FROM_STEP
        width = {c: float(np.mean(np.subtract(*node.bounds(c)[::-1])[late])) for c in (0, 1, 2)}  # β, r, f
        out[row.id] = {
            "fault_width": width[2],
            "r_width": width[1],
            "beta_width": width[0],
            "delay": row.detection_delay,
            "false_detections": row.false_detections,
            "false_detections_covered": row.false_detections_covered,
        }
    return out, rec


def network_figures(cfg: BenchConfig, tmp: Path) -> dict:
    from netsetest.analysis.exact import DEGENERATE_WIDTH
    from netsetest.config.schema import load_topology

    rows = []
    for name in SCENARIOS:
        for case in ("nsnim", "saim"):
            sc = load_topology(TOPOLOGY_DIR / f"{name}.toml", case, cfg.network_steps)
            for sig in ("paper", "worst"):
                for seed in cfg.network_seeds:
                    sdp, rec = _sdp_figures(sc, sig, seed, tmp / "network.json")
                    alone, _ = _sdp_figures(sc.alone(), sig, seed, tmp / "alone.json")
                    nodes = {}
                    exact = _exact_figures(sc, rec, sdp, local=not sc.health_groups)
                    for i in sc.ids:
                        nodes[i] = {
                            **exact[i],
                            # None where the network publishes a point (a reference's declared zero fault): no ratio
                            "sdp_alone_over_network": alone[i]["fault_width"] / sdp[i]["fault_width"] if sdp[i]["fault_width"] > DEGENERATE_WIDTH else None,
                            "delay_network": sdp[i]["delay"],
                            "delay_alone": alone[i]["delay"],
                            "false_detections": sdp[i]["false_detections"],
                            "false_detections_covered": sdp[i]["false_detections_covered"],
                        }
                    rows.append({"topology": name, "case": case, "signals": sig, "seed": seed, "nodes": nodes, "exact": not sc.health_groups})
                    gain = [v["sdp_alone_over_network"] for v in nodes.values() if v["sdp_alone_over_network"] is not None]
                    _log(f"  {name} {case} {sig} seed {seed}: SDP alone/network {min(gain):.3f}–{max(gain):.3f}")
    return {
        "steps": cfg.network_steps,
        "seeds": cfg.network_seeds,
        "runs": rows,
        "sweep": containment_sweep(cfg.network_steps, SWEEP_SEEDS),
        "exchange_cost": exchange_cost(cfg, tmp),
    }


SWEEP_SEEDS = tuple(range(10))  # the seeds 0–9
FALSE_MAX_FAULTY = 3  # a declaration the paper's faults break: four sensors are faulty at once from step 20


def containment_sweep(steps: int, seeds: Sequence[int]) -> dict:
    """Every seed of ``seeds``, both cases and signal families, in memory: ``paper6_reference`` and
    ``paper6_max_faulty`` as declared (violations, node-steps covered and contained, false detections where every
    assumption held), and ``paper6_max_faulty`` with a false declaration (``max_faulty = 3``: its misses must all
    fall where an assumption broke, and the node-steps it uncovers are counted).  Lockstep Zenoh publishes the
    same states as in memory (tests/process/test_zenoh_lockstep.py), so the verdicts carry over."""
    from dataclasses import replace

    from netsetest.config.schema import HealthGroup, load_topology
    from netsetest.runtime.inmemory import run_inmemory

    rows = []
    for name, false in (("paper6_reference", False), ("paper6_max_faulty", False), ("paper6_max_faulty", True)):
        for case in ("nsnim", "saim"):
            sc = load_topology(TOPOLOGY_DIR / f"{name}.toml", case, steps)
            if false:
                sc = replace(sc, health_groups=(HealthGroup(tuple(sc.ids), FALSE_MAX_FAULTY),))
            for sig in ("paper", "worst"):
                tot: Counter[str] = Counter()
                for seed in seeds:
                    sm = run_inmemory(sc, sig, "scheduled", seed).summary
                    tot.update(
                        runs=1,
                        violations=sm.violations_total,
                        misses_broken=sm.misses_assumption_broken_total,
                        evaluated=sm.node_steps_evaluated,
                        covered=sm.node_steps_covered,
                        contained=sm.node_steps_contained,
                        uncovered_health=sm.node_steps_not_covered.get(HEALTH, 0),
                        false_detections=sum(n.false_detections for n in sm.nodes),
                        false_detections_covered=sum(n.false_detections_covered for n in sm.nodes),
                    )
                declared = f"max_faulty = {FALSE_MAX_FAULTY} (false)" if false else "as declared"
                rows.append({"topology": name, "declared": declared, "case": case, "signals": sig, **tot})
                _log(
                    f"  {name} {declared} {case} {sig}, seeds {seeds[0]}–{seeds[-1]}: {tot['violations']} violations, {tot['covered']} of {tot['evaluated']} covered"
                )
    return {"seeds": list(seeds), "rows": rows}


COST_STEPS = (20, 120)  # two run lengths: the per-step time is their difference (start-up cancels)


def _run_seconds(topology: Path, steps: int) -> float:
    """Wall time of ``netsetest run TOPOLOGY --mode zenoh`` (secured, lockstep) as users start it."""
    cmd = [sys.executable, "-m", "netsetest.cli.main", "run", str(topology), "--mode", "zenoh", "--steps", str(steps), "--seed", "0", "--quiet"]
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited {out.returncode}: {out.stderr[-400:]}")
    return time.perf_counter() - t0


def exchange_cost(cfg: BenchConfig, tmp: Path) -> dict:
    """Lockstep time per step over Zenoh with the readings and without them (the same file with
    ``[network] readings = false``), for ``paper6_reference`` (one reading per step) and
    ``paper6_max_faulty`` (every node's): medians over ``cost_reps`` runs of each length, the variants
    interleaved so that the machine's drift falls on both alike."""
    out: dict[str, dict[str, float]] = {}
    for name in ("paper6_reference", "paper6_max_faulty"):
        base = TOPOLOGY_DIR / f"{name}.toml"
        off = tmp / f"{name}_no_readings.toml"
        text = base.read_text().replace('node_dir = "../nodes"', f'node_dir = "{(TOPOLOGY_DIR.parent / "nodes").as_posix()}"')
        text = text.replace("\nmax_faulty = 4", "")  # the k-of-N declaration rests on the readings: refused without them
        if "\n[network]" in text:
            text = text.replace("\n[network]", "\n[network]\nreadings = false", 1)
        else:
            text += "\n[network]\nreadings = false\n"
        off.write_text(text)
        times: dict[tuple[str, int], list[float]] = {}
        for _ in range(cfg.cost_reps):
            for variant, topo in (("readings", base), ("no_readings", off)):
                for n in COST_STEPS:
                    times.setdefault((variant, n), []).append(_run_seconds(topo, n))
        med = {key: statistics.median(v) for key, v in times.items()}
        out[name] = {v: 1e3 * (med[(v, COST_STEPS[1])] - med[(v, COST_STEPS[0])]) / (COST_STEPS[1] - COST_STEPS[0]) for v in ("readings", "no_readings")}
        _log(f"  {name} over Zenoh: {out[name]['readings']:.1f} ms per lockstep step with the readings, {out[name]['no_readings']:.1f} without")
    return {"ms_per_step": out, "reps": cfg.cost_reps, "steps": list(COST_STEPS)}


def _exact_figures(sc: Scenario, rec: Record, sdp: dict, local: bool = True) -> dict[int, dict]:
    """Per node: the SDP's fault width in the network over the central exact limit (with the run's health
    assumptions), and with ``local`` its exact limit alone over the central one (own fault, yaw rate;
    ``netsetest exact --local``)."""
    import numpy as np

    from netsetest.analysis.exact import FROM_STEP, exact_bounds, local_limits

    central = exact_bounds(sc, rec)
    keep = central.steps >= FROM_STEP

    def over(sdp_width: float, ex: np.ndarray) -> float | None:
        ex_w = float(np.mean(ex[keep, 1] - ex[keep, 0]))
        return sdp_width / ex_w if ex_w > 1e-6 else None

    limits = {lim.node: lim for lim in local_limits(sc, rec, central=central)} if local else {}
    out = {}
    for i in sc.ids:
        lim = limits.get(i)
        out[i] = {
            "fault": None if lim is None else _num(lim.fault_ratio),
            "r": None if lim is None else _num(lim.r_ratio),
            "sdp_network_over_exact": over(sdp[i]["fault_width"], central.interval("f", i)),
            "sdp_r_over_exact": over(sdp[i]["r_width"], central.interval("r")),
            "sdp_beta_over_exact": over(sdp[i]["beta_width"], central.interval("beta")),
        }
    return out


def _num(v: float) -> float | None:
    return None if math.isnan(v) else v


def network_markdown(doc: dict) -> str:
    """The network section of docs/results.md (netsetest_bench/docs.py)."""
    n = load_network(doc)
    T = "network"
    groups = n.groups()
    lines = [fill(T, "limits-head", n=n, seeds=", ".join(map(str, n.seeds)))]
    for (topology, case, signals), runs in groups.items():
        if runs[0].exact:  # else no exact limit with this assumption
            lines.append(_limits_row(topology, case, signals, runs))
    lines.append(fill(T, "reach-head"))
    lines += [_reach_row(topology, case, signals, runs) for (topology, case, signals), runs in groups.items()]
    every = [v for r in n.runs for v in r.nodes.values()]
    lines.append(
        fill(
            T,
            "false",
            runs=len(n.runs),
            false=sum(v.false_detections for v in every),
            false_covered=sum(v.false_detections_covered for v in every),
        )
    )
    if n.sweep:
        lines.append(fill(T, "sweep-head", first=n.sweep.seeds[0], last=n.sweep.seeds[-1]))
        lines += [fill(T, "sweep-row", r=r) for r in n.sweep.rows]
    cost = n.exchange_cost
    if cost and "paper6_reference" in cost.ms_per_step:
        parts = "; ".join(fill(T, "cost-part", name=name, c=c, change=100 * (c.readings / c.no_readings - 1)) for name, c in cost.ms_per_step.items())
        lines.append(fill(T, "cost", cost=cost, parts=parts))
    return "\n".join(lines) + "\n"


def _reach_row(topology: str, case: str, signals: str, runs: list[NetworkRun]) -> str:
    """What the exchange buys one topology, case and signal family, over its runs' nodes; each node's delays."""
    nodes = [r.nodes[i] for r in runs for i in sorted(runs[0].nodes)]
    first = [runs[0].nodes[i] for i in sorted(runs[0].nodes)]
    return fill(
        "network",
        "reach-row",
        topology=topology,
        case=case,
        signals=signals,
        gain=_span([v.sdp_alone_over_network for v in nodes], ".3f"),  # (None: the reference's own fault, a point)
        over=_span([v.sdp_network_over_exact for v in nodes]),
        ceiling=_span([v.ceiling() for v in nodes]),
        states=" · ".join((_span([v.sdp_r_over_exact for v in nodes]), _span([v.sdp_beta_over_exact for v in nodes]))),
        delays=" · ".join(fill("network", "delay", network=_d(v.delay_network), alone=_d(v.delay_alone)) for v in first),
    )


def _limits_row(topology: str, case: str, signals: str, runs: list[NetworkRun]) -> str:
    """Each node's exact limit alone over the central one, mean over the seeds (a reference's declared zero fault named)."""
    ids = sorted(runs[0].nodes)
    faults = []
    for i in ids:
        vals = [r.nodes[i].fault for r in runs]
        have = [v for v in vals if v is not None]
        faults.append(fill("network", "declared-zero") if len(have) < len(vals) else figure(sum(have) / len(have)))
    rs = [v for r in runs for i in ids if (v := r.nodes[i].r) is not None]
    return fill("network", "limits-row", topology=topology, case=case, signals=signals, faults=" / ".join(faults), r_min=min(rs), r_max=max(rs))


def _span(values: list[float | None], spec: str = ".2f") -> str:
    """min–max of the values there are (``-``: none; an older JSON without them)."""
    have = [v for v in values if v is not None]
    return f"{figure(min(have), spec)}–{figure(max(have), spec)}" if have else "-"


def _d(v: int | None) -> str:
    return "-" if v is None else str(v)


def network_summary_markdown(doc: dict) -> str:
    """The README's network section: per topology and case (paper signals), what the exchange buys a node."""
    n = load_network(doc)
    T = "network"
    lines = [fill(T, "summary-head")]
    for (topology, case, _), runs in n.groups("paper").items():
        nodes = [r.nodes[i] for r in runs for i in sorted(runs[0].nodes)]
        over = [x for v in nodes if (x := v.sdp_network_over_exact) is not None]
        over_s = _span(list(over)) if over else fill(T, "summary-no-exact")
        lines.append(fill(T, "summary-row", topology=topology, case=case, gain=_span([v.sdp_alone_over_network for v in nodes]), over=over_s))
    lines.append(fill(T, "summary-false", runs=len(n.runs), false=sum(v.false_detections for r in n.runs for v in r.nodes.values())))
    return "\n".join(lines) + "\n"


__all__ = ["network_figures", "network_markdown", "network_summary_markdown"]
