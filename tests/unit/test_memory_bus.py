"""The in-memory bus's routes: a key reaches exactly the handlers whose key expression matches it, in the order they
subscribed, whether the expression is exact or has wildcards, and a subscription made after a key was routed is on
that key's next message (the routes are built per key, from the exact subscriptions by key and the wildcard ones)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.bus.base import MemoryBus
from netsetest.bus.keys import matches
from netsetest.messages import End, Message, encode

CHUNKS = ["a", "b", "c"]
KEYS = [f"r/{x}/{y}" for x in CHUNKS for y in CHUNKS] + ["r/a", "r/a/b/c", "s/a/b"]
EXPRESSIONS = KEYS + ["r/*/b", "r/a/*", "r/**", "**", "r/*/*", "*/a/**"]


def _delivered(bus: MemoryBus, key: str, heard: list[tuple[int, str]]) -> list[int]:
    heard.clear()
    bus.inject(key, encode(End(steps=1)))
    bus.pump()
    return [n for n, _ in heard]


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(EXPRESSIONS), min_size=1, max_size=12), st.lists(st.sampled_from(KEYS), min_size=1, max_size=6))
def test_a_key_reaches_its_subscribers_in_subscription_order(expressions: list[str], keys: list[str]) -> None:
    bus = MemoryBus()
    heard: list[tuple[int, str]] = []

    def handler(n: int):  # one handler per subscription (the inbox keeps a queue per key and handler)
        return lambda key, msg: heard.append((n, key))

    first, rest = expressions[: len(expressions) // 2], expressions[len(expressions) // 2 :]
    for n, expr in enumerate(first):
        bus.subscribe(expr, handler(n))
    for key in keys:  # routed once before the later subscriptions
        assert _delivered(bus, key, heard) == [n for n, e in enumerate(first) if matches(e, key)]
    for n, expr in enumerate(rest, start=len(first)):
        bus.subscribe(expr, handler(n))
    for key in keys:
        assert _delivered(bus, key, heard) == [n for n, e in enumerate(expressions) if matches(e, key)]


def test_a_handler_subscribed_twice_hears_each_copy_once_per_subscription() -> None:
    bus = MemoryBus()
    got: list[Message] = []
    bus.subscribe("r/a/b", lambda k, m: got.append(m))
    bus.subscribe("r/*/b", lambda k, m: got.append(m))
    bus.inject("r/a/b", encode(End(steps=1)))
    bus.pump()
    assert len(got) == 2
