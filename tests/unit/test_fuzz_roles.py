"""Fuzzing the wire: ``decode`` with arbitrary bytes and msgpack values, and every role's message handler
with every message type on every key (Hypothesis).

A role's handler may drop a message, never raise; what it accepted must not make its next step raise
either.  Messages are mutated from those of a real in-memory run (so they reach deep code paths: a
collector closing steps, a node stepping on a forged neighbour state), one to three fields at a time,
with values of the field's type including extremes.  The short seeded run is part of the normal suite;
for a long run set ``NETSETEST_FUZZ_EXAMPLES`` (e.g. ``NETSETEST_FUZZ_EXAMPLES=20000 pytest
tests/unit/test_fuzz_roles.py``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from netsetest.bus import keys
from netsetest.bus.base import MemoryBus
from netsetest.config.schema import load_topology
from netsetest.messages import SCHEMA_VERSION, BadMessage, Message, Ready, decode, encode
from netsetest.roles.collector import Collector
from netsetest.roles.node import Node
from netsetest.roles.vehicle import Vehicle
from netsetest.runtime.inmemory import run_meta
from netsetest.runtime.processes import Barrier

# paper6 with sensor 3 declared a reference: every message kind, the same-step readings included
PAPER6 = Path(__file__).resolve().parents[2] / "topologies" / "paper6_reference.toml"
FUZZ_EXAMPLES_ENV = "NETSETEST_FUZZ_EXAMPLES"  # the long run: raise the number of examples per property
EXAMPLES = int(os.environ.get(FUZZ_EXAMPLES_ENV, "0")) or None
RUN = "fz"
STEPS = 4

SEEDED = settings(
    max_examples=EXAMPLES or 150,
    derandomize=EXAMPLES is None,  # the suite's short run is the same corpus every time
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    database=None,
)

# ---------------------------------------------------------------- decode


@SEEDED
@given(st.binary(max_size=300))
def test_decode_arbitrary_bytes_raises_only_bad_message(payload: bytes) -> None:
    try:
        decode(payload)
    except BadMessage:
        pass


_SCALARS = st.none() | st.booleans() | st.integers(min_value=-(2**63), max_value=2**64 - 1) | st.floats() | st.text(max_size=8) | st.binary(max_size=8)
_MSGPACK = st.recursive(
    _SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6) | st.integers(), inner, max_size=4),
    max_leaves=20,
)


@SEEDED
@given(_MSGPACK, st.sampled_from(["state", "input", "truth", "end", "ready", "x"]))
def test_decode_arbitrary_msgpack_raises_only_bad_message(value: object, tag: str) -> None:
    for v in (value, {"v": SCHEMA_VERSION, "type": tag, "x": value}, {"v": SCHEMA_VERSION, "type": tag, **(value if isinstance(value, dict) else {})}):
        try:
            payload = msgpack.packb(v, use_bin_type=True)
        except (TypeError, ValueError, OverflowError):
            continue  # not representable in msgpack: nothing a network could carry
        try:
            decode(payload)
        except BadMessage:
            pass


def test_decode_deep_nesting_and_invalid_utf8_everywhere() -> None:
    """The two payload families that crashed every role of a run (2 bytes each)."""
    for payload in (b"\xa1\xbe", b"\x91" * 100_000 + b"\xc0", b"\x81\xa1v\xa1\xbe", b"\x81" * 5000 + b"\xc0"):
        with pytest.raises(BadMessage):
            decode(payload)


# ---------------------------------------------------------------- role handlers


def _recorded_messages() -> list[tuple[str, bytes]]:
    """Every (key, payload) of two short in-memory paper6 SAIM runs: the templates to mutate; the second with every
    reading to its sender's out-neighbours only, so that the nodes cut by their neighbours' sets (issue 44)."""
    import dataclasses

    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(PAPER6, "saim", STEPS)
    seen: list[tuple[str, bytes]] = []
    for run in (sc, dataclasses.replace(sc, reading_scope="neighbours")):
        bus = MemoryBus()
        bus.subscribe("netsetest/**", lambda key, msg: seen.append((key, encode(msg))))
        run_inmemory(run, bus=bus, keep=False)
    return seen


TEMPLATES = _recorded_messages()


def _value_like(v: object) -> st.SearchStrategy:
    """Values of v's type, extremes included (so schema-valid mutations are common)."""
    if isinstance(v, bool):
        return st.booleans()
    if isinstance(v, int):
        return st.integers(min_value=-(2**63), max_value=2**64 - 1) | st.integers(-3, 200)
    if isinstance(v, float):
        return st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([0.0, -0.0, 1e-300, 1e300, 5e-324, 1.0, -1.0])
    if isinstance(v, str):
        return st.sampled_from(
            [
                "ok",
                "init",
                "init-prior",
                "fallback",
                "rejoin",
                "resume",
                "no-reading",
                "node",
                "vehicle",
                "collector",
                "none",
                "measurement",
                "fault-bound",
                "assumed",
                "1",
                "7",
                "",
            ]
        ) | st.text(max_size=6)
    if isinstance(v, list):
        inner = _value_like(v[0]) if v else st.integers(-1, 8)
        return st.lists(inner, min_size=max(0, len(v) - 1), max_size=len(v) + 1)
    if isinstance(v, dict):
        return st.dictionaries(
            st.sampled_from(["1", "2", "3", "4", "5", "6", "0", "99", "x"]), _value_like(next(iter(v.values()))) if v else st.floats(), max_size=7
        )
    return _MSGPACK


@st.composite
def _mutated(draw: st.DrawFn) -> tuple[str, bytes]:
    key, payload = draw(st.sampled_from(TEMPLATES))
    raw = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    for _ in range(draw(st.integers(0, 3))):
        field = draw(st.sampled_from(sorted(raw, key=str)))
        if field in ("v", "type"):
            continue
        inner = raw[field]
        if isinstance(inner, dict) and inner and all(isinstance(k, str) for k in inner) and draw(st.booleans()):
            part = draw(st.sampled_from(sorted(inner)))  # a part of a set (a state's published or continued one)
            inner[part] = draw(_value_like(inner[part]))
            continue
        raw[field] = draw(_value_like(raw[field]))
    try:
        out = msgpack.packb(raw, use_bin_type=True)
    except (TypeError, ValueError, OverflowError):
        out = payload
    return key, out


def _all_keys(sc) -> list[str]:
    out = [keys.truth(RUN), keys.end(RUN), "netsetest/other/x"]
    for i in sc.ids:
        out += [keys.node_input(RUN, i), keys.node_state(RUN, i), keys.reading(RUN, i), keys.ready_of(RUN, keys.role_name("node", i))]
    out += [keys.ready_of(RUN, keys.role_name("vehicle", None)), keys.ready_of(RUN, keys.role_name("collector", None))]
    return out


@SEEDED
@given(st.lists(st.tuples(_mutated(), st.integers(0, 10_000)), min_size=1, max_size=12))
def test_every_role_handler_drops_never_raises(deliveries: list[tuple[tuple[str, bytes], int]]) -> None:
    """Every role (vehicle, a node of each saturation kind, collector, the start-up barrier) gets every
    message on its own key and on a random other key; then nodes step and the collector finishes."""
    sc = load_topology(PAPER6, "saim", STEPS)
    bus = MemoryBus()
    vehicle = Vehicle(sc, bus, RUN)
    nodes = [Node(sc, i, bus, RUN) for i in sc.ids]
    collector = Collector(sc, bus, RUN, None)
    behind = Collector(sc, bus, RUN, None, realtime=True, budget=3 * len(sc.ids))  # real time, a budget it exceeds at once
    barrier = Barrier(bus, RUN, Ready(role="node", node=1), {("node", 2), ("vehicle", None), ("collector", None)})
    handlers = [vehicle.on_message, vehicle.on_ack, collector.on_message, behind.on_message, barrier.on_message, *(n.on_message for n in nodes)]
    all_keys = _all_keys(sc)
    for (key, payload), pick in deliveries:
        try:
            msg: Message = decode(payload)
        except BadMessage:
            continue
        for handler in handlers:
            handler(key, msg)
            handler(all_keys[pick % len(all_keys)], msg)
        behind.close_ready(most=0)
        for n in nodes:
            n.give_up = True
            while n.try_step():
                pass
    collector.finish(run_meta(sc, "inmemory", "lockstep", "paper", "scheduled", 0, RUN))
    behind.finish(run_meta(sc, "inmemory", "realtime", "paper", "scheduled", 0, RUN))


def test_the_fuzz_templates_cover_every_message_type() -> None:
    types = {msgpack.unpackb(p, raw=False, strict_map_key=False)["type"] for _, p in TEMPLATES}
    assert {"input", "state", "truth", "end", "reading"} <= types
    assert any(msgpack.unpackb(p, raw=False, strict_map_key=False).get("readings") for _, p in TEMPLATES)  # states that used a reading
    states = [
        msgpack.unpackb(p, raw=False, strict_map_key=False) for _, p in TEMPLATES if msgpack.unpackb(p, raw=False, strict_map_key=False)["type"] == "state"
    ]
    assert any({"region", "fault"} <= set(s["published"]) for s in states) and any("continues" in s for s in states)  # every part of both sets
    assert any(s.get("sets") for s in states)  # states cut by their neighbours' sets (issue 44)
    assert not math.isnan(len(TEMPLATES))


@SEEDED
@given(st.lists(_mutated(), min_size=1, max_size=12), st.integers(0, 400))
def test_the_live_view_never_raises(deliveries: list[tuple[str, bytes]], backlog: int) -> None:
    """``netsetest view`` draws whatever the observer decodes (forged states and truths included) or drops
    it; it never raises (runtime/view.py)."""
    rr = pytest.importorskip("rerun")
    from netsetest.runtime.view import APP_ID, LiveView

    rec = rr.RecordingStream(APP_ID)
    rec.memory_recording()  # kept in memory, dropped with the test
    view = LiveView(rec, tau_s=0.1)
    for _key, payload in deliveries:
        try:
            msg: Message = decode(payload)
        except BadMessage:
            continue
        view.feed(msg, backlog)
