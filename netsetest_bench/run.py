"""``netsetest bench``: the whole benchmark in one run (see docs/performance.md for what it means).

Parts, in order: per-node per-step solve times on the paper scenario (NSNIM/SAIM × scheduled/
per-rule, fast path vs. the previous default, the straightforward and the naive formulations); the
published intervals of the paper run against the exact limit (``netsetest exact``); the in-memory cost per node-step for ring-with-chords networks of 6, 24 and 96 nodes; the Zenoh lockstep
run against the in-memory run of the paper scenario; ``netsetest run`` of the paper network from
launch to step 0; one node process's peak RSS and start-up time; the largest real-time network without a
deadline miss; the defences (``netsetest run`` secured and ``--insecure`` under a 30 000 msg/s flood on
one node's input and state key and under an insider's crash payloads, netsetest_bench/attacks.py; RSS
slope over a long run, netsetest_bench/soak.py); the car as the truth (bench/plant.py), what the exchange
buys (bench/network.py), the paper's scenario per node and every estimator compared (bench/scenario.py), the published
width over the exact limit per coordinate, estimator and node (bench/widths.py).
``--quick`` uses fewer steps and samples (a few minutes); the default takes longer.  Times are wall-clock milliseconds on this
machine, measured side by side in one run; medians and ratios, not single runs, are the figures.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any, TypeVar
from pathlib import Path

import numpy as np

from netsetest_bench.figures.performance import (
    YARDSTICKS,
    Coordinates,
    CpuFloor,
    Crash,
    Defences,
    EndToEnd,
    Flood,
    Launch,
    NodeProfile,
    NodeStartup,
    PaperCase,
    Performance,
    Realtime,
    RunCheck,
    Scaling,
    ScalingRow,
    Soak,
    Tightness,
    Yardstick,
    Zenoh,
    fit_cpu,
)
from netsetest_bench.figures.performance import load as load_performance
from netsetest_bench.render import MISSING, as_fields, figure, fill, typed
from netsetest_bench.sections import PARTS
from netsetest_bench.topologies import RingVariant
from netsetest.config.schema import Scenario
from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.config import FULL, QUICK, BenchConfig

if TYPE_CHECKING:  # (the benchmark imports its parts lazily)
    from netsetest_bench.zenoh_runs import Lockstep

T = TypeVar("T")

PAPER6 = TOPOLOGY_DIR / "paper6.toml"


RT_VARIANTS: tuple[RingVariant, ...] = ("reference", "max_faulty", "car")
RT_VARIANT_ROWS = (  # the performance table's rows: variant, what it adds, the target, the headline key
    ("reference", "a reference sensor's readings (node 3's, read by every node)", "≥ 0.8", "realtime_max_nodes_reference_ratio"),
    (
        "max_faulty",
        "k-of-N health per group of six sensors (max_faulty per group: a node reads its group's readings)",
        "≥ 0.8",
        "realtime_max_nodes_max_faulty_ratio",
    ),
    ("car", "the CommonRoad car as the truth", "", "realtime_max_nodes_car_ratio"),
)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a and b else None


def _med(v: list[float] | list[float | None]) -> float | None:
    v = [x for x in v if x is not None]
    return statistics.median(v) if v else None


def paper_solve_times(cfg: BenchConfig) -> dict[str, PaperCase]:
    """Per case and variant (``nsnim/scheduled`` …): the fast path's step and the reference formulations on the same
    node-steps (bench/solvers.py's ``side_by_side``), with the captured run's verdict."""
    from netsetest.config.schema import load_topology

    from netsetest_bench.solvers import capture, side_by_side

    out = {}
    for case in ("nsnim", "saim"):
        for variant in ("scheduled", "per-rule"):
            sc = load_topology(PAPER6, case, cfg.steps)
            cap = capture(sc, variant)
            sched = variant == "scheduled"
            n_ref = cfg.ref_sched if sched else cfg.ref_rule
            n_prev = cfg.prev_sched if sched else cfg.prev_rule
            n_naive = cfg.naive if sched else 0
            t0 = time.perf_counter()
            check = RunCheck(cap.summary.violations_total, cap.summary.fallbacks, [r.fault_bound_mean_width for r in cap.summary.nodes])
            res = replace(_typed(PaperCase, side_by_side(cap, n_ref, n_naive, n_prev), "side_by_side"), run_summary=check)
            out[f"{case}/{variant}"] = res
            _log(
                f"  {case} {variant}: fast {res.fast_ms.median:.2f} ms (p95 {res.fast_ms.p95:.2f}), "
                + ", ".join(f"{k} ×{y.ratio:.1f}" for k, y in res.yardsticks())
                + f"  [{time.perf_counter() - t0:.0f} s]"
            )
    return out


def scaling(cfg: BenchConfig, tmp: Path) -> Scaling:
    from netsetest.config.schema import load_topology

    from netsetest_bench.solvers import capture
    from netsetest_bench.topologies import degrees, ring_topology, ring_with_chords

    capture(load_topology(PAPER6, "nsnim", 5), "scheduled")  # warm-up
    rows = []
    for n in cfg.scaling_sizes:
        sc = load_topology(ring_topology(tmp, n, cfg.scaling_steps))
        deg = degrees(ring_with_chords(n))
        ns = n * sc.steps
        cap = capture(sc, "scheduled")
        by_deg: dict[int, list[float]] = {}
        for c, t in zip(cap.cases, cap.step_ms):
            by_deg.setdefault(deg[c.node], []).append(t)
        row = ScalingRow(
            nodes=n,
            node_steps=ns,
            ms_per_node_step=1e3 * cap.wall_s / ns,
            estimator_ms_median=statistics.median(cap.step_ms),
            estimator_ms_mean=statistics.fmean(cap.step_ms),
            estimator_ms_median_by_degree={d: statistics.median(v) for d, v in sorted(by_deg.items())},
            fallbacks=cap.summary.fallbacks,
            violations=cap.summary.violations_total,
        )
        rows.append(row)
        _log(f"  {n} nodes: {row.ms_per_node_step:.2f} ms per node-step (estimator {row.estimator_ms_median:.2f} ms)")
    base = rows[0].ms_per_node_step or float("nan")
    return Scaling(rows=rows, spread_vs_smallest=[(r.ms_per_node_step or float("nan")) / base - 1 for r in rows])


def zenoh_overhead(cfg: BenchConfig) -> Zenoh:
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    from netsetest_bench.zenoh_runs import cli_run, observed_lockstep

    sc = load_topology(PAPER6, "nsnim")
    mem: list[float] = []
    zen: list[float | None] = []
    zen_open: list[float | None] = []
    obs: Lockstep | None = None
    obs_open: Lockstep | None = None
    for _ in range(3):  # interleaved, medians of three (the lockstep run shares two cores with everything else)
        t0 = time.perf_counter()
        run_inmemory(sc, "paper", "scheduled", 0)
        mem.append(time.perf_counter() - t0)
        obs = observed_lockstep(PAPER6)  # what `netsetest run` runs: secured, router star, forked roles
        zen.append(obs.stepping_s)
        obs_open = observed_lockstep(PAPER6, insecure=True)  # `netsetest run --insecure`: the open peer mesh
        zen_open.append(obs_open.stepping_s)
    floor = lockstep_cpu_floor(sc, obs, cfg.cpu_steps)
    cli_z = _typed(CliRun, cli_run(PAPER6, "zenoh", "lockstep"), "cli_run")
    cli_m = _typed(CliRun, cli_run(PAPER6, "inmemory", "lockstep"), "cli_run")
    res = Zenoh(
        inmemory_s=mem,
        zenoh_stepping_s=zen,
        ratio=_ratio(_med(zen), _med(mem)),
        zenoh_insecure_stepping_s=zen_open,
        ratio_insecure=_ratio(_med(zen_open), _med(mem)),
        zenoh_insecure_exit_codes=obs_open.exit_codes if obs_open else None,
        zenoh_startup_s=obs.startup_s if obs else None,
        zenoh_exit_codes=obs.exit_codes if obs else None,
        zenoh_violations=obs.summary.violations_total if obs and obs.summary else None,
        node_peak_rss_mb_in_run=obs.node_peak_rss_mb if obs else [],
        cpu_floor=floor,
        cli_end_to_end=EndToEnd(
            zenoh_s=cli_z.wall_s,
            inmemory_s=cli_m.wall_s,
            zenoh_exit=cli_z.exit_code,
            inmemory_exit=cli_m.exit_code,
            ratio=cli_z.wall_s / cli_m.wall_s,
        ),
    )
    _log(
        f"  in memory {_med(mem):.2f} s, Zenoh lockstep stepping {_med(zen) or float('nan'):.2f} s (ratio {res.ratio or float('nan'):.2f}), "
        f"--insecure {_med(zen_open) or float('nan'):.2f} s (ratio {res.ratio_insecure or float('nan'):.2f}); "
        f"end to end {cli_z.wall_s:.1f} s vs {cli_m.wall_s:.1f} s"
    )
    if floor:
        _log(
            f"  CPU per step: Zenoh {floor.zenoh_cpu_ms_per_step:.2f} ms in its processes, in memory {floor.inmemory_ms_per_step:.2f} ms; "
            f"on {floor.cores} cores the lockstep ratio cannot fall below {floor.ratio_floor:.2f}"
        )
    return res


@dataclasses.dataclass(frozen=True)
class CliRun:
    """What run.py reads of bench/zenoh_runs.py's ``cli_run``: one ``netsetest run`` as a user starts it."""

    wall_s: float
    exit_code: int | None


def lockstep_cpu_floor(sc: Scenario, short: Lockstep | None, steps: int) -> CpuFloor | None:
    """Why the lockstep Zenoh run cannot beat one process on this machine, in numbers: the CPU a step costs
    in the run's processes (per role), from the difference of a long and the short run (start-up cancels),
    against the in-memory run's time per step measured the same way; with ``cores`` cores the stepping
    phase is at least CPU/cores per step, so the ratio is at least (CPU per step / cores) / in-memory."""
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    from netsetest_bench.zenoh_runs import MACHINE_CORES, RoleUsage, observed_lockstep

    if short is None or short.stepping_s is None:
        return None
    long = observed_lockstep(PAPER6, steps=steps)
    extra = steps - short.steps
    if long.stepping_s is None or extra <= 0:
        return None
    per_role: dict[str, list[float]] = {}
    for name, u in long.usage.items():
        before = short.usage.get(name, RoleUsage(None, None, None)).cpu_s
        if u.cpu_s is None or before is None:
            return None
        per_role.setdefault(name.rstrip("0123456789"), []).append(1e3 * (u.cpu_s - before) / extra)
    t0 = time.perf_counter()
    run_inmemory(sc, "paper", "scheduled", 0)
    t1 = time.perf_counter()
    run_inmemory(load_topology(PAPER6, sc.case, steps), "paper", "scheduled", 0)
    mem_ms = 1e3 * ((time.perf_counter() - t1) - (t1 - t0)) / extra
    zen_cpu = sum(sum(v) for v in per_role.values())
    return CpuFloor(
        steps=steps,
        cores=MACHINE_CORES,
        inmemory_ms_per_step=mem_ms,
        zenoh_cpu_ms_per_step=zen_cpu,
        cpu_ms_per_step_by_role={r: (statistics.median(v), len(v)) for r, v in per_role.items()},
        zenoh_stepping_ms_per_step=1e3 * (long.stepping_s - short.stepping_s) / extra,
        ratio_floor=zen_cpu / MACHINE_CORES / mem_ms,
    )


def defences(cfg: BenchConfig) -> Defences:
    from netsetest_bench.attacks import crash, flood
    from netsetest_bench.soak import soak

    floods: list[Flood] = []  # input and state key, secured, then the same insecure
    crashes: list[Crash] = []  # secured, insecure
    for secured, label in ((True, "secured"), (False, "insecure")):
        for target in ("input", "state"):
            _log(f"flood ({label} run): {cfg.flood_rate} msg/s on node 2's {target} key from a process of its own")
            r = _typed(Flood, flood(PAPER6, cfg.flood_steps, cfg.flood_rate, target, secured), "flood")
            floods.append(r)
            _log(
                f"  step rate ratio {r.ratio or float('nan'):.2f} ({r.sent_per_s or float('nan'):.0f} msg/s sent), nodes lost {r.nodes_lost}, exit {r.exit_code}"
            )
        _log(f"crash payloads ({label} run): node 2's insider sends what once crashed every receiving role")
        c = _typed(Crash, crash(PAPER6, cfg.crash_steps, secured, pace=0.1), "crash")
        crashes.append(c)
        _log(f"  roles lost {c.roles_lost}, exit {c.exit_code}, nodes missing {c.nodes_missing}")
    _log(f"soak: {cfg.soak_steps} steps in memory, RSS sampled every 250 steps")
    so = _typed(Soak, soak(cfg.soak_steps), "soak")
    _log(
        f"  RSS {so.rss_start_mb or float('nan'):.1f} → {so.rss_end_mb or float('nan'):.1f} MB, slope {so.slope_mb_per_10k_steps or float('nan'):.2f} MB per 10 000 steps"
    )
    input_secured, state_secured, input_insecure, state_insecure = floods
    crash_secured, crash_insecure = crashes
    return Defences(
        flood_input_secured=input_secured,
        flood_state_secured=state_secured,
        flood_input_insecure=input_insecure,
        flood_state_insecure=state_insecure,
        crash_secured=crash_secured,
        crash_insecure=crash_insecure,
        soak=so,
    )


def tightness(tmp: Path) -> dict[str, Tightness]:
    """The paper run's published intervals against the exact limit (``netsetest exact``), per case: the headline
    run (paper6, its 80 steps, seed 0, paper signals), the one of the scenario part and the README's table, whatever
    ``--quick`` says (tests/inmemory/test_headline.py holds the committed figures to it)."""
    from netsetest.analysis.exact import COORDINATES, compare_record, exact_bounds
    from netsetest.config.schema import load_topology
    from netsetest.records.record import load_record, save_record
    from netsetest.runtime.inmemory import run_inmemory

    out = {}
    for case in ("nsnim", "saim"):
        sc = load_topology(PAPER6, case)
        run = run_inmemory(sc, "paper", "scheduled", 0)
        assert run.parts is not None  # kept in memory (run_inmemory's default)
        path = tmp / f"tightness-{case}.json"
        save_record(path, run.meta, run.parts["truth"], run.parts["nodes"], run.summary)
        rec = load_record(path)
        t0 = time.perf_counter()
        ex = exact_bounds(sc, rec, "used")
        cmp = compare_record(rec, ex)
        by_coordinate = [n.ratios[c] for n in cmp.nodes for c in COORDINATES]
        t = out[case] = Tightness(
            steps=sc.steps,
            exact_s=time.perf_counter() - t0,
            fault_bounds=ex.fault_bounds,
            bounded_nodes=list(ex.bounded_nodes),
            width_ratio=Coordinates(**{c: cmp.mean_width_ratio[c] for c in COORDINATES}),
            rms_radius_rel=Coordinates(**{c: cmp.mean_rms_radius_rel[c] for c in COORDINATES}),
            fault_width_ratio_by_node={n.node: n.ratios["f"].width_ratio for n in cmp.nodes},
            # published intervals not containing the exact one: the ratio is not a tightness figure there
            narrower=sum(r.narrower for r in by_coordinate),
            intervals=sum(r.steps + r.left_out for r in by_coordinate),
        )
        _log(
            f"  {case}: fault width / exact {t.width_ratio.f:.3f} (nodes "
            + ", ".join(f"{n.ratios['f'].width_ratio:.2f}" for n in cmp.nodes)
            + f"), r {t.width_ratio.r:.3f}, β {t.width_ratio.beta:.3f}; "
            f"narrower than exact on {t.narrower} of {t.intervals} intervals; exact in {t.exact_s:.1f} s"
        )
    return out


def run_bench(
    quick: bool = False,
    json_path: str | None = None,
    markdown_path: str | None = None,
    only: str | None = None,
    baseline: Path | None = None,
) -> int:
    """``baseline``: a checkout the node, widths and performance parts measure alternately beside this one
    (bench/node_budget.py, bench/widths.py, bench/baseline.py)."""
    from netsetest_bench.exact_cost import exact_cost_markdown, exact_figures
    from netsetest_bench.network import network_figures, network_markdown
    from netsetest_bench.plant import plant_figures, plant_markdown
    from netsetest_bench.scenario import compare_markdown, scenario_figures, scenario_markdown
    from netsetest_bench.flow import flow_figures, flow_markdown
    from netsetest_bench.logs import logs_figures, logs_markdown
    from netsetest_bench.view import view_figures, view_markdown
    from netsetest_bench.node_budget import node_figures, node_markdown
    from netsetest_bench.scaleout import scaleout_figures, scaleout_markdown
    from netsetest_bench.campaign import campaign_figures, campaign_markdown
    from netsetest_bench.widths import widths_figures, widths_markdown
    from netsetest_bench.zenoh_runs import (
        launch_to_step0,
        node_memory_profile,
        node_startup,
        realtime_fit,
        realtime_ladder,
        realtime_node_profile,
    )

    cfg = QUICK if quick else FULL
    t_all = time.perf_counter()
    date = time.strftime("%Y-%m-%d %H:%M:%S")
    started = dict(quick=quick, python=platform.python_version(), machine=platform.machine(), cpus=_cpus(), date=date, config=cfg)
    started |= dict(load_before=_load(), only=only)
    if only is not None and only != "performance":  # one part alone: its figures and its Markdown
        figures, render = {
            "exact": (exact_figures, exact_cost_markdown),
            "plant": (plant_figures, plant_markdown),
            "network": (network_figures, network_markdown),
            "scenario": (scenario_figures, lambda r: scenario_markdown(r) + "\n" + compare_markdown(r)),
            "flow": (flow_figures, flow_markdown),
            "view": (view_figures, view_markdown),
            "node": (lambda c, t: node_figures(c, t, baseline), node_markdown),
            "widths": (lambda c, t: widths_figures(c, t, baseline), widths_markdown),
            "scaleout": (scaleout_figures, scaleout_markdown),
            "logs": (logs_figures, logs_markdown),
            "campaign": (campaign_figures, campaign_markdown),
        }[only]
        with tempfile.TemporaryDirectory(prefix="nsbench-") as tmpd:
            part = figures(cfg, Path(tmpd))
        meta = started | dict(load_after=_load(), duration_s=time.perf_counter() - t_all)
        md = f"# netsetest benchmark: {only} ({'quick' if quick else 'full'}, {date})\n\n" + render(_as_written(part))
        _write(meta, {only: part}, md, json_path, markdown_path)
        return 0
    parts: dict[str, object] = {}
    with tempfile.TemporaryDirectory(prefix="nsbench-") as tmpd:
        tmp = Path(tmpd)
        _log("paper scenario: per-node per-step times, side by side")
        paper = paper_solve_times(cfg)
        _log("tightness: published intervals against the exact limit (paper run, steps ≥ 10)")
        tight = tightness(tmp)
        _log("in-memory cost per node-step vs network size")
        inmemory = scaling(cfg, tmp)
        _log("Zenoh lockstep vs in memory (paper scenario)")
        zen = zenoh_overhead(cfg)
        _log(f"the 8-process paper run (secured): launch → step 0, {cfg.launch_reps} runs")
        launch = _typed(Launch, launch_to_step0(PAPER6, cfg.launch_reps), "launch_to_step0")
        _log(f"  median {figure(launch.median_s)} s: " + ", ".join(figure(r.launch_to_step0_s) for r in launch.reps))
        _log("one node process: start-up and peak RSS")
        node = _typed(NodeStartup, node_startup(tmp, cfg.startup_reps) | {"memory_by_stage": node_memory_profile()}, "node_startup")
        _log(f"  {node}")
        _log("real time (τs = 0.1 s, nodes as processes): growing networks")
        ladder = realtime_ladder(tmp, cfg.rt_sizes, cfg.rt_steps, log=_log)
        _log("real time with a reference's readings, k-of-N health per group of six (max_faulty) and the car as the truth: the largest ring that fits")
        fit = realtime_fit(tmp, RT_VARIANTS, cfg.rt_sizes, _typed(Realtime, ladder, "realtime_ladder").max_nodes, cfg.rt_steps, log=_log)
        realtime = _typed(Realtime, ladder | {"variants": fit}, "realtime_fit")
        _log(f"a node's CPU per step by phase (real time, {cfg.profile_nodes} nodes, run --profile), default and trace objective")
        profiles = [
            _typed(NodeProfile, realtime_node_profile(tmp, cfg.profile_nodes, cfg.rt_steps, objective=o), "realtime_node_profile") for o in (None, "trace")
        ]
        for pr in profiles:
            _log(f"  {pr.objective}: {pr.process_ms_per_step} ms per node-step, {pr.deadline_misses} deadline misses")
        defs = defences(cfg)
        parts |= dict(paper=paper, tightness=tight, inmemory_scaling=inmemory, zenoh=zen, launch=launch, node=node, realtime=realtime)
        parts |= dict(node_profile=profiles[0], node_profile_trace=profiles[1], defences=defs)
        side = None
        if baseline is not None:
            from netsetest_bench.baseline import performance_side_by_side

            side = performance_side_by_side(cfg, tmp, baseline, quick)
            parts |= dict(baseline=side)
        if only is None:  # every part too; --only performance leaves them out
            parts |= dict(plant=plant_figures(cfg, tmp), network=network_figures(cfg, tmp), scenario=scenario_figures(cfg, tmp))
            parts |= dict(exact=exact_figures(cfg, tmp), widths=widths_figures(cfg, tmp))
    meta = started | dict(load_after=_load(), duration_s=time.perf_counter() - t_all)
    if json_path:  # the measurements first, as measured: a figure no renderer reads back loses no run (written again below)
        Path(json_path).write_text(json.dumps({"meta": meta, **parts}, indent=1, default=_jsonable) + "\n")
    parts |= headline(load_performance(_as_written({"meta": meta, **parts})))
    md = markdown(_as_written({"meta": meta, **parts}))
    if side is not None:
        from netsetest_bench.baseline import baseline_markdown

        md += "\n## Side by side with the baseline (netsetest_bench/baseline.py)\n\n" + baseline_markdown(_as_written(side))
    if only is None:
        for title, draw, key in (
            ("A car as the truth (netsetest_bench/plant.py)", plant_markdown, "plant"),
            ("What the exchange can buy (netsetest_bench/network.py)", network_markdown, "network"),
            ("The paper's scenario (netsetest_bench/scenario.py)", lambda r: scenario_markdown(r) + "\n" + compare_markdown(r), "scenario"),
            ("What `netsetest exact` costs under k-of-N health (netsetest_bench/exact_cost.py)", exact_cost_markdown, "exact"),
            ("Published width over the exact limit, per coordinate (netsetest_bench/widths.py)", widths_markdown, "widths"),
        ):
            md += f"\n## {title}\n\n" + draw(_as_written(parts[key]))
    _write(meta, parts, md, json_path, markdown_path, whole=only is None)
    return 0


def _write(meta: dict[str, object], parts: dict[str, object], md: str, json_path: str | None, markdown_path: str | None, whole: bool = False) -> None:
    """The figures (``meta`` and ``parts``: the file's keys but its meta) and the report; a ``whole`` run also writes
    each part's figures beside its JSON (<dir>/<part>.json, what ``--only PART --json`` writes), so that one run
    refreshes every generated doc."""
    if json_path:
        Path(json_path).write_text(json.dumps({"meta": meta, **parts}, indent=1, default=_jsonable) + "\n")
        for part in PARTS:
            if part in parts and whole:
                doc = {"meta": meta, part: parts[part]}
                (Path(json_path).parent / f"{part}.json").write_text(json.dumps(doc, indent=1, default=_jsonable) + "\n")
    if markdown_path:
        Path(markdown_path).write_text(md)
    print(md)


def headline(p: Performance) -> dict[str, object]:
    """The headline figures (the top-level keys of bench/results.json: TARGETS and netsetest_bench/spread.py read them)."""
    ns, sa = p.paper["nsnim/scheduled"], p.paper["saim/scheduled"]
    d = p.defences

    def ratio(y: Yardstick | None) -> float | None:
        return None if y is None else y.ratio

    return {
        "solve_ms_median": ns.fast_ms.median,
        "solve_ms_p95": ns.fast_ms.p95,
        "solve_ms_median_saim": sa.fast_ms.median,
        "solve_ms_p95_saim": sa.fast_ms.p95,
        "solve_ms_median_per_rule": p.paper["nsnim/per-rule"].fast_ms.median,
        "solve_ms_median_saim_per_rule": p.paper["saim/per-rule"].fast_ms.median,
        "straightforward_ratio": ratio(ns.straightforward),
        "naive_ratio": ratio(ns.naive),
        "previous_default_ratio": ratio(ns.prev),
        "zenoh_overhead_ratio": p.zenoh.ratio,
        "zenoh_overhead_ratio_insecure": p.zenoh.ratio_insecure,
        "zenoh_overhead_ratio_cpu_floor": None if p.zenoh.cpu_floor is None else p.zenoh.cpu_floor.ratio_floor,
        "scaling": [{"nodes": r.nodes, "ms_per_node_step": r.ms_per_node_step} for r in p.inmemory_scaling.rows],
        "realtime_max_nodes": p.realtime.max_nodes,
        **{f"realtime_max_nodes_{name}_ratio": v.ratio_to_plain for name, v in p.realtime.variants.items()},
        "realtime_node_cpu_ms_per_step": p.node_profile.process_ms_per_step,
        "realtime_node_cpu_ms_per_step_trace": p.node_profile_trace.process_ms_per_step,
        "fault_width_ratio_exact_nsnim": p.tightness["nsnim"].width_ratio.f,
        "fault_width_ratio_exact_saim": p.tightness["saim"].width_ratio.f,
        "node_rss_mb": _med([r.peak_rss_mb for r in p.node.reps]),
        "node_startup_s": _med([r.first_state_s for r in p.node.reps]),
        "node_first_estimate_s": _med([r.first_estimate_s for r in p.node.reps]),
        "launch_to_step0_s": p.launch.median_s,
        "flood_step_rate_ratio": min((r for t in ("input", "state") if (r := d.flood(t, "secured").ratio) is not None), default=None),
        "flood_step_rate_ratio_insecure_input": d.flood("input", "insecure").ratio,
        "flood_step_rate_ratio_insecure_state": d.flood("state", "insecure").ratio,
        "flood_nodes_lost": sum(d.flood(target, mode).nodes_lost for target in ("input", "state") for mode in ("secured", "insecure")),
        "crash_roles_lost": sum(1 if d.crash(mode).roles_lost is None else 0 for mode in ("secured", "insecure")),
        "soak_rss_slope_mb_per_10k_steps": d.soak.slope_mb_per_10k_steps,
    }


TARGETS = [
    ("solve_ms_median", "≤ 2 ms", lambda v: v <= 2.0),
    ("solve_ms_median_saim", "≤ 5 ms", lambda v: v <= 5.0),
    ("straightforward_ratio", "≥ 10", lambda v: v >= 10),
    ("naive_ratio", "≥ 20", lambda v: v >= 20),
    ("zenoh_overhead_ratio", "≤ 1.0", lambda v: v <= 1.0),
    ("fault_width_ratio_exact_nsnim", "≤ 1.15", lambda v: v <= 1.15),
    ("fault_width_ratio_exact_saim", "≤ 1.25", lambda v: v <= 1.25),
    ("node_rss_mb", "≤ 50 MB", lambda v: v <= 50),
    ("node_startup_s", "< 1 s", lambda v: v < 1.0),
    ("launch_to_step0_s", "< 1 s", lambda v: v < 1.0),
    ("realtime_max_nodes", "≥ 96", lambda v: v >= 96),
    ("realtime_max_nodes_reference_ratio", "≥ 0.8", lambda v: v >= 0.8),  # the readings' phase may cost ≤ 20 % of the size
    ("realtime_max_nodes_max_faulty_ratio", "≥ 0.8", lambda v: v >= 0.8),
    ("flood_step_rate_ratio", "≥ 0.5", lambda v: v >= 0.5),
    ("flood_nodes_lost", "0", lambda v: v == 0),
    ("crash_roles_lost", "0", lambda v: v == 0),
    ("soak_rss_slope_mb_per_10k_steps", "< 5 MB", lambda v: v < 5.0),
]


def verdicts(p: Performance) -> dict[str, str]:
    """Each target's verdict: yes, no, or — where the run did not measure the figure."""
    out = {}
    for key, _, ok in TARGETS:
        v = getattr(p, key)
        out[key] = MISSING if v is None else ("yes" if ok(v) else "no")
    return out


def _scaling_spread(p: Performance) -> float:
    return max(abs(x) for x in p.inmemory_scaling.spread_vs_smallest)


def performance_markdown(doc: dict) -> str:
    """The headline figures of a whole benchmark (README, docs/results.md, docs/performance.md)."""
    p = load_performance(doc)
    met = verdicts(p)
    plain_cpu = fit_cpu(p.realtime.runs, p.realtime_max_nodes)
    variant_rows = "".join(
        fill("performance", "variant-row", what=what, v=v, cpu=fit_cpu(v.runs, v.max_nodes), plain_cpu=plain_cpu, target=target, met=met[key] if target else "")
        + "\n"
        for variant, what, target, key in RT_VARIANT_ROWS
        if (v := p.realtime.variants.get(variant)) is not None
    )
    saim_prev = p.paper["saim/scheduled"].prev
    return fill(
        "performance",
        "doc",
        p=p,
        met=met,
        quick=" --quick" if p.meta.quick else "",
        minutes=p.meta.duration_s / 60,
        saim_prev_ratio=None if saim_prev is None else saim_prev.ratio,
        tightness_steps=p.tightness["nsnim"].steps,
        scaling_nodes=" / ".join(str(r.nodes) for r in p.scaling),
        scaling_ms=" / ".join(figure(r.ms_per_node_step) for r in p.scaling),
        scaling_flat="yes" if _scaling_spread(p) <= 0.3 else "no",
        zenoh_s=_med(p.zenoh.zenoh_stepping_s),
        inmemory_s=_med(p.zenoh.inmemory_s),
        node_rss_in_run=_med(p.zenoh.node_peak_rss_mb_in_run),
        variant_rows=variant_rows,
    )


def markdown(doc: dict) -> str:
    """A performance run's whole report (its --markdown; bench/results.md), from its figures."""
    p = load_performance(doc)
    met = verdicts(p)
    R = "report"
    lines = [fill(R, "head", p=p, kind="quick" if p.meta.quick else "full")]
    lines += [fill(R, "target-row", key=key, value=getattr(p, key), target=target, met=met[key]) for key, target, _ in TARGETS]
    if p.zenoh_overhead_ratio_cpu_floor is not None:  # why zenoh_overhead_ratio is what it is (section Zenoh)
        lines.append(fill(R, "floor-row", floor=p.zenoh_overhead_ratio_cpu_floor))
    spread = _scaling_spread(p)
    lines.append(fill(R, "spread-row", spread_pct=spread * 100, flat="yes" if spread <= 0.3 else "no"))
    lines.append(fill(R, "paper-head"))
    for key, r in p.paper.items():
        cells = {name: MISSING if y is None else fill(R, "yardstick-cell", y=y) for name in YARDSTICKS for y in (getattr(r, name),)}
        lines.append(fill(R, "paper-row", key=key, r=r, **cells))
    lines.append(fill(R, "widths-head"))
    for key, r in p.paper.items():
        lines.append(fill(R, "widths-row", key=key, parts="; ".join(fill(R, "widths-part", name=n, y=y) for n, y in r.yardsticks())))
    lines.append(fill(R, "tightness-head"))
    lines += [fill(R, "tightness-row", case=case, t=tt) for case, tt in p.tightness.items()]
    lines.append(fill(R, "scaling-head"))
    for row in p.inmemory_scaling.rows:
        by_degree = " / ".join(figure(row.estimator_ms_median_by_degree.get(k)) for k in (3, 4, 5))
        lines.append(fill(R, "scaling-row", r=row, by_degree=by_degree))
    lines += _zenoh_lines(p)
    lines += _realtime_lines(p)
    lines += _profile_lines(p.node_profile, p.node_profile_trace)
    lines += _defence_lines(p.defences)
    return "\n".join(lines) + "\n"


def _zenoh_lines(p: Performance) -> list[str]:
    """The Zenoh section: the lockstep ratio and why, start-up, and where a node's memory goes."""
    z, R = p.zenoh, "report"
    fl = z.cpu_floor
    floor = ""
    if fl is not None:
        roles = ", ".join(f"{r} {figure(v[0])}" + (f" × {v[1]}" if v[1] > 1 else "") for r, v in fl.cpu_ms_per_step_by_role.items())
        floor = fill(R, "cpu-floor", fl=fl, roles=roles) + "\n"
    text = fill(
        R,
        "zenoh",
        p=p,
        z=z,
        zenoh_s=_med(z.zenoh_stepping_s),
        inmemory_s=_med(z.inmemory_s),
        insecure_s=_med(z.zenoh_insecure_stepping_s),
        cpu_floor=floor,
        launches=", ".join(MISSING if r.launch_to_step0_s is None else fill(R, "launch", r=r) for r in p.launch.reps),
        rss_in_run=", ".join(figure(x, ".0f") for x in z.node_peak_rss_mb_in_run),
        node_reps="; ".join(fill(R, "node-rep", r=r) for r in p.node.reps),
    )
    return [text] + [fill(R, "stage-row", r=r) for r in p.node.memory_by_stage]


def _realtime_lines(p: Performance) -> list[str]:
    """The real-time ladder, run by run, and the largest ring each variant keeps."""
    rt, R = p.realtime, "report"
    lines = [fill(R, "realtime-head", rt=rt)]
    for r in rt.runs:
        pr = r.processes
        roles = " / ".join(figure(pr.role_cpu_pct.get(k), ".1f") for k in ("run", "vehicle", "collector"))
        lines.append(fill(R, "realtime-row", r=r, pr=pr, roles=roles))
    if rt.variants:
        lines.append(fill(R, "variants-head", rt=rt))
        for name, v in rt.variants.items():
            lines.append(fill(R, "variant-row", name=name, v=v, tried=", ".join(fill(R, "variant-try", r=r) for r in v.runs)))
    return lines


PROFILE_ROWS = (
    ("solve", "estimator step (data, Clarabel, certificate; two solves with the default objective `bank`)"),
    ("decode", "msgpack + validation of received messages"),
    ("handle", "the node's checks of them (context, plausibility, buffering)"),
    ("build", "building the published NodeState (validated)"),
    ("encode", "msgpack of it"),
    ("put", "Zenoh `Publisher.put` in the node's thread"),
    ("wait", "blocking for the next message: going to sleep and being woken (calls = wake-ups)"),
    ("other", "the rest of the node's thread: its loop, deciding to step, bookkeeping"),
    ("threads", "the process's other threads: Zenoh's runtime (TLS, routing), subscriber callbacks"),
)


def _profile_lines(*profiles: NodeProfile) -> list[str]:
    """The per-step node profile table (``realtime_node_profile``), one column pair per objective."""
    ok = [p for p in profiles if p.phases]
    R = "report"
    if not ok:
        return [fill(R, "no-profile", exits=", ".join(str(p.exit_code) for p in profiles))]
    lines = [
        fill(
            R,
            "profile-head",
            p0=ok[0],
            loads="; ".join(fill(R, "profile-load", p=p) for p in ok),
            columns=" | ".join(fill(R, "profile-column", p=p) for p in ok),
            dashes="---|---|" * len(ok),
        )
    ]
    for name, what in PROFILE_ROWS:
        cells = []
        for p in ok:
            ph = (p.phases or {})[name]
            cells += [figure(1000 * ph.ms_per_step, ".0f"), figure(ph.calls_per_step) if name not in ("other", "threads") else ""]
        lines.append(fill(R, "profile-row", name=name, cells=" | ".join(cells), what=what))
    totals = " | ".join(f"**{figure(1000 * p.process_ms(), '.0f')}** | " for p in ok)
    cores = ", ".join(fill(R, "profile-cores", p=p, cores=p.nodes * p.process_ms() / 100) for p in ok)
    lines.append(fill(R, "profile-process", cells=totals, cores=cores))
    return lines


def _defence_lines(d: Defences) -> list[str]:
    """Floods and crash payloads against `netsetest run`, and the soak."""
    R = "report"
    lines = [fill(R, "defences")]
    for mode in ("secured", "insecure"):
        for target, what in (("input", "node 2's input key"), ("state", "node 2's state key")):
            lines.append(fill(R, "flood", mode=mode, what=what, r=d.flood(target, mode)))
        crash = d.crash(mode)
        lines.append(fill(R, "crash", mode=mode, r=crash, lost="0" if crash.roles_lost == 0 else "some"))
    lines.append(fill(R, "soak", r=d.soak))
    return lines


def _cpus() -> int:
    import os

    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 0)


def _load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


def _typed(kind: type[T], doc: object, what: str) -> T:
    """A measuring helper's dict (numpy's numbers, int keys) as ``kind``: through JSON, as the file will hold it."""
    return typed(kind, _as_written(doc), f"{what}'s figures")


def _as_written(res: object) -> Any:
    """The figures as their file holds them (numpy's numbers as Python's, keys as strings): what every renderer reads,
    so that a run's report is what ``--render-docs`` makes of its file."""
    return json.loads(json.dumps(res, default=_jsonable))


def _jsonable(o: object) -> object:
    """What JSON holds of ``o``: a figures dataclass as its fields (under the name a field's ``json`` metadata gives,
    figures/network_sets.py's ``with``), numpy's numbers and arrays as Python's; anything else as its text."""
    if dataclasses.is_dataclass(o) and not isinstance(o, type):
        return as_fields(o)
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
