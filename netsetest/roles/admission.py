"""The collector's admission and defences: what it lets in, what it keeps of each open step, and which copy of a
step's truth and of a node's state it judges (roles/collector.py closes the steps, roles/judge.py judges them).

The network may be open, or a credentialed peer may lie; every defence drops, never repairs, and counts by reason:

- a message outside the run (:class:`RunScope`), for a step already closed, or further than ``WINDOW`` steps ahead
  of the newest truth is dropped (nothing is allocated per a step number it names);
- a repeated copy is a duplicate and dropped; the first copy is the one recorded — a *different* copy for the same
  (node, step) or step is kept (up to ``MAX_COPIES``) so that the step can be judged honestly;
- a truth must follow from the previous one through the vehicle model (x_k = f(x_{k−1}, u_{k−1}, w_{k−1},
  Vx_{k−1}), x_0 of the scenario) with the scenario's faults, speed, sensor inputs C̄ x̄ (``r``) and assumption
  flags (``fault_ok`` included) (:func:`truth_problem`; a recorded drive's, what the scenario fixes of it);
- a node's state must match the truth of its step where an honest node's must (judge.py ``state_mismatch``: its γ
  and its innovation y̌ = ỹ − C̄ x̂ with the true measurement ỹ; a step-0 ``init-prior`` state the profile's prior);
- when more than one copy passes, the collector cannot tell which one the sender sent: the step (a truth) or
  node-step (a state) is *contested* and judged on none;
- End counts only when it names the scheduled last step and that step's truth is here.

What the bus's full inbox dropped for us is noted (``Bus.overflow_listeners``: on the transport's thread, only on
the sender's own key) and taken into ``lost``: our loss, never the sender's silence.  So is a state more than
``WINDOW`` steps ahead once our inbox has turned messages away (a collector stopped longer than its inbox holds).
"""

from __future__ import annotations

from collections import Counter, deque

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import NodeConfig, Scenario
from netsetest.messages import End, Message, NodeState, RunScope, Truth
from netsetest.models.sensor import augmented
from netsetest.roles.judge import isclose, state_mismatch
from netsetest.roles.vehicle import envelope_holds, fault_bound_holds, mismatch_holds

WINDOW = 50  # steps a step may stay open behind the newest truth (bounds memory against a stalled node)
MAX_COPIES = 4  # differing copies of one step's truth, or one node-step's state, kept until the step closes
CHAIN_RTOL = 1e-12  # x_k recomputed from x_{k−1}: same code, same inputs — rounding only across machines
LOST_NOTES = 4096  # messages the bus's full inbox dropped, noted until the next step closes (a flood beyond: forgotten)


def same_set(a: NodeState, b: NodeState) -> bool:
    """Copies that publish the same sets are one for judging (bookkeeping fields may differ)."""
    return a.published == b.published and a.continues == b.continues and a.innov == b.innov and a.gamma == b.gamma


# ---------------------------------------------------------------- a truth against the scenario and the one before


def truth_problem(sc: Scenario, t: Truth, prev: Truth | None) -> str | None:
    """Why truth ``t`` cannot be the vehicle's (a drop reason), or None; ``prev``: the judged truth of the step
    before (None: unknown, then x cannot be checked, the rest can)."""
    return chain_problem(sc, t, prev) or own_truth_problem(sc, t)


def chain_problem(sc: Scenario, t: Truth, prev: Truth | None) -> str | None:
    """:func:`truth_problem`'s part that rests on the truth before (``prev``): x_k from x_{k−1} through the model (a
    recorded drive's reference follows no model: none); the rest is :func:`own_truth_problem`'s."""
    if sc.log is not None:
        return None
    k = t.step
    x = np.asarray(t.x)
    prev = prev if prev is not None and prev.step == k - 1 else None
    if k == 0:
        expect = sc.x0
    elif prev is not None:
        expect = sc.model.step(np.asarray(prev.x), prev.u, prev.w, prev.vx)
        if prev.e is not None:  # the plant's model mismatch of k−1 → k (docs/plant.md)
            expect = expect + np.asarray(prev.e)
    else:
        expect = None
    if expect is not None and not np.allclose(x, expect, rtol=CHAIN_RTOL, atol=1e-300):
        return "truth-not-from-model"
    return None


def own_truth_problem(sc: Scenario, t: Truth) -> str | None:
    """:func:`truth_problem`'s part that rests on the scenario alone (speed, every node's fault, sensor input and flags,
    the run's flags; a recorded drive's, what the scenario fixes of it): a frozen truth that passed it passes it again."""
    if sc.log is not None:
        return _log_truth_problem(sc, t)
    k = t.step
    x = np.asarray(t.x)
    if sc.plant == "ts" and not np.isclose(t.vx, sc.vx(k), rtol=CHAIN_RTOL, atol=0.0):
        return "truth-speed"
    if sc.plant != "ts" and not sc.speed_plausible(k, t.vx):
        return "truth-speed"  # a plant's Vx is its own, but always inside the model's range
    for n in sc.nodes:
        why = _node_problem(n, t, x)
        if why:
            return why
    return _flags_problem(sc, t)


def _node_problem(n: NodeConfig, t: Truth, x: np.ndarray) -> str | None:
    """Node ``n``'s part of truth ``t``: its fault, its sensor input C̄ x̄ and its flags as the scenario makes them."""
    i, k = n.id, t.step
    f = n.fault(k)
    if t.faults[i] != f:
        return "truth-fault"
    xf = augmented(x, f)
    if t.sector_ok[i] != n.sensor.sector_holds(xf) or t.fault_ok.get(i) != fault_bound_holds(n, k):
        return "truth-flags"
    r = t.r.get(i)
    if r is None or not isclose(r, float(n.sensor.Cbar @ xf), CHAIN_RTOL):
        return "truth-sensor-input"
    # v·v, not v**2: a forged huge value squares to inf (a float's ** raises OverflowError instead)
    if t.noise_ok[i] != bool(t.noise[i] * t.noise[i] <= n.sensor.R * (1 + 1e-12)):
        return "truth-flags"
    return None


def _flags_problem(sc: Scenario, t: Truth) -> str | None:
    """The run's assumption flags of truth ``t`` as its own values make them."""
    if t.dist_ok != bool(t.w * t.w <= sc.W * (1 + 1e-12)):
        return "truth-flags"
    if t.e is not None and t.mismatch_ok != mismatch_holds(sc, np.asarray(t.e)):
        return "truth-flags"
    if t.envelope_ok != envelope_holds(sc, t.ay, t.speed):
        return "truth-flags"
    if t.health_ok != sc.health_holds({n.id: n.fault(t.step) for n in sc.nodes}):
        return "truth-flags"
    return None


def _log_truth_problem(sc: Scenario, t: Truth) -> str | None:
    """A recorded drive's truth: what the scenario fixes of it (the reference's declared accuracy, the injected
    faults where the logged sensor is declared healthy, a speed the model covers); the logged values themselves
    are the vehicle's, authenticated by the transport (docs/your-log.md)."""
    assert sc.log is not None
    if t.x_acc is None or tuple(t.x_acc) != sc.log.mapping.accuracy:
        return "truth-accuracy"
    if not sc.speed_plausible(t.step, t.vx):
        return "truth-speed"
    for n in sc.nodes:
        if t.f_acc.get(n.id, 0.0) == 0.0 and t.faults[n.id] != n.fault(t.step):
            return "truth-fault"
    return None


# ---------------------------------------------------------------- the open steps


class Admission:
    """The open steps (after ``closed``, the last step the collector forgot) as admitted: their truth copies and
    state copies, what our own inbox lost of them, the run's End, and the drop counters."""

    def __init__(self, scenario: Scenario, bus: Bus, run_id: str, realtime: bool) -> None:
        """``realtime``: a truth past the window may be one our stopped process missed the steps before of."""
        self.sc, self.bus, self.run, self.realtime = scenario, bus, run_id, realtime
        self.scope = RunScope(frozenset(scenario.ids), scenario.steps)
        self.node_cfg = {n.id: n for n in scenario.nodes}  # looked up per state
        self.truth: dict[int, list[Truth]] = {}  # open steps: the copies received, first first
        self.states: dict[int, dict[int, list[NodeState]]] = {}  # open steps: node → copies, first first
        self.closed = -1  # the last step forgotten (closed)
        self.head = -1  # newest step with a truth copy
        self.prev_truth: Truth | None = None  # the judged truth of the last closed step
        self.drops: Counter[str] = Counter()
        self.open_node_steps = 0  # states held plus one per open step's truth copies: what the budget bounds
        self.peak_open_node_steps = 0
        # what the bus's full inbox dropped before we saw it: (step, node; None for a truth), noted on the
        # transport's thread (a deque's append is atomic), taken into ``lost`` (step → nodes) on ours
        self._lost_notes: deque[tuple[int, int | None]] = deque(maxlen=LOST_NOTES)
        self.lost: dict[int, set[int | None]] = {}
        self.end: End | None = None
        self._end_early = False  # an End was counted as early already
        self._end_recheck = 0  # Ends handled while truths they followed were still queued here: judged after them

    # ------------------------------------------------------------ receiving

    def take(self, key: str, msg: Message) -> int | None:
        """Admit ``msg`` (heard on ``key``) or drop it, counted.  A step to catch up to: a checked truth of that step
        came more than WINDOW steps past the newest we have after our inbox turned messages away; the caller closes
        the steps before it minus WINDOW (:meth:`Collector._catch_up`) and hands the truth in again."""
        reason = self.scope.reject(msg)
        if reason is not None:
            self.drops[reason] += 1
        elif isinstance(msg, Truth):
            far = self._take_truth(msg)
            if far is not None:
                return far
            if self._end_recheck and not self.bus.queued(keys.truth(self.run)):
                for _ in range(self._end_recheck):
                    self._judge_end()
                self._end_recheck = 0
        elif isinstance(msg, NodeState):
            self._take_state(key, msg)
        elif isinstance(msg, End):
            self._take_end(key, msg)
        else:
            self.drops["unexpected-type"] += 1
        return None

    def overflowed(self, key: str, msg: Message) -> None:
        """The bus dropped ``msg`` (on ``key``) for us (inbox full): our loss, never the sender's silence.  Only
        on its sender's own key: an insider flooding its state key with another node's states or with truths
        must not make that node's silence, or a truth never sent, read as our loss.  Transport thread: note only."""
        if isinstance(msg, NodeState) and key == keys.node_state(self.run, msg.node):
            self._lost_notes.append((msg.step, msg.node))
        elif isinstance(msg, Truth) and key == keys.truth(self.run):
            self._lost_notes.append((msg.step, None))

    def take_lost(self, everything: bool = False) -> None:
        """Notes of steps within WINDOW of the newest truth into ``lost`` (never allocate per a step we were
        told); later ones stay noted (``everything``: at the end, each of the run's steps)."""
        far = self.sc.steps if everything else max(self.head, self.closed) + WINDOW
        later = []
        while self._lost_notes:
            k, node = self._lost_notes.popleft()
            if k > far:
                later.append((k, node))
            elif self.closed < k <= self.sc.steps and (node is None or node in self.node_cfg):
                self.lost.setdefault(k, set()).add(node)
        self._lost_notes.extend(later)

    def _held(self, n: int) -> None:
        self.open_node_steps += n
        self.peak_open_node_steps = max(self.peak_open_node_steps, self.open_node_steps)

    def _take_truth(self, msg: Truth) -> int | None:
        k = msg.step
        if k <= self.closed:
            self.drops["truth-after-close"] += 1
            return None
        if k > max(self.head, self.closed) + WINDOW:
            if not self.behind() or truth_problem(self.sc, msg, self.prev_truth):
                self.drops["truth-ahead"] += 1  # never allocate per a step number we were told
                return None
            return k
        why = truth_problem(self.sc, msg, self.prev_truth)  # checked again at close, when the previous truth is surely known
        if why:
            self.drops[why] += 1
            return None
        copies = self.truth.setdefault(k, [])
        if msg in copies:
            self.drops["duplicate-truth"] += 1
        elif len(copies) >= MAX_COPIES:
            self.drops["truth-copies"] += 1
        else:
            copies.append(msg)
            self._held(1)
            self.head = max(self.head, k)
        return None

    def _take_state(self, key: str, msg: NodeState) -> None:
        if key != keys.node_state(self.run, msg.node):
            self.drops["state-on-foreign-key"] += 1
            return
        k = msg.step
        if k <= self.closed:
            self.drops["state-after-close"] += 1
            return
        if k > max(self.head, self.closed) + WINDOW:
            self.drops["state-ahead"] += 1
            if self.behind():  # its truth is still to come (we lost the ones between): ours to count, not its silence
                self._lost_notes.append((k, msg.node))
            return
        copies = self.states.setdefault(k, {}).setdefault(msg.node, [])
        if any(same_set(msg, c) for c in copies):
            self.drops["duplicate-state"] += 1  # the same ellipsoid: the first copy is the one recorded
        elif len(copies) >= MAX_COPIES:
            self.drops["state-copies"] += 1
        else:
            copies.append(msg)
            self._held(1)

    def _take_end(self, key: str, msg: End) -> None:
        if key != keys.end(self.run) or msg.steps != self.sc.steps:
            self.drops["end-not-scheduled"] += 1
            return
        # kept, and it counts once the last step's truth is here.  Over Zenoh the End may overtake the last truth
        # (another key): that is ordering, not hostility; an End before the step before the last is early, and so
        # is one whose last truth never comes (counted at the end).  Truths still queued here came before it: the
        # pump serves keys in turn, so the End overtook them in our own inbox (a collector behind a fast run), and
        # it is judged once they are handled
        self.end = msg
        if self.bus.queued(keys.truth(self.run)):
            self._end_recheck += 1
        else:
            self._judge_end()

    def _judge_end(self) -> None:
        """Count the kept End as early if the truth it should follow is still far off (and not lost here)."""
        if self.sc.steps not in self.truth and max(self.head, self.closed) < self.sc.steps - 1 and not self.overloaded():
            self.drops["end-early"] += 1
            self._end_early = True

    def end_never_met(self) -> None:
        """At the run's end: a kept End whose last step never came is early (unless we lost it ourselves)."""
        if self.end is not None and not self._end_early and self.sc.steps not in self.truth and self.closed < self.sc.steps and not self.overloaded():
            self.drops["end-early"] += 1

    @property
    def ended(self) -> End | None:
        """The vehicle's End, once the scheduled last step's truth has arrived too."""
        if self.end is None or (self.sc.steps not in self.truth and self.closed < self.sc.steps):
            return None
        return self.end

    def overloaded(self) -> bool:
        """Whether our own inbox turned messages away (we fell behind): a truth missing then may be one we
        lost, which is our trouble (counted as such), not the End's."""
        return bool(self.bus.dropped["inbox-full"] or self.bus.dropped["inbox-evicted"])

    def behind(self) -> bool:
        """Real time, and our own inbox turned messages away: the clock may have gone on more than WINDOW
        steps past the newest truth we have (a collector stopped, or far behind)."""
        return self.realtime and self.overloaded()

    # ------------------------------------------------------------ an open step

    def reported(self, k: int, alive_only: bool) -> bool:
        """Every node (``alive_only``: every one the vehicle heard, with a reading) has a state of step k here."""
        copies = self.truth.get(k)
        want = frozenset(copies[0].alive) if alive_only and copies and k > 0 else self.scope.ids
        if alive_only and self.truth.get(k + 1):
            # the next truth's alive list is who the vehicle heard at k: a node it gave up on (killed, to
            # rejoin later) is not waited for, else progress stalls until WINDOW and a rejoin waits on it
            want = want.intersection(self.truth[k + 1][0].alive)
        if copies and copies[0].no_reading:
            want = want - {i for i in copies[0].no_reading if self.sc.silent_without_reading(i, k)}  # it publishes nothing for the step
        return want <= self.states.get(k, {}).keys()  # (asked per message in lockstep: no set built of the run's ids)

    def lost_truth(self, k: int) -> bool:
        """Our inbox dropped step k's truth and no copy came: nothing of the step can be judged."""
        return not self.truth.get(k) and None in self.lost.get(k, ())

    def judged_truth(self, k: int) -> Truth | None:
        """The one copy of step k's truth consistent with the scenario and the previous truth, or None."""
        good = []
        for t in self.truth.get(k, []):
            why = chain_problem(self.sc, t, self.prev_truth)  # (its own part it passed when taken in: _take_truth)
            if why:
                self.drops[why] += 1
            else:
                good.append(t)
        if len(good) > 1:
            self.drops["truth-conflict"] += len(good)  # cannot tell the vehicle's: judge the step on none
            return None
        return good[0] if good else None

    def judged_states(self, k: int, tr: Truth | None) -> tuple[dict[int, NodeState], frozenset[int]]:
        """Per node the copy of its state of step k to record (absent: none can be its own), and the nodes whose copy
        is one of several that can (contested)."""
        judged, contested = {}, set()
        for i in self.sc.ids:
            copies = self.states.get(k, {}).get(i, [])
            good = copies if tr is None else [st for st in copies if not self._mismatch(i, st, tr)]
            if tr is not None and len(good) > 1:
                self.drops["state-conflict"] += len(good)
            if good:
                judged[i] = good[0]
                if len(good) > 1:
                    contested.add(i)
        return judged, frozenset(contested)

    def _mismatch(self, i: int, st: NodeState, tr: Truth) -> bool:
        why = state_mismatch(self.node_cfg[i], st, tr)
        if why:
            self.drops[why] += 1
        return bool(why)

    def forget(self, k: int, truth: Truth | None) -> None:
        """Step k is closed (``truth``: its judged truth, None: none, or closed unjudged): nothing of it is kept."""
        self.lost.pop(k, None)
        held = self.states.pop(k, {})
        self.open_node_steps -= len(self.truth.pop(k, [])) + sum(map(len, held.values()))
        self.prev_truth = truth
        self.closed = k
