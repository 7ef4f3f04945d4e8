"""The benchmark's figures of looking at a run (``netsetest bench --only view``, issue 30).

- ``live``: ``netsetest run paper6 --clock realtime`` (τs = 0.1 s, secured default, roles as processes)
  with ``--view`` and without, in pairs run back to back (the pair's order alternates), each run sampled
  by the real-time runs' own machinery (netsetest_bench/zenoh_runs.py: ``cli_run`` and its
  ``ProcessSampler``): the nodes' deadline misses, a node's CPU per step (its median share of a core over
  the stepping phase × τs), the view's CPU (its process, which also serves the page and the stream:
  runtime/view_server.py), and the view's lag behind the run, which the view measures itself (runtime/view.py
  ``Lag``: per step, when the step's truth was handed to the browsers' connections minus when the vehicle
  published the step; ``run --view-lag-json`` hands it over) with the frames it dropped.
- ``page``: ``netsetest report RECORD --html`` of an 80-step paper6 record, opened ``page_reps`` times in
  headless Chromium (netsetest_bench/browser.py, a fresh browser each time): the page's load event, first
  contentful paint and the moment BokehJS had rendered every root, from the navigation's start; the CPU its
  renderer used by then (main thread and whole process: what the page costs, which load on the machine
  does not inflate, so a slow opening can be told from a slow page); the page's size.
- ``big_page``: the same for a 1000-step record of a 24-node ring (bench/topologies.py), run in memory: its
  size (the target: under 5 MB; lines are decimated for display, records/report_html.py ``MAX_POINTS``) and
  once its time to render.

Records and pages are made as a user makes them (``netsetest run``, ``netsetest report`` as processes);
the machine's load average before each run is kept beside its figures.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from netsetest.scenarios import TOPOLOGY_DIR
from netsetest_bench.figures.view import Spread, spread
from netsetest_bench.figures.view import load as load_view
from netsetest_bench.render import MISSING, figure, fill
from netsetest_bench.config import BenchConfig

PAPER6 = TOPOLOGY_DIR / "paper6.toml"
PAPER6_TAU_S = 0.1  # paper6.toml's τs (the issue's: the live view at 10 steps a second)
PAGE_STEPS = 80  # the report page: an 80-step paper6 record
BIG_NODES, BIG_STEPS = 24, 1000  # and the page that must stay under PAGE_LIMIT_MB
LAG_TARGET_S = 0.5  # the view's median lag behind the run
OPEN_TARGET_S = 2.0  # the report page open in Chromium
PAGE_LIMIT_MB = 5.0
COMMAND_TIMEOUT_S = 1800.0  # a 24-node, 1000-step in-memory run on a loaded machine (506 s at load average 20 on two cores)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _load() -> float:
    return os.getloadavg()[0]


def _quantile(values: list[float], q: float) -> float | None:
    """The ``q`` quantile (linear between order statistics), None for no values."""
    if not values:
        return None
    if len(values) == 1:
        return values[0]
    return statistics.quantiles(values, n=100, method="inclusive")[round(q * 100) - 1]


def live_run(steps: int, view: bool, tmp: Path) -> dict:
    """One real-time paper6 run (``netsetest run``, secured default), with its live view or without."""
    from netsetest_bench.zenoh_runs import cli_run

    lag_file = tmp / "lag.json"
    lag_file.unlink(missing_ok=True)
    load = _load()
    r = cli_run(
        PAPER6,
        "zenoh",
        "realtime",
        steps=steps,
        timeout=300 + steps * PAPER6_TAU_S,
        sample_stepping_s=steps * PAPER6_TAU_S,
        extra=["--view", "--view-lag-json", str(lag_file)] if view else None,
    )
    s, pr = r["summary"] or {}, r["processes"] or {}
    share = pr.get("node_cpu_pct_median")
    lag = json.loads(lag_file.read_text()) if view and lag_file.exists() else {}
    lags = lag.get("lags_s", [])
    return {
        "view": view,
        "steps": steps,
        "load_before": load,
        "exit_code": r["exit_code"],
        "deadline_misses": sum(n.get("deadline_misses") or 0 for n in s.get("nodes", [])) if s else None,
        "late_steps": len(r.get("late_per_step") or {}),
        "nodes_missing": s.get("nodes_missing") if s else None,
        "node_cpu_ms_per_step": None if share is None else share / 100.0 * PAPER6_TAU_S * 1000.0,
        "view_cpu_pct": (pr.get("role_cpu_pct") or {}).get("?"),  # the view process, its server included (not a netsetest role)
        "other_work_pct": pr.get("other_work_pct"),
        "lag_steps": len(lags),
        "lag_median_s": statistics.median(lags) if lags else None,
        "lag_p95_s": _quantile(lags, 0.95),
        "lag_max_s": max(lags) if lags else None,
        "unsent": lag.get("unsent"),
        "dropped_frames": lag.get("dropped_frames"),
    }


def live_figures(steps: int, pairs: int, tmp: Path) -> dict:
    """``pairs`` pairs of real-time runs, with and without the view, interleaved (the first of a pair
    alternates); per side the median and range of each figure."""
    runs = []
    for p in range(pairs):
        for view in (True, False) if p % 2 == 0 else (False, True):
            _log(f"real-time paper6, {steps} steps, {'with' if view else 'without'} the live view (pair {p + 1} of {pairs}, load {_load():.1f})")
            r = live_run(steps, view, tmp)
            _log(
                f"  exit {r['exit_code']}, deadline misses {r['deadline_misses']}, node CPU {r['node_cpu_ms_per_step']} ms/step, "
                f"view CPU {r['view_cpu_pct']} %, lag median {r['lag_median_s']} s p95 {r['lag_p95_s']} s, dropped frames {r['dropped_frames']}"
            )
            runs.append(r)
    return {"steps": steps, "pairs": pairs, "tau_s": PAPER6_TAU_S, "runs": runs}


def _cli(*args: str) -> None:
    """A ``netsetest`` command as a user runs it (one clear line when it fails)."""
    out = subprocess.run([sys.executable, "-m", "netsetest.cli.main", *args], capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    if out.returncode != 0:
        raise RuntimeError(f"netsetest {' '.join(args[:2])} … exited {out.returncode}: {out.stderr.strip()[-300:]}")


def page_figures(topology: Path, reps: int, tmp: Path, name: str) -> dict:
    """A record of ``topology`` (in memory, seed 0), its report page, and ``reps`` openings in Chromium."""
    from netsetest_bench.browser import BOKEH_READY, load_page

    record, page = tmp / f"{name}.jsonl", tmp / f"{name}.html"
    t0 = time.perf_counter()
    _cli("run", str(topology), "--mode", "inmemory", "--seed", "0", "--record", str(record), "--quiet")
    run_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    _cli("report", str(record), "--html", str(page))
    report_s = time.perf_counter() - t0
    opens = []
    for rep in range(reps):
        load = _load()
        seen = load_page(page.resolve().as_uri(), tmp / f"{name}-browser{rep}", {}, ready=BOKEH_READY)
        opens.append({"load_before": load, "errors": len(seen.errors), **seen.timings})
        _log(f"  {name} page opened: {seen.timings} ms, {len(seen.errors)} console errors (load {load:.1f})")
    record.unlink()
    size = page.stat().st_size
    page.unlink()
    return {"record_run_s": run_s, "report_s": report_s, "size_mb": size / 1e6, "opens": opens}


def view_figures(cfg: BenchConfig, tmp: Path) -> dict:
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology
    from netsetest.records.report_html import MAX_POINTS

    assert load_topology(PAPER6).tau_s == PAPER6_TAU_S, "paper6.toml's τs changed: the lag and CPU per step are read at PAPER6_TAU_S"
    out: dict = {"live": live_figures(cfg.view_steps, cfg.view_pairs, tmp)}
    _log(f"the report page of an {PAGE_STEPS}-step paper6 record in headless Chromium, {cfg.page_reps} times")
    out["page"] = {"nodes": 6, "steps": PAGE_STEPS, **page_figures(PAPER6, cfg.page_reps, tmp, "paper6")}
    _log(f"the report page of a {BIG_STEPS}-step, {BIG_NODES}-node ring record")
    big = ring_topology(tmp, BIG_NODES, BIG_STEPS)
    out["big_page"] = {"nodes": BIG_NODES, "steps": BIG_STEPS, "max_points": MAX_POINTS, **page_figures(big, 1, tmp, "ring")}
    return out


def _cell(m: Spread, spec: str, unit: str = "") -> str:
    return MISSING if m.median is None else fill("view", "spread", m=m, spec=spec, unit=unit)


def _unit(v: float | None, spec: str, unit: str) -> str:
    return MISSING if v is None else figure(v, spec) + unit


def _target(ok: bool | None) -> str:
    return MISSING if ok is None else fill("view", "met" if ok else "missed")


def _within_noise(a: Spread, b: Spread) -> str:
    """Whether the runs with the view and without overlap (the noise is the spread between runs alike)."""
    if a.lo is None or a.hi is None or b.lo is None or b.hi is None:
        return MISSING
    return fill("view", "overlap" if a.lo <= b.hi and b.lo <= a.hi else "apart")


def view_summary_markdown(doc: dict) -> str:
    """The targets of issue 30 against the measured figures (docs/records.md)."""
    v = load_view(doc)
    live, page, big = v.live, v.page, v.big_page
    on, off = live.side(True), live.side(False)
    cpu_on, cpu_off = spread([r.node_cpu_ms_per_step for r in on]), spread([r.node_cpu_ms_per_step for r in off])
    misses_on, misses_off = spread([r.deadline_misses for r in on]), spread([r.deadline_misses for r in off])
    lag = spread([r.lag_median_s for r in on])
    ready, cpu = spread([o.ready_ms for o in page.opens]), spread([o.renderer_cpu_ms for o in page.opens])
    opened = None if ready.median is None else ready.median < 1000 * OPEN_TARGET_S
    loads = [r.load_before for r in live.runs]
    page_loads = [o.load_before for o in page.opens]
    lines = [
        fill(
            "view",
            "summary",
            live=live,
            page=page,
            big=big,
            cpu_on=_cell(cpu_on, ".2f", " ms"),
            cpu_off=_cell(cpu_off, ".2f", " ms"),
            cpu_noise=_within_noise(cpu_on, cpu_off),
            misses_on=_cell(misses_on, ".0f"),
            misses_off=_cell(misses_off, ".0f"),
            misses_noise=_within_noise(misses_on, misses_off),
            lag_target=LAG_TARGET_S,
            lag=_cell(lag, ".3f", " s"),
            lag_met=_target(None if lag.median is None else lag.median <= LAG_TARGET_S),
            lag_p95=_cell(spread([r.lag_p95_s for r in on]), ".3f", " s"),
            dropped=_cell(spread([r.dropped_frames for r in on]), ".0f"),
            open_target=OPEN_TARGET_S,
            ready=_cell(ready, ".0f", " ms"),
            ready_met=_target(opened),
            cpu=_cell(cpu, ".0f", " ms"),
            cpu_met=_target(None if cpu.median is None else cpu.median < 1000 * OPEN_TARGET_S),
            page_limit=PAGE_LIMIT_MB,
            size_met=_target(big.size_mb < PAGE_LIMIT_MB),
            on=len(on),
            off=len(off),
            load_lo=min(loads),
            load_hi=max(loads),
            opens=len(page.opens),
            page_load_lo=min(page_loads),
            page_load_hi=max(page_loads),
        )
    ]
    if opened is False and cpu.median is not None and cpu.median < 1000 * OPEN_TARGET_S and ready.median is not None:
        lines.append(fill("view", "machine", cpu=cpu.median, slower=ready.median / cpu.median))
    lines.append("")
    return "\n".join(lines)


def view_markdown(doc: dict) -> str:
    """Every run and page opening (docs/results.md)."""
    v = load_view(doc)
    T = "view"
    lines = [view_summary_markdown(doc).rstrip("\n"), fill(T, "runs-head", live=v.live)]
    for r in v.live.runs:
        lines.append(
            fill(
                T,
                "run-row",
                side=fill(T, "with" if r.view else "without"),
                r=r,
                node_cpu=_unit(r.node_cpu_ms_per_step, ".2f", " ms"),
                view_cpu=_unit(r.view_cpu_pct, ".0f", " %"),
                lag_median=_unit(r.lag_median_s, ".3f", " s"),
                lag_p95=_unit(r.lag_p95_s, ".3f", " s"),
                lag_max=_unit(r.lag_max_s, ".3f", " s"),
                other=_unit(r.other_work_pct, ".0f", " %"),
            )
        )
    lines.append(fill(T, "pages-head"))
    for p, block in ((v.page, "page-name"), (v.big_page, "big-page-name")):
        name = fill(T, block, p=p)
        for o in p.opens:
            lines.append(
                fill(
                    T,
                    "opening-row",
                    name=name,
                    p=p,
                    o=o,
                    load_event=_unit(o.load_event_ms, ".0f", " ms"),
                    paint=_unit(o.first_contentful_paint_ms, ".0f", " ms"),
                    ready=_unit(o.ready_ms, ".0f", " ms"),
                    main=_unit(o.main_thread_cpu_ms, ".0f", " ms"),
                    renderer=_unit(o.renderer_cpu_ms, ".0f", " ms"),
                )
            )
    lines.append(fill(T, "tail", big=v.big_page))
    return "\n".join(lines)
