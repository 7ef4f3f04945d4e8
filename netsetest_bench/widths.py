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
from dataclasses import dataclass, fields
from pathlib import Path

from netsetest.config.schema import Case
from netsetest.models.signals import SignalKind
from netsetest_bench.config import BenchConfig
from netsetest_bench.figures.widths import Commits, RegionCase, RegionCost, RegionRun, Row, Run, SideBySide, SideCase, StepFigure, Widths
from netsetest_bench.figures.widths import load as load_widths
from netsetest_bench.render import fill, typed

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


def plan(cfg: BenchConfig) -> list[WidthRun]:
    """The listed runs (paper6 NSNIM and SAIM with the paper's signals and worst-case ones, the car's held-out drives,
    paper6_reference, paper6_max_faulty), then every other bundled scenario once."""
    from netsetest.scenarios import bundled_topologies

    families: tuple[tuple[SignalKind, tuple[int, ...]], ...] = (("paper", (0,)), ("worst", tuple(cfg.widths_worst_seeds)))
    runs = [WidthRun(f"paper6 {case.upper()}, {sig} signals", "paper6", case, sig, seeds, LISTED) for case in CASES for sig, seeds in families]
    runs += [WidthRun(f"{CAR} {case.upper()}, held-out seeds", CAR, case, "paper", tuple(cfg.widths_car_seeds), LISTED) for case in CASES]
    runs += [WidthRun(t, t, None, "paper", (0,), LISTED, without_region=True) for t in ("paper6_reference", "paper6_max_faulty")]
    runs += [WidthRun(t, t, None, "paper", (0,), OTHER, cfg.widths_lap_steps if t == "paper6_lap" else None) for t in bundled_topologies() if t not in TARGETED]
    return runs


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _measure(run: WidthRun) -> Run:
    from netsetest.analysis.compare import compare

    t0 = time.perf_counter()
    c = compare(run.topology, run.estimators, (run.case,), (run.signals,), run.seeds, run.steps)
    rows = [Row(**{f.name: getattr(r, f.name) for f in fields(r)}, plant=c.plant) for r in c.rows]  # compare --json's rows
    fig = Run(
        label=run.label,
        topology=run.topology,
        case=run.case,
        signals=run.signals,
        seeds=list(run.seeds),
        target=run.target,
        steps=c.steps,
        without_region=run.without_region,
        runs=c.runs,
        rows=rows,
    )
    _log(f"  {run.label}: sdp worst node {_worst(fig.by_estimator()['sdp']):.3f} (target {run.target}), {time.perf_counter() - t0:.0f} s")
    return fig


def widths_figures(cfg: BenchConfig, tmp: Path, baseline: Path | None = None) -> Widths:
    """Every run of :func:`plan`, compared (JOBS at once, in processes of their own); the region's cost; with a
    ``baseline`` checkout, the step side by side with it."""
    from concurrent.futures import ProcessPoolExecutor

    from netsetest.analysis.exact import FROM_STEP

    from netsetest_bench.network_sets import sets_figures

    with ProcessPoolExecutor(JOBS) as pool:
        runs = list(pool.map(_measure, plan(cfg)))
    _log("the region's cost per node-step (paper6, in memory, this process alone)")
    cost, sets = region_cost(), sets_figures(cfg, tmp)
    side = None
    if baseline is not None:
        _log(f"the step side by side with the baseline {baseline} (paper6, in memory, processes of their own, alternating)")
        try:
            side = step_side_by_side(baseline)
        except SideBySideFailed as e:  # (the comparisons above stand: the table says what failed)
            _log(f"  {e}")
            side = SideBySide(error=str(e))
    return Widths(from_step=FROM_STEP, runs=runs, cost=cost, sets=sets, side_by_side=side)


@contextmanager
def _region_timers(moves: list[float], cuts_ms: list[float]) -> Iterator[None]:
    """Every call of the region's two pieces timed while the block runs [ms]: the move of the region through the step
    (``LocalEstimator._moved_region``, into ``moves``) and its cut (:data:`~netsetest.estimator.cuts.REGION`, into
    ``cuts_ms``)."""
    from netsetest.estimator import cuts, sdp

    moved, cut = sdp.LocalEstimator._moved_region, cuts.REGION.apply

    def timed_moved(est: sdp.LocalEstimator, *args: object) -> object:
        t0 = time.perf_counter()
        out = moved(est, *args)  # type: ignore[arg-type]  # the method's own arguments, passed through
        moves.append(1e3 * (time.perf_counter() - t0))
        return out

    def timed_cut(ctx: cuts.StepContext, res: cuts.StepResult) -> cuts.StepResult:
        t0 = time.perf_counter()
        out = cut(ctx, res)
        if ctx.blend is not None:  # (step 0's cut, from the prior, is no step the run times)
            cuts_ms.append(1e3 * (time.perf_counter() - t0))
        return out

    sdp.LocalEstimator._moved_region = timed_moved  # type: ignore[method-assign,assignment]  # restored below
    object.__setattr__(cuts.REGION, "apply", timed_cut)  # (the Cut is frozen; every cut list holds this one)
    try:
        yield
    finally:
        sdp.LocalEstimator._moved_region = moved  # type: ignore[method-assign]  # the method back
        object.__setattr__(cuts.REGION, "apply", cut)


def region_cost(steps: int = COST_STEPS, runs: int = COST_RUNS) -> RegionCost:
    """Per case (paper6 NSNIM, SAIM): ``runs`` runs of ``steps`` steps after a warm-up run, each the median over its
    node-steps of the estimator's step (bench/solvers.py's ``capture``: the in-run time of ``LocalEstimator.step``),
    of the region's move and of its cut, and the region's share of the step time (the move and the cut over all
    steps, summed); the case's figure is the median over the runs."""
    from netsetest_bench.solvers import capture
    from netsetest.config.schema import load_topology

    out: list[RegionCase] = []
    for case in CASES:
        capture(load_topology("paper6", case, COST_WARM_UP), "scheduled")
        per_run = []
        for _ in range(runs):
            moves: list[float] = []
            cuts_ms: list[float] = []
            with _region_timers(moves, cuts_ms):
                cap = capture(load_topology("paper6", case, steps), "scheduled")
            per_run.append(
                RegionRun(
                    step_ms=statistics.median(cap.step_ms),
                    moved_ms=statistics.median(moves),
                    cut_ms=statistics.median(cuts_ms),
                    share=(sum(moves) + sum(cuts_ms)) / sum(cap.step_ms),
                )
            )
        c = RegionCase(
            step_ms=statistics.median(r.step_ms for r in per_run),
            moved_ms=statistics.median(r.moved_ms for r in per_run),
            cut_ms=statistics.median(r.cut_ms for r in per_run),
            share=statistics.median(r.share for r in per_run),
            per_run=per_run,
        )
        out.append(c)
        _log(f"  paper6 {case.upper()}: step {c.step_ms:.3f} ms per node-step, region {100 * c.share:.0f} %")
    nsnim, saim = out  # CASES' order
    return RegionCost(steps=steps, runs=runs, nsnim=nsnim, saim=saim)


class SideBySideFailed(RuntimeError):
    """The step program failed or hung on a checkout (say, a baseline without bench/solvers.py's side_by_side)."""


def _step_runs(case: Case, steps: int, runs: int, code: Path | None) -> list[tuple[float, float]]:
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
    return [(in_run, replayed) for in_run, replayed in json.loads(out.stdout.strip().splitlines()[-1])]


def step_side_by_side(baseline: Path, steps: int = COST_STEPS, processes: int = SIDE_PROCESSES, runs: int = SIDE_RUNS) -> SideBySide:
    """Per case and figure of :data:`STEP_FIGURES`, ``processes`` processes of this checkout and of ``baseline`` in
    turn, ``runs`` runs in each (:func:`_step_runs`): every run's figure, the fastest run and the median run of each
    checkout, and the fastest runs' difference against :data:`STEP_TARGET_MS`.  The fastest run is the code's cost
    where nothing else took the machine: this host has episodes of seconds in which a run is 1.5 times slower
    (docs/performance-history.md), which a median of a few runs does not hide."""
    from netsetest_bench.node_budget import THIS_CHECKOUT, checkout_commit

    commits = Commits(this=checkout_commit(THIS_CHECKOUT), baseline=checkout_commit(baseline))
    out: list[SideCase] = []
    for case in CASES:
        this: list[tuple[float, float]] = []
        base: list[tuple[float, float]] = []
        for _ in range(processes):
            this += _step_runs(case, steps, runs, None)
            base += _step_runs(case, steps, runs, baseline)
        c = SideCase(*(_step_figure([r[n] for r in this], [r[n] for r in base]) for n, _ in enumerate(STEP_FIGURES)))
        out.append(c)
        _log(f"  paper6 {case.upper()}: " + "; ".join(f"{key} {1e3 * c.figure(key).over_ms:+.0f} µs" for key, _ in STEP_FIGURES))
    nsnim, saim = out  # CASES' order
    return SideBySide(steps=steps, processes=processes, runs=runs, target_ms=STEP_TARGET_MS, commits=commits, nsnim=nsnim, saim=saim)


def _step_figure(this: list[float], base: list[float]) -> StepFigure:
    """One figure of :data:`STEP_FIGURES` from every run of each checkout: the fastest runs judged against the target."""
    over = min(this) - min(base)
    return StepFigure(
        this_ms=this,
        baseline_ms=base,
        this=min(this),
        baseline=min(base),
        this_median=statistics.median(this),
        baseline_median=statistics.median(base),
        over_ms=over,
        over_median_ms=statistics.median(this) - statistics.median(base),
        met=over <= STEP_TARGET_MS,
    )


# ---------------------------------------------------------------- rendering


def _worst(row: Row) -> float:
    """The largest per-node ratio of the row over r, β and f (a point exact interval has none)."""
    return max((v for ratios in row.ratio_exact_by_node.values() for v in ratios if v is not None), default=float("nan"))


def _pooled(row: Row) -> list[float | None]:
    """r, β, f: mean width over exact, pooled over nodes (compare's ratio)."""
    beta, r = row.ratio_exact_state
    return [r, beta, row.ratio_exact]


def _f(v: float | None, spec: str = ".3f") -> str:
    return "–" if v is None else format(v, spec)


def _cell(row: Row) -> str:
    """r / β / f pooled over nodes, with the worst node's largest ratio and the absolute excess where exact is a point."""
    text = " / ".join(_f(v) for v in _pooled(row)) + f" (≤ {_f(_worst(row))})"
    return text + (f", {row.pinned_excess:+.1e} abs." if row.pinned_excess is not None else "")


def _met(run: Run, row: Row) -> bool:
    return _worst(row) <= run.target and row.violations == 0 and row.narrower == 0


def _run_label(run: Run) -> str:
    seeds = ",".join(map(str, run.seeds))
    return f"{run.label} (seed{'s' if len(run.seeds) > 1 else ''} {seeds}; {run.steps} steps)"


def _widths(res: dict | Widths) -> Widths:
    return load_widths(res) if isinstance(res, dict) else res  # (not isinstance Widths: a test may import the module twice)


W = "widths"  # the part's template (templates/widths.md)


def widths_summary_markdown(res: dict | Widths) -> str:
    """Every run: the SDP against its target, the paper's own set beside it."""
    w = _widths(res)
    lines = [fill(W, "summary-head", estimators=",".join(ESTIMATORS), from_step=w.from_step)]
    for run in w.runs:
        rows = run.by_estimator()
        sdp = rows["sdp"]
        lines.append(
            fill(
                W,
                "summary-row",
                label=_run_label(run),
                run=run,
                sdp=_cell(sdp),
                ellipsoid=_cell(rows["sdp-ellipsoid"]),
                exact=", ".join(sdp.exact_reference),
                narrower=sum(r.narrower for r in run.rows),
                compared=sum(r.compared for r in run.rows),
                violations=sum(r.violations for r in run.rows),
                met=fill(W, "yes" if _met(run, sdp) else "not-met"),
            )
        )
    return "\n".join(lines) + "\n"


def cost_markdown(cost: dict | RegionCost) -> str:
    """The region's cost per node-step, per case."""
    rc = typed(RegionCost, cost, "the region's cost") if isinstance(cost, dict) else cost
    lines = [fill(W, "cost-head", c=rc)]
    for case in CASES:
        c = rc.case(case)
        runs = ", ".join(f"{r.step_ms:.3f}" for r in c.per_run)
        lines.append(fill(W, "cost-row", case=case.upper(), c=c, runs=runs, share=100 * c.share))
    return "\n".join(lines) + "\n"


def side_by_side_markdown(side: dict | SideBySide) -> str:
    """Issue 28's cost target: the step of this checkout against the baseline's, side by side, in a run and replayed."""
    s = typed(SideBySide, side, "the step side by side") if isinstance(side, dict) else side
    if s.error is not None or s.commits is None:
        return fill(W, "side-error", error=s.error) + "\n"
    lines = [fill(W, "side-head", s=s)]
    for case in CASES:
        for key, what in STEP_FIGURES:
            c = s.case(case).figure(key)
            lines.append(fill(W, "side-row", case=case.upper(), what=what, c=c, met=fill(W, "side-met" if c.met else "side-not-met")))
    return "\n".join(lines) + "\n"


def sets_section(res: dict | Widths) -> str:
    """Issue 44's tables (bench/network_sets.py), or where the figures are older than them, that they are not there."""
    from netsetest_bench.network_sets import sets_markdown

    sets = _widths(res).sets
    return fill(W, "no-sets") + "\n" if sets is None else sets_markdown(sets)


def widths_markdown(res: dict | Widths) -> str:
    """Every run: the SDP against its target, then every estimator's r / β / f over exact, then per node; then the
    region's cost (figures measured before it had one: none); then what a node takes from its network (issue 44)."""
    w = _widths(res)
    lines = [widths_summary_markdown(w)]
    if w.cost is not None:
        lines += [cost_markdown(w.cost)]
    if w.side_by_side is not None:
        lines += [side_by_side_markdown(w.side_by_side)]
    lines += [fill(W, "every-head"), ""]
    names = list(dict.fromkeys(r.estimator for run in w.runs for r in run.rows if r.estimator not in ("sdp", "sdp-ellipsoid", "exact")))
    lines += ["| run | " + " | ".join(f"`{n}`" for n in names) + " |", "|---|" + "---|" * len(names)]
    for run in w.runs:
        rows = run.by_estimator()
        lines.append(f"| {run.label} | " + " | ".join(_cell(rows[n]) if n in rows else "–" for n in names) + " |")
    lines += ["", fill(W, "per-node-head"), ""]
    for run in w.runs:
        nodes = sorted({i for r in run.rows for i in r.ratio_exact_by_node})
        lines += [f"{_run_label(run)}:", "", "| estimator | " + " | ".join(f"node {i}" for i in nodes) + " |", "|---|" + "---|" * len(nodes)]
        for r in run.rows:
            by = r.ratio_exact_by_node
            cells = [" / ".join(_f(by[i][m]) for m, _ in COORDS) if i in by else "" for i in nodes]
            lines.append(f"| `{r.estimator}` | " + " | ".join(cells) + " |")
        lines.append("")
    if w.sets is not None:
        lines += [fill(W, "sets-head"), "", sets_section(w)]
    return "\n".join(lines)


def region_markdown(res: dict | Widths) -> str:
    """What the region buys the set estimators: each with and without it, side by side, r / β / f over exact."""
    w = _widths(res)
    methods = [n for n in ("zonotope", "interval", "strip", "setprop") if any(n in r.by_estimator() for r in w.runs)]
    columns = " | ".join(fill(W, "region-column", method=m) for m in methods)
    lines = [fill(W, "region-head", from_step=w.from_step, columns=columns, dashes="---|" * len(methods))]
    for run in (r for r in w.runs if r.without_region):
        rows = run.by_estimator()
        cells = [f"{_cell(rows[m + '-noregion'])} → {_cell(rows[m])}" if m in rows and m + "-noregion" in rows else "–" for m in methods]
        violations, narrower = sum(rows[m].violations for m in methods if m in rows), sum(rows[m].narrower for m in methods if m in rows)
        lines.append(fill(W, "region-row", run=run, cells=" | ".join(cells), violations=violations, narrower=narrower))
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
