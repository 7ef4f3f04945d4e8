"""A node's screens (roles/node.py, bus/base.py) drop a payload undecoded only where its handler would drop
the decoded message, for the same reason: whatever step it names and wherever the node is, a screened-out
input, neighbour state or reading is one the handler drops under the screen's reason, keeping nothing."""

from __future__ import annotations

from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.bus import keys
from netsetest.bus.base import MemoryBus
from netsetest.config.schema import load_topology
from netsetest.messages import NodeInput, Reading
from netsetest.roles.node import Node
from message_helpers import make_state

REFERENCE = Path(__file__).resolve().parents[2] / "topologies" / "paper6_reference.toml"
STEPS = 20
SC = load_topology(REFERENCE, None, STEPS)
P_ID = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0]


def _messages(node: Node, step: int) -> list[tuple[str, object, str | None]]:
    """(key, message, what the node's screen of that key says of ``step``) for every kind it screens."""
    j, ref = node.others[0], node.read_from[0]
    sc = node.sc
    return [
        (
            keys.node_input("t", node.id),
            NodeInput(step=step, node=node.id, y=0.01, gamma=1.0, u_prev=(sc.steer_low + sc.steer_high) / 2, vx_prev=sc.vx(max(step - 1, 0))),
            node._passed_input(step),
        ),
        (keys.node_state("t", j), make_state(step=step, node=j, xhat=[0.0] * 3, P=P_ID, rho=1.0, gamma=1.0, innov=0.0, status="ok"), node._passed_state(step)),
        (keys.reading("t", ref), Reading(step=step, node=ref, y=0.01, gamma=1.0), node._passed_reading(step)),
    ]


@settings(max_examples=200, deadline=None)
@given(k=st.integers(-1, STEPS), step=st.integers(0, STEPS + 5))
def test_what_a_screen_drops_the_handler_drops_for_the_same_reason(k: int, step: int) -> None:
    node = Node(SC, 2, MemoryBus(), "t")
    assert node.read_from and node.others  # node 2 reads reference 3 and hears its neighbours
    node.k = k  # where the node is: the handlers and the screens read only k (white box, for every k at once)
    for key, msg, why in _messages(node, step):
        if why is None:
            continue
        before = (dict(node.inputs), {s: dict(m) for s, m in node.inbox.items()}, {s: dict(r) for s, r in node.readings.items()})
        node.on_message(key, msg)  # type: ignore[arg-type]  # one of the Message kinds
        assert node.drops == {why: 1}, (key, step, k, node.drops)
        assert (node.inputs, node.inbox, node.readings) == before
        node.drops.clear()


def test_the_screens_pass_what_a_node_can_still_use() -> None:
    node = Node(SC, 2, MemoryBus(), "t")
    node.k = 5
    assert [why for _, _, why in _messages(node, 6)] == [None, None, None]  # the next input and reading, a state ahead
    assert [why for _, _, why in _messages(node, 5)] == ["node-input-mismatch", None, "stale"]  # our step's states are used next
    assert [why for _, _, why in _messages(node, STEPS + 1)] == ["step-beyond-run"] * 3
