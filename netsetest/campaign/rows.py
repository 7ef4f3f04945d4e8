"""A run's rows: one per node, every input parameter and every figure (:data:`COLUMNS`, in this order).

A run that failed its verdict is rows like any other (``verdict`` FAIL, ``cause`` the verdict line); a run
that raised, or whose worker died, is rows with its ``cause`` and the figures null.  Every row carries the
command that replays its run (``replay``).  The columns in :data:`TIMING` (and ``worker``) say how and
where the run went, not what it found: they differ between two runs of the same inputs; every other column
is the same whichever worker ran it, and however many there were.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import netsetest
from netsetest.runtime.report import outcome, verdict

if TYPE_CHECKING:
    from netsetest.campaign.spec import Campaign, Planned
    from netsetest.campaign.worker import RunOutcome

EXACT_NAMES = {"beta": "beta", "r": "r", "f": "fault"}  # analysis/exact.py's coordinates → the columns' names
ERROR = "ERROR"  # the verdict column of a run that raised or whose worker died: no verdict exists


@dataclass(frozen=True)
class Column:
    name: str
    type: str  # pyarrow's: string, int64, float64, bool
    doc: str


def _c(name: str, type_: str, doc: str) -> Column:
    return Column(name, type_, doc)


INPUTS = (
    _c("run_key", "string", "the digest of the run's inputs (campaign/spec.py run_key)"),
    _c("campaign", "string", "the campaign's name"),
    _c("topology", "string", "the topology as the run was given it (a path or a bundled name)"),
    _c("scenario", "string", "the topology's name"),
    _c("settings_digest", "string", "the files' values, overrides included"),
    _c("estimator", "string", "the campaign's estimator value ('file': every node its topology's own); a partition"),
    _c("case", "string", "nsnim or saim; a partition"),
    _c("signals", "string", "paper or worst"),
    _c("seed", "int64", "the run's seed"),
    _c("steps", "int64", "the run's steps"),
    _c("manoeuvre", "string", "the --manoeuvre given (null: the file's)"),
    _c("speed_kmh", "float64", "the --speed given (null: the file's)"),
    _c("fault_scale", "float64", "the --fault-scale given (null: the file's faults)"),
    _c("log", "string", "the --log given: a recorded drive as the world (null: the file's world)"),
    _c("variant", "string", "the SDP's variant"),
    _c("objective", "string", "the SDP's objective"),
    _c("node", "int64", "the node of this row"),
    _c("node_estimator", "string", "the estimator this node ran"),
    _c("fault_declared", "float64", "the node's declared [fault_bound] size (null: none)"),
    _c("fault_peak", "float64", "the largest |f_k| of the node's true fault over the run"),
)
OUTCOME = (
    _c("verdict", "string", "the run's verdict word (PASS, FAIL, …, ERROR: no verdict)"),
    _c("exit_code", "int64", "what `netsetest run` exits with for this run (null: ERROR)"),
    _c("cause", "string", "why the run did not pass: its verdict line, or its error (null: passed)"),
    _c("replay", "string", "the command that replays the run"),
    _c("violations_total", "int64", "the run's misses where every assumption held"),
    _c("node_steps_covered_total", "int64", "the run's node-steps judged with every assumption held"),
)
NODE = (
    _c("steps_reported", "int64", "node-steps the node published"),
    _c("steps_evaluated", "int64", "of them judged against the truth"),
    _c("steps_contained", "int64", "of them contained"),
    _c("steps_covered", "int64", "judged with every assumption held"),
    _c("coverage", "float64", "steps_covered / steps_evaluated: the share the guarantee applied to"),
    _c("violations", "int64", "misses where every assumption held (must be 0)"),
    _c("misses_assumption_broken", "int64", "misses outside the guarantee"),
    _c("fallbacks", "int64", "steps the node published its guaranteed fallback"),
)
WIDTHS = (
    _c("beta_width", "float64", "mean width of the published sideslip interval [rad]"),
    _c("r_width", "float64", "mean width of the published yaw-rate interval [rad/s]"),
    _c("fault_width", "float64", "mean width of the published fault interval [rad/s]"),
)
DETECTION = (
    _c("fault_onset", "int64", "first step the true fault exceeds the tolerance (null: none)"),
    _c("first_detection", "int64", "first step the published fault interval excludes 0 (null: none)"),
    _c("detection_delay", "int64", "steps from the onset to the first detection (null: none)"),
    _c("detected_steps", "int64", "steps detected"),
    _c("false_detections", "int64", "detections while the fault was within the tolerance"),
    _c("false_detections_covered", "int64", "of them where every assumption held"),
)
EXACT = tuple(
    _c(f"{c}_over_exact", "float64", f"mean published {c} width / the exact limit's, steps ≥ 10 (null: a point exact interval)") for c in ("beta", "r", "fault")
) + (_c("narrower_than_exact", "int64", "node-step intervals narrower than the exact limit's (must be 0 where it rests on no more)"),)
TIMING = (
    _c("solve_ms_median", "float64", "the node's median estimator step [ms]"),
    _c("wall_s", "float64", "the run's wall time in its worker [s]"),
    _c("cpu_s", "float64", "the run's CPU time in its worker (its thread's) [s]"),
    _c("finished_at", "float64", "when the campaign received it [Unix s]"),
)
PROVENANCE = (
    _c("worker", "string", "host:pid of the process that ran it"),
    _c("netsetest_version", "string", "the version that ran it"),
)
COLUMNS: tuple[Column, ...] = (*INPUTS, *OUTCOME, *NODE, *WIDTHS, *DETECTION, *EXACT, *TIMING, *PROVENANCE)
PARTITIONS = ("estimator", "case")  # the dataset's directories: estimator=<name>/case=<case>/
VARYING = tuple(c.name for c in (*TIMING, *PROVENANCE))  # differ between two runs of the same inputs


@functools.cache
def _version() -> str:
    return netsetest.__version__  # looked up once (importlib.metadata: ~90 ms)


def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def _inputs(c: Campaign, p: Planned, n: int) -> dict:
    s, sc = p.spec, p.spec.scenario
    return {
        "run_key": p.key,
        "campaign": c.name,
        "topology": sc.topology,
        "scenario": p.info.name,
        "settings_digest": p.info.settings_digest,
        "estimator": p.estimator,
        "case": p.info.case,
        "signals": s.signals,
        "seed": s.seed,
        "steps": p.info.steps,
        "manoeuvre": sc.manoeuvre,
        "speed_kmh": sc.speed,
        "fault_scale": sc.fault_scale,
        "log": sc.log,
        "variant": s.variant,
        "objective": s.objective,
        "node": p.info.node_ids[n],
        "node_estimator": p.info.node_estimators[n],
        "fault_declared": p.info.fault_declared[n],
        "fault_peak": p.info.fault_peak[n],
    }


def rows_of(c: Campaign, p: Planned, o: RunOutcome) -> list[dict]:
    """The run's rows (one per node of its scenario), every column of :data:`COLUMNS`."""
    base = {col.name: None for col in COLUMNS}
    run = {
        "replay": p.spec.command(),
        "solve_ms_median": None,
        "wall_s": o.wall_s,
        "cpu_s": o.cpu_s,
        "finished_at": time.time(),
        "worker": o.worker,
        "netsetest_version": _version(),
    }
    s = o.summary
    if s is None:
        run |= {"verdict": ERROR, "cause": o.error}
    else:
        v = outcome(s)
        run |= {
            "verdict": v.word,
            "exit_code": v.code,
            "cause": None if v.code == 0 else verdict(s),
            "violations_total": s.violations_total,
            "node_steps_covered_total": s.node_steps_covered,
        }
    rows = []
    for n, node in enumerate(p.info.node_ids):
        row = base | _inputs(c, p, n) | run
        if s is not None:
            row |= _node_figures(c, s.node(node))
        if o.exact is not None:
            ratios = next(r.ratios for r in o.exact.nodes if r.node == node)
            row |= {f"{EXACT_NAMES[coord]}_over_exact": _num(x.width_ratio) for coord, x in ratios.items()}
            row["narrower_than_exact"] = sum(x.narrower for x in ratios.values())
        rows.append(row)
    return rows


def _node_figures(c: Campaign, n) -> dict:
    out = {
        "steps_reported": n.steps_reported,
        "steps_evaluated": n.steps_evaluated,
        "steps_contained": n.steps_contained,
        "steps_covered": n.steps_covered,
        "coverage": n.steps_covered / n.steps_evaluated if n.steps_evaluated else None,
        "violations": n.violations,
        "misses_assumption_broken": n.misses_assumption_broken,
        "fallbacks": n.fallbacks,
        "solve_ms_median": n.solve_ms_median,
    }
    if "widths" in c.figures:
        out |= {"beta_width": n.beta_mean_width, "r_width": n.r_mean_width, "fault_width": n.fault_bound_mean_width}
    if "detection" in c.figures:
        out |= {
            k: getattr(n, k) for k in ("fault_onset", "first_detection", "detection_delay", "detected_steps", "false_detections", "false_detections_covered")
        }
    return out
