"""What each closed step adds to the run: its record rows, the running totals per node and for the run, and at
the end the summary (records/summary.py RunSummary) they make.  Nothing per step survives a closed step here
but a node's solve time (the median needs them).

The counts follow the verdict's rule (docs/coverage.md, docs/summary.md): a node-step judged is contained,
missed or undecided; it is covered when its dependency cone is intact (a miss there is a ``violation``, an
estimator failure; a miss after a broken assumption is ``misses_assumption_broken``, by its cause); a node-step
not judged is rejected (it reported, nothing it sent can be its own), without a reading, the collector's own
loss (its overload: never a node's silence), or missing (only then is the node blamed).
"""

from __future__ import annotations

import statistics
from array import array
from collections import Counter
from dataclasses import dataclass, field

import msgspec
import numpy as np

from netsetest.config.schema import NodeConfig, Scenario
from netsetest.messages import NodeState, Truth
from netsetest.models.manoeuvres import SINE_SPEED, WITH_AMPLITUDE
from netsetest.models.plant import VEHICLE_NAMES
from netsetest.models.vehicle import KMH
from netsetest.records.meta import RunMeta
from netsetest.records.summary import RUN_FIELDS, CarSummary, InheritedOrigin, NodeSummary, RunSummary, StopCause
from netsetest.roles.fdi import FdiStatus, FdiTotals
from netsetest.roles.judge import INHERITED, NO_REFERENCE, TRUTH_UNKNOWN, Containment, NodeVerdict, network_rests

# ---------------------------------------------------------------- the record's rows


def published_bounds(st: NodeState, c: Containment | None) -> list[list[float]]:
    """The published set's per-coordinate bounds [[lo, hi] ×3] (ProvenSet.bounds: a set estimator's own, else the
    ellipsoid ∩ its fault range ∩ its region; the judge's where it computed them)."""
    if c is not None and c.bounds is not None:
        return c.bounds.tolist()
    lo, hi = st.published.bounds()
    return np.stack([lo, hi], axis=1).tolist()


def state_row(st: NodeState, v: NodeVerdict, contested: bool, bounds: list[list[float]], no_reference: bool = False) -> dict:
    """The record's line of a judged node-step."""
    c = v.containment
    unjudged = None if c is not None else ("contested" if contested else NO_REFERENCE if no_reference else TRUTH_UNKNOWN)  # neither contained nor a miss
    origin = v.cone.origin
    return {
        "step": v.step,
        "published": msgspec.to_builtins(st.published),  # the set as sent (netsetest/proven.py; defaults left out)
        **({"continues": msgspec.to_builtins(st.continues)} if st.continues is not None else {}),  # where not the published one
        "status": st.status,
        **({"resumed_from": st.resumed_from} if st.resumed_from is not None else {}),  # carried through steps without a reading
        "rho_cert": st.rho_cert,
        "solve_ms": st.solve_ms,
        "used": st.used,
        "missing": st.missing,
        "readings": [j for j, _, _ in st.readings],
        "health": st.health,
        "sets": st.sets,
        "late": st.late,
        "E": c.E if c is not None else None,
        "judged": c is not None,
        "not_judged_why": unjudged,
        "contained": None if c is None else bool(c.contained),
        "missed": None if c is None else bool(c.missed),  # proven apart from the truth (a point truth: not contained)
        "continues_contained": None if c is None else bool(c.continues_contained),  # the set the node continues from
        "assumptions_ok": v.cone.ok,
        **({"inconsistent": True} if v.inconsistent else {}),  # without a reference: its own data prove an assumption broken
        "not_covered_cause": v.cone.cause,
        "inherited_from": [origin.node, origin.step, origin.why] if origin is not None else None,
        "contested": contested,
        "sector": list(st.sector) if st.sector is not None else None,
        "sector_basis": st.sector_basis,
        "bounds": bounds,
        "cuts": st.cuts or [[], [], []],  # per coordinate β, r, f: the cuts that narrowed the published interval
    }


def truth_row(t: Truth) -> dict:
    """The record's line of a step's judged truth (the vehicle's drop counters go to the summary)."""
    d = t.model_dump(mode="json")
    for f in ("v", "type", "drops"):
        d.pop(f, None)
    return d


# ---------------------------------------------------------------- running totals


@dataclass
class NodeTotals:
    """Running per-node figures of the summary (nothing per step survives a closed step but ``solve``)."""

    E_max: float | None = None
    violations: int = 0
    broken_misses: int = 0
    assumption_violations: int = 0
    sector_breaks: int = 0
    sector_failures: int = 0  # derived sectors that missed C̄ x̄ inside an intact cone
    sectors_assumed: int = 0
    first_sector_break: int | None = None
    width_sum: float = 0.0  # of the published fault interval
    beta_width_sum: float = 0.0  # and of β, r
    r_width_sum: float = 0.0
    reported: int = 0
    rejected: int = 0  # states that did not match the truth (forged, or from a forged input)
    contested: int = 0  # node-steps with more than one matching copy: judged on none
    evaluated: int = 0
    contained: int = 0
    missed: int = 0  # proven: the published set and the truth (a reference's box) are disjoint
    undecided: int = 0  # a reference's box overlaps the published set without lying in it (docs/your-log.md)
    covered: int = 0
    missing_steps: int = 0
    no_reading: int = 0  # node-steps without a reading (a gap in a recorded drive): an SDP node's after step 0 published nothing, the others are judged
    inconsistent: int = 0  # without a reference: its own data proved one of its assumptions broken (roles/judge.py Judge.inconsistent)
    missing_from: int | None = None
    rejoined_at: int | None = None  # first step heard from again after ``missing_from``
    last_heard: int | None = None  # newest step with a state from this node (judged or not)
    fallbacks: int = 0
    late: int = 0
    neighbour_missing: int = 0
    dropped: int = 0
    fdi: FdiTotals = field(default_factory=FdiTotals)  # guaranteed fault detection (roles/fdi.py)
    drops: dict[str, int] = field(default_factory=dict)
    cuts: dict[str, int] = field(default_factory=dict)  # per cut, the published intervals (β, r, f per step) it narrowed
    solve: array = field(default_factory=lambda: array("d"))  # 8 bytes per step: the median needs them

    def summary(self, n: NodeConfig, deadline_misses: int, rests_on: str = "") -> NodeSummary:
        mean = lambda total: total / self.reported if self.reported else None  # noqa: E731  # a one-line local helper
        return NodeSummary(
            id=n.id,
            estimator=n.estimator,
            max_E=self.E_max,
            violations=self.violations,
            misses_assumption_broken=self.broken_misses,
            assumption_violations=self.assumption_violations,
            sector_failures=self.sector_failures,
            sectors_assumed=self.sectors_assumed,
            sector_breaks=self.sector_breaks,
            first_sector_break=self.first_sector_break,
            fault_bound_mean_width=mean(self.width_sum),
            beta_mean_width=mean(self.beta_width_sum),
            r_mean_width=mean(self.r_width_sum),
            solve_ms_median=statistics.median(self.solve) if self.solve else None,
            fallbacks=self.fallbacks,
            steps_reported=self.reported,
            steps_rejected=self.rejected,
            steps_contested=self.contested,
            steps_evaluated=self.evaluated,
            steps_contained=self.contained,
            steps_missed=self.missed,
            steps_undecided=self.undecided,
            steps_no_reading=self.no_reading,
            steps_inconsistent=self.inconsistent,
            steps_covered=self.covered,
            missing_steps=self.missing_steps,
            missing_from=self.missing_from,
            rejoined_at=self.rejoined_at,
            neighbour_messages_missing=self.neighbour_missing,
            dropped_messages=self.dropped,
            drops=self.drops,
            deadline_misses=deadline_misses,
            fault_onset=self.fdi.fault_onset,
            first_detection=self.fdi.first_detection,
            detection_delay=self.fdi.detection_delay,
            detected_steps=self.fdi.detected_steps,
            healthy_steps=self.fdi.healthy_steps,
            false_detections=self.fdi.false_detections,
            false_detections_covered=self.fdi.false_detections_covered,
            rests_on=rests_on,
            cuts=dict(sorted(self.cuts.items())),
        )


@dataclass
class CarTotals:
    """Running figures of a nonlinear plant's transitions k → k+1 (the summary's CarSummary)."""

    transitions: int = 0
    e_max: np.ndarray = field(default_factory=lambda: np.zeros(2))
    ratio_max: float = 0.0
    e_outside: int = 0
    e_outside_first: int | None = None
    ay_peak: float = 0.0
    speed_lo: float = np.inf
    speed_hi: float = -np.inf
    ay_margin: float = np.inf
    speed_margin: float = np.inf
    envelope_left: int = 0

    def add(self, sc: Scenario, t: Truth) -> None:
        if t.speed is not None:
            self.speed_lo, self.speed_hi = min(self.speed_lo, t.speed / KMH), max(self.speed_hi, t.speed / KMH)
            if sc.envelope is not None:
                self.speed_margin = min(self.speed_margin, sc.envelope.speed_margin(t.speed))
        if t.e is None or t.ay is None:
            return  # the last step: no transition
        self.transitions += 1
        self.e_max = np.maximum(self.e_max, np.abs(t.e))
        if sc.uncertainty is not None:
            self.ratio_max = max(self.ratio_max, sc.uncertainty.ratio(np.asarray(t.e)))
        if not t.mismatch_ok:
            self.e_outside += 1
            self.e_outside_first = t.step if self.e_outside_first is None else self.e_outside_first
        self.ay_peak = max(self.ay_peak, abs(t.ay))
        if sc.envelope is not None:
            self.ay_margin = min(self.ay_margin, sc.envelope.ay_margin(t.ay))
        self.envelope_left += not t.envelope_ok

    def summary(self, sc: Scenario) -> CarSummary:
        unc, env = sc.uncertainty, sc.envelope
        bound = None
        if unc is not None:
            bound = f"box [{', '.join(f'{b:.3g}' for b in np.diag(unc.G))}]" if unc.kind == "box" else "ellipsoid E = " + str(np.round(unc.E, 8).tolist())
        seen = self.transitions > 0
        return CarSummary(
            plant=sc.plant_label,
            car=f"CommonRoad vehicle {sc.vehicle_id}, {VEHICLE_NAMES[sc.vehicle_id]}",
            manoeuvre=manoeuvre_text(sc),
            bound=bound,
            transitions=self.transitions,
            e_max=self.e_max.tolist(),
            e_max_ratio=self.ratio_max if unc is not None and seen else None,
            e_outside=self.e_outside,
            e_outside_first=self.e_outside_first,
            envelope=env.text if env is not None else None,
            ay_peak=self.ay_peak,
            speed_kmh=[self.speed_lo, self.speed_hi] if np.isfinite(self.speed_lo) else [0.0, 0.0],
            ay_margin=self.ay_margin if env is not None and seen else None,
            speed_margin_kmh=self.speed_margin if env is not None and seen else None,
            envelope_left=self.envelope_left,
        )


@dataclass(frozen=True)
class CollectorFigures:
    """The collector's own figures of the summary: why it stopped before the End (None: the run ended), its memory
    budget (None: lockstep has none) and peak in open node-steps, its longest stall [s] and the step before it."""

    stopped: StopCause | None
    budget: int | None
    peak: int
    stall_s: float
    stall_step: int | None


def manoeuvre_text(sc: Scenario) -> str:
    """The manoeuvre as it was driven: its name, amplitude where it has one, and its speed reference."""
    amp = f"@{sc.steer_high:g} rad" if sc.manoeuvre in WITH_AMPLITUDE and sc.manoeuvre != "paper" else ""
    sp = sc.speed
    speed = f"{sp.mean_kmh:g} ± {sp.amplitude_kmh:g} km/h" if sc.manoeuvre in SINE_SPEED and sp.amplitude_kmh else f"{sp.mean_kmh:g} km/h"
    return f"{sc.manoeuvre}{amp} at {speed}"


TOTALS_OF_ROWS = {  # the summary's totals of its node rows: field → NodeSummary field
    "violations_total": "violations",
    "misses_assumption_broken_total": "misses_assumption_broken",
    "sector_failures_total": "sector_failures",
}
NODE_STEP_COUNTS = {  # the summary's node-step counts: field → NodeTotals field summed over the nodes
    "node_steps_reported": "reported",
    "node_steps_rejected": "rejected",
    "node_steps_contested": "contested",
    "node_steps_evaluated": "evaluated",
    "node_steps_contained": "contained",
    "node_steps_missed": "missed",
    "node_steps_undecided": "undecided",
    "node_steps_no_reading": "no_reading",
    "node_steps_inconsistent": "inconsistent",
    "node_steps_covered": "covered",
}


class RunTotals:
    """The run's running totals: per node (:class:`NodeTotals`), the node-steps outside the guarantee by cause and
    where they inherited it from, the car's transitions, the scheduled losses, and the collector's own overload."""

    def __init__(self, scenario: Scenario) -> None:
        self.sc = scenario
        self.nodes = {i: NodeTotals() for i in scenario.ids}
        self.not_covered: Counter[str] = Counter()  # evaluated node-steps outside the guarantee, by cause
        self.misses_by_cause: Counter[str] = Counter()  # misses outside the guarantee, by their node-step's cause
        self.origins: dict[tuple[int, str], list[int]] = {}  # (node, why) → [first step, node-steps] of "inherited"
        self.car = CarTotals() if scenario.plant != "ts" and scenario.log is None else None  # a plant's drive (a log's car is its own)
        self.losses: Counter[str] = Counter()
        self.vehicle_drops: dict[str, int] = {}
        self.overloaded_steps = 0  # steps of which we lost something ourselves: past the budget, or our full inbox
        self.overloaded_node_steps = 0  # node-steps not judged for that reason (each in no other count)

    def closed(self, i: int, k: int, tr: Truth | None, cone_ok: bool, heard: bool) -> None:
        """Node i's step k closed, judged or not: the truth's fault and sector, the cone, whether it was heard."""
        t = self.nodes[i]
        if tr is not None:
            t.fdi.truth(k, tr.faults[i], self.sc.fault_tolerance)
            if not tr.sector_ok[i]:
                t.sector_breaks += 1
                if t.first_sector_break is None:
                    t.first_sector_break = k
        if not cone_ok:
            t.assumption_violations += 1
        if heard:
            t.last_heard = k
            if t.missing_from is not None and t.rejoined_at is None:
                t.rejoined_at = k

    def judged(self, i: int, k: int, st: NodeState, v: NodeVerdict, bounds: list[list[float]], contested: bool, sector_failed: bool) -> None:
        """Node i's state of step k, judged (``contested``: one of several that can be its own, on no verdict)."""
        t = self.nodes[i]
        t.contested += contested
        t.sectors_assumed += st.sector_basis == "assumed"
        t.sector_failures += sector_failed
        t.reported += 1
        t.no_reading += st.innov is None  # a prediction-only set, or a prior (Scenario.silent_without_reading): judged like any
        t.inconsistent += v.inconsistent
        cone, c = v.cone, v.containment
        if c is not None:
            t.evaluated += 1
            t.E_max = c.E if t.E_max is None else max(t.E_max, c.E)
            t.contained += c.contained
            t.missed += c.missed
            t.undecided += not c.contained and not c.missed
            if cone.ok:
                t.covered += 1
            else:
                self.not_covered[cone.cause or INHERITED] += 1
                if cone.origin is not None:
                    o = self.origins.setdefault((cone.origin.node, cone.origin.why), [cone.origin.step, 0])
                    o[1] += 1
            if cone.ok and c.certain_miss:
                t.violations += 1  # the published set, or the one the node continues from, missed on a covered node-step
            elif c.missed:
                t.broken_misses += 1
                self.misses_by_cause[cone.cause or INHERITED] += 1
        if st.status in ("ok", "fallback") and k > 0:
            t.solve.append(st.solve_ms)
        t.fallbacks += st.status == "fallback"
        t.late += st.late
        t.neighbour_missing += len(st.missing)
        t.dropped = max(t.dropped, st.dropped)
        t.drops = dict(st.drops)
        t.width_sum += bounds[2][1] - bounds[2][0]
        t.beta_width_sum += bounds[0][1] - bounds[0][0]
        t.r_width_sum += bounds[1][1] - bounds[1][0]
        for names in st.cuts:
            for name in names:
                t.cuts[name] = t.cuts.get(name, 0) + 1

    def fdi(self, i: int, k: int, status: FdiStatus, tr: Truth, covered: bool) -> None:
        """Node i's judged step k's detection status (judged rows only: a contested copy may be forged)."""
        self.nodes[i].fdi.add(k, status, tr.faults[i], self.sc.fault_tolerance, covered)

    def unjudged(self, i: int, k: int, reported: bool, lost: bool, no_reading: bool) -> None:
        """Node i's step k with no state to judge: rejected if it reported, the collector's loss if our inbox
        dropped it, no reading (a gap in a recorded drive: nothing was due), else missing (only then is the
        node blamed)."""
        t = self.nodes[i]
        if reported:
            t.rejected += 1  # it reported, but nothing it sent can be its own
        elif no_reading:
            t.no_reading += 1
            t.last_heard = k  # nothing was due: silent, not lost
        elif lost:
            t.last_heard = k  # it published; our inbox dropped it: not judged, never missing
            self.overloaded_node_steps += 1
        else:
            t.missing_steps += 1
            if t.missing_from is None:
                t.missing_from = k

    def truth(self, tr: Truth) -> None:
        """A closed step's judged truth: the car's transition, the scheduled losses, the vehicle's drop counters."""
        if self.car is not None:
            self.car.add(self.sc, tr)
        for j, i in tr.lost:
            self.losses[f"{j}->{i}"] += 1
        self.vehicle_drops = dict(tr.drops)

    def overloaded(self, k: int, heard: set[int]) -> None:
        """Step k closed unjudged for our own loss: every node-step of it counted as the collector's overload and
        nowhere else (a node heard at k, ``heard``, is heard, never reported missing or rejoined for it)."""
        for i in heard:
            self.nodes[i].last_heard = k
        self.overloaded_node_steps += len(self.sc.ids)
        self.overloaded_steps += 1

    def summary(
        self,
        meta: RunMeta,
        last: int,
        own_drops: Counter[str],
        drops: dict[str, dict[str, int]],
        deadline_misses: dict[int, int],
        collector: CollectorFigures,
    ) -> RunSummary:
        """The run's summary, its last closed step ``last``: ``own_drops`` the collector's drop counters, ``drops``
        other roles' (the runtime's), ``deadline_misses`` per node (a node not named: its late steps)."""
        rows = [self.nodes[n.id].summary(n, deadline_misses.get(n.id, self.nodes[n.id].late), network_rests(self.sc, n.id)) for n in self.sc.nodes]
        log = self.sc.log
        return RunSummary(
            **{k: getattr(meta, k) for k in RUN_FIELDS},
            **{total: sum(getattr(r, name) for r in rows) for total, name in TOTALS_OF_ROWS.items()},
            steps_completed=last,
            **{total: sum(getattr(t, name) for t in self.nodes.values()) for total, name in NODE_STEP_COUNTS.items()},
            reference_accuracy=None if log is None or log.mapping.r is None else list(log.mapping.accuracy),
            drive_log=None if log is None else log.path,
            node_steps_not_covered=dict(sorted(self.not_covered.items())),
            inherited_from=[InheritedOrigin(j, why, first, count) for (j, why), (first, count) in sorted(self.origins.items())],
            misses_by_cause=dict(sorted(self.misses_by_cause.items())),
            car=self.car.summary(self.sc) if self.car is not None else None,
            nodes_missing=self._missing(last),
            nodes_rejoined=[i for i, t in self.nodes.items() if t.missing_from is not None and t.last_heard == last],  # a gap, then heard up to the last step
            losses=dict(sorted(self.losses.items())),
            losses_total=sum(self.losses.values()),
            dropped_messages=dict(own_drops),  # by the collector; per node in nodes[*]
            drops=self._drops(rows, own_drops, drops),
            nodes=rows,
            stopped=collector.stopped,
            steps_overloaded=self.overloaded_steps,
            node_steps_overloaded=self.overloaded_node_steps,
            collector_budget=collector.budget,
            collector_peak=collector.peak,
            collector_stall_s=collector.stall_s,
            collector_stall_step=collector.stall_step,
        )

    def _missing(self, last: int) -> list[int]:
        """The nodes lost for good: silent at the last step (no step closed: no one)."""
        heard = {i: -1 if t.last_heard is None else t.last_heard for i, t in self.nodes.items()}
        return [i for i, k in heard.items() if last >= 0 and k < last]

    def _drops(self, rows: list[NodeSummary], own: Counter[str], more: dict[str, dict[str, int]]) -> dict[str, dict[str, int]]:
        """Every role's drop counters (the collector's, the vehicle's, each node's, the runtime's), roles without any left out."""
        by_role = {"collector": dict(sorted(own.items())), "vehicle": dict(sorted(self.vehicle_drops.items()))}
        by_role.update({f"node {r.id}": dict(sorted(r.drops.items())) for r in rows})
        by_role.update(more)
        return {role: d for role, d in by_role.items() if d}
