"""The performance part side by side with another checkout (``netsetest bench --only performance --baseline DIR``):
issue 45's figures for this checkout and the baseline in one run, alternating, one program for both.

- the estimator's step, NSNIM and SAIM (paper6, scheduled): bench/widths.py's :func:`step_side_by_side`, processes
  of each checkout in turn, the median node-step replayed (the performance part's figure) and in the run;
- the in-memory node-step of the rings of 6, 24 and 96 nodes: :data:`SCALING_PROGRAM` (the performance part's own
  ``scaling``, which the baseline has too) in processes of each checkout in turn;
- real time (τs = 0.1 s): the ring ladder of the performance part, every size run by this checkout and then by the
  baseline (its code by ``PYTHONPATH``, the same rings, the same environment), each checkout's ladder ending at its
  first size that misses twice; a run's node CPU per step beside it.

A figure is judged on the fastest run of each checkout (the code's cost where nothing else took the machine: this
host has episodes in which a whole run is 1.5 times slower) with the median run beside it, against
:data:`TARGETS`; the ratio this/baseline is the figure a loaded machine changes least.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from netsetest_bench.figures.baseline import load as load_side
from netsetest_bench.render import MISSING, as_fields, fill
from netsetest_bench.zenoh_runs import code_env, realtime_run
from netsetest_bench.config import BenchConfig

SCALING_PROCESSES = 2  # processes of each checkout for the in-memory rings, alternating
SCALING_PROGRAM = """
import dataclasses, json, sys, tempfile
from pathlib import Path
try:  # a checkout from before issue 46 keeps the benchmark inside the package
    from netsetest.bench.run import FULL, QUICK, scaling
except ImportError:
    from netsetest_bench.run import FULL, QUICK, scaling
cfg = QUICK if sys.argv[1] == "quick" else FULL
with tempfile.TemporaryDirectory(prefix="nsbench-") as tmp:
    print(json.dumps(scaling(cfg, Path(tmp)), default=dataclasses.asdict))  # typed figures (since issue 46) as their file holds them
"""  # one program for this checkout and the baseline (bench/run.py's scaling, which 16f81b4 has)
TARGETS = {  # issue 45, ms (or nodes): the figure's key → (at most / at least, value)
    "step_nsnim": ("≤", 0.25),
    "step_saim": ("≤", 1.6),
    "node_step_24": ("≤", 0.6),
    "node_step_96": ("≤", 0.6),
    "realtime_nodes": ("≥", 96),
    "node_cpu_ms": ("≤", 1.2),
}


class BaselineFailed(RuntimeError):
    """A program failed or hung on a checkout."""


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _scaling_run(quick: bool, code: Path | None) -> dict:
    where = code or "this checkout"
    try:
        out = subprocess.run(
            [sys.executable, "-c", SCALING_PROGRAM, "quick" if quick else "full"],
            env={**os.environ, **code_env(code)},
            capture_output=True,
            text=True,
            timeout=1800,
            check=False,
        )
    except subprocess.TimeoutExpired:
        raise BaselineFailed(f"the in-memory rings on {where} did not finish in 1800 s") from None
    if out.returncode != 0:
        last = out.stderr.strip().splitlines()[-1:]
        raise BaselineFailed(f"the in-memory rings on {where} failed (exit {out.returncode}): {last[0] if last else 'no message'}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def scaling_side_by_side(quick: bool, baseline: Path, processes: int = SCALING_PROCESSES) -> dict:
    """Per ring size, the in-memory ms per node-step of each checkout: every process's, the fastest and the median."""
    runs: dict[str, list[dict]] = {"this": [], "baseline": []}
    for _ in range(processes):
        runs["this"].append(_scaling_run(quick, None))
        runs["baseline"].append(_scaling_run(quick, baseline))
    out: dict = {}
    for i, row in enumerate(runs["this"][0]["rows"]):
        n = row["nodes"]
        this = [r["rows"][i]["ms_per_node_step"] for r in runs["this"]]
        base = [r["rows"][i]["ms_per_node_step"] for r in runs["baseline"]]
        out[str(n)] = _figure(this, base)
        _log(f"  {n} nodes in memory: {min(this):.3f} ms per node-step, baseline {min(base):.3f} (fastest)")
    return out


def _figure(this: list[float], base: list[float]) -> dict:
    return {
        "this_runs": this,
        "baseline_runs": base,
        "this": min(this),
        "baseline": min(base),
        "this_median": statistics.median(this),
        "baseline_median": statistics.median(base),
        "ratio": min(this) / min(base),
    }


def realtime_side_by_side(directory: Path, sizes: list[int], steps: int, baseline: Path, retries: int = 1) -> dict:
    """The real-time ladder of both checkouts, each size run by this one and then by the baseline; each ladder stops at
    its first size that misses (after ``retries``); per checkout its largest size and every run's row."""
    from netsetest_bench.topologies import ring_topology

    out: dict = {name: {"max_nodes": None, "runs": [], "going": True} for name in ("this", "baseline")}
    for n in sizes:
        topo = ring_topology(directory, n, steps)
        for name, code in (("this", None), ("baseline", baseline)):
            side = out[name]
            if not side["going"]:
                continue
            ok, rows = realtime_run(topo, n, steps, retries, _log, f" ({name})", env=code_env(code))
            side["runs"] += rows
            side["going"] = ok
            if ok:
                side["max_nodes"] = n
        if not (out["this"]["going"] or out["baseline"]["going"]):
            break
    for side in out.values():
        del side["going"]
        cpu = [r["node_cpu_ms_per_step"] for r in side["runs"] if r["node_cpu_ms_per_step"] is not None and r["nodes"] >= 48]
        side["node_cpu_ms_per_step"] = {"median": statistics.median(cpu) if cpu else None, "min": min(cpu) if cpu else None, "runs": len(cpu)}
    return out


def performance_side_by_side(cfg: BenchConfig, directory: Path, baseline: Path, quick: bool) -> dict:
    """Issue 45's figures of this checkout and ``baseline`` side by side (module doc)."""
    from netsetest_bench.node_budget import THIS_CHECKOUT, checkout_commit
    from netsetest_bench.widths import SideBySideFailed, step_side_by_side

    out: dict = {"commits": {"this": checkout_commit(THIS_CHECKOUT), "baseline": checkout_commit(baseline)}}
    _log(f"side by side with {baseline}: the estimator's step (paper6, processes of their own, alternating)")
    try:
        out["step"] = json.loads(json.dumps(step_side_by_side(baseline), default=as_fields))  # as its file holds it, like the rest of ``out``
    except SideBySideFailed as e:
        out["step"] = {"error": str(e)}
    _log("side by side: in-memory rings of 6, 24 and 96 nodes (processes of their own, alternating)")
    try:
        out["scaling"] = scaling_side_by_side(quick, baseline)
    except BaselineFailed as e:
        out["scaling"] = {"error": str(e)}
    _log("side by side: real time (τs = 0.1 s), every size by this checkout and then the baseline")
    out["realtime"] = realtime_side_by_side(directory, cfg.rt_sizes, cfg.rt_steps, baseline)
    out["figures"] = figures(out)
    return out


def figures(side: dict) -> dict[str, dict]:
    """The issue's figures (:data:`TARGETS`) of both checkouts: the fastest run and the median run of each."""
    out: dict[str, dict] = {}
    step = side.get("step") or {}
    for case in ("nsnim", "saim"):
        c = (step.get(case) or {}).get("replayed")
        if c:
            out[f"step_{case}"] = {k: c[k] for k in ("this", "baseline", "this_median", "baseline_median")} | {"ratio": c["this"] / c["baseline"]}
    for n in ("6", "24", "96"):
        c = (side.get("scaling") or {}).get(n)
        if c:
            out[f"node_step_{n}"] = {k: c[k] for k in ("this", "baseline", "this_median", "baseline_median", "ratio")}
    rt = side.get("realtime") or {}
    if rt:
        this, base = rt["this"], rt["baseline"]
        out["realtime_nodes"] = {"this": this["max_nodes"], "baseline": base["max_nodes"]}
        a, b = this["node_cpu_ms_per_step"], base["node_cpu_ms_per_step"]
        out["node_cpu_ms"] = {"this": a["min"], "baseline": b["min"], "this_median": a["median"], "baseline_median": b["median"]}
        if a["min"] and b["min"]:
            out["node_cpu_ms"]["ratio"] = a["min"] / b["min"]
    for key, f in out.items():
        if key in TARGETS and f.get("this") is not None:
            how, value = TARGETS[key]
            f["target"] = f"{how} {value}"
            f["met"] = f["this"] <= value if how == "≤" else f["this"] >= value
    return out


FIGURE_ROWS = (
    ("step_nsnim", "NSNIM estimator step, median node-step replayed (ms)"),
    ("step_saim", "SAIM estimator step, median node-step replayed (ms)"),
    ("node_step_6", "in-memory node-step, 6 nodes (ms)"),
    ("node_step_24", "in-memory node-step, 24 nodes (ms)"),
    ("node_step_96", "in-memory node-step, 96 nodes (ms)"),
    ("realtime_nodes", "real-time nodes at τs = 0.1 s (largest ring without a miss)"),
    ("node_cpu_ms", "node CPU per real-time step, rings of 48 nodes and more (ms)"),
)


def _value(v: int | float | None) -> str:
    """A figure of the table: a count as it is, a time to three decimals."""
    return MISSING if v is None else str(v) if isinstance(v, int) else format(v, ".3f")


def baseline_markdown(doc: dict) -> str:
    """The side-by-side table: per figure this checkout and the baseline (fastest / median run), their ratio, the target."""
    side, T = load_side(doc), "baseline"
    lines = [fill(T, "head", c=side.commits)]
    for key, what in FIGURE_ROWS:
        f = side.figures.get(key)
        if f is None:
            lines.append(fill(T, "not-measured-row", what=what))
            continue
        this = fill(T, "pair", fastest=_value(f.this), median=_value(f.this_median)) if f.this_median is not None else _value(f.this)
        base = fill(T, "pair", fastest=_value(f.baseline), median=_value(f.baseline_median)) if f.baseline_median is not None else _value(f.baseline)
        met = "" if f.met is None else ("yes" if f.met else "no")
        lines.append(fill(T, "row", what=what, this=this, baseline=base, f=f, met=met))
    for name, part in (("step", side.step), ("scaling", side.scaling)):
        if part.error is not None:
            lines.append(fill(T, "not-measured", part=name, error=part.error))
    if side.realtime is not None:
        lines.append(fill(T, "realtime-head"))
        for name, ladder in (("this", side.realtime.this), ("baseline", side.realtime.baseline)):
            lines.append(fill(T, "realtime-line", name=name, runs=", ".join(fill(T, "realtime-run", r=r) for r in ladder.runs)))
    return "\n".join(lines) + "\n"


__all__ = ["BaselineFailed", "baseline_markdown", "figures", "performance_side_by_side", "realtime_side_by_side", "scaling_side_by_side"]
