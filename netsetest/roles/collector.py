"""The collector role: admits the run's messages, has every closed step judged (roles/judge.py) and
writes the record and the summary.

For node i at step k it computes E_i,k = e_i,kᵀ P_i,k⁻¹ e_i,k with e = x̄_i,k − x̂_i,k and declares
containment when its published set (netsetest/proven.py: E_i,k ≤ ρ_i, its region, its fault range) holds the
truth; where the node continues from another set (``NodeState.continues``), that set must hold it too.  A miss is
attributed by the step's *dependency cone*, one step deep over judged inputs (docs/coverage.md): the estimate of
(i, k) relies on its own sector condition and noise bound at k, the disturbance bound at k−1, and on the exact
copies of the states it used (its own previous set and its neighbours' of k−1, named by digest in
``NodeState.inputs``), each judged directly against the truth of k−1; step 0 relies on the initial ellipsoid
containing x̄_0 (Assumption 1).  A miss inside an intact cone is an estimator failure (``violations``); a miss
after a broken assumption is reported separately (``misses_assumption_broken``).  A saturating node's sector
premise is what its published sector rests on (``sector_basis``): the noise bound only, the declared fault bound,
or — for an assumed sector — the sector itself checked against the truth's C̄ x̄.  A derived sector that misses
the truth inside an intact cone is counted as a ``sector_failure`` (an estimator bug).

A loop of a few parts: each message goes to the admission (roles/admission.py: every defence, the open steps'
copies, which copy is judged); each step, once ready, is judged, its rows written and its figures added to the
run's totals (roles/totals.py, which also makes the summary); in lockstep the collector acknowledges the truths
it took in (roles/flow.py).

Streaming and bounded: the collector keeps the truth and the states of the steps not yet *closed*.
Step k is closed (judged, written to the record sink, forgotten) in order, once its truth is here and
every node reported, or the alive ones did and the truth is ``CLOSE_LAG`` steps further, or the truth
is ``WINDOW`` steps further whatever arrived; :meth:`Collector.finish` closes the rest.  Only running totals
per node remain for the summary.

Keeping up.  In lockstep the collector acknowledges the truths it has taken in (a Ready with ``acked``
every ``ACK_STRIDE`` steps) and the vehicle stays within its window of it (roles/flow.py), so the run's
own messages never exceed the bus's bounded inbox, however slow the collector is.  In real time the clock
cannot wait: the collector takes every message off the bus first and closes steps when nothing is waiting
(:meth:`Collector.close_ready`), keeping the open steps up to ``budget`` node-steps
(``OPEN_NODE_STEPS_BUDGET``); past it the oldest steps close unjudged, counted as the collector's
overload (``steps_overloaded``, ``node_steps_overloaded``; the verdict says *collector overloaded*).  A
message its full inbox dropped all the same (the bus tells it: ``Bus.overflow_listeners``) counts there
too; so does a truth or state more than ``WINDOW`` steps past the newest truth once its inbox has turned
messages away (a collector stopped longer than its inbox holds: :meth:`Collector._catch_up` closes the steps
it lost and judges on).  Neither is ever a node's silence: a node that published is never reported missing
or rejoined.

With the admission's defences (a truth must follow from the one before through the vehicle model; a state must
match the truth of its step where an honest node's must; two copies that both pass are judged on neither), a miss
the verdict counts comes from a state the node itself computed from its true input.
"""

from __future__ import annotations

from collections import Counter

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.messages import End, Message, NodeState, Ready, Truth
from netsetest.records.meta import RunMeta
from netsetest.records.record import RecordSink
from netsetest.records.summary import RunSummary, StopCause
from netsetest.roles.admission import WINDOW, Admission
from netsetest.roles.fdi import classify
from netsetest.roles.flow import Acknowledgments
from netsetest.roles.judge import NO_CHECKS, Judge, NodeVerdict, StepInputs
from netsetest.roles.totals import CollectorFigures, RunTotals, published_bounds, state_row, truth_row

CLOSE_LAG = 2  # a step whose alive nodes reported closes this many truths later (late and rejoining states)
# Real time: the node-steps (states held, one truth per step counted as one more) the collector keeps open
# before it closes the oldest step unjudged.  A decoded paper6 message takes about 2.4 KB (x̂, P, its region
# and bookkeeping; measured with tracemalloc), so the default holds about 50 MB: paper6 (six nodes, τs =
# 0.1 s) 280 s behind the clock.
OPEN_NODE_STEPS_BUDGET = 20_000


class Collector:
    """The collector role (module doc): its admission (roles/admission.py), the judge (roles/judge.py), the run's
    totals (roles/totals.py), the record sink, and the collector's side of the flow control (roles/flow.py)."""

    def __init__(
        self, scenario: Scenario, bus: Bus, run_id: str, sink: RecordSink | None = None, realtime: bool = False, budget: int = OPEN_NODE_STEPS_BUDGET
    ) -> None:
        """``realtime``: close steps only in :meth:`close_ready` (the caller's loop, when the bus is drained)
        and within ``budget`` open node-steps; lockstep: as messages arrive, and acknowledge the truths."""
        self.sc, self.bus, self.run, self.sink = scenario, bus, run_id, sink
        self.realtime, self.budget = realtime, budget
        self.admission = Admission(scenario, bus, run_id, realtime)
        self.judge = Judge(scenario)
        self.totals = RunTotals(scenario)
        self.acks = Acknowledgments(scenario.steps)  # lockstep flow control, the collector's side
        self.prev_checks = NO_CHECKS  # the last closed step's copies, judged as inputs of the next
        self.prev_overloaded = False  # the last closed step was closed unjudged for our own loss (no truth read)
        bus.overflow_listeners[self.on_message] = self.admission.overflowed
        screen = self.admission.scope.beyond
        bus.subscribe(keys.truth(run_id), self.on_message, screen=screen)
        bus.subscribe(keys.node_state(run_id, "*"), self.on_message, screen=screen)
        bus.subscribe(keys.end(run_id), self.on_message)
        if not realtime:
            bus.declare_publisher(keys.ready_of(run_id, keys.role_name("collector")))

    # ------------------------------------------------------------------ the loop

    def on_message(self, key: str, msg: Message) -> None:
        """Admit ``msg``; lockstep: close what is ready and acknowledge the truths taken in."""
        far = self.admission.take(key, msg)
        if far is not None:  # real time: a truth past the window once our inbox turned messages away
            self._catch_up(far)
            self.admission.take(key, msg)
        if not self.realtime:
            self._close_ready()
            step = self.acks.due(self.admission.head)
            if step is not None:
                self.bus.publish(keys.ready_of(self.run, keys.role_name("collector")), Ready(role="collector", seen_all=True, acked=step))

    def close_ready(self, most: int | None = None) -> None:
        """Real time, called when the bus is drained: close what is ready (at most ``most`` steps, so that
        the caller gets back to its bus soon), then the oldest steps unjudged while more than ``budget``
        node-steps are open."""
        self._close_ready(most)
        adm = self.admission
        if adm.open_node_steps > self.budget:
            adm.take_lost()
        while adm.open_node_steps > self.budget and adm.closed < self.sc.steps:
            self._close_overloaded(adm.closed + 1)

    def _close_ready(self, most: int | None = None) -> None:
        """Close step after step while the next is ready: its truth is here and every node reported, or every
        alive one did and the truth is CLOSE_LAG steps further, or the truth is WINDOW steps further whatever came."""
        adm, done = self.admission, 0
        while adm.closed < self.sc.steps and (most is None or done < most):
            k = adm.closed + 1
            here = k in adm.truth
            full = here and adm.reported(k, alive_only=False)
            if not (adm.head >= k + WINDOW or full or here and adm.head >= k + CLOSE_LAG and adm.reported(k, alive_only=True)):
                return
            if not done:
                adm.take_lost()  # once per closing run, not per message: a flood's notes are scanned rarely
            self._close(k)
            done += 1

    def _catch_up(self, k: int) -> None:
        """Real time: the truth of step k came more than WINDOW steps past the newest we have, after our inbox
        turned messages away (checked, and never otherwise: a truth so far ahead is then not the vehicle's).
        The truths between are ones we lost: close the steps before k − WINDOW, judged where we hold their
        truth, else as our overload, so that step k is taken in and judging goes on (before, every later truth
        was 'ahead' too: the collector judged nothing more and reported every node missing)."""
        adm = self.admission
        adm.take_lost()
        while adm.closed < k - WINDOW:
            j = adm.closed + 1
            if adm.truth.get(j):
                self._close(j)
            else:
                self._close_overloaded(j)

    @property
    def ended(self) -> End | None:
        """The vehicle's End, once the scheduled last step's truth has arrived too (None: not yet)."""
        return self.admission.ended

    @property
    def started(self) -> bool:
        return self.admission.head >= 0 or self.admission.closed >= 0

    @property
    def progress(self) -> int:
        """Last step for which every alive node's ellipsoid has arrived (with its truth)."""
        adm = self.admission
        k = adm.closed
        while k + 1 in adm.truth and adm.reported(k + 1, alive_only=True):
            k += 1
        return k

    # ------------------------------------------------------------------ closing a step

    def _close(self, k: int) -> None:
        """Judge step k, stream it to the sink, add it to the totals and forget it."""
        adm = self.admission
        if adm.lost_truth(k):
            self._close_overloaded(k)  # our inbox dropped its truth: nothing of it can be judged, our trouble
            return
        tr = adm.judged_truth(k)
        judged, contested = adm.judged_states(k, tr)
        copies, lost = adm.states.get(k, {}), adm.lost.get(k, set())
        verdict = self.judge.step(StepInputs(k, tr, adm.prev_truth, judged, contested, copies, self.prev_overloaded), self.prev_checks)
        overloaded_before = self.totals.overloaded_node_steps
        for i in self.sc.ids:
            v, heard = verdict.nodes[i], bool(copies.get(i))
            self.totals.closed(i, k, tr, v.cone.ok, heard)
            st = judged.get(i)
            if st is None:
                self.totals.unjudged(i, k, heard, i in lost, tr is not None and i in tr.no_reading)
            else:
                self._node_step(i, k, st, v, tr, i in contested)
        # a step of which we lost a node-step ourselves (a note of a message that was not the one judged is none)
        self.totals.overloaded_steps += self.totals.overloaded_node_steps > overloaded_before
        if tr is not None:
            self.totals.truth(tr)
            if self.sink is not None:
                self.sink.truth(truth_row(tr))
        adm.forget(k, tr)
        self.prev_checks, self.prev_overloaded = verdict.checks, False

    def _node_step(self, i: int, k: int, st: NodeState, v: NodeVerdict, tr: Truth | None, contested: bool) -> None:
        """Node i's judged state of step k: its record row and its totals."""
        bounds = published_bounds(st, v.containment)
        fdi = classify(bounds[2][0], bounds[2][1], self.sc.fault_tolerance)
        if self.sink is not None:
            self.sink.state(i, state_row(st, v, contested, bounds, tr is not None and not tr.reference) | {"fdi": fdi})
        failed = self.judge.sector_failed(i, st, tr, v.cone.ok and not contested)
        self.totals.judged(i, k, st, v, bounds, contested, failed)
        if tr is not None and v.containment is not None:  # judged rows only: a contested copy may be forged
            self.totals.fdi(i, k, fdi, tr, v.cone.ok)

    def _close_overloaded(self, k: int) -> None:
        """Close step k unjudged, past the memory budget or without the truth our inbox dropped: nothing
        recorded, every node-step of it counted as the collector's overload and nowhere else (we closed it
        before we could tell who published: no node is counted missing for it; a node heard at k is heard,
        never reported missing or rejoined for it); the next step's inputs are then not judged, so its
        node-steps are outside the guarantee, never covered by it."""
        adm = self.admission
        copies, lost = adm.states.get(k, {}), adm.lost.get(k, set())
        self.totals.overloaded(k, {i for i in self.sc.ids if copies.get(i) or i in lost})
        adm.forget(k, None)
        self.prev_checks, self.prev_overloaded = NO_CHECKS, True

    # ------------------------------------------------------------------ the end

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
        adm = self.admission
        adm.take_lost(everything=True)
        last = max([adm.head, *adm.states, *adm.lost], default=-1)  # a step we lost whole is still the run's
        if through is not None:
            last = min(last, through)
        adm.end_never_met()
        for k in range(adm.closed + 1, min(last, self.sc.steps) + 1):
            self._close(k)
        own_drops = adm.drops + (Counter() if self.bus.shared else self.bus.dropped)
        figures = CollectorFigures(stopped, self.budget if self.realtime else None, adm.peak_open_node_steps, *stall)
        summary = self.totals.summary(meta, adm.closed, own_drops, drops or {}, deadline_misses or {}, figures)
        if self.sink is not None:
            self.sink.summary(summary)
            self.sink.close()
        return summary
