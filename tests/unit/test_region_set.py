"""RegionSet (sets.py): a set estimator's set cut by its region of x and a fault range; membership needs all three,
the bounds and support are outer bounds of the intersection, and the wire form round-trips and refuses malformed
parts."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fuzzing import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.messages import NodeState, decode, encode
from netsetest.polygon import Polygon
from netsetest.sets import Box, RegionSet, SetFormatError, Zonotope, set_from_wire, set_to_wire
from message_helpers import make_state

BASE = Zonotope(np.zeros(3), np.diag([1.0, 1.0, 1.0]))
REGION = Polygon(np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]]))
S = RegionSet(BASE, REGION, (-0.2, 0.3))


def test_membership_needs_the_base_set_the_region_and_the_fault_range() -> None:
    assert S.contains(np.array([0.1, -0.2, 0.25]))
    assert not S.contains(np.array([0.6, 0.0, 0.0]))  # outside the region (inside the base)
    assert not S.contains(np.array([0.0, 0.0, 0.5]))  # outside the fault range
    thin = RegionSet(Zonotope(np.zeros(3), np.diag([0.1, 0.1, 1.0])), REGION, (-1.0, 1.0))
    assert not thin.contains(np.array([0.3, 0.0, 0.0]))  # outside the base (inside the region)
    lo, hi = S.bounds()
    np.testing.assert_array_equal(lo, [-0.5, -0.5, -0.2])
    np.testing.assert_array_equal(hi, [0.5, 0.5, 0.3])


@settings(max_examples=examples(200), deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3), st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))
def test_support_bounds_every_member(point: list[float], direction: list[float]) -> None:
    """support(d) is an upper bound of dᵀx over the set (the least of two outer bounds)."""
    x, d = np.array(point), np.array(direction)
    if S.contains(x):
        assert d @ x <= S.support(d) + 1e-12


def test_the_wire_form_round_trips_and_malformed_parts_are_refused() -> None:
    wire = json.loads(json.dumps(set_to_wire(S)))
    back = set_from_wire(wire, 3)
    assert isinstance(back, RegionSet) and set_to_wire(back) == set_to_wire(S)
    ok = set_to_wire(S)
    bad = [
        ok | {"region": [0.0, 0.0, 1.0, 0.0, 1.0]},  # odd
        ok | {"region": [0.0, 0.0, 1.0, 0.0]},  # two vertices
        ok | {"region": [0.0, 0.0, 1.0, 0.0, float("nan"), 1.0]},
        ok | {"fault": [1.0, 0.0]},
        ok | {"fault": [0.0]},
        ok | {"set": ok},  # nested
        ok | {"set": {"type": "box", "lo": [0, 0], "hi": [1, 1]}},
        {k: v for k, v in ok.items() if k != "fault"},
    ]
    for d in bad:
        with pytest.raises(SetFormatError):
            set_from_wire(d, 3)
    with pytest.raises(SetFormatError, match="dimension 3"):
        set_from_wire(set_to_wire(RegionSet(Box(np.zeros(4), np.ones(4)), REGION, (0.0, 1.0))), 4)


def test_a_node_state_carries_a_region_set_and_its_bounds() -> None:
    st_ = make_state(step=1, node=2, xhat=[0.0, 0.0, 0.0], P=np.eye(3).reshape(-1).tolist(), rho=1.0, gamma=1.0, innov=0.0, status="ok", set=set_to_wire(S))
    back = decode(encode(st_))
    assert isinstance(back, NodeState)
    lo, hi = back.published.bounds()
    np.testing.assert_array_equal(np.stack([lo, hi]), np.stack(S.bounds()))
