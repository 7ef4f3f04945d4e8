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

PAPER6 = TOPOLOGY_DIR / "paper6.toml"
PAPER6_TAU_S = 0.1  # paper6.toml's τs (the issue's: the live view at 10 steps a second)
PAGE_STEPS = 80  # the issue's report page: an 80-step paper6 record
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


def view_figures(cfg: dict, tmp: Path) -> dict:
    from netsetest_bench.topologies import ring_topology
    from netsetest.config.schema import load_topology
    from netsetest.records.report_html import MAX_POINTS

    assert load_topology(PAPER6).tau_s == PAPER6_TAU_S, "paper6.toml's τs changed: the lag and CPU per step are read at PAPER6_TAU_S"
    out: dict = {"live": live_figures(cfg["view_steps"], cfg["view_pairs"], tmp)}
    _log(f"the report page of an {PAGE_STEPS}-step paper6 record in headless Chromium, {cfg['page_reps']} times")
    out["page"] = {"nodes": 6, "steps": PAGE_STEPS, **page_figures(PAPER6, cfg["page_reps"], tmp, "paper6")}
    _log(f"the report page of a {BIG_STEPS}-step, {BIG_NODES}-node ring record")
    big = ring_topology(tmp, BIG_NODES, BIG_STEPS)
    out["big_page"] = {"nodes": BIG_NODES, "steps": BIG_STEPS, "max_points": MAX_POINTS, **page_figures(big, 1, tmp, "ring")}
    return out


def _med(runs: list[dict], key: str) -> tuple[float | None, float | None, float | None]:
    v = [r[key] for r in runs if r.get(key) is not None]
    return (statistics.median(v), min(v), max(v)) if v else (None, None, None)


def _cell(m: tuple[float | None, float | None, float | None], spec: str, unit: str = "") -> str:
    med, lo, hi = m
    if med is None or lo is None or hi is None:
        return "—"
    return f"{med:{spec}}{unit} ({lo:{spec}}–{hi:{spec}})"


def _side(res: dict, view: bool) -> list[dict]:
    return [r for r in res["live"]["runs"] if r["view"] == view]


def _target(ok: bool | None) -> str:
    return "—" if ok is None else "met" if ok else "**missed**"


def _within_noise(on: list[dict], off: list[dict], key: str) -> str:
    """Whether the runs with the view and without overlap in ``key`` (the noise is the spread between runs alike)."""
    a, b = _med(on, key), _med(off, key)
    if None in (a[1], a[2], b[1], b[2]):
        return "—"
    return "met (the ranges overlap)" if a[1] <= b[2] and b[1] <= a[2] else "**missed** (the ranges are apart)"  # type: ignore[operator]  # checked above


def view_summary_markdown(res: dict) -> str:
    """The targets of issue 30 against the measured figures (docs/records.md)."""
    live, page, big = res["live"], res["page"], res["big_page"]
    on, off = _side(res, True), _side(res, False)
    lag = _med(on, "lag_median_s")
    ready, cpu = _med(page["opens"], "ready_ms"), _med(page["opens"], "renderer_cpu_ms")
    opened = None if ready[0] is None else ready[0] < 1000 * OPEN_TARGET_S
    lines = [
        "| what | target | measured (median, range) | |",
        "|---|---|---|---|",
        f"| a node's CPU per step, real-time paper6 at τs = {live['tau_s']:g} s, with the view / without | within noise | "
        f"{_cell(_med(on, 'node_cpu_ms_per_step'), '.2f', ' ms')} / {_cell(_med(off, 'node_cpu_ms_per_step'), '.2f', ' ms')} | "
        f"{_within_noise(on, off, 'node_cpu_ms_per_step')} |",
        f"| deadline misses per run, with the view / without | within noise | {_cell(_med(on, 'deadline_misses'), '.0f')} / "
        f"{_cell(_med(off, 'deadline_misses'), '.0f')} | {_within_noise(on, off, 'deadline_misses')} |",
        f"| the view's lag behind the run (each run's median) | ≤ {LAG_TARGET_S:g} s | {_cell(lag, '.3f', ' s')} | "
        f"{_target(None if lag[0] is None else lag[0] <= LAG_TARGET_S)} |",
        f"| its 95th percentile (each run's) | | {_cell(_med(on, 'lag_p95_s'), '.3f', ' s')} | |",
        f"| frames the view dropped (behind) per run | | {_cell(_med(on, 'dropped_frames'), '.0f')} | |",
        f"| the {page['steps']}-step paper6 report page rendered in Chromium | < {OPEN_TARGET_S:g} s | {_cell(ready, '.0f', ' ms')} | {_target(opened)} |",
        f"| the CPU its renderer used by then (the page's own cost) | < {OPEN_TARGET_S:g} s | {_cell(cpu, '.0f', ' ms')} | "
        f"{_target(None if cpu[0] is None else cpu[0] < 1000 * OPEN_TARGET_S)} |",
        f"| the {big['steps']}-step, {big['nodes']}-node report page's size | < {PAGE_LIMIT_MB:g} MB | {big['size_mb']:.2f} MB | "
        f"{_target(big['size_mb'] < PAGE_LIMIT_MB)} |",
    ]
    loads = [r["load_before"] for r in live["runs"]]
    page_loads = [o["load_before"] for o in page["opens"]]
    lines += [
        "",
        f"{len(on)} + {len(off)} runs of {live['steps']} steps, the machine's load average before them {min(loads):.1f}–{max(loads):.1f} "
        f"(two cores); the page opened {len(page['opens'])} times at load average {min(page_loads):.1f}–{max(page_loads):.1f}.",
    ]
    if opened is False and cpu[0] is not None and cpu[0] < 1000 * OPEN_TARGET_S and ready[0] is not None:
        lines.append(
            f"What the page costs is under the target: its renderer needed {cpu[0]:.0f} ms of CPU to render it. Rendering took "
            f"{ready[0] / cpu[0]:.1f}× that, the rest waiting for cores that other work held: the miss is the loaded machine's."
        )
    lines.append("")
    return "\n".join(lines)


def view_markdown(res: dict) -> str:
    """Every run and page opening (docs/results.md)."""
    live, page, big = res["live"], res["page"], res["big_page"]
    f = lambda v, spec, unit="": "—" if v is None else format(v, spec) + unit  # noqa: E731  # a one-line local helper
    lines = [
        view_summary_markdown(res).rstrip("\n"),
        "",
        f"Real-time paper6 runs (τs = {live['tau_s']:g} s, {live['steps']} steps, secured), in pairs with the live view and without, "
        "in the order run. A node's CPU per step is its median share of a core over the stepping phase × τs; the view's CPU is its "
        "process, which serves the page and the stream itself; its lag is per step the time the step's truth was handed to the "
        "browsers' connections minus the time the vehicle published the step; other work is what the rest of the machine used meanwhile (two cores: 200 %).",
        "",
        "| view | load before | exit | deadline misses | late steps | node CPU per step | view CPU | lag median | lag p95 | lag max | frames dropped | other work |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in live["runs"]:
        lines.append(
            f"| {'with' if r['view'] else 'without'} | {r['load_before']:.1f} | {r['exit_code']} | {r['deadline_misses']} | {r['late_steps']} | "
            f"{f(r['node_cpu_ms_per_step'], '.2f', ' ms')} | {f(r['view_cpu_pct'], '.0f', ' %')} | {f(r['lag_median_s'], '.3f', ' s')} | "
            f"{f(r['lag_p95_s'], '.3f', ' s')} | {f(r['lag_max_s'], '.3f', ' s')} | {f(r['dropped_frames'], 'd')} | {f(r['other_work_pct'], '.0f', ' %')} |"
        )
    lines += [
        "",
        "`netsetest report --html` pages opened in headless Chromium (a fresh browser each time), ms from the navigation's start by the "
        "page's clock: its load event, first contentful paint, and BokehJS done rendering every root (the page as a user sees it); "
        "the CPU the page's renderer used by then, its main thread and all its threads.",
        "",
        "| page | size | load before | load event | first contentful paint | rendered | main-thread CPU | renderer CPU | console errors |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for p, name in ((page, f"paper6, {page['steps']} steps"), (big, f"{big['nodes']}-node ring, {big['steps']} steps")):
        for o in p["opens"]:
            lines.append(
                f"| {name} | {p['size_mb']:.2f} MB | {o['load_before']:.1f} | {f(o['load_event_ms'], '.0f', ' ms')} | "
                f"{f(o['first_contentful_paint_ms'], '.0f', ' ms')} | {f(o['ready_ms'], '.0f', ' ms')} | {f(o['main_thread_cpu_ms'], '.0f', ' ms')} | "
                f"{f(o['renderer_cpu_ms'], '.0f', ' ms')} | {o['errors']} |"
            )
    lines += ["", f"Each line of the pages is drawn from at most {big['max_points']} points; the record and `netsetest export` keep every step.", ""]
    return "\n".join(lines)
