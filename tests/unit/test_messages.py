"""Wire format (msgpack + pydantic), the in-memory bus and key expressions (docs/design.md §6)."""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest

from netsetest.bus import keys
from netsetest.bus.base import MemoryBus
from netsetest.messages import (
    SCHEMA_VERSION,
    BadMessage,
    End,
    NodeInput,
    NodeState,
    Ready,
    Truth,
    decode,
    encode,
)
from netsetest.proven import SYM_ATOL, SYM_RTOL, ProvenSet, spd_problem

from message_helpers import SET_FIELDS, make_state, raw_message

# floats that a lossy encoding (float32, decimal text) would not preserve
X = [0.1, 1 / 3, -2.5e-300]
P = [0.3, 1e-17, -0.1 / 7, 1e-17, 0.3, 2 / 3, -0.1 / 7, 2 / 3, 1.7976931348623157e308]


def _state(**kw) -> NodeState:
    """A state whose published set takes the keywords of SET_FIELDS (x̂ = X, P = P, ρ = 1/3 unless given)."""
    base = dict(
        step=7,
        node=3,
        xhat=X,
        P=P,
        rho=1 / 3,
        gamma=0.8123456789012345,
        innov=-0.0123456789,
        status="ok",
        rho_cert=1.0000000001,
        solve_ms=24.75,
        used=[2, 4],
        missing=[4],
        late=True,
    )
    base.update(kw)
    return make_state(**base)


MESSAGES = [
    Ready(role="collector"),
    Ready(role="node", node=5),
    NodeInput(step=0, node=1, y=0.123456789012345678, gamma=1.0),
    NodeInput(step=12, node=6, y=-1e-12, gamma=0.7200000000000001, u_prev=0.0175 + 0.0367 * 0.3, vx_prev=100 / 3.6, expect_from=[1, 5], lost_from=[5]),
    _state(),
    _state(status="init", rho_cert=None, used=[], missing=[], late=False),
    _state(sector=(0.123456789, 0.876543211), sector_basis="fault-bound"),
    _state(sector=(0.5, 0.5), sector_basis="fault-bound", fault=[-0.2, 0.2]),
    _state(region=[0.0, 0.0, 1.0, 0.0, 1.0, 1.0], fault=[-0.2, 0.2], continues=ProvenSet(xhat=X, P=P, rho=1 / 3)),
    _state(status="init-prior", sector=(1.0, 0.0), sector_basis="measurement"),
    _state(status="no-reading", innov=None, rho_cert=None, used=[], missing=[]),  # a step without the node's reading
    _state(status="fallback", innov=None),  # a set estimator's last set again, at a step without its reading
    _state(region=[0.0, 0.0, 1.0, 0.0, 1.0, 1.0], fault=[-0.2, 0.2], cuts=[["region"], ["region"], ["fault-size", "region", "health-fault"]]),
    Truth(
        step=80,
        x=[1e-3 / 7, -0.2 / 3],
        faults={1: 0.1745, 2: 0.08725},
        u=0.03,
        w=-0.99,
        vx=27.77777777777778,
        noise={1: math.cos(0.2 * math.pi), 2: 0.5},
        gamma={1: 0.77, 2: 1.0},
        y={1: 0.01 / 3, 2: 0.1},
        y_nofault={1: -0.0, 2: 0.0},
        sector_ok={1: True, 2: False},
        noise_ok={1: True, 2: True},
        dist_ok=False,
        lost=[(2, 1), (6, 1)],
        alive=[1, 2, 3],
        r={1: -0.0312345678901, 2: 0.5},
        fault_ok={1: True, 2: False},
    ),
    End(steps=80),
    End(steps=3, reason="aborted: node 4 silent"),
]


@pytest.mark.parametrize("msg", MESSAGES, ids=lambda m: type(m).__name__)
def test_round_trip_exact(msg):
    payload = encode(msg)
    assert isinstance(payload, bytes)
    raw = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    assert raw["v"] == SCHEMA_VERSION and raw["type"] == msg.type
    back = decode(payload)
    assert type(back) is type(msg)
    assert back == msg
    # exact float equality field by field (== on models would also accept 0.0 == -0.0)
    for name, val in msg.model_dump().items():
        got = getattr(back, name)
        if isinstance(val, float):
            assert got == val and math.copysign(1, got) == math.copysign(1, val)
    assert encode(back) == payload


def test_round_trip_float_bits():
    m = _state()
    back = decode(encode(m)).published
    assert [x.hex() for x in back.xhat] == [x.hex() for x in X]
    assert [x.hex() for x in back.P] == [x.hex() for x in P]
    assert back.rho.hex() == (1 / 3).hex()


# ---------------------------------------------------------------- rejection


def _pack(d) -> bytes:
    return msgpack.packb(d, use_bin_type=True)


def _mut(msg, **changes) -> bytes:
    """``msg`` packed with ``changes`` (_DEL: the key removed); a key of SET_FIELDS changes its published set."""
    d = raw_message(msg)
    for k, v in changes.items():
        target = d["published"] if k in SET_FIELDS and "published" in d else d
        if v is _DEL:
            del target[k]
        else:
            target[k] = v
    return _pack(d)


_DEL = object()
NI = NodeInput(step=3, node=2, y=0.01, gamma=0.9)

BAD = [
    ("garbage", b"\xc1\xc1\xc1", "undecodable", None),
    ("truncated", _pack(raw_message(_state()))[:-3], "undecodable", None),
    ("empty", b"", "undecodable", None),
    ("list", _pack([1, "state", 3]), "not-a-map", None),
    ("scalar", _pack(42), "not-a-map", None),
    ("version-1", _mut(_state(), v=1), "schema-version", None),  # a node of before the ProvenSets
    ("version-2", _mut(_state(), v=2), "schema-version", None),  # a truth of before the int node ids
    ("version-4", _mut(_state(), v=4), "schema-version", None),
    ("version-missing", _mut(_state(), v=_DEL), "schema-version", None),
    ("version-str", _mut(_state(), v="2"), "schema-version", None),
    ("unknown-type", _mut(_state(), type="bogus"), "invalid", "bogus"),
    ("type-missing", _mut(End(steps=1), type=_DEL), "invalid", None),
    ("P-8", _mut(_state(), P=P[:8]), "invalid", "P"),
    ("P-10", _mut(_state(), P=P + [0.0]), "invalid", "P"),
    ("xhat-2", _mut(_state(), xhat=X[:2]), "invalid", "xhat"),
    ("xhat-nan", _mut(_state(), xhat=[0.0, float("nan"), 0.0]), "invalid", "xhat"),
    ("xhat-inf", _mut(_state(), xhat=[float("inf"), 0.0, 0.0]), "invalid", "xhat"),
    ("xhat-neg-inf", _mut(_state(), xhat=[0.0, 0.0, float("-inf")]), "invalid", "xhat"),
    ("P-nan", _mut(_state(), P=[float("nan")] + P[1:]), "invalid", "P"),
    ("step-negative", _mut(_state(), step=-1), "invalid", "step"),
    ("step-float", _mut(_state(), step=1.5), "invalid", "step"),
    ("end-steps-negative", _mut(End(steps=1), steps=-1), "invalid", "steps"),
    ("state-gamma-0", _mut(_state(), gamma=0.0), "invalid", "gamma"),
    ("state-gamma-big", _mut(_state(), gamma=1.0000001), "invalid", "gamma"),
    ("input-gamma-0", _mut(NI, gamma=0.0), "invalid", "gamma"),
    ("input-gamma-big", _mut(NI, gamma=1.5), "invalid", "gamma"),
    ("input-y-nan", _mut(NI, y=float("nan")), "invalid", "y"),
    ("node-0", _mut(NI, node=0), "invalid", "node"),
    ("rho-0", _mut(_state(), rho=0.0), "invalid", "rho"),
    ("status-unknown", _mut(_state(), status="great"), "invalid", "status"),
    ("extra-field", _mut(_state(), secret=1), "invalid", "secret"),
    ("extra-field-end", _mut(End(steps=1), zz=0), "invalid", "zz"),
    ("missing-field", _mut(_state(), xhat=_DEL), "invalid", "xhat"),
    ("published-missing", _mut(_state(), published=_DEL), "invalid", "published"),
    (
        "set-and-region",
        _mut(_state(), region=[0.0, 0.0, 1.0, 0.0, 1.0, 1.0], set={"type": "box", "lo": [0, 0, 0], "hi": [1, 1, 1]}),
        "invalid",
        "set estimator",
    ),
    ("set-malformed", _mut(_state(), set={"type": "box", "lo": [1, 0, 0], "hi": [0, 1, 1]}), "invalid", "box"),
    (
        "continues-not-spd",
        _mut(_state(continues=ProvenSet(xhat=X, P=P, rho=1.0)), continues={"xhat": X, "P": [1.0, 2.0, 0, 2.0, 1.0, 0, 0, 0, 1.0], "rho": 1.0}),
        "invalid",
        "continues",
    ),
    ("missing-field-input", _mut(NI, node=_DEL), "invalid", "node"),
    ("truth-faults-nan", _mut(next(m for m in MESSAGES if isinstance(m, Truth)), faults={1: float("nan")}), "invalid", "faults"),
    ("truth-r-inf", _mut(next(m for m in MESSAGES if isinstance(m, Truth)), r={1: float("inf")}), "invalid", "r"),
    ("sector-h1-0", _mut(_state(), sector=[0.0, 0.5]), "invalid", "sector"),
    ("sector-h1-big", _mut(_state(), sector=[1.5, 0.5]), "invalid", "sector"),
    ("sector-h-negative", _mut(_state(), sector=[0.5, -0.1]), "invalid", "sector"),
    ("sector-nan", _mut(_state(), sector=[0.5, float("nan")]), "invalid", "sector"),
    ("sector-3", _mut(_state(), sector=[0.5, 0.5, 0.5]), "invalid", "sector"),
    ("sector-basis-unknown", _mut(_state(), sector_basis="hope"), "invalid", "sector_basis"),
    ("fault-range-reversed", _mut(_state(), fault=[0.2, -0.2]), "invalid", "fault"),
    ("fault-range-inf", _mut(_state(), fault=[-float("inf"), 0.2]), "invalid", "fault"),
    ("fault-range-3", _mut(_state(), fault=[-0.2, 0.0, 0.2]), "invalid", "fault"),
    ("region-odd", _mut(_state(), region=[0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.5]), "region-odd", "region"),
    ("region-2-vertices", _mut(_state(), region=[0.0, 0.0, 1.0, 0.0]), "region-vertices", "region"),
    ("region-too-long", _mut(_state(), region=[0.0] * 1000), "region-vertices", "region"),
    ("region-nan", _mut(_state(), region=[0.0, 0.0, 1.0, float("nan"), 1.0, 1.0]), "region-not-finite", "region"),
    ("sets-not-used", _mut(_state(), used=[2], sets=[2, 3]), "invalid", "sets"),  # a neighbour's set the step did not receive
    ("sets-node-0", _mut(_state(), used=[2], sets=[0]), "invalid", "sets"),
    # y̌ none exactly where the node had no reading: status no-reading (or a set estimator's fallback)
    ("innov-none-ok", _mut(_state(), innov=None), "invalid", "innov"),
    ("innov-none-resume", _mut(_state(), innov=None, status="resume", resumed_from=3), "invalid", "innov"),
    ("no-reading-with-innov", _mut(_state(), status="no-reading"), "invalid", "innov"),
    ("cuts-unknown", _mut(_state(), cuts=[["region"], [], ["luck"]]), "invalid", "cuts"),  # only the cuts there are
    ("cuts-2", _mut(_state(), cuts=[["region"], ["region"]]), "invalid", "cuts"),  # one list per coordinate β, r, f
]


@pytest.mark.parametrize("payload,reason,field", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_decode_rejects(payload, reason, field):
    with pytest.raises(BadMessage) as exc:
        decode(payload)
    assert exc.value.reason == reason
    assert isinstance(exc.value, ValueError)
    if field is not None:
        assert field in str(exc.value), str(exc.value)


def test_the_published_fault_interval_is_the_ellipsoids_within_its_fault_range():
    """ProvenSet.bounds: x̂ ∓ √(ρ P_jj), the fault's clipped to the fault range where one is sent (never widened)."""
    P1 = [1.0, 0, 0, 0, 1.0, 0, 0, 0, 0.04]
    st = _state(xhat=[0.0, 0.0, 0.1], P=P1, rho=1.0)
    lo, hi = st.published.bounds()
    np.testing.assert_allclose([lo[2], hi[2]], [-0.1, 0.3])
    np.testing.assert_allclose(np.array(_state(xhat=[0.0, 0.0, 0.1], P=P1, rho=1.0, fault=[-0.2, 0.2]).published.bounds())[:, 2], [-0.1, 0.2])
    np.testing.assert_allclose(np.array(_state(xhat=[0.0, 0.0, 0.1], P=P1, rho=1.0, fault=[-1.0, 1.0]).published.bounds())[:, 2], [-0.1, 0.3])
    np.testing.assert_allclose(
        np.array(_state(xhat=[0.0, 0.0, 0.1], P=P1, rho=1.0, fault=[-1.0, 1.0]).published.bounds())[:, :2], np.array(st.published.bounds())[:, :2]
    )


def test_valid_mutation_baseline():
    """The mutation helper itself yields decodable payloads when nothing bad is changed."""
    assert decode(_mut(_state(), innov=0.5)).innov == 0.5
    assert decode(_mut(NI, gamma=1.0)).gamma == 1.0


# ---------------------------------------------------------------- MemoryBus


def test_memory_bus_fifo_and_key_filter():
    bus = MemoryBus()
    got: list[tuple[str, object]] = []
    bus.subscribe("netsetest/r1/node/*/state", lambda k, m: got.append((k, m)))
    sent = []
    for step in range(5):
        for node in (3, 1, 2):
            m = _state(step=step, node=node)
            bus.publish(keys.node_state("r1", node), m)
            sent.append((keys.node_state("r1", node), m))
    bus.publish(keys.node_state("r2", 1), _state())  # other run: not delivered
    bus.publish(keys.end("r1"), End(steps=5))  # other key: not delivered
    assert got == []  # nothing before pump
    n = bus.pump()
    assert n == len(sent)
    assert got == sent
    assert not bus.dropped
    assert bus.pump() == 0


def test_memory_bus_pump_limit():
    bus = MemoryBus()
    got = []
    bus.subscribe("**", lambda k, m: got.append(m.steps))
    for s in range(4):
        bus.publish(keys.end("r"), End(steps=s))
    assert bus.pump(limit=3) == 3 and got == [0, 1, 2]
    assert bus.pump() == 1 and got == [0, 1, 2, 3]


def test_memory_bus_drops_malformed():
    bus = MemoryBus()
    got = []
    bus.subscribe("netsetest/r/**", lambda k, m: got.append(m))
    good1, good2 = _state(step=1), _state(step=2)
    bus.publish(keys.node_state("r", 3), good1)
    bus.inject(keys.node_state("r", 3), b"\xc1garbage")
    bus.inject(keys.node_state("r", 3), _mut(_state(), P=P[:8]))
    bus.inject(keys.node_state("r", 3), _mut(_state(), v=99))
    bus.inject(keys.node_state("r", 3), _pack([1, 2, 3]))
    bus.publish(keys.node_state("r", 3), good2)
    assert bus.pump() == 2
    assert got == [good1, good2]
    assert bus.dropped == {"undecodable": 1, "invalid": 1, "schema-version": 1, "not-a-map": 1}
    assert sum(bus.dropped.values()) == 4
    assert bus.received == 6


def test_memory_bus_handler_never_called_for_bad_payload():
    bus = MemoryBus()
    calls = []
    bus.subscribe("netsetest/r/vehicle/input/2", lambda k, m: calls.append(m))
    bus.inject(keys.node_input("r", 2), _mut(NI, gamma=0.0))
    bus.inject(keys.node_input("r", 2), _mut(NI, y=float("inf")))
    assert bus.pump() == 0
    assert calls == []
    assert bus.dropped["invalid"] == 2


# ---------------------------------------------------------------- key expressions


@pytest.mark.parametrize(
    "pattern,key,ok",
    [
        ("netsetest/r/node/*/state", "netsetest/r/node/3/state", True),
        ("netsetest/r/node/*/state", "netsetest/r/node/12/state", True),
        ("netsetest/r/node/*/state", "netsetest/r/node/3/x/state", False),
        ("netsetest/r/node/*/state", "netsetest/r/node/state", False),
        ("netsetest/r/node/*/state", "netsetest/q/node/3/state", False),
        ("netsetest/*/vehicle/truth", "netsetest/r/vehicle/truth", True),
        ("netsetest/*/truth", "netsetest/r/vehicle/truth", False),
        ("netsetest/r/**", "netsetest/r/node/3/state", True),
        ("netsetest/r/**", "netsetest/r/control/end", True),
        ("netsetest/r/**", "netsetest/r", True),  # ** matches zero chunks too
        ("netsetest/r/**", "netsetest/rr/control/end", False),
        ("**/state", "netsetest/r/node/3/state", True),
        ("**/state", "netsetest/r/node/3/status", False),
        ("netsetest/**/state", "netsetest/r/node/3/state", True),
        ("netsetest/**/input/*", "netsetest/r/vehicle/input/4", True),
        ("netsetest/**/input/*", "netsetest/r/vehicle/input", False),
        ("**", "a/b/c", True),
        ("*", "a", True),
        ("*", "a/b", False),
        ("a/b", "a/b", True),
        ("a/b", "a/b/c", False),
        ("a/b/c", "a/b", False),
    ],
)
def test_key_matches(pattern, key, ok):
    assert keys.matches(pattern, key) is ok


def test_key_builders():
    assert keys.node_input("r", 4) == "netsetest/r/vehicle/input/4"
    assert keys.truth("r") == "netsetest/r/vehicle/truth"
    assert keys.node_state("r", 2) == "netsetest/r/node/2/state"
    assert keys.ready("r") == "netsetest/r/control/ready"
    assert keys.end("r") == "netsetest/r/control/end"
    assert keys.matches("netsetest/r/node/*/state", keys.node_state("r", 6))
    assert not keys.matches("netsetest/r/node/*/state", keys.node_input("r", 6))


def test_int_accepted_for_float_fields():
    """msgpack may carry 1 for 1.0: integers in float fields are fine."""
    m = decode(_mut(_state(), P=[1, 0, 0, 0, 1, 0, 0, 0, 1], innov=0, gamma=1))
    assert m.published.P == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0] and m.gamma == 1.0


@pytest.mark.parametrize(
    "change",
    [dict(xhat=["0.1", "0.2", "0.3"]), dict(innov=b"1"), dict(gamma=True)],
    ids=["str-xhat", "bytes-innov", "bool-gamma"],
)
def test_decode_rejects_non_numbers_in_float_fields(change):
    with pytest.raises(BadMessage) as exc:
        decode(_mut(_state(), **change))
    assert exc.value.reason == "invalid"


def _numpy_spd_problem(P: np.ndarray) -> str | None:
    """The check decode() made before spd_problem: numpy's allclose and Cholesky."""
    if not np.allclose(P, P.T, rtol=SYM_RTOL, atol=SYM_ATOL):
        return "P is not symmetric"
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        return "P is not positive definite"
    return None


def test_spd_problem_agrees_with_numpy():
    """The plain-float symmetric/positive-definite check accepts and rejects exactly what numpy's did,
    across scales, near-singular shapes and asymmetries at the tolerance."""
    rng = np.random.default_rng(7)
    verdicts: dict[str | None, int] = {}
    for t in range(20000):
        A = rng.normal(size=(3, 3)) * 10.0 ** rng.integers(-8, 8)
        kind = t % 5
        if kind == 0:
            P = A @ A.T
        elif kind == 1:
            P = A + A.T  # symmetric, often indefinite
        elif kind == 2:
            P = A  # generally not symmetric
        elif kind == 3:  # rank one plus a tiny ±identity: pivots at rounding level
            v = rng.normal(size=3)
            P = np.outer(v, v) + rng.choice([-1e-14, 1e-14]) * np.abs(v).max() ** 2 * np.eye(3)
        else:  # one entry off by a relative 1e-10 … 1e-8 around the symmetry tolerance
            P = A @ A.T
            i, j = rng.integers(0, 3, 2)
            P[i, j] *= 1 + rng.choice([1e-10, 1e-9, 2e-9, 1e-8]) * rng.choice([-1, 1])
        want = _numpy_spd_problem(P)
        assert spd_problem([float(x) for x in P.ravel()]) == want, P
        verdicts[want] = verdicts.get(want, 0) + 1
    assert min(verdicts.values()) > 2000 and len(verdicts) == 3  # every verdict well represented


# ---------------------------------------------------------------- bounded inbox


def test_inbox_bounded_per_key_and_fair():
    """A flood on one key: the surplus is dropped at once, and a message on another key is handled in the
    very next pump, not after the flood."""
    from netsetest.bus.base import MAX_PER_KEY, MAX_ROUNDS

    bus = MemoryBus()
    got: list[str] = []
    bus.subscribe("netsetest/r/**", lambda k, m: got.append(k))
    flooded, quiet = keys.node_state("r", 3), keys.node_state("r", 4)
    for k in range(10 * MAX_PER_KEY):  # ever later steps: each one finds the queue full of earlier ones
        bus.publish(flooded, _state(node=3, step=k))
    bus.publish(quiet, _state(node=4))
    assert bus.dropped["inbox-full"] == 9 * MAX_PER_KEY
    assert bus.pending() == MAX_PER_KEY + 1
    n = bus.pump()
    assert quiet in got and n == MAX_ROUNDS + 1  # one pump: at most MAX_ROUNDS from the flooded key
    while bus.pump():
        pass
    assert got.count(flooded) == MAX_PER_KEY and bus.pending() == 0


def test_flood_never_evicts_the_step_a_role_waits_for():
    """The input a node waits for arrives into a key already full of a flood (future steps, invalid values):
    it is kept and handled (a flood of NaN inputs once lost a node for the whole run)."""
    from netsetest.bus.base import MAX_PER_KEY

    bus = MemoryBus()
    got: list[NodeState] = []
    bus.subscribe("netsetest/r/**", lambda k, m: got.append(m))
    key = keys.node_state("r", 3)
    for k in range(100, 100 + 2 * MAX_PER_KEY):  # schema-valid, far ahead
        bus.publish(key, _state(step=k))
    for _ in range(5 * MAX_PER_KEY):  # invalid values: never queued at all
        bus.inject(key, _mut(_state(), xhat=[math.nan, 0.0, 0.0]))
    genuine = _state(step=5)
    bus.publish(key, genuine)
    assert bus.pending() == MAX_PER_KEY
    assert bus.dropped["invalid"] == 5 * MAX_PER_KEY and bus.dropped["inbox-full"] == MAX_PER_KEY
    assert bus.dropped["inbox-evicted"] == 1  # the farthest step made room
    while bus.pump():
        pass
    assert genuine in got and max(m.step for m in got) == 100 + MAX_PER_KEY - 2


def test_barrier_drops_a_ready_on_a_wrong_key_on_every_bus():
    """A schema-valid Ready on another role's key is dropped and counted, on every Bus implementation
    (the Barrier once called a method only one bus had: four roles crashed on one message)."""
    from netsetest.bus.base import Bus
    from netsetest.runtime.processes import Barrier

    for cls in [MemoryBus, *_zenoh_bus_classes()]:
        assert callable(getattr(cls, "drop", None)), cls
    bus = MemoryBus()
    me = Ready(role="node", node=1, seen_all=False)
    barrier = Barrier(bus, "r", me, {("node", 2), ("node", 3)})
    bus.publish(keys.ready_of("r", keys.role_name("node", 2)), Ready(role="node", node=3, seen_all=True))
    bus.publish(keys.ready_of("r", keys.role_name("node", 2)), _state())
    bus.pump()
    assert barrier.heard == set() and bus.dropped == {"ready-wrong-key": 1, "unexpected-type": 1}
    assert issubclass(MemoryBus, Bus)


def _zenoh_bus_classes() -> list[type]:
    from netsetest.bus.zenoh_bus import ZenohBus

    return [ZenohBus]


@pytest.mark.parametrize(
    "payload",
    [
        b"\xa1\xbe",  # a msgpack string of invalid UTF-8: UnicodeDecodeError
        b"\x91" * 1000 + b"\x00",  # an array nested 1000 deep: RecursionError
        b"\x81\xa1v" + b"\x91" * 5000 + b"\x00",  # the same inside the header's map
        b"\x81\xa4type" + b"\xa2\xff\xfe",  # invalid UTF-8 as a value
    ],
)
def test_decode_raises_only_bad_message(payload):
    with pytest.raises(BadMessage):
        decode(payload)


def test_inbox_bounded_number_of_keys():
    from netsetest.bus.base import MAX_KEYS

    bus = MemoryBus()
    bus.subscribe("netsetest/r/node/*/state", lambda k, m: None)
    for i in range(MAX_KEYS + 10):  # a wildcard subscription must not allocate per forged key
        bus.inject(f"netsetest/r/node/x{i}/state", encode(_state()))
    assert bus.pending() == MAX_KEYS and bus.dropped["inbox-keys"] == 10


def test_truth_maps_must_name_the_same_nodes():
    t = next(m for m in MESSAGES if isinstance(m, Truth))  # (it once read MESSAGES[6], a state: refused for another reason)
    assert decode(_pack(raw_message(t))) == t
    for bad in ({"faults": {}}, {"noise": {1: 0.0}}, {"faults": {"x": 0.0, 2: 0.0}}, {"faults": {0: 0.0, 2: 0.0}}):
        with pytest.raises(BadMessage, match="faults|noise"):
            decode(_pack(raw_message(t, **bad)))


def test_truth_fault_unknown_only_without_a_reading():
    """Truth.fault_unknown names nodes without a reading of the step, each once."""
    t = next(m for m in MESSAGES if isinstance(m, Truth))
    gap = raw_message(t, no_reading=[2], y={1: 0.1}, y_nofault={1: 0.1})
    assert decode(_pack({**gap, "fault_unknown": [2]})).fault_unknown == [2]
    for bad in ([1], [2, 2]):
        with pytest.raises(BadMessage, match="fault_unknown"):
            decode(_pack({**gap, "fault_unknown": bad}))


def test_run_scope():
    from netsetest.messages import RunScope

    scope = RunScope(frozenset({1, 2}), steps=10)
    t = next(m for m in MESSAGES if isinstance(m, Truth))
    assert scope.reject(NodeInput(step=10, node=2, y=0.0, gamma=1.0)) is None
    assert scope.reject(NodeInput(step=11, node=2, y=0.0, gamma=1.0)) == "step-beyond-run"
    assert scope.reject(NodeInput(step=1, node=3, y=0.0, gamma=1.0)) == "unknown-node"
    assert scope.reject(NodeInput(step=1, node=1, y=0.0, gamma=1.0, expect_from=[7])) == "unknown-node"
    assert scope.reject(End(steps=2**62)) == "step-beyond-run"
    t = t.model_copy(update={"step": 3, "lost": [(2, 1)], "alive": [1, 2]})
    assert scope.reject(t) is None  # its maps, losses and alive list name nodes 1 and 2 only
    assert scope.reject(t.model_copy(update={"alive": [1, 2, 3]})) == "unknown-node"
    assert scope.reject(t.model_copy(update={"lost": [(6, 1)]})) == "unknown-node"
    assert RunScope(frozenset({1, 2, 3}), 99).reject(t) == "truth-wrong-nodes"
    assert scope.reject(_state(node=2, step=3, used=[1], missing=[5])) == "unknown-node"
    # a state names nodes in its sender, used, missing, sets and readings: an unknown one anywhere drops it
    fits = {"node": 2, "step": 3, "used": [1], "missing": [1], "sets": [1], "readings": [(1, 0.1, 1.0)]}
    assert scope.reject(_state(**fits)) is None
    for named in ({"node": 3}, {"used": [1, 7], "sets": []}, {"missing": [7]}, {"sets": [7], "used": [1, 7]}, {"readings": [(1, 0.1, 1.0), (7, 0.1, 1.0)]}):
        assert scope.reject(_state(**(fits | named))) == "unknown-node", named
    assert scope.reject(_state(**(fits | {"step": 11}))) == "step-beyond-run"
