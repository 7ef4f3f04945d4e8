"""Published width over the exact limit, per coordinate (``netsetest bench --only widths``): issue 28's targets.

For every run of :func:`plan`, ``netsetest compare`` (analysis/compare.py, the very computation the CLI prints)
with the SDP, every set estimator and the exact limit, and on paper6_reference and paper6_max_faulty (readings: the
runs where the region has the most to cut) every set estimator without its region too (``<name>-noregion``: the
method as its paper defines it, estimator/region.py): per estimator and per node, the mean published width over
the exact one from step FROM_STEP for r, β and f; where the exact interval is a point (a reference's declared zero fault) the absolute width
over it instead; the intervals narrower than exact where the assumptions held (a sound set has none) and the
violations.  The SDP's target is r, β and f ≤ 1.05 on the listed runs and ≤ 1.10 on every other bundled scenario,
judged on the worst node; the table says where it is missed.  The comparisons run JOBS at a time in processes of
their own: no time of them is a figure.

Then, in this process alone, what the region costs (:func:`region_cost`): the estimator's step per node-step on
paper6 NSNIM and SAIM, in memory as a node runs it, and the region's part of it, its move and its cut timed in the
same runs.  With ``--baseline DIR`` (a checkout of 29290ba, the code before every node kept a region), issue 28's
target side by side (:func:`step_side_by_side`): processes of this checkout and of the baseline in turn, one program
for both (:data:`STEP_PROGRAM`), the step in the run and replayed; the fastest runs are judged against
:data:`STEP_TARGET_MS`, the median runs stand beside them.  A baseline the program fails on is reported in the table,
with the part's other figures kept.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

from netsetest.config.schema import Case
from netsetest.models.signals import SignalKind

LISTED, OTHER = 1.05, 1.10  # the SDP's targets: the listed runs, every other bundled scenario
ESTIMATORS = ("sdp", "zonotope", "interval", "strip", "setprop", "exact")
WITHOUT_REGION = ("zonotope-noregion", "interval-noregion", "strip-noregion", "setprop-noregion")  # the before/after runs' too
JOBS = 2  # comparisons measured at once (tightness only: no time of this part is a figure)
CAR = "paper6_car"
TARGETED = ("paper6", CAR, "paper6_reference", "paper6_max_faulty")  # the topologies of the listed runs
CASES: tuple[Case, ...] = ("nsnim", "saim")
COORDS = ((1, "r"), (0, "β"), (2, "f"))  # (index in [β, r, f], label): the table's order
COST_STEPS, COST_RUNS, COST_WARM_UP = 40, 3, 5  # the region's cost: steps per run, runs per case, warm-up steps
SIDE_PROCESSES, SIDE_RUNS = 4, 3  # side by side with the baseline: processes per checkout and case, alternating; runs in each
STEP_TARGET_MS = 0.25  # issue 28: the step at most this much over the code before every node kept a region
STEP_PROGRAM = """
import json, statistics, sys
try:  # a checkout from before issue 46 keeps the benchmark inside the package
    from netsetest.bench.solvers import capture, side_by_side
except ImportError:
    from netsetest_bench.solvers import capture, side_by_side
from netsetest.config.schema import load_topology
from netsetest.scenarios import TOPOLOGY_DIR
case, steps, runs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
topology = str(TOPOLOGY_DIR / "paper6.toml")
capture(load_topology(topology, case, steps), "scheduled")
out = []
for _ in range(runs):
    cap = capture(load_topology(topology, case, steps), "scheduled")
    out.append([statistics.median(cap.step_ms), side_by_side(cap, 0, 0, 0)["fast_ms"]["median"]])
print(json.dumps(out))
"""  # one program for this checkout and the baseline (bench/solvers.py's capture and side_by_side, which 29290ba has)
STEP_FIGURES = (("in_run", "in the run, as a node runs it"), ("replayed", "replayed, as the performance part's median node-step"))


@dataclass(frozen=True)
class WidthRun:
    """One comparison of the part: a topology, case, signal family and seeds, and the SDP's target there."""

    label: str
    topology: str  # a bundled name
    case: Case | None  # None: the file's
    signals: SignalKind
    seeds: tuple[int, ...]
    target: float
    steps: int | None = None  # None: the file's
    without_region: bool = False  # also every set estimator without its region (what the region buys, side by side)

    @property
    def estimators(self) -> tuple[str, ...]:
        return (*ESTIMATORS[:-1], *(WITHOUT_REGION if self.without_region else ()), ESTIMATORS[-1])


def plan(cfg: dict) -> list[WidthRun]:
    """The listed runs (paper6 NSNIM and SAIM with the paper's signals and worst-case ones, the car's held-out drives,
    paper6_reference, paper6_max_faulty), then every other bundled scenario once."""
    from netsetest.scenarios import bundled_topologies

    families: tuple[tuple[SignalKind, tuple[int, ...]], ...] = (("paper", (0,)), ("worst", tuple(cfg["widths_worst_seeds"])))
    runs = [WidthRun(f"paper6 {case.upper()}, {sig} signals", "paper6", case, sig, seeds, LISTED) for case in CASES for sig, seeds in families]
    runs += [WidthRun(f"{CAR} {case.upper()}, held-out seeds", CAR, case, "paper", tuple(cfg["widths_car_seeds"]), LISTED) for case in CASES]
    runs += [WidthRun(t, t, None, "paper", (0,), LISTED, without_region=True) for t in ("paper6_reference", "paper6_max_faulty")]
    runs += [
        WidthRun(t, t, None, "paper", (0,), OTHER, cfg["widths_lap_steps"] if t == "paper6_lap" else None) for t in bundled_topologies() if t not in TARGETED
    ]
    return runs


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _measure(run: WidthRun) -> dict:
    from netsetest.analysis.compare import compare, comparison_document

    t0 = time.perf_counter()
    c = compare(run.topology, run.estimators, (run.case,), (run.signals,), run.seeds, run.steps)
    rows = comparison_document(c)
    sdp = next(r for r in rows if r["estimator"] == "sdp")
    _log(f"  {run.label}: sdp worst node {_worst(sdp):.3f} (target {run.target}), {time.perf_counter() - t0:.0f} s")
    return asdict(run) | {"runs": c.runs, "steps": c.steps, "rows": rows}


def widths_figures(cfg: dict, tmp: Path, baseline: Path | None = None) -> dict:
    """Every run of :func:`plan`, compared (JOBS at once, in processes of their own); the region's cost; with a
    ``baseline`` checkout, the step side by side with it."""
    from concurrent.futures import ProcessPoolExecutor

    from netsetest.analysis.exact import FROM_STEP

    from netsetest_bench.network_sets import sets_figures

    with ProcessPoolExecutor(JOBS) as pool:
        runs = list(pool.map(_measure, plan(cfg)))
    _log("the region's cost per node-step (paper6, in memory, this process alone)")
    out = {"from_step": FROM_STEP, "runs": runs, "cost": region_cost(), "sets": sets_figures(cfg, tmp)}
    if baseline is not None:
        _log(f"the step side by side with the baseline {baseline} (paper6, in memory, processes of their own, alternating)")
        try:
            out["side_by_side"] = step_side_by_side(baseline)
        except SideBySideFailed as e:  # (the comparisons above stand: the table says what failed)
            _log(f"  {e}")
            out["side_by_side"] = {"error": str(e)}
    return out


@contextmanager
def _region_timers(times: dict[str, list[float]]) -> Iterator[None]:
    """Every call of the region's two pieces timed while the block runs (ms into ``times``): the move of the
    region through the step (``LocalEstimator._moved_region``) and its cut (:data:`~netsetest.estimator.cuts.REGION`)."""
    from netsetest.estimator import cuts, sdp

    moved, cut = sdp.LocalEstimator._moved_region, cuts.REGION.apply

    def timed_moved(est: sdp.LocalEstimator, *args: object) -> object:
        t0 = time.perf_counter()
        out = moved(est, *args)  # type: ignore[arg-type]  # the method's own arguments, passed through
        times["moved"].append(1e3 * (time.perf_counter() - t0))
        return out

    def timed_cut(ctx: cuts.StepContext, res: cuts.StepResult) -> cuts.StepResult:
        t0 = time.perf_counter()
        out = cut(ctx, res)
        if ctx.blend is not None:  # (step 0's cut, from the prior, is no step the run times)
            times["cut"].append(1e3 * (time.perf_counter() - t0))
        return out

    sdp.LocalEstimator._moved_region = timed_moved  # type: ignore[method-assign,assignment]  # restored below
    object.__setattr__(cuts.REGION, "apply", timed_cut)  # (the Cut is frozen; every cut list holds this one)
    try:
        yield
    finally:
        sdp.LocalEstimator._moved_region = moved  # type: ignore[method-assign]  # the method back
        object.__setattr__(cuts.REGION, "apply", cut)


def region_cost(steps: int = COST_STEPS, runs: int = COST_RUNS) -> dict:
    """Per case (paper6 NSNIM, SAIM): ``runs`` runs of ``steps`` steps after a warm-up run, each the median over its
    node-steps of the estimator's step (bench/solvers.py's ``capture``: the in-run time of ``LocalEstimator.step``),
    of the region's move and of its cut, and the region's share of the step time (the move and the cut over all
    steps, summed); the case's figure is the median over the runs."""
    from netsetest_bench.solvers import capture
    from netsetest.config.schema import load_topology

    out: dict = {"steps": steps, "runs": runs}
    for case in CASES:
        capture(load_topology("paper6", case, COST_WARM_UP), "scheduled")
        per_run = []
        for _ in range(runs):
            times: dict[str, list[float]] = {"moved": [], "cut": []}
            with _region_timers(times):
                cap = capture(load_topology("paper6", case, steps), "scheduled")
            per_run.append(
                {
                    "step_ms": statistics.median(cap.step_ms),
                    "moved_ms": statistics.median(times["moved"]),
                    "cut_ms": statistics.median(times["cut"]),
                    "share": (sum(times["moved"]) + sum(times["cut"])) / sum(cap.step_ms),
                }
            )
        out[case] = {key: statistics.median(r[key] for r in per_run) for key in per_run[0]} | {"per_run": per_run}
        _log(f"  paper6 {case.upper()}: step {out[case]['step_ms']:.3f} ms per node-step, region {100 * out[case]['share']:.0f} %")
    return out


class SideBySideFailed(RuntimeError):
    """The step program failed or hung on a checkout (say, a baseline without bench/solvers.py's side_by_side)."""


def _step_runs(case: Case, steps: int, runs: int, code: Path | None) -> list[dict[str, float]]:
    """:data:`STEP_PROGRAM` in a process of its own, on ``code``'s netsetest (None: this checkout's): after a run of
    the same length, ``runs`` runs, each the step median per node-step [ms] in the run and replayed (:data:`STEP_FIGURES`)."""
    from netsetest_bench.zenoh_runs import code_env

    env = {**os.environ, **code_env(code)}
    where = code or "this checkout"
    try:
        out = subprocess.run(
            [sys.executable, "-c", STEP_PROGRAM, case, str(steps), str(runs)], env=env, capture_output=True, text=True, timeout=900, check=False
        )
    except subprocess.TimeoutExpired:
        raise SideBySideFailed(f"the step program on {where} did not finish in 900 s") from None
    if out.returncode != 0:
        last = out.stderr.strip().splitlines()[-1:]
        raise SideBySideFailed(f"the step program on {where} failed (exit {out.returncode}): {last[0] if last else 'no message'}")
    return [dict(zip((key for key, _ in STEP_FIGURES), run)) for run in json.loads(out.stdout.strip().splitlines()[-1])]


def step_side_by_side(baseline: Path, steps: int = COST_STEPS, processes: int = SIDE_PROCESSES, runs: int = SIDE_RUNS) -> dict:
    """Per case and figure of :data:`STEP_FIGURES`, ``processes`` processes of this checkout and of ``baseline`` in
    turn, ``runs`` runs in each (:func:`_step_runs`): every run's figure, the fastest run and the median run of each
    checkout, and the fastest runs' difference against :data:`STEP_TARGET_MS`.  The fastest run is the code's cost
    where nothing else took the machine: this host has episodes of seconds in which a run is 1.5 times slower
    (docs/performance-history.md), which a median of a few runs does not hide."""
    from netsetest_bench.node_budget import checkout_commit

    out: dict = {
        "steps": steps,
        "processes": processes,
        "runs": runs,
        "target_ms": STEP_TARGET_MS,
        "commits": {"this": checkout_commit(Path(__file__).resolve().parents[2]), "baseline": checkout_commit(baseline)},
    }
    for case in CASES:
        rows: dict[str, list[dict[str, float]]] = {"this": [], "baseline": []}
        for _ in range(processes):
            rows["this"] += _step_runs(case, steps, runs, None)
            rows["baseline"] += _step_runs(case, steps, runs, baseline)
        out[case] = {}
        for key, _ in STEP_FIGURES:
            this, base = [r[key] for r in rows["this"]], [r[key] for r in rows["baseline"]]
            over = min(this) - min(base)
            out[case][key] = {
                "this_ms": this,
                "baseline_ms": base,
                "this": min(this),
                "baseline": min(base),
                "this_median": statistics.median(this),
                "baseline_median": statistics.median(base),
                "over_ms": over,
                "over_median_ms": statistics.median(this) - statistics.median(base),
                "met": over <= STEP_TARGET_MS,
            }
        _log(f"  paper6 {case.upper()}: " + "; ".join(f"{key} {1e3 * out[case][key]['over_ms']:+.0f} µs" for key, _ in STEP_FIGURES))
    return out


# ---------------------------------------------------------------- rendering


def _worst(row: dict) -> float:
    """The largest per-node ratio of the row over r, β and f (a point exact interval has none)."""
    return max((v for ratios in row["ratio_exact_by_node"].values() for v in ratios if v is not None), default=float("nan"))


def _pooled(row: dict) -> list[float | None]:
    """r, β, f: mean width over exact, pooled over nodes (compare's ratio)."""
    beta, r = row["ratio_exact_state"]
    return [r, beta, row["ratio_exact"]]


def _f(v: float | None, spec: str = ".3f") -> str:
    return "–" if v is None else format(v, spec)


def _cell(row: dict) -> str:
    """r / β / f pooled over nodes, with the worst node's largest ratio and the absolute excess where exact is a point."""
    text = " / ".join(_f(v) for v in _pooled(row)) + f" (≤ {_f(_worst(row))})"
    return text + (f", {row['pinned_excess']:+.1e} abs." if row.get("pinned_excess") is not None else "")


def _met(run: dict, row: dict) -> bool:
    return _worst(row) <= run["target"] and row["violations"] == 0 and row["narrower"] == 0


def _run_label(run: dict) -> str:
    seeds = ",".join(map(str, run["seeds"]))
    return f"{run['label']} (seed{'s' if len(run['seeds']) > 1 else ''} {seeds}; {run['steps']} steps)"


def _rows(run: dict) -> dict[str, dict]:
    return {r["estimator"]: r for r in run["rows"]}


def widths_summary_markdown(res: dict) -> str:
    """Every run: the SDP against its target, the paper's own set beside it."""
    lines = [
        f"`netsetest compare <topology> --estimators {','.join(ESTIMATORS)}` per run (with `<name>-noregion` too where a "
        "run compares the set estimators without their region); mean published width over the "
        f"exact limit from step {res['from_step']}, r / β / f pooled over nodes, and in brackets the largest per-node "
        "ratio of the three; where the exact interval is a point (a reference's declared zero fault) the absolute width "
        "over it instead (abs.). Exact limit: the fault bounds it applies and, under k-of-N health, the ends its search "
        "left relaxed (an outer bound of the limit there, so a ratio may fall below 1; such an end is not counted "
        "narrower). Target: the SDP's every node and coordinate ≤ the run's target, with no violation and "
        "no interval narrower than exact where the assumptions held.",
        "",
        "| run | target | sdp r / β / f | sdp-ellipsoid (the paper's own set) | exact limit | narrower than exact | violations | met |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for run in res["runs"]:
        rows = _rows(run)
        sdp = rows["sdp"]
        narrower = sum(r["narrower"] for r in run["rows"])
        compared = sum(r["compared"] for r in run["rows"])
        lines.append(
            f"| {_run_label(run)} | ≤ {run['target']:.2f} | {_cell(sdp)} | {_cell(rows['sdp-ellipsoid'])} | "
            f"{', '.join(sdp.get('exact_reference', []))} | {narrower} of {compared} | {sum(r['violations'] for r in run['rows'])} | {'yes' if _met(run, sdp) else '**no**'} |"
        )
    return "\n".join(lines) + "\n"


def cost_markdown(cost: dict) -> str:
    """The region's cost per node-step, per case."""
    lines = [
        f"The region's cost: paper6 in memory, {cost['runs']} runs of {cost['steps']} steps per case after a warm-up, "
        "each the median over its node-steps, the median of the runs (per run in brackets). Step: the estimator's step "
        "as a node runs it; move and cut: the region's, timed in the same runs; share: the two over the step time, "
        "summed over the run. Issue 28's target (the step at most 0.25 ms over the code before every node kept a "
        "region, 29290ba) is judged side by side with that checkout (`--baseline`).",
        "",
        "| case | step (ms per node-step) | region move (ms) | region cut (ms) | region share of the step |",
        "|---|---|---|---|---|",
    ]
    for case in CASES:
        c = cost[case]
        runs = ", ".join(f"{r['step_ms']:.3f}" for r in c["per_run"])
        lines.append(f"| paper6 {case.upper()} | {c['step_ms']:.3f} ({runs}) | {c['moved_ms']:.3f} | {c['cut_ms']:.3f} | {100 * c['share']:.0f} % |")
    return "\n".join(lines) + "\n"


def side_by_side_markdown(side: dict) -> str:
    """Issue 28's cost target: the step of this checkout against the baseline's, side by side, in a run and replayed."""
    if "error" in side:
        return f"The step side by side with the baseline was not measured: {side['error']}.\n"
    commits = side["commits"]
    lines = [
        f"The step side by side with the code before every node kept a region (`{commits['baseline']}`; this checkout: "
        f"`{commits['this']}`, uncommitted changes aside): paper6 in memory, {side['processes']} processes of each "
        f"alternating, one program for both; each process runs {side['steps']} steps once to warm up, then "
        f"{side['runs']} times: per run the median over its node-steps of the estimator's step as a node runs it (in "
        "the run), and of the same steps replayed back to back, as the performance part times its median node-step "
        "(replayed). The fastest run of each checkout (the code's cost where nothing else took the machine) and the "
        f"median run; target (issue 28): the fastest at most {side['target_ms']} ms over the baseline's.",
        "",
        "| case | figure | this checkout: fastest / median run (ms per node-step) | baseline: fastest / median run | over the baseline: fastest / median | within the target |",
        "|---|---|---|---|---|---|",
    ]
    for case in CASES:
        for key, what in STEP_FIGURES:
            c = side[case][key]
            lines.append(
                f"| paper6 {case.upper()} | {what} | {c['this']:.3f} / {c['this_median']:.3f} | {c['baseline']:.3f} / {c['baseline_median']:.3f} | "
                f"{c['over_ms']:+.3f} / {c['over_median_ms']:+.3f} ms | {'yes' if c['met'] else 'no'} |"
            )
    return "\n".join(lines) + "\n"


def sets_section(res: dict) -> str:
    """Issue 44's tables (bench/network_sets.py), or where the figures are older than them, that they are not there."""
    from netsetest_bench.network_sets import sets_markdown

    if "sets" not in res:
        return "Not measured in these figures (they are older than issue 44's part): measure them with the command above.\n"
    return sets_markdown(res["sets"])


def widths_markdown(res: dict) -> str:
    """Every run: the SDP against its target, then every estimator's r / β / f over exact, then per node; then the
    region's cost (figures measured before it had one: none); then what a node takes from its network (issue 44)."""
    runs = res["runs"]
    lines = [widths_summary_markdown(res)]
    if "cost" in res:
        lines += [cost_markdown(res["cost"])]
    if "side_by_side" in res:
        lines += [side_by_side_markdown(res["side_by_side"])]
    lines += ["Every estimator, r / β / f over exact pooled over nodes (largest per-node ratio):", ""]
    names = list(dict.fromkeys(r["estimator"] for run in runs for r in run["rows"] if r["estimator"] not in ("sdp", "sdp-ellipsoid", "exact")))
    lines += ["| run | " + " | ".join(f"`{n}`" for n in names) + " |", "|---|" + "---|" * len(names)]
    for run in runs:
        rows = _rows(run)
        lines.append(f"| {run['label']} | " + " | ".join(_cell(rows[n]) if n in rows else "–" for n in names) + " |")
    lines += ["", "Per node, r / β / f over exact ('–': the exact interval is a point):", ""]
    for run in runs:
        nodes = sorted({int(i) for r in run["rows"] for i in r["ratio_exact_by_node"]})
        lines += [f"{_run_label(run)}:", "", "| estimator | " + " | ".join(f"node {i}" for i in nodes) + " |", "|---|" + "---|" * len(nodes)]
        for r in run["rows"]:
            by = {int(i): v for i, v in r["ratio_exact_by_node"].items()}
            cells = [" / ".join(_f(by[i][m]) for m, _ in COORDS) if i in by else "" for i in nodes]
            lines.append(f"| `{r['estimator']}` | " + " | ".join(cells) + " |")
        lines.append("")
    if "sets" in res:
        lines += ["What a node takes from its network (issue 44, netsetest_bench/network_sets.py):", "", sets_section(res)]
    return "\n".join(lines)


def region_markdown(res: dict) -> str:
    """What the region buys the set estimators: each with and without it, side by side, r / β / f over exact."""
    runs = res["runs"]
    methods = [n for n in ("zonotope", "interval", "strip", "setprop") if any(n in _rows(r) for r in runs)]
    lines = [
        "r / β / f, mean published width over the exact limit pooled over nodes from step "
        f"{res['from_step']} (largest per-node ratio), each set estimator without its region (the method as its paper "
        "defines it, `<name>-noregion`) → with it; violations and intervals narrower than exact where the assumptions "
        "held, with the region.",
        "",
        "| run | " + " | ".join(f"`{m}` without → with" for m in methods) + " | violations, narrower (with) |",
        "|---|" + "---|" * len(methods) + "---|",
    ]
    for run in (r for r in runs if r["without_region"]):
        rows = _rows(run)
        cells = [f"{_cell(rows[m + '-noregion'])} → {_cell(rows[m])}" if m in rows and m + "-noregion" in rows else "–" for m in methods]
        bad = sum(rows[m]["violations"] for m in methods if m in rows), sum(rows[m]["narrower"] for m in methods if m in rows)
        lines.append(f"| {run['label']} | " + " | ".join(cells) + f" | {bad[0]}, {bad[1]} |")
    return "\n".join(lines) + "\n"


__all__ = [
    "ESTIMATORS",
    "SideBySideFailed",
    "WidthRun",
    "cost_markdown",
    "plan",
    "region_cost",
    "region_markdown",
    "side_by_side_markdown",
    "step_side_by_side",
    "widths_figures",
    "widths_markdown",
    "widths_summary_markdown",
]
