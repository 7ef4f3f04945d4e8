"""ProvenSet (netsetest/proven.py): what a node proves as one set.  Its bounds are the ellipsoid's within the fault range
and the region's, made once; its membership is the judge's rule (exact against ρ, the fault range and the polygon; a
set estimator's set by its own tolerance); its wire form is checked on decode; the digest changes with every part."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from netsetest.messages import state_digest
from netsetest.polygon import Polygon
from netsetest.proven import ProvenSet, contains_both, continued_set
from netsetest.sets import Box, RegionSet, Zonotope, set_to_wire

from message_helpers import make_state

P_DIAG = [0.04, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 0.25]  # half-widths 0.2, 0.3, 0.5 at ρ = 1
SQUARE = [-0.1, -0.1, 0.1, -0.1, 0.1, 0.1, -0.1, 0.1]  # (β, r) ∈ [−0.1, 0.1]², counter-clockwise
SET = ProvenSet(xhat=[0.0, 0.0, 0.1], P=P_DIAG, rho=1.0, region=SQUARE, fault=[-0.2, 0.3])


def test_the_bounds_are_the_ellipsoids_within_the_fault_range_and_the_region() -> None:
    lo, hi = SET.bounds()
    np.testing.assert_allclose(lo, [-0.1, -0.1, -0.2])
    np.testing.assert_allclose(hi, [0.1, 0.1, 0.3])
    wide = ProvenSet(xhat=[0.0, 0.0, 0.1], P=P_DIAG, rho=1.0, region=[v * 10 for v in SQUARE], fault=[-1.0, 1.0])
    np.testing.assert_allclose(np.stack(wide.bounds()), [[-0.2, -0.3, -0.4], [0.2, 0.3, 0.6]])  # never widened by a looser part
    alone = ProvenSet(xhat=[0.0, 0.0, 0.1], P=P_DIAG, rho=1.0)
    assert alone.is_ellipsoid and not SET.is_ellipsoid
    np.testing.assert_allclose(np.stack(alone.bounds()), np.stack(wide.bounds()))


def test_the_bounds_are_made_once_and_handed_out_as_copies() -> None:
    s = ProvenSet(xhat=[0.0, 0.0, 0.1], P=P_DIAG, rho=1.0, region=SQUARE)
    lo, _ = s.bounds()
    lo[:] = 99.0  # a caller's change does not reach the set
    assert s.bounds()[0][0] == -0.1
    assert s._bounds is s._bounds  # cached on the instance (no recomputation per reader)


def test_membership_needs_the_ellipsoid_the_fault_range_and_the_region() -> None:
    assert SET.contains(np.array([0.05, -0.05, 0.2]))
    assert not SET.contains(np.array([0.15, 0.0, 0.1]))  # outside the region (inside the ellipsoid)
    assert not SET.contains(np.array([0.0, 0.0, 0.35]))  # outside the fault range (inside the ellipsoid)
    thin = ProvenSet(xhat=[0.0, 0.0, 0.1], P=[0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.25], rho=1.0, region=SQUARE, fault=[-0.2, 0.3])
    assert not thin.contains(np.array([0.09, 0.09, 0.1]))  # inside region and range, outside the ellipsoid (E = 1.62)
    e = SET.E(np.array([0.0, 0.0, 0.6]))
    assert e == pytest.approx(1.0) and ProvenSet(xhat=SET.xhat, P=SET.P, rho=e).contains(np.array([0.0, 0.0, 0.6]))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3), st.floats(0.05, 2.0))
def test_membership_is_the_judges_rule(point: list[float], rho: float) -> None:
    """E = eᵀP⁻¹e ≤ ρ exactly (np.linalg.solve, as the judge had it), lo ≤ f ≤ hi exactly, x in the polygon."""
    s = ProvenSet(xhat=[0.0, 0.01, 0.1], P=P_DIAG, rho=rho, region=SQUARE, fault=[-0.2, 0.3])
    x = np.array(point)
    e = x - np.array(s.xhat)
    want = float(e @ np.linalg.solve(np.reshape(s.P, (3, 3)), e)) <= rho and -0.2 <= x[2] <= 0.3
    want = want and Polygon(np.reshape(SQUARE, (-1, 2))).contains(x[:2])
    assert s.contains(x) == want


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3),
    st.lists(st.floats(1e-6, 1e3), min_size=3, max_size=3),
    st.floats(1e-6, 1e3),
    st.one_of(st.none(), st.tuples(st.floats(-1e3, 1e3), st.floats(0.0, 1e3))),
    st.sampled_from([SQUARE, None]),
)
def test_the_fault_bounds_alone_are_the_bounds_last_coordinate(
    xhat: list[float], diag: list[float], rho: float, fault: tuple[float, float] | None, region: list[float] | None
) -> None:
    """What a node takes of a neighbour's set (its fault's bounds) without the region or the other coordinates: the same
    floats as the whole bounds' last coordinate, asked before them or after (then read from them)."""
    P = [diag[0], 0.0, 0.0, 0.0, diag[1], 0.0, 0.0, 0.0, diag[2]]
    fr = None if fault is None else [fault[0], fault[0] + fault[1]]
    s = ProvenSet(xhat=xhat, P=P, rho=rho, region=region, fault=fr)
    first = s.fault_bounds()
    lo, hi = s.bounds()
    assert first == (lo[-1], hi[-1]) == s.fault_bounds()


def test_a_set_estimators_set_is_its_own() -> None:
    own = RegionSet(Zonotope(np.zeros(3), np.diag([1.0, 1.0, 1.0])), Polygon(np.reshape(SQUARE, (-1, 2))), (-0.2, 0.3))
    s = ProvenSet(xhat=[0.0, 0.0, 0.0], P=[9.0, 0, 0, 0, 9.0, 0, 0, 0, 9.0], rho=1.0, set=set_to_wire(own))
    np.testing.assert_array_equal(np.stack(s.bounds()), np.stack(own.bounds()))
    for x in ([0.05, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.5]):
        assert s.contains(np.array(x)) == own.contains(np.array(x))
    assert isinstance(s.own_set, RegionSet)
    assert s.fault_bounds() == (own.bounds()[0][-1], own.bounds()[1][-1])


@pytest.mark.parametrize(
    "change, why",
    [
        ({"P": [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0]}, "positive definite"),
        ({"P": [1.0, 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]}, "symmetric"),
        ({"rho": 0.0}, "rho"),
        ({"xhat": [0.0, math.nan, 0.0]}, "xhat"),
        ({"xhat": [0.0, 0.0]}, "xhat"),
        ({"fault": [0.3, -0.2]}, "lo > hi"),
        ({"fault": [-math.inf, 0.3]}, "fault"),
        ({"region": SQUARE[:-1]}, "odd"),
        ({"region": SQUARE[:4]}, "region"),
        ({"region": [0.0] * 1000}, "region"),
        ({"set": {"type": "box", "lo": [1.0, 0, 0], "hi": [0.0, 1, 1]}}, "box"),
        ({"set": set_to_wire(Box(np.zeros(3), np.ones(3)))}, "carries its own"),  # beside the region and fault range
        ({"extra": 1}, "extra"),
    ],
)
def test_a_malformed_wire_form_fails_decode(change: dict, why: str) -> None:
    base = SET if "set" not in change or why != "box" else ProvenSet(xhat=SET.xhat, P=SET.P, rho=SET.rho)
    wire = msgspec.to_builtins(base) | change
    with pytest.raises(msgspec.ValidationError, match=why):
        msgspec.msgpack.decode(msgspec.msgpack.encode(wire), type=ProvenSet)


def test_the_wire_form_round_trips_bit_for_bit_and_leaves_absent_parts_out() -> None:
    back = msgspec.msgpack.decode(msgspec.msgpack.encode(SET), type=ProvenSet)
    assert back == SET and [v.hex() for v in back.P] == [v.hex() for v in SET.P]
    assert set(msgspec.to_builtins(ProvenSet(xhat=SET.xhat, P=SET.P, rho=1.0))) == {"xhat", "P", "rho"}


def test_the_continued_set_is_its_ellipsoid_within_the_published_region() -> None:
    own = ProvenSet(xhat=[0.0, 0.0, 0.0], P=P_DIAG, rho=1.0)
    whole = continued_set(SET, own)
    assert whole.region == SET.region and whole.fault is None and whole.xhat == own.xhat
    assert continued_set(SET, None) is SET
    assert whole.contains(np.array([0.05, 0.0, -0.45])) and not SET.contains(np.array([0.05, 0.0, -0.45]))  # no fault range


@settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3), st.floats(0.05, 2.0), st.sampled_from([SQUARE, None]))
def test_the_continued_sets_membership_without_building_it(point: list[float], rho: float, region: list[float] | None) -> None:
    """The judge asks the set a node continues from without building it (a new set, its region checked and parsed
    again), and the region both sets share once: the same answers as the built sets', at random points and at the
    region's corners and edges (inside either ellipsoid, both, or neither); without ``continues``, the published set's."""
    pub = ProvenSet(xhat=[0.0, 0.01, 0.1], P=P_DIAG, rho=1.0, region=region, fault=[-0.2, 0.3])
    own = ProvenSet(xhat=[0.01, 0.0, -0.1], P=P_DIAG, rho=rho)
    for x in (np.array(point), np.array([0.1, 0.1, point[2]]), np.array([0.1, point[1], point[2]])):
        assert contains_both(pub, own, x) == (pub.contains(x), continued_set(pub, own).contains(x))
        assert contains_both(pub, own, x, pub.E(x)) == contains_both(pub, own, x)
        assert contains_both(pub, None, x) == (pub.contains(x), pub.contains(x))


@pytest.mark.parametrize("part", ["xhat", "P", "rho", "region", "fault", "continues"])
def test_the_digest_changes_with_every_part_of_either_set(part: str) -> None:
    base = make_state(step=3, node=2, xhat=SET.xhat, P=SET.P, rho=1.0, region=SQUARE, fault=[-0.2, 0.3], gamma=1.0, innov=0.0, status="ok")
    changes: dict[str, dict] = {
        "xhat": {"xhat": [0.0, 0.0, 0.2]},
        "P": {"P": [0.05, 0, 0, 0, 0.09, 0, 0, 0, 0.25]},
        "rho": {"rho": 2.0},
        "region": {"region": [v * 2 for v in SQUARE]},
        "fault": {"fault": [-0.2, 0.25]},
    }
    if part == "continues":
        other = msgspec.structs.replace(base, continues=ProvenSet(xhat=SET.xhat, P=SET.P, rho=1.0))
    else:
        other = msgspec.structs.replace(base, published=msgspec.structs.replace(base.published, **changes[part]))
    assert state_digest(other) != state_digest(base)
    assert state_digest(base) == state_digest(msgspec.structs.replace(base))
