"""messages.peek_step: what a bus's screen reads of a payload before decoding it (netsetest/bus/base.py).
It must never raise whatever the bytes, and must read the very step decode() would give."""

from __future__ import annotations

import msgspec
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.bus.base import MemoryBus
from netsetest.messages import SCHEMA_VERSION, End, NodeInput, Reading, Ready, decode, encode, peek_step
from message_helpers import make_state

P_ID = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]


def test_peek_step_reads_the_step_of_every_kind_that_names_one() -> None:
    state = make_state(step=12, node=2, xhat=[0.0] * 3, P=P_ID, rho=1.0, gamma=1.0, innov=0.0, status="ok", drops={"stale": 3}, used=[1])
    for msg, step in (
        (state, 12),
        (NodeInput(step=0, node=1, y=0.1, gamma=1.0), 0),
        (Reading(step=5, node=3, y=0.1, gamma=0.5), 5),
        (Ready(role="node", node=4), None),
        (End(steps=80), None),  # an End names the run's length, not a step
    ):
        payload = encode(msg)
        assert peek_step(payload) == step == getattr(decode(payload), "step", None)


def test_peek_step_is_none_for_what_names_no_valid_step() -> None:
    for raw in (b"", b"\xc1", b"\x91\x01", msgspec.msgpack.encode([1, 2]), msgspec.msgpack.encode({1: 2, "step": 5})):
        assert peek_step(raw) is None
    for step in (-1, True, 1.0, "3", None, [3]):
        assert peek_step(msgspec.msgpack.encode({"v": SCHEMA_VERSION, "type": "state", "step": step})) is None
    assert peek_step(b"\x91" * 100_000 + b"\x01") is None  # nested deeper than any decoder's stack: no RecursionError
    # the rest is not read: a payload decode() refuses still names its step (a screen may drop it undecoded)
    assert peek_step(msgspec.msgpack.encode({"v": SCHEMA_VERSION, "type": "state", "step": 9, "P": "not a matrix"})) == 9


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_peek_step_never_raises(payload: bytes) -> None:
    step = peek_step(payload)
    assert step is None or (type(step) is int and step >= 0)


def test_the_in_memory_bus_ignores_screens_its_roles_handlers_drop_the_same() -> None:
    """In memory every payload is decoded once for all subscribers: a screen would drop it for one
    subscriber and not another's handler, so the bus leaves it to the handlers (the module doc)."""
    bus = MemoryBus()
    got: list[int] = []
    bus.subscribe("k", lambda key, msg: got.append(msg.step), screen=lambda step: "stale")  # type: ignore[attr-defined]  # a Reading
    bus.publish("k", Reading(step=1, node=1, y=0.0, gamma=1.0))
    bus.pump()
    assert got == [1] and not bus.dropped and bus.received == 1
