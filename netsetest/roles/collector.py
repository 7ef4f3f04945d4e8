"""The collector role: admits the run's messages, has every closed step judged (roles/judge.py) and
writes the record and the summary.

For node i at step k it computes E_i,k = e_i,kᵀ P_i,k⁻¹ e_i,k with e = x̄_i,k − x̂_i,k and declares
containment when its published set (netsetest/proven.py: E_i,k ≤ ρ_i, its region, its fault range) holds the
truth; where the node continues from another set (``NodeState.continues``), that set must hold it too.  A miss is attributed by the step's *dependency cone*, one step deep over
judged inputs (docs/coverage.md): the estimate of (i, k) relies on its own sector condition and noise
bound at k, the disturbance bound at k−1, and on the exact copies of the states it used (its own
previous set and its neighbours' of k−1, named by digest in ``NodeState.inputs``), each judged directly
against the truth of k−1; step 0 relies on the initial ellipsoid containing x̄_0 (Assumption 1).  A miss
inside an intact cone is an estimator failure (``violations``); a miss after a broken assumption is
reported separately (``misses_assumption_broken``).  A saturating node's sector
premise is what its published sector rests on (``sector_basis``): the noise bound only, the declared
fault bound, or — for an assumed sector — the sector itself checked against the truth's C̄ x̄.  A derived
sector that misses the truth inside an intact cone is counted as a ``sector_failure`` (an estimator bug).

Streaming and bounded: the collector keeps the truth and the states of the steps not yet *closed*.
Step k is closed (judged, written to the record sink, forgotten) in order, once its truth is here and
every node reported, or the alive ones did and the truth is ``CLOSE_LAG`` steps further, or the truth
is ``WINDOW`` steps further whatever arrived; :meth:`finish` closes the rest.  Only running totals per
node remain for the summary.

Keeping up.  In lockstep the collector acknowledges the truths it has taken in (a Ready with ``acked``
every ``ACK_STRIDE`` steps) and the vehicle stays within ``ACK_WINDOW`` steps of it (roles/flow.py), so
the run's own messages never exceed the bus's bounded inbox, however slow the collector is.  In real time
the clock cannot wait: the collector takes every message off the bus first and closes steps when nothing
is waiting (:meth:`close_ready`), keeping the open steps up to ``budget`` node-steps
(``OPEN_NODE_STEPS_BUDGET``); past it the oldest steps close unjudged, counted as the collector's
overload (``steps_overloaded``, ``node_steps_overloaded``; the verdict says *collector overloaded*).  A
message its full inbox dropped all the same (the bus tells it: ``Bus.overflow_listeners``) counts there
too; so does a truth or state more than ``WINDOW`` steps past the newest truth once its inbox has turned
messages away (a collector stopped longer than its inbox holds: :meth:`_catch_up` closes the steps it
lost and judges on).  Neither is ever a node's silence: a node that published is never reported missing or rejoined.

Defences (the network may be open, or a credentialed peer may lie), each counted by reason:

- a message outside the run (:class:`RunScope`), for a step already closed, or further than ``WINDOW``
  steps ahead of the newest truth is dropped (nothing is allocated per a step number it names);
- a repeated copy is a duplicate and dropped; the first copy is the one recorded — a *different* copy
  for the same (node, step) or step is kept (up to a few) so that the step can be judged honestly;
- a truth must follow from the previous one through the vehicle model (x_k = f(x_{k−1}, u_{k−1},
  w_{k−1}, Vx_{k−1}), x_0 of the scenario) with the scenario's faults, speed, sensor inputs C̄ x̄
  (``r``) and assumption flags (``fault_ok`` included);
- a node's state must match the truth of its step where an honest node's must: its γ and its
  innovation y̌ = ỹ − C̄ x̂ with the true measurement ỹ; a step-0 ``init-prior`` state the profile's
  prior ellipsoid (an ``init`` state, the prior updated by ỹ₀, is checked by γ and innovation only);
- when more than one copy passes, the collector cannot tell which one the sender sent: the step (a
  truth) or node-step (a state) is *contested* and judged on none (``contested`` in the record);
- End counts only when it names the scheduled last step and that step's truth is here.

A miss the verdict counts therefore comes from a state the node itself computed from its true input.
"""

from __future__ import annotations

import statistics
from array import array
from collections import Counter, deque
from dataclasses import dataclass, field

import msgspec
import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import NodeConfig, Scenario
from netsetest.messages import End, Message, NodeState, Ready, RunScope, Truth
from netsetest.models.sensor import augmented
from netsetest.records.meta import RunMeta
from netsetest.records.record import RecordSink
from netsetest.models.manoeuvres import SINE_SPEED, WITH_AMPLITUDE
from netsetest.models.plant import VEHICLE_NAMES
from netsetest.models.vehicle import KMH
from netsetest.records.summary import RUN_FIELDS, CarSummary, InheritedOrigin, NodeSummary, RunSummary, StopCause
from netsetest.roles.fdi import FdiTotals, classify
from netsetest.roles.judge import INHERITED, NO_CHECKS, NO_REFERENCE, TRUTH_UNKNOWN, Containment, Judge, NodeVerdict, StepInputs, isclose, state_mismatch
from netsetest.roles.flow import ACK_STRIDE
from netsetest.roles.vehicle import envelope_holds, fault_bound_holds, mismatch_holds

WINDOW = 50  # steps a step may stay open behind the newest truth (bounds memory against a stalled node)
CLOSE_LAG = 2  # a step whose alive nodes reported closes this many truths later (late and rejoining states)
MAX_COPIES = 4  # differing copies of one step's truth, or one node-step's state, kept until the step closes
CHAIN_RTOL = 1e-12  # x_k recomputed from x_{k−1}: same code, same inputs — rounding only across machines
# Real time: the node-steps (states held, one truth per step counted as one more) the collector keeps open
# before it closes the oldest step unjudged.  A decoded paper6 message takes about 2.4 KB (x̂, P, its region
# and bookkeeping; measured with tracemalloc), so the default holds about 50 MB: paper6 (six nodes, τs =
# 0.1 s) 280 s behind the clock.
OPEN_NODE_STEPS_BUDGET = 20_000
LOST_NOTES = 4096  # messages the bus's full inbox dropped, noted until the next step closes (a flood beyond: forgotten)


def _same_set(a: NodeState, b: NodeState) -> bool:
    """Copies that publish the same sets are one for judging (bookkeeping fields may differ)."""
    return a.published == b.published and a.continues == b.continues and a.innov == b.innov and a.gamma == b.gamma


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
    no_reading: int = 0  # node-steps without a reading (a gap in a recorded drive): nothing published, nothing covered
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
    solve: array = field(default_factory=lambda: array("d"))  # 8 bytes per step: the median needs them


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


def manoeuvre_text(sc: Scenario) -> str:
    """The manoeuvre as it was driven: its name, amplitude where it has one, and its speed reference."""
    amp = f"@{sc.steer_high:g} rad" if sc.manoeuvre in WITH_AMPLITUDE and sc.manoeuvre != "paper" else ""
    sp = sc.speed
    speed = f"{sp.mean_kmh:g} ± {sp.amplitude_kmh:g} km/h" if sc.manoeuvre in SINE_SPEED and sp.amplitude_kmh else f"{sp.mean_kmh:g} km/h"
    return f"{sc.manoeuvre}{amp} at {speed}"


def _bounds(st: NodeState, c: Containment | None) -> list[list[float]]:
    """The published set's per-coordinate bounds [[lo, hi] ×3] (ProvenSet.bounds: a set estimator's own, else the
    ellipsoid ∩ its fault range ∩ its region; the judge's where it computed them)."""
    if c is not None and c.bounds is not None:
        return c.bounds.tolist()
    lo, hi = st.published.bounds()
    return np.stack([lo, hi], axis=1).tolist()


def _state_entry(st: NodeState, v: NodeVerdict, contested: bool, bounds: list[list[float]], no_reference: bool = False) -> dict:
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
    }


class Collector:
    def __init__(
        self, scenario: Scenario, bus: Bus, run_id: str, sink: RecordSink | None = None, realtime: bool = False, budget: int = OPEN_NODE_STEPS_BUDGET
    ) -> None:
        """``realtime``: close steps only in :meth:`close_ready` (the caller's loop, when the bus is drained)
        and within ``budget`` open node-steps; lockstep: as messages arrive, and acknowledge the truths."""
        self.sc, self.bus, self.run = scenario, bus, run_id
        self.realtime, self.budget = realtime, budget
        self.open_node_steps = 0  # states held plus one per open step's truth copies: what the budget bounds
        self.peak_open_node_steps = 0
        self.overloaded_steps = 0  # steps of which we lost something ourselves: past the budget, or our full inbox
        self.overloaded_node_steps = 0  # node-steps not judged for that reason (each in no other count)
        self.acked = -1  # the newest truth acknowledged to the vehicle (lockstep)
        # what the bus's full inbox dropped before we saw it: (step, node; None for a truth), noted on the
        # transport's thread (a deque's append is atomic), taken into ``lost`` (step → nodes) on ours
        self._lost_notes: deque[tuple[int, int | None]] = deque(maxlen=LOST_NOTES)
        self.lost: dict[int, set[int | None]] = {}
        bus.overflow_listeners[self.on_message] = self._overflowed
        self.node_cfg = {n.id: n for n in scenario.nodes}  # looked up per state
        self.sink = sink
        self.scope = RunScope(frozenset(scenario.ids), scenario.steps)
        self.truth: dict[int, list[Truth]] = {}  # open steps: the copies received, first first
        self.states: dict[int, dict[int, list[NodeState]]] = {}  # open steps: node → copies, first first
        self.closed = -1  # last closed step
        self.head = -1  # newest step with a truth copy
        self.prev_truth: Truth | None = None  # the judged truth of the last closed step
        self.prev_overloaded = False  # the last closed step was closed unjudged for our own loss (no truth read)
        self.judge = Judge(scenario)
        self.prev_checks = NO_CHECKS  # the last closed step's copies, judged as inputs of the next
        self.origins: dict[tuple[int, str], list[int]] = {}  # (node, why) → [first step, node-steps] of "inherited"
        self.totals = {i: NodeTotals() for i in scenario.ids}
        self.losses: Counter[str] = Counter()
        self.vehicle_drops: dict[str, int] = {}
        self.not_covered: Counter[str] = Counter()  # evaluated node-steps outside the guarantee, by cause
        self.misses_by_cause: Counter[str] = Counter()  # misses outside the guarantee, by their node-step's cause
        self.car = CarTotals() if scenario.plant != "ts" and scenario.log is None else None  # a plant's drive (a log's car is its own)
        self.drops: Counter[str] = Counter()
        self._end: End | None = None
        self._end_early = False  # an End was counted as early already
        self._end_recheck = 0  # Ends handled while truths they followed were still queued here: judged after them
        bus.subscribe(keys.truth(run_id), self.on_message, screen=self.scope.beyond)
        bus.subscribe(keys.node_state(run_id, "*"), self.on_message, screen=self.scope.beyond)
        bus.subscribe(keys.end(run_id), self.on_message)
        if not realtime:
            bus.declare_publisher(keys.ready_of(run_id, keys.role_name("collector")))

    # ------------------------------------------------------------------ receiving

    def on_message(self, key: str, msg: Message) -> None:
        reason = self.scope.reject(msg)
        if reason is not None:
            self.drops[reason] += 1
        elif isinstance(msg, Truth):
            self._on_truth(msg)
            if self._end_recheck and not self.bus.queued(keys.truth(self.run)):
                for _ in range(self._end_recheck):
                    self._judge_end()
                self._end_recheck = 0
        elif isinstance(msg, NodeState):
            self._on_state(key, msg)
        elif isinstance(msg, End):
            self._on_end(key, msg)
        else:
            self.drops["unexpected-type"] += 1
        if not self.realtime:
            self._close_ready()
            self._acknowledge()

    def _overflowed(self, key: str, msg: Message) -> None:
        """The bus dropped ``msg`` (on ``key``) for us (inbox full): our loss, never the sender's silence.  Only
        on its sender's own key: an insider flooding its state key with another node's states or with truths
        must not make that node's silence, or a truth never sent, read as our loss.  Transport thread: note only."""
        if isinstance(msg, NodeState) and key == keys.node_state(self.run, msg.node):
            self._lost_notes.append((msg.step, msg.node))
        elif isinstance(msg, Truth) and key == keys.truth(self.run):
            self._lost_notes.append((msg.step, None))

    def _take_lost(self, everything: bool = False) -> None:
        """Notes of steps within WINDOW of the newest truth into ``lost`` (never allocate per a step we were
        told); later ones stay noted (``everything``: at the end, each of the run's steps)."""
        far = self.sc.steps if everything else max(self.head, self.closed) + WINDOW
        later = []
        while self._lost_notes:
            k, node = self._lost_notes.popleft()
            if k > far:
                later.append((k, node))
            elif self.closed < k <= self.sc.steps and (node is None or node in self.totals):
                self.lost.setdefault(k, set()).add(node)
        self._lost_notes.extend(later)

    def _acknowledge(self) -> None:
        """Lockstep: tell the vehicle the newest truth taken in, every ACK_STRIDE steps (its window, roles/vehicle.py)."""
        if self.head >= self.acked + ACK_STRIDE or self.head == self.sc.steps > self.acked:  # the last: the vehicle's End waits for it
            self.acked = self.head
            self.bus.publish(keys.ready_of(self.run, keys.role_name("collector")), Ready(role="collector", seen_all=True, acked=self.head))

    def close_ready(self, most: int | None = None) -> None:
        """Real time, called when the bus is drained: close what is ready (at most ``most`` steps, so that
        the caller gets back to its bus soon), then the oldest steps unjudged while more than ``budget``
        node-steps are open."""
        self._close_ready(most)
        if self.open_node_steps > self.budget:
            self._take_lost()
        while self.open_node_steps > self.budget and self.closed < self.sc.steps:
            self._close_overloaded(self.closed + 1)

    def _held(self, n: int) -> None:
        self.open_node_steps += n
        self.peak_open_node_steps = max(self.peak_open_node_steps, self.open_node_steps)

    def _on_truth(self, msg: Truth) -> None:
        k = msg.step
        if k <= self.closed:
            self.drops["truth-after-close"] += 1
            return
        if k > max(self.head, self.closed) + WINDOW:
            if not self._behind() or self._inconsistent(msg):
                self.drops["truth-ahead"] += 1  # never allocate per a step number we were told
                return
            self._catch_up(k)
        why = self._inconsistent(msg)  # checked again at close, when the previous truth is surely known
        if why:
            self.drops[why] += 1
            return
        copies = self.truth.setdefault(k, [])
        if msg in copies:
            self.drops["duplicate-truth"] += 1
        elif len(copies) >= MAX_COPIES:
            self.drops["truth-copies"] += 1
        else:
            copies.append(msg)
            self._held(1)
            self.head = max(self.head, k)

    def _on_state(self, key: str, msg: NodeState) -> None:
        if key != keys.node_state(self.run, msg.node):
            self.drops["state-on-foreign-key"] += 1
            return
        k = msg.step
        if k <= self.closed:
            self.drops["state-after-close"] += 1
            return
        if k > max(self.head, self.closed) + WINDOW:
            self.drops["state-ahead"] += 1
            if self._behind():  # its truth is still to come (we lost the ones between): ours to count, not its silence
                self._lost_notes.append((k, msg.node))
            return
        copies = self.states.setdefault(k, {}).setdefault(msg.node, [])
        if any(_same_set(msg, c) for c in copies):
            self.drops["duplicate-state"] += 1  # the same ellipsoid: the first copy is the one recorded
        elif len(copies) >= MAX_COPIES:
            self.drops["state-copies"] += 1
        else:
            copies.append(msg)
            self._held(1)

    def _behind(self) -> bool:
        """Real time, and our own inbox turned messages away: the clock may have gone on more than WINDOW
        steps past the newest truth we have (a collector stopped, or far behind)."""
        return self.realtime and self._overloaded()

    def _catch_up(self, k: int) -> None:
        """Real time: the truth of step k came more than WINDOW steps past the newest we have, after our inbox
        turned messages away (checked, and never otherwise: a truth so far ahead is then not the vehicle's).
        The truths between are ones we lost: close the steps before k − WINDOW, judged where we hold their
        truth, else as our overload, so that step k is taken in and judging goes on (before, every later truth
        was 'ahead' too: the collector judged nothing more and reported every node missing)."""
        self._take_lost()
        while self.closed < k - WINDOW:
            j = self.closed + 1
            if self.truth.get(j):
                self._close(j)
            else:
                self._close_overloaded(j)

    def _on_end(self, key: str, msg: End) -> None:
        if key != keys.end(self.run) or msg.steps != self.sc.steps:
            self.drops["end-not-scheduled"] += 1
        else:
            # kept, and it counts once the last step's truth is here.  Over Zenoh the End may overtake the
            # last truth (another key): that is ordering, not hostility; an End before the step before the
            # last is early, and so is one whose last truth never comes (counted at finish).  Truths still
            # queued here came before it: the pump serves keys in turn, so the End overtook them in our own
            # inbox (a collector behind a fast run), and it is judged once they are handled
            self._end = msg
            if self.bus.queued(keys.truth(self.run)):
                self._end_recheck += 1
            else:
                self._judge_end()

    def _judge_end(self) -> None:
        """Count the kept End as early if the truth it should follow is still far off (and not lost here)."""
        if self.sc.steps not in self.truth and max(self.head, self.closed) < self.sc.steps - 1 and not self._overloaded():
            self.drops["end-early"] += 1
            self._end_early = True

    def _overloaded(self) -> bool:
        """Whether our own inbox turned messages away (we fell behind): a truth missing then may be one we
        lost, which is our trouble (counted as such), not the End's."""
        return bool(self.bus.dropped["inbox-full"] or self.bus.dropped["inbox-evicted"])

    @property
    def ended(self) -> End | None:
        """The vehicle's End, once the scheduled last step's truth has arrived too."""
        if self._end is None or (self.sc.steps not in self.truth and self.closed < self.sc.steps):
            return None
        return self._end

    @property
    def started(self) -> bool:
        return self.head >= 0 or self.closed >= 0

    @property
    def progress(self) -> int:
        """Last step for which every alive node's ellipsoid has arrived (with its truth)."""
        k = self.closed
        while k + 1 in self.truth and self._reported(k + 1, alive_only=True):
            k += 1
        return k

    def _reported(self, k: int, alive_only: bool) -> bool:
        copies = self.truth.get(k)
        want = set(copies[0].alive) if alive_only and copies and k > 0 else set(self.sc.ids)
        if alive_only and self.truth.get(k + 1):
            # the next truth's alive list is who the vehicle heard at k: a node it gave up on (killed, to
            # rejoin later) is not waited for, else progress stalls until WINDOW and a rejoin waits on it
            want &= set(self.truth[k + 1][0].alive)
        if copies:
            want -= set(copies[0].no_reading)  # without a reading a node publishes nothing for the step
        return want <= set(self.states.get(k, {}))

    # ------------------------------------------------------------------ closing steps

    def _close_ready(self, most: int | None = None) -> None:
        done = 0
        while self.closed < self.sc.steps and (most is None or done < most):
            k = self.closed + 1
            here = k in self.truth
            if not (
                self.head >= k + WINDOW
                or here
                and self._reported(k, alive_only=False)
                or here
                and self.head >= k + CLOSE_LAG
                and self._reported(k, alive_only=True)
            ):
                return
            if not done:
                self._take_lost()  # once per closing run, not per message: a flood's notes are scanned rarely
            self._close(k)
            done += 1

    def _judged_truth(self, k: int) -> Truth | None:
        """The one copy of step k's truth consistent with the scenario and the previous truth, or None."""
        good = []
        for t in self.truth.get(k, []):
            why = self._inconsistent(t)
            if why:
                self.drops[why] += 1
            else:
                good.append(t)
        if len(good) > 1:
            self.drops["truth-conflict"] += len(good)  # cannot tell the vehicle's: judge the step on none
            return None
        return good[0] if good else None

    def _inconsistent(self, t: Truth) -> str | None:
        if self.sc.log is not None:
            return self._inconsistent_log(t)
        sc, k = self.sc, t.step
        x = np.asarray(t.x)
        prev = self.prev_truth if self.prev_truth is not None and self.prev_truth.step == k - 1 else None
        if k == 0:
            expect = sc.x0
        elif prev is not None:
            expect = sc.model.step(np.asarray(prev.x), prev.u, prev.w, prev.vx)
            if prev.e is not None:  # the plant's model mismatch of k−1 → k (docs/plant.md)
                expect = expect + np.asarray(prev.e)
        else:
            expect = None  # the previous truth is unknown: x cannot be checked, the rest can
        if expect is not None and not np.allclose(x, expect, rtol=CHAIN_RTOL, atol=1e-300):
            return "truth-not-from-model"
        if sc.plant == "ts" and not np.isclose(t.vx, sc.vx(k), rtol=CHAIN_RTOL, atol=0.0):
            return "truth-speed"
        if sc.plant != "ts" and not sc.speed_plausible(k, t.vx):
            return "truth-speed"  # a plant's Vx is its own, but always inside the model's range
        for n in sc.nodes:
            s = str(n.id)
            f = n.fault(k)
            if t.faults[s] != f:
                return "truth-fault"
            xf = augmented(x, f)
            if t.sector_ok[s] != n.sensor.sector_holds(xf) or t.fault_ok.get(s) != fault_bound_holds(n, k):
                return "truth-flags"
            r = t.r.get(s)
            if r is None or not isclose(r, float(n.sensor.Cbar @ xf), CHAIN_RTOL):
                return "truth-sensor-input"
            # v·v, not v**2: a forged huge value squares to inf (a float's ** raises OverflowError instead)
            if t.noise_ok[s] != bool(t.noise[s] * t.noise[s] <= n.sensor.R * (1 + 1e-12)):
                return "truth-flags"
        if t.dist_ok != bool(t.w * t.w <= sc.W * (1 + 1e-12)):
            return "truth-flags"
        if t.e is not None and t.mismatch_ok != mismatch_holds(sc, np.asarray(t.e)):
            return "truth-flags"
        if t.envelope_ok != envelope_holds(sc, t.ay, t.speed):
            return "truth-flags"
        if t.health_ok != sc.health_holds({n.id: n.fault(k) for n in sc.nodes}):
            return "truth-flags"
        return None

    def _inconsistent_log(self, t: Truth) -> str | None:
        """A recorded drive's truth: what the scenario fixes of it (the reference's declared accuracy, the injected
        faults where the logged sensor is declared healthy, a speed the model covers); the logged values themselves
        are the vehicle's, authenticated by the transport (docs/your-log.md)."""
        sc = self.sc
        assert sc.log is not None
        if t.x_acc is None or tuple(t.x_acc) != sc.log.mapping.accuracy:
            return "truth-accuracy"
        if not sc.speed_plausible(t.step, t.vx):
            return "truth-speed"
        for n in sc.nodes:
            s = str(n.id)
            if t.f_acc.get(s, 0.0) == 0.0 and t.faults[s] != n.fault(t.step):
                return "truth-fault"
        return None

    def _judge_state(self, i: int, k: int, tr: Truth | None) -> tuple[NodeState | None, bool]:
        """(the copy to record, whether it is the only one that can be node i's own); None: none can."""
        copies = self.states.get(k, {}).get(i, [])
        if tr is None:
            return (copies[0], len(copies) == 1) if copies else (None, False)
        good = []
        for st in copies:
            why = state_mismatch(self.node_cfg[i], st, tr)
            if why:
                self.drops[why] += 1
            else:
                good.append(st)
        if len(good) > 1:
            self.drops["state-conflict"] += len(good)
        return (good[0], len(good) == 1) if good else (None, False)

    def _close(self, k: int) -> None:
        """Judge step k, stream it to the sink, add it to the totals and forget it."""
        if not self.truth.get(k) and None in self.lost.get(k, ()):
            self._close_overloaded(k)  # our inbox dropped its truth: nothing of it can be judged, our trouble
            return
        tr = self._judged_truth(k)
        judged, contested = {}, set()
        for i in self.sc.ids:
            st, sole = self._judge_state(i, k, tr)
            if st is not None:
                judged[i] = st
                if not sole:
                    contested.add(i)
        copies = self.states.get(k, {})
        lost = self.lost.get(k, set())
        overloaded_before = self.overloaded_node_steps
        inputs = StepInputs(k, tr, self.prev_truth, judged, frozenset(contested), copies, self.prev_overloaded)
        verdict = self.judge.step(inputs, self.prev_checks)
        for i in self.sc.ids:
            t, st, v = self.totals[i], judged.get(i), verdict.nodes[i]
            if tr is not None:
                t.fdi.truth(k, tr.faults[str(i)], self.sc.fault_tolerance)
            if tr is not None and not tr.sector_ok[str(i)]:
                t.sector_breaks += 1
                if t.first_sector_break is None:
                    t.first_sector_break = k
            if not v.cone.ok:
                t.assumption_violations += 1
            if copies.get(i):
                t.last_heard = k
                if t.missing_from is not None and t.rejoined_at is None:
                    t.rejoined_at = k
            if st is None:
                self._unjudged(t, k, bool(copies.get(i)), i in lost, tr is not None and i in tr.no_reading)
                continue
            t.contested += i in contested
            t.sectors_assumed += st.sector_basis == "assumed"
            t.sector_failures += self.judge.sector_failed(i, st, tr, v.cone.ok and i not in contested)
            bounds = _bounds(st, v.containment)
            fdi = classify(bounds[2][0], bounds[2][1], self.sc.fault_tolerance)
            if self.sink is not None:
                self.sink.state(i, _state_entry(st, v, i in contested, bounds, tr is not None and not tr.reference) | {"fdi": fdi})
            self._add(t, k, st, v, bounds)
            if tr is not None and v.containment is not None:  # judged rows only: a contested copy may be forged
                t.fdi.add(k, fdi, tr.faults[str(i)], self.sc.fault_tolerance, v.cone.ok)
        # a step of which we lost a node-step ourselves (a note of a message that was not the one judged is none)
        self.overloaded_steps += self.overloaded_node_steps > overloaded_before
        if tr is not None and self.car is not None:
            self.car.add(self.sc, tr)
        if tr is not None:
            for j, i in tr.lost:
                self.losses[f"{j}->{i}"] += 1
            self.vehicle_drops = dict(tr.drops)
            if self.sink is not None:
                self.sink.truth(self._truth_entry(tr))
        self._forget(k)
        self.prev_truth = tr
        self.prev_checks = verdict.checks
        self.prev_overloaded = False
        self.closed = k

    def _unjudged(self, t: NodeTotals, k: int, reported: bool, lost: bool, no_reading: bool) -> None:
        """Node-step k with no state to judge: rejected if it reported, the collector's loss if our inbox
        dropped it, no reading (a gap in a recorded drive: nothing was due), else missing (only then is the
        node blamed)."""
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

    def _forget(self, k: int) -> None:
        self.lost.pop(k, None)
        held = self.states.pop(k, {})
        self.open_node_steps -= len(self.truth.pop(k, [])) + sum(map(len, held.values()))

    def _close_overloaded(self, k: int) -> None:
        """Close step k unjudged, past the memory budget or without the truth our inbox dropped: nothing
        recorded, every node-step of it counted as the collector's overload and nowhere else (we closed it
        before we could tell who published: no node is counted missing for it; a node heard at k is heard,
        never reported missing or rejoined for it); the next step's inputs are then not judged, so its
        node-steps are outside the guarantee, never covered by it."""
        copies, lost = self.states.get(k, {}), self.lost.get(k, set())
        for i in self.sc.ids:
            if copies.get(i) or i in lost:
                self.totals[i].last_heard = k
        self.overloaded_node_steps += len(self.sc.ids)
        self.overloaded_steps += 1
        self._forget(k)
        self.prev_truth, self.prev_checks, self.prev_overloaded = None, NO_CHECKS, True
        self.closed = k

    def _add(self, t: NodeTotals, k: int, st: NodeState, v: NodeVerdict, bounds: list[list[float]]) -> None:
        t.reported += 1
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

    @staticmethod
    def _truth_entry(t: Truth) -> dict:
        d = t.model_dump(mode="json")
        for f in ("v", "type", "drops"):  # the vehicle's drop counters go to the summary
            d.pop(f, None)
        return d

    # ------------------------------------------------------------------ summary

    def finish(
        self,
        meta: RunMeta,
        deadline_misses: dict[int, int] | None = None,
        drops: dict[str, dict[str, int]] | None = None,
        stopped: StopCause | None = None,
        through: int | None = None,
        stall: tuple[float, int | None] = (0.0, None),
    ) -> RunSummary:
        """Close every open step (``through``: those up to that step only; the later ones, cut short by a signal or
        our own stall, are forgotten: neither judged nor any node's silence), then the summary (also written to the
        sink, which is closed).

        ``drops``: further drop counters by role (the runtime's, e.g. a shared in-memory bus); ``stopped``:
        why the collector stopped before the vehicle's End (None: the run ended); ``stall``: the collector's longest
        stall [s] and the step checked before it (runtime/processes.py StallWatch).
        """
        self._take_lost(everything=True)
        last = max([self.head, *self.states, *self.lost], default=-1)  # a step we lost whole is still the run's
        if through is not None:
            last = min(last, through)
        if self._end is not None and not self._end_early and self.sc.steps not in self.truth and self.closed < self.sc.steps and not self._overloaded():
            self.drops["end-early"] += 1  # the run ends, and the End's last step never came
        for k in range(self.closed + 1, min(last, self.sc.steps) + 1):
            self._close(k)
        last = self.closed
        node_rows = [self._node_summary(n, (deadline_misses or {}).get(n.id, self.totals[n.id].late)) for n in self.sc.nodes]
        own_drops = self.drops + (Counter() if self.bus.shared else self.bus.dropped)
        by_role: dict[str, dict[str, int]] = {"collector": dict(sorted(own_drops.items())), "vehicle": dict(sorted(self.vehicle_drops.items()))}
        by_role.update({f"node {r.id}": dict(sorted(r.drops.items())) for r in node_rows})
        by_role.update(drops or {})
        totals = self.totals.values()
        summary = RunSummary(
            **{k: getattr(meta, k) for k in RUN_FIELDS},
            violations_total=sum(r.violations for r in node_rows),
            misses_assumption_broken_total=sum(r.misses_assumption_broken for r in node_rows),
            sector_failures_total=sum(r.sector_failures for r in node_rows),
            steps_completed=last,
            node_steps_reported=sum(t.reported for t in totals),
            node_steps_rejected=sum(t.rejected for t in totals),
            node_steps_contested=sum(t.contested for t in totals),
            node_steps_evaluated=sum(t.evaluated for t in totals),
            node_steps_contained=sum(t.contained for t in totals),
            node_steps_missed=sum(t.missed for t in totals),
            node_steps_undecided=sum(t.undecided for t in totals),
            node_steps_no_reading=sum(t.no_reading for t in totals),
            node_steps_inconsistent=sum(t.inconsistent for t in totals),
            reference_accuracy=None if self.sc.log is None or self.sc.log.mapping.r is None else list(self.sc.log.mapping.accuracy),
            drive_log=None if self.sc.log is None else self.sc.log.path,
            node_steps_covered=sum(t.covered for t in totals),
            node_steps_not_covered=dict(sorted(self.not_covered.items())),
            inherited_from=[InheritedOrigin(j, why, first, count) for (j, why), (first, count) in sorted(self.origins.items())],
            misses_by_cause=dict(sorted(self.misses_by_cause.items())),
            car=self.car.summary(self.sc) if self.car is not None else None,
            # lost for good: silent at the last step; rejoined: a gap, then heard from up to the last step
            nodes_missing=[i for i, t in self.totals.items() if last >= 0 and (t.last_heard is None or t.last_heard < last)],  # (no step: no one)
            nodes_rejoined=[i for i, t in self.totals.items() if t.missing_from is not None and t.last_heard == last],
            losses=dict(sorted(self.losses.items())),
            losses_total=sum(self.losses.values()),
            dropped_messages=dict(own_drops),  # by the collector; per node in nodes[*]
            drops={role: d for role, d in by_role.items() if d},
            nodes=node_rows,
            stopped=stopped,
            steps_overloaded=self.overloaded_steps,
            node_steps_overloaded=self.overloaded_node_steps,
            collector_budget=self.budget if self.realtime else None,
            collector_peak=self.peak_open_node_steps,
            collector_stall_s=stall[0],
            collector_stall_step=stall[1],
        )
        if self.sink is not None:
            self.sink.summary(summary)
            self.sink.close()
        return summary

    def _node_summary(self, n: NodeConfig, deadline_misses: int) -> NodeSummary:
        t = self.totals[n.id]
        return NodeSummary(
            id=n.id,
            estimator=n.estimator,
            max_E=t.E_max,
            violations=t.violations,
            misses_assumption_broken=t.broken_misses,
            assumption_violations=t.assumption_violations,
            sector_failures=t.sector_failures,
            sectors_assumed=t.sectors_assumed,
            sector_breaks=t.sector_breaks,
            first_sector_break=t.first_sector_break,
            fault_bound_mean_width=t.width_sum / t.reported if t.reported else None,
            beta_mean_width=t.beta_width_sum / t.reported if t.reported else None,
            r_mean_width=t.r_width_sum / t.reported if t.reported else None,
            solve_ms_median=statistics.median(t.solve) if t.solve else None,
            fallbacks=t.fallbacks,
            steps_reported=t.reported,
            steps_rejected=t.rejected,
            steps_contested=t.contested,
            steps_evaluated=t.evaluated,
            steps_contained=t.contained,
            steps_missed=t.missed,
            steps_undecided=t.undecided,
            steps_no_reading=t.no_reading,
            steps_inconsistent=t.inconsistent,
            steps_covered=t.covered,
            missing_steps=t.missing_steps,
            missing_from=t.missing_from,
            rejoined_at=t.rejoined_at,
            neighbour_messages_missing=t.neighbour_missing,
            dropped_messages=t.dropped,
            drops=t.drops,
            deadline_misses=deadline_misses,
            fault_onset=t.fdi.fault_onset,
            first_detection=t.fdi.first_detection,
            detection_delay=t.fdi.detection_delay,
            detected_steps=t.fdi.detected_steps,
            healthy_steps=t.fdi.healthy_steps,
            false_detections=t.fdi.false_detections,
            false_detections_covered=t.fdi.false_detections_covered,
        )
