"""What every run mode shares at its end: the per-node table, the summary JSON, the record, progress."""

from __future__ import annotations

import json
import sys
import textwrap
import time
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple, TextIO

if TYPE_CHECKING:  # every role and command imports this module (exit codes); the records load where a run ends
    from netsetest.records.record import MemorySink, RecordSink
    from netsetest.records.summary import RunSummary


def log(role: str, text: str) -> None:
    """A role's or the launcher's line on stderr: ``[role] text``."""
    print(f"[{role}] {text}", file=sys.stderr, flush=True)


class Progress:
    """One line per update on a terminal (\\r), a line every 10 % otherwise; always to stderr."""

    def __init__(self, total: int, label: str, stream: TextIO | None = None, enabled: bool = True) -> None:
        stream = stream or sys.stderr  # looked up now: sys.stderr may have been replaced since import
        self.total, self.label, self.stream, self.enabled = total, label, stream, enabled
        self.tty = enabled and stream.isatty()
        self.last_pct = -1
        self.t0 = time.monotonic()

    def update(self, done: int, extra: str = "") -> None:
        if not self.enabled:
            return
        pct = int(100 * done / max(self.total, 1))
        if pct == self.last_pct:
            return
        if self.tty:
            self.stream.write(f"\r{self.label}: step {done}/{self.total} ({pct:3d} %) {extra}\033[K")
            self.stream.flush()
        elif pct // 10 != self.last_pct // 10 or pct == 100:
            self.stream.write(f"{self.label}: step {done}/{self.total} ({pct} %, {time.monotonic() - self.t0:.1f} s) {extra}\n")
            self.stream.flush()
        self.last_pct = pct

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def _fmt(v: object, spec: str) -> str:
    return "-" if v is None else format(v, spec)


LEGEND = (
    "max E: largest eᵀP⁻¹e (inside while ≤ ρ = 1); viol.: misses where every assumption held (must be 0); "
    "assump.viol: node-steps outside the guarantee; miss(assump.): misses there; fault width: mean width of "
    "the published fault bounds (β, r width: of the state's); missing: first step not reported"
)


LEGEND_WIDTH = 120  # characters: the legend folds to the width of the table above it (117 with the β and r width columns)


class Outcome(NamedTuple):
    """A run's verdict word and its exit code: one decision (:func:`outcome`), so they always agree."""

    word: str
    code: int


def outcome(summary: RunSummary, strict: bool = False) -> Outcome:
    """The verdict's first word and the exit code, decided together (docs/summary.md):

    - ``FAIL`` (exit 1): a miss where every assumption held; ``FAIL (vehicle gone)`` (exit 1): the
      collector stopped waiting for the vehicle before its End; ``FAIL (collector stalled)`` (exit 1): the
      collector did not run for longer than its session's lease (the run's stall limit), so the run ended there;
    - ``INTERRUPTED`` (exit 130): the run was stopped by Ctrl-C or SIGTERM;
    - ``FAIL (--strict)`` (exit 1, ``strict`` only: ``run --strict``, for CI users who want a run to fail
      there): a set missed the truth outside the guarantee, where the run would otherwise pass or lose a node;
    - ``NODE LOST`` (exit 3): a node stopped reporting for good;
    - ``PASS (partial coverage)`` (exit 0): the guarantee did not apply to every node-step the run should
      have had judged (not covered, not judged, rejected, a node back after a gap, the collector overloaded);
    - ``PASS`` (exit 0): it applied to every node-step of every node.
    """
    if summary.violations_total:
        return Outcome("FAIL", EXIT_VIOLATION)
    if summary.stopped == "interrupted":
        return Outcome("INTERRUPTED", EXIT_INTERRUPTED)
    if summary.stopped is not None:
        return Outcome(f"FAIL ({summary.stopped})", EXIT_VIOLATION)
    if strict and summary.misses_assumption_broken_total:
        return Outcome("FAIL (--strict)", EXIT_VIOLATION)
    if summary.nodes_missing:
        return Outcome("NODE LOST", EXIT_NODE_LOST)
    expected = (summary.steps_completed + 1) * len(summary.nodes)
    # an undecided node-step (a recorded drive's reference cannot tell) is never counted as contained
    full = summary.node_steps_covered == summary.node_steps_evaluated == expected and not summary.node_steps_undecided
    return Outcome("PASS" if full else "PASS (partial coverage)", EXIT_OK)


def car_lines(summary: RunSummary) -> list[str]:
    """The output's header with a nonlinear plant (docs/plant.md): the plant and car, the manoeuvre, the
    largest e_k against its bound and where it left it, and the drive against the declared envelope."""
    c = summary.car
    if c is None:
        return []
    out = [f"car: {c.plant} ({c.car}), manoeuvre {c.manoeuvre}"]
    if c.bound is None:
        out.append(f"model mismatch: no [model_uncertainty] declared (e_k = 0 assumed); largest |e_β|, |e_r| {c.e_max[0]:.3g}, {c.e_max[1]:.3g}")
    else:
        where = (
            f"; e_k left it on {c.e_outside} of {c.transitions} steps (first k = {c.e_outside_first})"
            if c.e_outside
            else f"; inside it on all {c.transitions} steps"
        )
        ratio = "-" if c.e_max_ratio is None else f"{c.e_max_ratio:.2f}"
        out.append(f"model mismatch: largest e_k {ratio} × its bound ({c.bound}; |e_β| {c.e_max[0]:.3g}, |e_r| {c.e_max[1]:.3g}){where}")
    drive = f"peak |a_y| {c.ay_peak:.2f} m/s², speed {c.speed_kmh[0]:.1f}–{c.speed_kmh[1]:.1f} km/h"
    if c.envelope is None:
        out.append(f"envelope: none declared; {drive}")
    else:
        left = f"; left on {c.envelope_left} of {c.transitions} steps" if c.envelope_left else "; inside on every step"
        out.append(f"envelope {c.envelope}: {drive}; margin {_fmt(c.ay_margin, '.2f')} m/s², {_fmt(c.speed_margin_kmh, '.1f')} km/h{left}")
    from netsetest.models.envelope import MISMATCH_CAUSES

    mismatch = sum(n for cause, n in summary.node_steps_not_covered.items() if cause in MISMATCH_CAUSES)
    if mismatch:
        out.append(f"node-steps after a step whose e_k left its bound: {mismatch} (not covered by the guarantee)")
    return out + [""]


NETWORK_LINES = 12  # nodes the header lists what they rest on (a large network's others summed up)


def cut_lines(summary: RunSummary) -> list[str]:
    """The cuts behind the published intervals, as the nodes named them (NodeState.cuts), summed over the nodes: how
    many intervals (β, r, f of every reported step) each cut narrowed; the rest are the solve's or the method's own."""
    total: dict[str, int] = {}
    for n in summary.nodes:
        for name, count in n.cuts.items():
            total[name] = total.get(name, 0) + count
    intervals = 3 * sum(n.steps_reported for n in summary.nodes)
    if not total or not intervals:
        return []
    counts = ", ".join(f"{name} {count}" for name, count in sorted(total.items(), key=lambda kv: -kv[1]))
    return [f"published intervals narrowed by each cut (of {intervals}; the nodes' cuts per node in the summary): {counts}", ""]


def network_lines(summary: RunSummary) -> list[str]:
    """The output's header where nodes rest on what their network proves (docs/network.md): per node, the readings,
    the neighbours' sets and the declarations its sets may rest on beyond its own data (NodeSummary.rests_on)."""
    rows = [n for n in summary.nodes if n.rests_on]
    if not rows:
        return []
    out = ["what each node's sets may rest on beyond its own data (the collector judges each where used):"]
    out += [f"  node {n.id}: {n.rests_on}" for n in rows[:NETWORK_LINES]]
    if len(rows) > NETWORK_LINES:
        out.append(f"  … and {len(rows) - NETWORK_LINES} more nodes (the summary's nodes[*].rests_on)")
    return out + [""]


def uncovered_misses(summary: RunSummary) -> str:
    """The misses outside the guarantee in words, with their cause ('' when there are none): a user must not
    read a run whose sets missed the truth as a pass without being told why the guarantee did not hold."""
    from netsetest.models.envelope import MISMATCH_CAUSES
    from netsetest.roles.judge import INHERITED  # where the summary is printed, the judge has run or is loaded

    if not summary.misses_assumption_broken_total:
        return ""
    inherited = summary.misses_by_cause.get(INHERITED, 0)
    head = f"; {summary.misses_assumption_broken_total} set(s) missed the truth outside the guarantee"
    if inherited:
        head += f" ({inherited} of them resting on an input that missed it)"
    parts = []
    for cause, (what, advice) in MISMATCH_CAUSES.items():
        steps = summary.node_steps_not_covered.get(cause, 0)
        if steps:
            parts.append(f"{what} on {steps} node-steps: the guarantee does not hold there; {advice}")
    rest = {c: n for c, n in summary.misses_by_cause.items() if c not in MISMATCH_CAUSES and c != INHERITED}
    if rest:
        parts.append("misses where an assumption of their own step broke: " + ", ".join(f"{c} {n}" for c, n in rest.items()))
    return head + (f": {'; '.join(parts)}" if parts else "")


def format_table(summary: RunSummary, strict: bool = False) -> str:
    """The run's output: the car's header, the per-node table, and the verdict line (``strict``: ``run --strict``)."""
    mixed = len({r.estimator for r in summary.nodes}) > 1  # name each node's method where they differ
    head = [
        "node",
        *(["estimator"] if mixed else []),
        "max E",
        "viol.",
        "assump.viol",
        "miss(assump.)",
        "fault width",
        "β width",
        "r width",
        "solve ms",
        "fallbacks",
        "missing",
        "deadline",
    ]
    rows = [
        [
            str(r.id),
            *([r.estimator] if mixed else []),
            _fmt(r.max_E, ".3f"),
            str(r.violations),
            str(r.assumption_violations),
            str(r.misses_assumption_broken),
            _fmt(r.fault_bound_mean_width, ".4f"),
            _fmt(r.beta_mean_width, ".4f"),
            _fmt(r.r_mean_width, ".4f"),
            _fmt(r.solve_ms_median, ".2f"),
            str(r.fallbacks),
            "-" if r.missing_from is None else f"from {r.missing_from}",
            str(r.deadline_misses),
        ]
        for r in summary.nodes
    ]
    widths = [max(len(h), *(len(r[c]) for r in rows)) for c, h in enumerate(head)]
    line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731  # a one-line local helper
    out = [*car_lines(summary), *network_lines(summary), line(head), line(["-" * w for w in widths])] + [line(r) for r in rows]
    out.extend(textwrap.wrap(LEGEND, LEGEND_WIDTH))
    out.append("")
    out.extend(fdi_table(summary))
    out.extend(cut_lines(summary))
    out.extend(_notes(summary))
    out.append(_last_line(summary, strict))
    return "\n".join(out)


def _notes(summary: RunSummary) -> list[str]:
    """The lines under the tables: misses after a broken assumption, nodes missing or rejoined, losses, drops."""
    out = []
    if summary.misses_assumption_broken_total:
        out.append(f"{summary.misses_assumption_broken_total} miss(es) after a broken assumption (not covered by the guarantee).")
    if summary.nodes_missing:
        out.append(f"nodes missing: {summary.nodes_missing}")
    if summary.nodes_rejoined:
        out.append(f"nodes rejoined: {summary.nodes_rejoined}")
    if summary.losses_total:
        out.append(f"scheduled message losses: {summary.losses_total}")
    for role, reasons in summary.drops.items():
        out.append(f"dropped by {role}: " + ", ".join(f"{r} {n}" for r, n in reasons.items()))
    return out


def _last_line(summary: RunSummary, strict: bool) -> str:
    """The last line: the run, its security mode (Zenoh) and the verdict."""
    security = f" (security: {summary.security})" if summary.security else ""
    seed = f", seed {summary.seed}" if summary.seed is not None else ""
    world = f"log {summary.drive_log}" if summary.drive_log is not None else f"signals {summary.signals}"  # a log draws no signals
    return (
        f"{outcome(summary, strict).word}: {summary.mode or ''} run{security}, case {summary.case}, {world}, "
        f"variant {summary.variant}{seed if summary.drive_log is None else ''}, steps 0–{summary.steps_completed}: {verdict(summary)}."
    )


def fdi_table(summary: RunSummary) -> list[str]:
    """Guaranteed fault detection per node (docs/fdi.md): what a fault-diagnosis engineer reads first."""
    head = ["node", "fault from", "detected from", "delay", "detected steps", "proved healthy", "false detections"]
    rows = [
        [
            str(r.id),
            _fmt(r.fault_onset, "d"),
            _fmt(r.first_detection, "d"),
            _fmt(r.detection_delay, "d"),
            str(r.detected_steps),
            str(r.healthy_steps),
            str(r.false_detections) + (f" ({r.false_detections_covered} covered)" if r.false_detections_covered else ""),
        ]
        for r in summary.nodes
    ]
    widths = [max(len(h), *(len(r[c]) for r in rows)) for c, h in enumerate(head)]
    line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731  # a one-line local helper
    return [
        "fault detection (detected: the published fault interval excludes 0; docs/fdi.md):",
        line(head),
        line(["-" * w for w in widths]),
        *(line(r) for r in rows),
        "",
    ]


MAX_ORIGINS = 3  # origins of "inherited" named in the verdict line; the summary JSON has them all


def own_data(summary: RunSummary) -> str:
    """What a recorded drive's nodes proved alone where the reference gave no truth (roles/judge.py Judge.inconsistent)."""
    n = summary.node_steps_inconsistent
    bad = ", ".join(f"node {r.id}: {r.steps_inconsistent}" for r in summary.nodes if r.steps_inconsistent)
    return (
        f"a node's own reading contradicted its declared bounds and its own set of the step before on {n} node-step(s) ({bad}: an assumption "
        "broke there, or an earlier set missed the truth)"
        if n
        else "no node's own reading contradicted its declared bounds"
    )


def verdict(summary: RunSummary) -> str:
    """The result in words, never more than was checked: how many node-steps the guarantee covered."""
    if summary.drive_log is not None and summary.reference_accuracy is None:  # a recorded drive without a reference: nothing can be judged against a truth
        return (
            f"no reference in the log: none of {summary.node_steps_reported} node-steps judged (the truth is unknown); {own_data(summary)}; "
            f"violations {summary.violations_total}"
            + (f"; {summary.node_steps_no_reading} node-step(s) without a reading" if summary.node_steps_no_reading else "")
        )
    return _covered(summary) + _not_judged(summary) + _ended(summary) + uncovered_misses(summary)


def _covered(summary: RunSummary) -> str:
    """The verdict's head: violations, the node-steps contained of those judged, those the guarantee covered and why the
    others were not, whose sets they inherited that from."""
    evaluated, contained, covered = summary.node_steps_evaluated, summary.node_steps_contained, summary.node_steps_covered
    acc = summary.reference_accuracy
    if acc is not None:  # a recorded drive: the truth is a box, and three counts say what the reference proves
        counts = (
            f"contained on {contained}, missed on {summary.node_steps_missed}, undecided on {summary.node_steps_undecided} of {evaluated} "
            f"node-steps (a recorded drive; reference ± {acc[0]:.3g} rad, ± {acc[1]:.3g} rad/s)"
        )
    else:
        counts = f"contained on {contained} of {evaluated} node-steps"
    if summary.violations_total:
        head = f"CONTAINMENT VIOLATED {summary.violations_total} time(s) where the assumptions held; {counts}"
    else:
        head = counts
    applied = "no assumption proven broken on" if acc is not None else "the guarantee applied on"
    text = f"{head}; {applied} {covered}"
    causes = summary.node_steps_not_covered
    if causes:
        text += f" (not covered {evaluated - covered}: " + ", ".join(f"{c} {n}" for c, n in causes.items()) + ")"
    if summary.inherited_from:
        shown = [f"node {o.node} {o.why} from step {o.first_step} ({o.node_steps})" for o in summary.inherited_from[:MAX_ORIGINS]]
        more = len(summary.inherited_from) - MAX_ORIGINS
        text += "; inherited from " + ", ".join(shown) + (f" and {more} more (see the summary)" if more > 0 else "")
    return text


def _not_judged(summary: RunSummary) -> str:
    """The node-steps reported but not judged, and why: no truth, no reading, no copy that matched, an overloaded collector."""
    text = ""
    if summary.node_steps_reported > summary.node_steps_evaluated:
        why = "no reference, truth unknown or copies contested" if summary.reference_accuracy is not None else "truth unknown or copies contested"
        text += f"; {summary.node_steps_reported - summary.node_steps_evaluated} node-step(s) not judged ({why})"
    if summary.node_steps_no_reading:
        text += f"; {summary.node_steps_no_reading} node-step(s) without a reading (gaps in the log: an SDP node publishes nothing after step 0, uncovered; a set estimator its prediction and every node at step 0 its prior, judged)"
    if summary.node_steps_inconsistent:
        text += f"; at steps without a reference, {own_data(summary)}"
    if summary.node_steps_rejected:
        text += f"; {summary.node_steps_rejected} node-step(s) rejected (no copy matched the truth)"
    if summary.steps_overloaded:
        b = summary.collector_budget
        why = f"past its budget of {b} open node-steps" if b is not None and summary.collector_peak > b else "its inbox full"
        text += (
            f"; collector overloaded on {summary.steps_overloaded} step(s) ({why}): "
            f"{summary.node_steps_overloaded} node-step(s) not judged (collector overloaded), no node blamed"
        )
    return text


def _ended(summary: RunSummary) -> str:
    """The nodes lost for good, and how the run ended where it did not end with the vehicle's End."""
    text = ""
    missing = {r.id: r.missing_from for r in summary.nodes if r.id in summary.nodes_missing}
    if missing:
        text += "; lost for good: " + ", ".join(f"node {i} from step {'-' if k is None else k}" for i, k in missing.items())
    if summary.stopped == "vehicle gone":
        text += "; the vehicle's End never came (no message for the collector's idle timeout)"
    elif summary.stopped == "interrupted":
        text += f"; interrupted (Ctrl-C or SIGTERM): the counts are of steps 0–{summary.steps_completed} of the run's {summary.steps}"
    elif summary.stopped == "collector stalled":
        text += (
            f"; the collector stalled {summary.collector_stall_s:.0f} s after step {summary.collector_stall_step} (its process did not run: "
            "stopped, or the machine swapping), long enough to lose its Zenoh session (run --stall-limit) and the messages in flight "
            "to it: the run ended there, no node blamed"
        )
    return text


def record_sink(record: str | None, keep: bool = False) -> tuple[RecordSink | None, MemorySink | None]:
    """The sink a run's collector writes to: the record file (opened now), and/or memory when ``keep``."""
    from netsetest.records.record import MemorySink, TeeSink, open_sink

    memory = MemorySink() if keep else None
    file = open_sink(record) if record else None
    sinks = [s for s in (file, memory) if s is not None]
    return (TeeSink(*sinks) if len(sinks) > 1 else sinks[0] if sinks else None), memory


def write_summary(summary: RunSummary, summary_json: str | None) -> None:
    if summary_json:
        Path(summary_json).write_text(json.dumps(summary.to_dict(), indent=2) + "\n")


EXIT_OK, EXIT_VIOLATION, EXIT_BAD_INPUT, EXIT_NODE_LOST = 0, 1, 2, 3
EXIT_INTERRUPTED = 130  # Ctrl-C or SIGTERM reached the command (128 + SIGINT, as shells report it)
EXIT_COLLECTOR_STALLED = 4  # the vehicle process's, never the run's: it ended the run, the collector having acknowledged
# nothing for the stall limit (the launcher then has the collector write its summary, whose verdict names the stall)


def exit_code(summary: RunSummary, strict: bool = False) -> int:
    """The exit code that goes with the verdict's first word (:func:`outcome`)."""
    return outcome(summary, strict).code
