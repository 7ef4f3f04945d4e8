"""The run summary: the per-node table and totals the collector closes a run with.

The same object is the record's last line (``{"kind": "summary", "summary": {...}}``), the MCAP verdict
message and the ``--summary-json`` file.  In code it is a :class:`RunSummary`; at the record boundary
it is converted with :meth:`RunSummary.to_dict` / :meth:`RunSummary.from_dict`, so the file format is
unchanged.  Records written before a field existed load with its default (0, empty, or None), so old
records still load; a field of the wrong type is a ``ValueError`` (the loaders report a malformed record).

Drop and loss counters stay mappings: their keys (roles, reasons, causes) are data, not a schema.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Literal

import msgspec

from netsetest.estimator.names import SDP
from netsetest.validation import split_error

DEFAULT_ESTIMATOR = SDP  # the node estimator of records written before nodes could run others
StopCause = Literal["vehicle gone", "interrupted", "collector stalled"]
"""Why a collector wrote its summary before the vehicle's End: no message for its idle timeout, a signal, or its own
stall past its session's lease (the run's stall limit: the messages then in flight to it were lost)."""
RUN_FIELDS = ("mode", "security", "variant", "objective", "case", "signals", "steps", "seed", "clock")
"""The run's settings copied from its meta (each only if the meta has it; written in this order)."""


@dataclass(frozen=True)
class NodeSummary:
    """One node's row of the summary (``max_E`` and the means are None where nothing was measured)."""

    id: int
    estimator: str = DEFAULT_ESTIMATOR
    max_E: float | None = None
    violations: int = 0  # misses where every assumption held (of the published set or the one the node continues from)
    misses_assumption_broken: int = 0
    assumption_violations: int = 0
    sector_failures: int = 0  # derived sectors that missed C̄ x̄ inside an intact cone
    sectors_assumed: int = 0
    sector_breaks: int = 0
    first_sector_break: int | None = None
    fault_bound_mean_width: float | None = None
    beta_mean_width: float | None = None  # of the published sideslip and yaw-rate intervals (None: older summaries)
    r_mean_width: float | None = None
    solve_ms_median: float | None = None
    fallbacks: int = 0
    steps_reported: int = 0
    steps_rejected: int = 0
    steps_contested: int = 0
    steps_evaluated: int = 0
    steps_contained: int = 0
    steps_missed: int = 0  # proven apart from the truth (a model's run: every judged step not contained)
    steps_undecided: int = 0  # a reference's truth box overlapping the set without lying in it (docs/your-log.md)
    steps_no_reading: int = 0  # without a reading (a gap in a recorded drive): an SDP node's after step 0 published nothing (uncovered), the others judged
    steps_inconsistent: int = 0  # without a reference: its own data proved one of its assumptions broken
    steps_covered: int = 0
    missing_steps: int = 0
    missing_from: int | None = None
    rejoined_at: int | None = None
    neighbour_messages_missing: int = 0
    dropped_messages: int = 0
    drops: dict[str, int] = field(default_factory=dict)  # by reason
    deadline_misses: int = 0
    # guaranteed fault detection (roles/fdi.py, docs/fdi.md): steps, None where there is none
    fault_onset: int | None = None  # first step whose true fault exceeds the declared tolerance
    first_detection: int | None = None  # first step whose published fault interval excludes it
    detection_delay: int | None = None  # steps from the onset to the first detection of a real fault
    detected_steps: int = 0
    healthy_steps: int = 0  # proved fault-free
    false_detections: int = 0  # detected while the true fault was within the tolerance
    false_detections_covered: int = 0  # of them, where every assumption held (each is also a violation)
    # what the node's sets may rest on beyond its own data and its neighbours' innovations (roles/judge.py, network_rests:
    # readings and their declarations, its in-neighbours' whole sets, its own bound others rely on); "" where nothing
    rests_on: str = ""
    # per cut (docs/estimator.md, "One step"), how many of the node's published intervals (β, r and f of every step
    # it reported) it narrowed, as the node named them (NodeState.cuts)
    cuts: dict[str, int] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class InheritedOrigin:
    """Where the node-steps counted as ``inherited`` come from: an input (node, from step ``first_step``)
    that did not hold the truth or could not be judged (``why``), and how many node-steps rested on it."""

    node: int
    why: str  # missed the truth | truth unknown | not judged | not from its true input | noise | sector
    first_step: int
    node_steps: int

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class CarSummary:
    """What the car did in a run whose truth is a nonlinear plant (docs/plant.md): the plant and manoeuvre,
    the model mismatch e_k against its declared bound, and the drive against its declared envelope.
    ``transitions``: the steps k → k+1 measured; margins are negative where the drive left the envelope."""

    plant: str  # e.g. single-track/3
    car: str  # the CommonRoad parameter set's car
    manoeuvre: str  # the manoeuvre with its amplitude and speed reference
    bound: str | None = None  # the declared [model_uncertainty] in words (None: e_k = 0 assumed)
    transitions: int = 0
    e_max: list[float] = field(default_factory=lambda: [0.0, 0.0])  # largest |e_β|, |e_r|
    e_max_ratio: float | None = None  # largest e_k in the bound's own norm (≤ 1: inside; None: no bound)
    e_outside: int = 0  # transitions whose e_k left the bound
    e_outside_first: int | None = None  # the first of them (k of k → k+1)
    envelope: str | None = None  # the declared [envelope] in words (None: not declared)
    ay_peak: float = 0.0  # largest |a_y| the tyres carried [m/s²] (Plant.transition_ay)
    speed_kmh: list[float] = field(default_factory=lambda: [0.0, 0.0])  # the car's slowest and fastest speed
    ay_margin: float | None = None  # ay_max − the largest |a_y| [m/s²] (None: no envelope)
    speed_margin_kmh: float | None = None  # the smallest distance of the speed to the envelope's range's ends
    envelope_left: int = 0  # transitions outside the envelope

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RunSummary:
    """The verdict of a run: totals over node-steps, per-role drop counters and one row per node.

    The run's settings (``mode`` … ``clock``) are None where the meta did not have them (e.g.
    ``security`` outside Zenoh); they are then left out of the dict.
    """

    violations_total: int = 0
    misses_assumption_broken_total: int = 0
    sector_failures_total: int = 0
    steps_completed: int = -1  # the last closed step
    node_steps_reported: int = 0
    node_steps_rejected: int = 0  # no copy matched the truth
    node_steps_contested: int = 0  # more than one matching copy: not judged
    node_steps_evaluated: int = 0
    node_steps_contained: int = 0
    node_steps_missed: int = 0  # the published set proven apart from the truth
    node_steps_undecided: int = 0  # neither: a recorded drive's reference cannot tell (docs/your-log.md)
    node_steps_no_reading: int = 0  # a log's gap: no reading (an SDP node after step 0 published nothing; other sets judged)
    node_steps_inconsistent: int = 0  # without a reference: a node's own data proved one of its assumptions broken (never "contained")
    reference_accuracy: list[float] | None = None  # a recorded drive's reference: its declared half-widths (β rad, r rad/s); None: none, or a model's run
    drive_log: str | None = None  # the recorded drive that was the world (docs/your-log.md); None: a model's run
    node_steps_covered: int = 0  # evaluated with every assumption held
    node_steps_not_covered: dict[str, int] = field(default_factory=dict)  # evaluated outside the guarantee, by cause
    inherited_from: list[InheritedOrigin] = field(default_factory=list)  # the origins of cause "inherited"
    misses_by_cause: dict[str, int] = field(default_factory=dict)  # misses outside the guarantee, by their node-step's cause
    car: CarSummary | None = None  # a nonlinear plant's run: what the car did (None: the T-S plant, older records)
    nodes_missing: list[int] = field(default_factory=list)  # silent at the last step
    nodes_rejoined: list[int] = field(default_factory=list)
    losses: dict[str, int] = field(default_factory=dict)  # scheduled message losses, by kind
    losses_total: int = 0
    dropped_messages: dict[str, int] = field(default_factory=dict)  # by the collector, by reason
    drops: dict[str, dict[str, int]] = field(default_factory=dict)  # role → reason → count
    nodes: list[NodeSummary] = field(default_factory=list)
    stopped: StopCause | None = None  # the collector stopped before the vehicle's End (None: the run ended)
    # the collector keeping up (real time: roles/collector.py; lockstep holds the vehicle instead)
    steps_overloaded: int = 0  # steps closed unjudged, past the collector's memory budget
    node_steps_overloaded: int = 0  # node-steps not judged for the collector's trouble: of those steps, and those its full inbox dropped
    collector_budget: int | None = None  # open node-steps the collector may hold (real time; None: lockstep, the vehicle waits)
    collector_peak: int = 0  # the most node-steps it held open
    collector_stall_s: float = 0.0  # the collector's longest stall [s] (its process did not run: stopped, swapping), ≥ 1 s
    collector_stall_step: int | None = None  # the step it had checked before that stall
    mode: str | None = None
    security: str | None = None
    variant: str | None = None
    objective: str | None = None
    case: str | None = None
    signals: str | None = None
    steps: int | None = None
    seed: int | None = None
    clock: str | None = None

    @property
    def fallbacks(self) -> int:
        return sum(n.fallbacks for n in self.nodes)

    def node(self, node_id: int) -> NodeSummary:
        """The row of node ``node_id`` (KeyError if the run has no such node)."""
        for n in self.nodes:
            if n.id == node_id:
                return n
        raise KeyError(node_id)

    def to_dict(self) -> dict:
        """The record's and ``--summary-json``'s object (key order as the collector has always written it)."""
        out: dict = {k: getattr(self, k) for k in RUN_FIELDS if getattr(self, k) is not None}
        for f in fields(self):
            if f.name not in RUN_FIELDS:
                v = getattr(self, f.name)
                if f.name == "car":
                    if v is not None:  # a T-S run's summary is as before
                        out[f.name] = v.to_dict()
                    continue
                out[f.name] = [n.to_dict() for n in v] if f.name in ("nodes", "inherited_from") else v
        return out

    @classmethod
    def from_dict(cls, d: object) -> RunSummary:
        """The typed summary of a record's or ``--summary-json``'s object: fields it lacks take their
        defaults; a value of the wrong type (a bool for an int included) is a ValueError naming it."""
        try:
            return msgspec.convert(d, cls)
        except msgspec.ValidationError as exc:
            what, where = split_error(exc)
            raise ValueError(f"summary{'.' + where if where else ''}: {what}") from None
