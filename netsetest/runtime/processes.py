"""Main loops of the role processes over any bus (used by ``netsetest vehicle|node|collector``).

Start-up barrier: every role repeats :class:`Ready` until it is started, every 0.1 s and at once when
it hears a role for the first time (so a newcomer hears it without waiting for the period, and its
``seen_all`` goes out as soon as it holds; a few hops, not a few periods); a role sets ``seen_all`` once it
has heard every role it exchanges messages with (the vehicle and the collector: everyone; a node: the
vehicle, the collector and its in- and out-neighbours).  The vehicle publishes step 0 when every node
and the collector report ``seen_all`` — by then every subscription is known where it matters.  A node
listens to its peers' Ready only: with everyone hearing everyone, N roles' Ready every 0.1 s are N²·10
messages a second to decode (≈90 000 at 96 nodes), which kept a 96-node run from ever starting.

Lockstep: the vehicle publishes step k+1 once every alive node has published step k and the collector
has acknowledged step k+1−``ack_window`` (roles/flow.py; it waits for the collector up to the stall limit:
the launcher ends the run if the collector dies); a node silent for ``node_timeout`` s is declared dead and
the run goes on without it.  A node waits for its expected
neighbours at most ``neighbour_timeout`` s, then proceeds without the missing ones.
Real time: the vehicle publishes a step every τs; nodes step as soon as their input arrives.
"""

from __future__ import annotations

import ctypes
import math
import os
import signal
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.messages import Message, Ready
from netsetest.profile import PhaseProfile, observe_bus, observe_node
from netsetest.records.meta import RunMeta
from netsetest.roles.node import Node
from netsetest.runtime.gc_policy import long_run
from netsetest.runtime.report import EXIT_BAD_INPUT, EXIT_COLLECTOR_STALLED, EXIT_VIOLATION, exit_code, log, record_sink, write_summary
from netsetest.runtime.rolespec import CollectorSpec, NodeSpec, ScenarioSpec, VehicleSpec, ZenohSpec
from netsetest.runtime.stops import StopRequests
from netsetest.runtime.timeouts import READING_POLL, READING_WAIT

if TYPE_CHECKING:  # a node process never loads the vehicle and the collector (memory: docs/performance-history.md)
    from netsetest.bus.zenoh_bus import ZenohBus
    from netsetest.records.summary import RunSummary, StopCause
    from netsetest.roles.collector import Collector
    from netsetest.roles.vehicle import Vehicle
    from netsetest.runtime.channel import ChannelWriter

READY_PERIOD_S = 0.1
IDLE_WAIT_S = 1.0  # a started node with nothing due sleeps until a message arrives (or this long)
REALTIME_SETTLE_S = 0.5  # real time: from "all ready" to step 0, for the start-up's tail of work to drain
EXIT_STOPPED = 128 + signal.SIGTERM  # a role stopped by SIGTERM/SIGINT
REALTIME_CLOSE_BATCH = 10  # real time: steps the collector closes between two looks at its bus (a few ms each)
REALTIME_DRAIN_PUMPS = 50  # real time: pumps that empty the collector's bus before it judges (a flood cannot hold it there)
END_GRACE_S = 2.0  # the collector's wait, after the End, for the last states (they travel on other keys)
CRASH_FLUSH_S = 0.2  # --crash-after: time for the last state to leave before SIGKILL
STALL_S = 1.0  # a turn of the collector's loop this late (it pumps every 0.05 s) is a stall: the process did not run
STALL_LOG_S = 10.0  # a stall this long is logged
LEASE_RISK = 0.75  # a process silent this part of the lease may have lost its session: Zenoh sends a keep-alive only
# every quarter of it when nothing else goes out, so the router may have heard nothing for up to a quarter more


# The environment of every role process, set by the launchers (``netsetest run``, the benchmark); a
# value the user already exported wins.  One BLAS thread: a node's algebra is 3×3 to 20×20, and a
# hundred processes must not each start one BLAS thread per core.  Two malloc arenas instead of one
# per thread (Zenoh's threads).  Zenoh's rx runtime with one worker thread instead of two (the others
# have one already); a role handles a few messages per step.  Syntax: zenoh-runtime's ZENOH_RUNTIME (RON).
ROLE_ENV = {"OPENBLAS_NUM_THREADS": "1", "MALLOC_ARENA_MAX": "2", "ZENOH_RUNTIME": "(rx: (worker_threads: 1))"}


def role_env(base: Mapping[str, str] | None = None) -> dict[str, str]:
    """``base`` (default: this process's environment) with :data:`ROLE_ENV` where it sets nothing."""
    env = dict(os.environ if base is None else base)
    for name, value in ROLE_ENV.items():
        env.setdefault(name, value)
    return env


class Stop(Exception):
    """SIGTERM/SIGINT reached a role process: close the bus and leave."""


def install_signal_handlers() -> None:
    def handler(signum: int, frame: object) -> None:
        raise Stop(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, handler)
    signal.signal(signal.SIGINT, handler)


class StallWatch:
    """The collector's own stalls: turns of its loop that came :data:`STALL_S` or more late (SIGSTOP, a swapping
    machine).  A stall is not the vehicle's silence (:meth:`turn` returns it, to be left out of the idle time); one
    of ``lease`` s or more lost the collector's session (the router closed it, with what was in flight to it), and
    one of :data:`LEASE_RISK` of it may have (:attr:`session_at_risk`, until a message comes)."""

    def __init__(self, lease: float, now: float) -> None:
        self.lease, self.last = lease, now
        self.longest = 0.0  # the longest stall of the run [s]
        self.step: int | None = None  # the step checked before it
        self.since_message = 0.0  # the longest stall since a message last came

    def turn(self, now: float, step: int) -> float:
        """A turn of the loop at ``now``, ``step`` checked: the stall before it [s] (0.0: none)."""
        gap, self.last = now - self.last, now
        if gap < STALL_S:
            return 0.0
        if gap > self.longest:
            self.longest, self.step = gap, step
        self.since_message = max(self.since_message, gap)
        if gap >= STALL_LOG_S:
            log("collector", f"stalled {gap:.0f} s after step {step} (the process was stopped, or the machine swapping)")
        return gap

    def heard(self) -> None:
        """A message came: whatever stalled before, the session works."""
        self.since_message = 0.0

    @property
    def session_at_risk(self) -> bool:
        return self.since_message >= LEASE_RISK * self.lease


def release_free_memory() -> None:
    """Give the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing where it is missing).

    A role compiles and imports its modules before it opens its session: what the imports freed stays
    resident in the heap's free lists (≈1.4 MB in a node), and the session and the run come on top of it,
    so it adds to the process' peak RSS (docs/performance-history.md, *Imports and memory*).  Call once, after
    the imports and before the bus opens (no other thread yet); the heap refills as the role needs.
    """
    trim = getattr(ctypes.CDLL(None), "malloc_trim", None)  # the symbols already loaded: libc's
    if trim is not None:
        trim(0)


class Barrier:
    """Tracks Ready messages of the other roles and repeats our own until we are started."""

    def __init__(self, bus: Bus, run_id: str, me: Ready, others: set[tuple[str, int | None]], lazy: bool = False) -> None:
        """``lazy``: Ready messages do not wake the role (a node: it ticks every READY_PERIOD_S until started)."""
        self.bus, self.run, self.me, self.others = bus, run_id, me, others
        self.heard: set[tuple[str, int | None]] = set()
        self.heard_at: dict[tuple[str, int | None], float] = {}  # last Ready (a restarted node's comes late)
        self.complete: set[tuple[str, int | None]] = set()  # roles that reported seen_all
        self.last_sent = 0.0
        self.sent_all = False  # a Ready of ours with seen_all has gone out
        self.prompt = False  # a role was heard for the first time: answer now, not at the next period
        for role, node in sorted(others, key=str):
            bus.subscribe(keys.ready_of(run_id, keys.role_name(role, node)), self.on_message, lazy=lazy)

    def on_message(self, key: str, msg: Message) -> None:
        if not isinstance(msg, Ready):
            self.bus.drop("unexpected-type")
            return
        if key != keys.ready_of(self.run, keys.role_name(msg.role, msg.node)):
            self.bus.drop("ready-wrong-key")  # a role speaks for itself only (the ACL allows its own key)
            return
        who = (msg.role, msg.node)
        self.prompt |= who not in self.heard  # it needs our Ready too; and our seen_all may have just become true
        self.heard.add(who)
        self.heard_at[who] = time.monotonic()
        if msg.seen_all:
            self.complete.add(who)

    @property
    def quiet(self) -> bool:
        """Nothing more to say: our seen_all went out and every role we wait for reported its own (so each
        heard us; the transport is reliable).  Repeating Ready then only loads the start of the run: a
        hundred nodes ticking cost ≈0.8 of a core, into step 0."""
        return self.sent_all and self.others <= self.complete

    def next_due(self) -> float | None:
        """When our next Ready is due (None: :attr:`quiet`, none is)."""
        return None if self.quiet else self.last_sent + READY_PERIOD_S

    def tick(self, now: float, **changes: object) -> None:
        if self.prompt or (not self.quiet and now - self.last_sent >= READY_PERIOD_S):
            seen_all = self.others <= self.heard
            self.bus.publish(keys.ready_of(self.run, keys.role_name(self.me.role, self.me.node)), self.me.model_copy(update={"seen_all": seen_all, **changes}))
            self.last_sent = now
            self.prompt = False
            self.sent_all |= seen_all


def _all_roles(sc: Scenario) -> set[tuple[str, int | None]]:
    return {("vehicle", None), ("collector", None)} | {("node", i) for i in sc.ids}


def node_peers(sc: Scenario, node_id: int) -> set[tuple[str, int | None]]:
    """The roles node ``node_id`` exchanges messages with: vehicle, collector, in- and out-neighbours."""
    neighbours = set(sc.node(node_id).in_weights) | {n.id for n in sc.nodes if node_id in n.in_weights}
    return {("vehicle", None), ("collector", None)} | {("node", j) for j in neighbours - {node_id}}


@long_run()  # the garbage collector's policy for a run (runtime/gc_policy.py)
def run_vehicle(spec: VehicleSpec, sc: Scenario, bus: Bus) -> int:
    """The vehicle's loop.  ``spec.await_rejoin``: (node, step) pairs; in lockstep, step+1 waits (at most
    ``node_timeout``) for the node.  ``spec.quiet``: no line on success (errors are still logged).  Lockstep waits
    for the collector's acknowledgments (``spec.ack_window``, roles/flow.py) at most ``spec.zenoh.stall_limit`` without
    one: past it the collector is stopped or has lost its session, and the vehicle ends the run (:data:`EXIT_COLLECTOR_STALLED`)."""
    from netsetest.roles.vehicle import Vehicle

    run_id, realtime = spec.zenoh.resolved_run_id, spec.clock == "realtime"
    vehicle = Vehicle(sc, bus, run_id, spec.signals, spec.seed, realtime=realtime, window=spec.ack_window)
    barrier = Barrier(bus, run_id, Ready(role="vehicle"), _all_roles(sc) - {("vehicle", None)})
    if not _everyone_ready(barrier, bus, spec.start_timeout):
        return EXIT_VIOLATION
    barrier.tick(time.monotonic() + READY_PERIOD_S)  # a last Ready with seen_all for everyone
    if not spec.quiet:
        log("vehicle", f"all {len(sc.ids)} nodes and the collector are ready; clock {spec.clock}")
    code = _realtime(vehicle, bus, sc.tau_s) if realtime else _lockstep(spec, vehicle, barrier, bus)
    if code == 0:
        time.sleep(0.2)  # let End reach everyone before the session closes
    return code


def _everyone_ready(barrier: Barrier, bus: Bus, start_timeout: float) -> bool:
    """The start-up barrier: until every other role reported ``seen_all`` (False, and logged, after ``start_timeout``)."""
    t0 = time.monotonic()
    while not (barrier.others <= barrier.complete):
        barrier.tick(time.monotonic())
        bus.pump(timeout=0.02)
        if time.monotonic() - t0 > start_timeout:
            missing = sorted(f"{r}{'' if n is None else ' ' + str(n)}" for r, n in barrier.others - barrier.complete)
            log("vehicle", f"start-up timed out after {start_timeout:.0f} s; not ready: {', '.join(missing)}")
            return False
    return True


def _realtime(vehicle: Vehicle, bus: Bus, tau_s: float) -> int:
    """A step every ``tau_s`` whatever the nodes did."""
    # the machine is still busy with the start-up (the last roles' warm-up, their sessions, the Ready traffic)
    # when everyone is ready; a real-time clock must not start into that (a hundred nodes missed step 0 and 1 by
    # tens of ms): the deadlines count from step 0
    settle_until = time.monotonic() + REALTIME_SETTLE_S
    while (left := settle_until - time.monotonic()) > 0:
        bus.pump(timeout=min(left, 0.05))
    vehicle.advance()
    next_tick = time.monotonic()
    while not vehicle.done:
        bus.pump(timeout=max(0.0, min(next_tick + tau_s - time.monotonic(), 0.05)))
        if time.monotonic() >= next_tick + tau_s:
            next_tick += tau_s
            vehicle.advance()
    return 0


def _lockstep(spec: VehicleSpec, vehicle: Vehicle, barrier: Barrier, bus: Bus) -> int:
    """The next step once every alive node published this one (a node silent ``node_timeout`` is dead), a
    rejoining node is back (:class:`RejoinHolds`), the collector's window is open (roles/flow.py; the run ends
    once it held past the stall limit) and ``pace`` has passed."""
    from netsetest.roles.flow import Hold

    node_timeout = spec.node_timeout
    holds, hold = RejoinHolds(spec.await_rejoin), Hold(node_timeout, spec.zenoh.stall_limit)
    dead_at: dict[int, float] = {}  # node → when the vehicle went on without it
    vehicle.advance()
    t_step = time.monotonic()
    while not vehicle.done:
        bus.pump(timeout=min(0.05, max(0.0, t_step + node_timeout - time.monotonic())))
        now = time.monotonic()
        if not vehicle.ready_to_advance():
            if now - t_step > node_timeout:
                log("vehicle", f"step {vehicle.k}: no state from node(s) {sorted(vehicle.waiting_for())} in {node_timeout:g} s; going on without")
                dead_at.update((n, now) for n in vehicle.waiting_for())
                vehicle.advance()
                t_step = now
        elif holds.holding(vehicle, barrier, dead_at, now - t_step, node_timeout):
            pass
        elif not vehicle.window_open():  # the collector is behind: hold, blame no node
            held = hold.held(now, vehicle.acked)
            if held == "tell":
                log("vehicle", f"step {vehicle.k + 1}: waiting for the collector (it acknowledged step {vehicle.acked})")
            elif held == "stalled":
                log("vehicle", f"step {vehicle.k + 1}: the collector acknowledged nothing for {spec.zenoh.stall_limit:g} s (--stall-limit): ending the run")
                return EXIT_COLLECTOR_STALLED
            t_step = now  # the nodes' time starts when the step is published
        elif now - t_step >= spec.pace:  # lockstep paced for watching
            vehicle.advance()
            t_step = now
            hold.released()
    return 0


class RejoinHolds:
    """Lockstep ``--await-rejoin NODE@R``: step R+1 waits until the restarted node has announced itself
    (a Ready heard after the vehicle went on without it), then step R+2 until its first (rejoin) state of
    step R+1 is in, so that it is expected again at once; each wait at most ``node_timeout``."""

    def __init__(self, pairs: Sequence[tuple[int, int]]) -> None:
        self.ready: dict[int, set[int]] = {}  # step → nodes whose Ready we wait for
        self.state: dict[int, set[int]] = {}  # step → nodes whose state of that step we wait for
        for node, step in pairs:
            self.ready.setdefault(step, set()).add(node)

    def holding(self, vehicle: Vehicle, barrier: Barrier, dead_at: dict[int, float], waited: float, node_timeout: float) -> bool:
        k = vehicle.k

        def back(node: int) -> bool:
            return node in vehicle.alive or barrier.heard_at.get(("node", node), -math.inf) > dead_at.get(node, math.inf)

        pending = sorted({n for n in self.ready.get(k, ()) if not back(n)} | {n for n in self.state.get(k, ()) if n not in vehicle.heard.get(k, set())})
        if not pending:
            for node in self.ready.pop(k, ()):
                self.state.setdefault(k + 1, set()).add(node)
            self.state.pop(k, None)
            return False
        if waited > node_timeout:
            log("vehicle", f"step {k}: rejoining node(s) {pending} not back in {node_timeout:g} s; going on without")
            self.ready.pop(k, None)
            self.state.pop(k, None)
            return False
        return True


@long_run()  # the garbage collector's policy for a run (runtime/gc_policy.py)
def run_node(spec: NodeSpec, sc: Scenario, bus: Bus) -> int:
    """A node's loop.  ``spec.crash_after``: SIGKILL this process right after publishing that step (``run --kill``: exactly there)."""
    node_id, run_id, realtime, neighbour_timeout, crash_after = (
        spec.id,
        spec.zenoh.resolved_run_id,
        spec.clock == "realtime",
        spec.neighbour_timeout,
        spec.crash_after,
    )
    # lockstep waits for its neighbours and readings: they go through the inbox, whose step-aware bound
    # keeps the awaited one under a flood of the key (a ring buffer drops the oldest: an insider flooding
    # its own state key made its neighbours wait out their timeout every step).  Real time never waits for
    # a neighbour and waits for the readings within a budget: both lazy, so the N readings of a step under
    # max_faulty cost the node a few polls, not N callbacks and wake-ups
    # the step's part its readings do not enter is solved while they cross the network (the same result)
    prof = PhaseProfile() if spec.profile is not None else None  # --profile: the bus and the node observed (netsetest/profile.py); else nothing on their path
    if prof is not None:
        observe_bus(bus, prof)  # (before the node subscribes)
    node = Node(sc, node_id, bus, run_id, spec.variant, rejoin=spec.rejoin, objective=spec.objective, lazy=realtime, early=True)
    profiled = observe_node(node, prof) if prof is not None else None
    role = f"node {node_id}"
    barrier = Barrier(bus, run_id, Ready(role="node", node=node_id), node_peers(sc, node_id), lazy=True)
    reading_wait = (READING_WAIT * sc.tau_s, READING_POLL * sc.tau_s) if realtime else None  # budget, poll period
    barrier.tick(time.monotonic())  # announce ourselves first: the others start meanwhile
    node.warm_up()  # before we can report seen_all, so before the run can start
    while not node.ended:
        if node.k < 0:
            barrier.tick(time.monotonic())  # until started
        bus.pump(timeout=_node_wait(node, barrier.next_due(), neighbour_timeout, reading_wait, time.monotonic()))
        while True:
            now = time.monotonic()
            if realtime:  # step with whatever neighbours have arrived; the readings of the step are worth a short wait
                node.give_up = not node.awaiting_readings() or (node.waiting_since is not None and now - node.waiting_since > READING_WAIT * sc.tau_s)
            elif node.waiting_since is not None and now - node.waiting_since > neighbour_timeout:
                log(role, f"step {node.k + 1}: neighbour(s) {node.missing()} silent for {neighbour_timeout:g} s; going on without")
                node.give_up = True
            if not node.try_step(now):
                break
            if node.k == crash_after:
                time.sleep(CRASH_FLUSH_S)  # the state of step k leaves before the crash
                log(role, f"killing myself (SIGKILL) after step {node.k} as asked")
                os.kill(os.getpid(), signal.SIGKILL)
    if spec.profile is not None and prof is not None and profiled is not None:
        prof.write(spec.profile, f"node-{node_id}", profiled())
    return 0


def _node_wait(node: Node, ready_due: float | None, neighbour_timeout: float, reading_wait: tuple[float, float] | None, now: float) -> float:
    """How long a node may block for its next message: until its next Ready is due (not started yet; None:
    none is due, :attr:`Barrier.quiet`, and the step-0 input will wake it);
    lockstep, waiting for a neighbour: until the neighbour deadline (its state wakes the node); real time
    (``reading_wait``: the budget and the poll period in s), waiting for a reading: the poll period (readings
    are lazy) or until the budget is spent if sooner; else :data:`IDLE_WAIT_S`.  Event-driven otherwise: a
    hundred idle nodes polling every few ms would keep two cores busy waking up."""
    if node.k < 0:
        return IDLE_WAIT_S if ready_due is None else max(0.0, ready_due - now)
    if node.waiting_since is not None:
        if reading_wait is None:
            return max(0.0, node.waiting_since + neighbour_timeout - now)
        budget, poll = reading_wait
        return max(0.0, min(node.waiting_since + budget - now, poll))
    return IDLE_WAIT_S


@long_run()  # the garbage collector's policy for a run (runtime/gc_policy.py)
def run_collector(spec: CollectorSpec, sc: Scenario, bus: Bus, meta: RunMeta, on_summary: Callable[[RunSummary], None] | None = None) -> int:
    """The collector's loop: judge until End (or the vehicle is gone, or SIGTERM, or it stalled past its session's
    lease, ``spec.zenoh.stall_limit``), then write the summary (the steps checked before a signal or a stall)."""
    with StopRequests() as stop:  # from here a signal is acted on between two turns of the loop, never mid-step
        return _collect(spec, sc, bus, meta, on_summary, stop)


def _collect(spec: CollectorSpec, sc: Scenario, bus: Bus, meta: RunMeta, on_summary: Callable[[RunSummary], None] | None, stop: StopRequests) -> int:
    """:func:`run_collector`'s set-up, loop and summary, ``stop`` the signals it was sent."""
    from netsetest.roles.collector import Collector
    from netsetest.runtime.channel import ChannelWriter, RunFinished

    run_id = spec.zenoh.resolved_run_id
    sink, _ = record_sink(spec.record)  # opened now: the record grows step by step and survives a crash
    collector = Collector(sc, bus, run_id, sink, realtime=spec.clock == "realtime")
    if sink is not None:
        sink.meta(meta)
    barrier = Barrier(bus, run_id, Ready(role="collector"), _all_roles(sc) - {("collector", None)})
    channel = ChannelWriter(spec.channel_fd) if spec.channel_fd is not None else None  # to the launcher: progress, summary
    stalls = StallWatch(spec.zenoh.stall_limit, time.monotonic())
    stopped = _judge_until_end(collector, bus, barrier, channel, stalls, stop, spec.idle_timeout)
    # stopped by a signal or our stall: the steps checked so far (the later ones are cut short, not a node's silence)
    through = collector.progress if stopped in ("interrupted", "collector stalled") else None
    summary = collector.finish(meta, stopped=stopped, through=through, stall=(stalls.longest, stalls.step))
    write_summary(summary, spec.summary_json)
    if channel is not None:
        channel.send(RunFinished(summary))
        channel.close()
    if on_summary:
        on_summary(summary)
    return EXIT_STOPPED if stopped == "interrupted" else exit_code(summary)


def _judge_until_end(
    collector: Collector, bus: Bus, barrier: Barrier, channel: ChannelWriter | None, stalls: StallWatch, stop: StopRequests, idle_timeout: float
) -> StopCause | None:
    """The collector's loop: messages in, ready steps judged, progress out, until the vehicle's End (None), or why
    it stopped before: a signal, its own stall past the lease, no message for ``idle_timeout`` s."""
    last_msg = stalls.last
    while True:
        now = time.monotonic()
        gap = stalls.turn(now, collector.progress)
        last_msg += gap  # our own stall is not the vehicle's silence
        stopped = _stop_requested(gap, stalls, stop)
        if stopped is not None:
            return stopped
        if not collector.started:
            barrier.tick(now)
        if _take_messages(bus, collector.realtime):
            last_msg = time.monotonic()
            stalls.heard()
        if collector.realtime:
            collector.close_ready(REALTIME_CLOSE_BATCH)
        if channel is not None:
            channel.step(collector.progress)
        if (end := collector.ended) is not None:
            _await_last_states(collector, bus, end.steps)
            if channel is not None:
                channel.step(collector.progress)
            return None
        if now - last_msg > idle_timeout:
            return _gone_quiet(stalls, idle_timeout)


def _stop_requested(gap: float, stalls: StallWatch, stop: StopRequests) -> StopCause | None:
    """Our stall of ``gap`` s past the lease (the router closed our session, and what was in flight to us is lost:
    the run cannot go on), or a signal (after a stall that may have cost our session, the stall is the cause)."""
    if gap >= stalls.lease:
        log("collector", f"stalled {gap:.0f} s, past the stall limit ({stalls.lease:g} s, Zenoh's lease): ending the run")
        return "collector stalled"
    if stop.signal is not None:
        log("collector", f"stopped by {stop.signal}; writing what was checked")
        return "collector stalled" if stalls.session_at_risk else "interrupted"
    return None


def _take_messages(bus: Bus, realtime: bool) -> bool:
    """A pump of at most 0.05 s; real time, then all off the bus before judging (its inbox is bounded).  Whether a
    message came."""
    if not bus.pump(timeout=0.05):
        return False
    for _ in range(REALTIME_DRAIN_PUMPS if realtime else 0):
        if not bus.pump(timeout=0.0):
            break
    return True


def _await_last_states(collector: Collector, bus: Bus, last: int) -> None:
    """The End overtakes the last states on other paths: wait until they are in (or END_GRACE_S)."""
    t_end = time.monotonic()
    while collector.progress < last and time.monotonic() - t_end < END_GRACE_S:
        bus.pump(timeout=0.05)
        if collector.realtime:
            collector.close_ready()


def _gone_quiet(stalls: StallWatch, idle_timeout: float) -> StopCause:
    """No message for ``idle_timeout`` s: the vehicle is gone, or our session was lost while we stalled."""
    stopped: StopCause = "collector stalled" if stalls.session_at_risk else "vehicle gone"  # (nothing came since: it was lost)
    why = "our session was lost while we stalled" if stopped == "collector stalled" else "the vehicle is gone"
    log("collector", f"no message for {idle_timeout:g} s: {why}; writing what was received")
    return stopped


# ---------------------------------------------------------------- a role process from its spec


def role_bus(who: str, zenoh: ZenohSpec) -> ZenohBus:
    """The Zenoh bus of role ``who`` (its certificate name, keys.role_name) as ``zenoh`` says: a peer of the open
    mesh, or an mTLS client of the run's router with its own credentials (BusError, CredentialsError)."""
    from netsetest.bus.zenoh_bus import ZenohBus
    from netsetest.runtime.security import client_settings, identity

    settings = client_settings(identity(zenoh.credentials, who)) if zenoh.credentials else None
    return ZenohBus(zenoh.mode, list(zenoh.listen), list(zenoh.connect), base_file=zenoh.config, settings=settings, lease_s=zenoh.stall_limit)


def serve_role(name: str, who: str, scenario: ScenarioSpec, zenoh: ZenohSpec, body: Callable[[Scenario, Bus], int]) -> int:
    """Run a role process: load its scenario (ConfigError to the caller), open its bus, run ``body``;
    ``name`` for its log lines, ``who`` its certificate name (keys.role_name).  Exit code: ``body``'s;
    EXIT_BAD_INPUT when the bus cannot open; :data:`EXIT_STOPPED` on SIGTERM/SIGINT."""
    from netsetest.bus.zenoh_bus import BusError
    from netsetest.runtime.security import CredentialsError

    sc = scenario.load()
    install_signal_handlers()
    release_free_memory()
    try:
        bus = role_bus(who, zenoh)
    except (BusError, CredentialsError) as exc:
        log(name, str(exc))
        return EXIT_BAD_INPUT
    except Stop as why:  # Ctrl-C while the run is still starting: no traceback (the process' exit drops a half-open session)
        log(name, f"stopped by {why} while opening its session")
        return EXIT_STOPPED
    try:
        return body(sc, bus)
    except Stop as why:
        log(name, f"stopped by {why}")
        return EXIT_STOPPED
    finally:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, signal.SIG_IGN)  # leaving: a late signal must not cut the session's close short
        bus.close()


def vehicle_main(spec: VehicleSpec) -> int:
    """``netsetest vehicle``."""
    return serve_role("vehicle", keys.role_name("vehicle"), spec.scenario, spec.zenoh, lambda sc, bus: run_vehicle(spec, sc, bus))


def node_main(spec: NodeSpec) -> int:
    """``netsetest node``: an id not in the topology is a ConfigError (exit 2)."""

    def body(sc: Scenario, bus: Bus) -> int:
        sc.node(spec.id)  # unknown id → ConfigError, exit 2
        return run_node(spec, sc, bus)

    return serve_role(f"node {spec.id}", keys.role_name("node", spec.id), spec.scenario, spec.zenoh, body)


def collector_main(spec: CollectorSpec, on_summary: Callable[[RunSummary], None] | None = None) -> int:
    """``netsetest collector``: the run's meta data from the spec, ``on_summary`` called with the summary."""
    from netsetest.runtime.inmemory import run_meta
    from netsetest.runtime.security import SECURITY_INSECURE, SECURITY_MTLS

    def body(sc: Scenario, bus: Bus) -> int:
        meta = run_meta(sc, "zenoh", spec.clock, spec.signals, spec.variant, spec.seed, spec.zenoh.resolved_run_id, spec.objective)
        meta = meta.with_security(SECURITY_MTLS if spec.zenoh.credentials else SECURITY_INSECURE)
        return run_collector(spec, sc, bus, meta, on_summary)

    return serve_role("collector", keys.role_name("collector"), spec.scenario, spec.zenoh, body)
