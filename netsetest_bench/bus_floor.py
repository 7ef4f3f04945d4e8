"""Zenoh's floor under a node (``netsetest bench --only node``, issue 31): a bare bus process.

A process that is a ring node's bus and nothing else: netsetest's own :class:`~netsetest.bus.zenoh_bus.ZenohBus`,
opened as the node's (``processes.role_bus``: the node's certificate, a client of a router opened as ``netsetest
run`` opens it, ``launcher.open_network``, its access control included; or ``--insecure``, a peer), subscribed to
the node's keys as the node subscribes (its input with a callback, its in-neighbours' states lazy, as in real
time, the End key), and publishing the node's state each step.  It receives and sends exactly the node's messages
of a real-time run (τs of the ring), the payloads the node and its peers published in an in-memory run of the
same ring (the same keys, the same sizes), but runs no estimator and no handler: on each input it publishes the
state of that step.  Its process CPU per step (every thread) is what the bus costs a node before the node does
anything: if that alone exceeds a per-step budget, no code of the node's own can meet it.

The rest of the node's world is played by this (the benchmark's) process: one bus per role the node talks to
(the vehicle, its in-neighbours, the collector), each with its own credentials, publishing the node's input and
its neighbours' states every τs and subscribed to the node's state (so the node's puts go where they go in a run:
to the router, or to each subscriber of the peer mesh).  The bare process measures itself (``time.process_time_ns``
and its own thread's ``time.thread_time_ns``) from its :data:`WARM_STEPS`-th step to its last and prints one JSON
line; ``python -m netsetest_bench.bus_floor PAYLOADS NODE-ARGV…`` is that process (the node's own command line,
``NodeSpec.to_argv``).
"""

from __future__ import annotations

import json
import secrets
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec  # a default dependency (the bench must not need the dev extra's msgpack)

from netsetest.bus import keys
from netsetest.bus.base import Bus, Handler, MemoryBus
from netsetest.config.schema import Scenario
from netsetest.messages import Message, Ready
from netsetest.profile import PhaseProfile, observe_bus
from netsetest.runtime.processes import IDLE_WAIT_S, READY_PERIOD_S, REALTIME_SETTLE_S  # the node's and the real-time clock's

if TYPE_CHECKING:
    from netsetest.bus.zenoh_bus import ZenohBus

WARM_STEPS = 2  # steps before the measured window (the first puts, the first wake-ups)
START_TIMEOUT_S = 60.0  # the bare process's start-up (imports, session) on a loaded machine
PAYLOAD_RUN = "mem"  # the run id of the in-memory run the payloads come from (runtime/inmemory.py)
_PAYLOAD_ROOT = f"{keys.ROOT}/{PAYLOAD_RUN}/"
PROFILED = ("decode", "wait", "put")  # the bare process's own thread, by phase (netsetest/profile.py, on in it)
FIGURES = (  # key, what, unit: the rows of the table
    ("process_us", "CPU per step, every thread", "µs"),
    ("thread_us", "… of it its own thread", "µs"),
    ("decode_us", "… … decoding the lazy copies (msgspec, the checks of `messages.decode`)", "µs"),
    ("wait_us", "… … going to sleep and waking up", "µs"),
    ("put_us", "… … the put", "µs"),
    ("rest_us", "… … the rest (the pump: its lazy subscriptions' channels, the inbox; the loop)", "µs"),
    ("threads_us", "… of it the other threads (Zenoh's runtime, TLS, the input's callback)", "µs"),
    ("received", "messages received per step", ""),
    ("sent", "messages sent per step", ""),
    ("per_message_us", "per message received or sent", "µs"),
)


class _CapturingBus(MemoryBus):
    """The in-memory bus, keeping every payload published, by key and step."""

    def __init__(self) -> None:
        super().__init__()
        self.payloads: dict[str, dict[int, bytes]] = {}

    def _send(self, key: str, payload: bytes) -> None:
        step = msgspec.msgpack.decode(payload).get("step")
        if isinstance(step, int):
            self.payloads.setdefault(_rel(key), {})[step] = payload
        super()._send(key, payload)


@dataclass(frozen=True)
class RingPayloads:
    """What node ``node`` of a ring receives and sends per step: each key's payload per step, relative to the
    run's root (``vehicle/input/3``, ``node/2/state``)."""

    node: int
    others: tuple[int, ...]  # its in-neighbours
    steps: int
    by_key: dict[str, dict[int, bytes]]

    def sent(self, step: int) -> bytes:
        return self.by_key[_rel(keys.node_state(PAYLOAD_RUN, self.node))][step]


def _rel(key: str) -> str:
    return key.removeprefix(_PAYLOAD_ROOT)


def median_node(sc: Scenario) -> int:
    """The first node with the median number of in-neighbours (the ring's typical node)."""
    counts = {n.id: len([j for j in n.in_weights if j != n.id]) for n in sc.nodes}
    median = sorted(counts.values())[len(counts) // 2]
    return next(i for i, c in counts.items() if c == median)


def ring_payloads(sc: Scenario, node: int) -> RingPayloads:
    """The payloads of ``node`` and its in-neighbours, step by step, from an in-memory run of ``sc``."""
    from netsetest.runtime.inmemory import run_inmemory

    bus = _CapturingBus()
    run_inmemory(sc, bus=bus, keep=False)
    others = tuple(j for j in sc.node(node).in_weights if j != node)
    wanted = [keys.node_input(PAYLOAD_RUN, node), *(keys.node_state(PAYLOAD_RUN, j) for j in (node, *others))]
    return RingPayloads(node, others, sc.steps, {_rel(k): bus.payloads[_rel(k)] for k in wanted})


# ---------------------------------------------------------------- the bare process


def _ignore(key: str, msg: Message) -> None:
    """No handling: the bus has taken and decoded the copy; the node's handler would start here."""


def subscribe_as_node(bus: Bus, run_id: str, node: int, others: tuple[int, ...], on_input: Handler) -> str:
    """A real-time node's subscriptions and publisher (roles/node.py ``Node.__init__`` with ``lazy=True``, the
    plain ring: no readings): its input with a callback, its in-neighbours' states lazy, End; its state key."""
    bus.subscribe(keys.node_input(run_id, node), on_input)
    for j in others:
        bus.subscribe(keys.node_state(run_id, j), _ignore, lazy=True)
    bus.subscribe(keys.end(run_id), _ignore)
    own = keys.node_state(run_id, node)
    bus.declare_publisher(own)
    return own


def bare_node(bus: ZenohBus, run_id: str, payloads: RingPayloads) -> dict:
    """The bare node's loop on ``bus`` (module doc): its figures over the window, per step."""
    node = payloads.node
    inputs: list[int] = []

    def on_input(key: str, msg: Message) -> None:
        inputs.append(getattr(msg, "step", -1))

    prof = PhaseProfile()  # its thread's phases, as in the node's profiled runs (nothing written)
    observe_bus(bus, prof)  # its decodes and waits, as a profiled node's (before it subscribes)
    own = subscribe_as_node(bus, run_id, node, payloads.others, on_input)
    ready_due = 0.0
    sent = 0
    start: tuple[int, int, int, int] | None = None
    while True:
        if not sent and time.monotonic() >= ready_due:  # until started, as a node
            bus.publish(keys.ready_of(run_id, keys.role_name("node", node)), Ready(role="node", node=node, seen_all=True))
            ready_due = time.monotonic() + READY_PERIOD_S
        bus.pump(timeout=IDLE_WAIT_S if sent else READY_PERIOD_S)  # as a started node waits: woken by its input
        while inputs:
            k = inputs.pop(0)
            if not 0 <= k <= payloads.steps:
                continue
            t = prof.now()
            bus.send_raw(own, payloads.sent(k))  # the node's payload, encoded already
            prof.add("put", t)
            sent += 1
            if k == WARM_STEPS - 1:
                start = (time.process_time_ns(), time.thread_time_ns(), bus.received, sent)
                prof.start_window()
            if k == payloads.steps and start is not None:
                n = payloads.steps - WARM_STEPS + 1
                process, thread = time.process_time_ns() - start[0], time.thread_time_ns() - start[1]
                received, out = (bus.received - start[2]) / n, (sent - start[3]) / n
                phases = prof.report(n)["phases"]
                mine = {f"{p}_us": 1e3 * phases[p]["ms_per_step"] for p in PROFILED}
                return {
                    "steps": n,
                    "process_us": process / 1e3 / n,
                    "thread_us": thread / 1e3 / n,
                    **mine,
                    "rest_us": thread / 1e3 / n - sum(mine.values()),
                    "threads_us": (process - thread) / 1e3 / n,
                    "received": received,
                    "sent": out,
                    "per_message_us": process / 1e3 / n / (received + out) if received + out else float("nan"),
                }


def _payloads_to_file(p: RingPayloads, path: Path) -> None:
    path.write_bytes(msgspec.msgpack.encode({"node": p.node, "others": list(p.others), "steps": p.steps, "by_key": p.by_key}))


def _payloads_from_file(path: Path) -> RingPayloads:
    raw = msgspec.msgpack.decode(path.read_bytes())
    return RingPayloads(raw["node"], tuple(raw["others"]), raw["steps"], {k: {int(s): b for s, b in v.items()} for k, v in raw["by_key"].items()})


def bare_main(argv: list[str]) -> int:
    """``python -m netsetest_bench.bus_floor PAYLOADS NODE-ARGV…``: the bare process; its figures on stdout."""
    from netsetest.bus.zenoh_bus import ZenohBus
    from netsetest.runtime.processes import serve_role
    from netsetest.runtime.rolespec import NodeSpec

    payloads = _payloads_from_file(Path(argv[0]))
    spec = NodeSpec.from_argv(argv[1:])

    def body(sc: Scenario, bus: Bus) -> int:
        assert isinstance(bus, ZenohBus)  # serve_role opens one
        print(json.dumps(bare_node(bus, spec.zenoh.resolved_run_id, payloads)), flush=True)
        return 0

    return serve_role(f"bare node {spec.id}", keys.role_name("node", spec.id), spec.scenario, spec.zenoh, body)


# ---------------------------------------------------------------- the node's world, in this process


def floor_run(topology: Path, payloads: RingPayloads, secured: bool, tmp: Path) -> dict:
    """One bare process between a router opened as ``netsetest run`` opens it (``secured``) or in the open
    peer mesh, and the node's world in this process: its figures (:data:`FIGURES`) and the load before."""
    from netsetest.runtime.launcher import LaunchOptions, Network, open_network, plan_run
    from netsetest.runtime.processes import role_bus, role_env
    from netsetest.runtime.rolespec import NodeSpec, ScenarioSpec

    node, run_id = payloads.node, f"floor{secrets.token_hex(4)}"
    plan = plan_run(LaunchOptions(str(topology), clock="realtime", insecure=not secured, run_id=run_id))
    tau = plan.scenario.tau_s
    # the roles node i exchanges messages with: who (certificate name) → its process name in the network
    world = {"vehicle": "vehicle", "collector": "collector", **{keys.role_name("node", j): f"node{j}" for j in payloads.others}}
    network = open_network(plan, run_id, str(tmp / run_id)) if secured else Network([*world.values(), f"node{node}"], run_id, None)
    load = " ".join(Path("/proc/loadavg").read_text().split()[:3])
    buses: dict[str, ZenohBus] = {}
    proc: subprocess.Popen | None = None
    try:
        heard: list[int] = []
        for who, name in world.items():
            buses[who] = bus = role_bus(who, network.zenoh(name))
            bus.subscribe(keys.node_state(run_id, node), lambda key, msg: None, lazy=True)  # its out-neighbours, the collector, the vehicle
        buses["vehicle"].subscribe(keys.ready_of(run_id, keys.role_name("node", node)), lambda key, msg: heard.append(1))
        buses["vehicle"].declare_publisher(keys.node_input(run_id, node))
        for j in payloads.others:
            buses[keys.role_name("node", j)].declare_publisher(keys.node_state(run_id, j))
        file = tmp / f"payloads-{run_id}.msgpack"
        _payloads_to_file(payloads, file)
        spec = NodeSpec(ScenarioSpec(str(topology)), node, clock="realtime", zenoh=network.zenoh(f"node{node}"))
        proc = subprocess.Popen(
            [sys.executable, "-m", "netsetest_bench.bus_floor", str(file), *spec.to_argv()],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
            text=True,
            env=role_env(),
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while not heard and time.monotonic() < deadline and proc.poll() is None:
            buses["vehicle"].pump(timeout=0.05)
        if not heard:
            return {"secured": secured, "load_before": load, "error": "the bare process never reported ready"}
        time.sleep(REALTIME_SETTLE_S)
        t0 = time.monotonic()
        for k in range(payloads.steps + 1):  # the vehicle's input of step k, then the neighbours' states of step k
            time.sleep(max(0.0, t0 + k * tau - time.monotonic()))
            buses["vehicle"].send_raw(keys.node_input(run_id, node), payloads.by_key[_rel(keys.node_input(PAYLOAD_RUN, node))][k])
            for j in payloads.others:
                buses[keys.role_name("node", j)].send_raw(keys.node_state(run_id, j), payloads.by_key[_rel(keys.node_state(PAYLOAD_RUN, j))][k])
        out, err = proc.communicate(timeout=START_TIMEOUT_S)
        if proc.returncode != 0 or not out.strip():
            return {"secured": secured, "load_before": load, "error": f"exit {proc.returncode}: {err.strip()[-300:]}"}
        return {"secured": secured, "load_before": load, **json.loads(out.strip().splitlines()[-1])}
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        for bus in buses.values():
            bus.close()
        network.close()


def floor_summary(runs: list[dict]) -> dict:
    """Median and range over the runs of each figure (the runs that measured)."""
    ok = [r for r in runs if "error" not in r]
    if not ok:
        return {}
    return {key: {"median": statistics.median(r[key] for r in ok), "min": min(r[key] for r in ok), "max": max(r[key] for r in ok)} for key, _, _ in FIGURES}


if __name__ == "__main__":
    raise SystemExit(bare_main(sys.argv[1:]))
