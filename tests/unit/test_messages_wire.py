"""The msgspec message layer's own checks, written by hand where pydantic used to do them: the version
check before the typed decode, the drop reasons of odd payloads, finite numbers in every float field,
numpy scalars on the wire, the compatibility of the wire with the previous (pydantic) format, and the
pydantic-style helpers (``model_dump``/``model_copy``) the roles and tests use."""

from __future__ import annotations

import math

import msgpack
import msgspec
import numpy as np
import pytest

from netsetest.messages import (
    MAX_DETAIL,
    SCHEMA_VERSION,
    BadMessage,
    End,
    NodeInput,
    NodeState,
    Reading,
    Ready,
    Truth,
    decode,
    encode,
)

from message_helpers import SET_FIELDS, make_state, raw_message, truth

P_EYE = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]


def _state(**kw: object) -> NodeState:
    base: dict[str, object] = dict(step=4, node=2, xhat=[0.1, -0.2, 0.3], P=P_EYE, rho=1.0, gamma=0.9, innov=0.01, status="ok")
    base.update(kw)
    return make_state(**base)


EVERY_KIND = [
    Ready(role="node", node=3, seen_all=True),
    NodeInput(step=2, node=1, y=0.5, gamma=0.9, u_prev=0.02, vx_prev=27.0, expect_from=[2], lost_from=[3], deadline=1e9),
    _state(),
    _state(sector=(0.8, 0.1), sector_basis="measurement", used=[1, 3], missing=[3], late=True, dropped=2, drops={"x": 2}),
    truth(),
    End(steps=5, reason="aborted"),
    Reading(step=4, node=3, y=0.01, gamma=0.7),
    _state(readings=[(3, 0.01, 0.7)]),
]


def _pack(d: object) -> bytes:
    return msgpack.packb(d, use_bin_type=True)


def _reason(payload: bytes) -> str:
    with pytest.raises(BadMessage) as exc:
        decode(payload)
    return exc.value.reason


# ---------------------------------------------------------------- the wire


@pytest.mark.parametrize("msg", EVERY_KIND, ids=lambda m: type(m).__name__)
def test_version_and_type_always_sent(msg):
    """Fields at their default may be left out, ``v`` never (it has a default too); ``type`` is the tag."""
    raw = msgpack.unpackb(encode(msg), raw=False, strict_map_key=False)
    assert raw["v"] == SCHEMA_VERSION and raw["type"] == msg.type
    js = msg.model_dump(mode="json")
    for f in msgspec.structs.fields(msg):
        default = f.default_factory() if f.default_factory is not msgspec.NODEFAULT else f.default
        if getattr(msg, f.name) != default:
            # (a truth's node ids: int keys on the wire, strings in JSON)
            assert msgspec.json.decode(msgspec.json.encode(raw[f.encode_name])) == js[f.name], f.name
    assert "set" not in raw["published"] and "continues" not in raw and "rho_cert" not in raw if isinstance(msg, NodeState) else True


@pytest.mark.parametrize("msg", EVERY_KIND, ids=lambda m: type(m).__name__)
def test_previous_wire_format_decodes(msg):
    """The pydantic version sent every field (``v`` first, ``type`` second; a NodeState's published set
    leaves its absent parts out): such a payload decodes to the same message, and what we send decodes the same
    way under the previous rules (every field it leaves out has the default the old schema had)."""
    full = raw_message(msg)
    assert list(full)[:2] == ["v", "type"]
    back = decode(_pack(full))
    assert back == msg and type(back) is type(msg)
    ours = msgpack.unpackb(encode(msg), raw=False, strict_map_key=False)
    assert {**full, **ours} == msgpack.unpackb(_pack(full), raw=False, strict_map_key=False)  # what is missing is the default


@pytest.mark.parametrize("msg", EVERY_KIND, ids=lambda m: type(m).__name__)
def test_missing_version_is_rejected(msg):
    """``v`` has a default for constructing messages, but a payload without it is not the current version."""
    d = raw_message(msg)
    del d["v"]
    assert _reason(_pack(d)) == "schema-version"
    for bad in (None, 0, 1, SCHEMA_VERSION + 1, str(SCHEMA_VERSION), [SCHEMA_VERSION]):  # (1: before the sets were ProvenSets)
        d["v"] = bad
        assert _reason(_pack(d)) == "schema-version", bad
    d["v"] = True  # == 1 in Python: an old version's number, and a bool besides
    assert _reason(_pack(d)) == "schema-version"


@pytest.mark.parametrize(
    "payload,reason",
    [
        (_pack(None), "not-a-map"),
        (_pack("state"), "not-a-map"),
        (_pack({1: 2}), "schema-version"),  # a map, without v
        (_pack({1: 2, "v": SCHEMA_VERSION, "type": "end", "steps": 1}), "invalid"),  # a current-version map with a non-string key
        (_pack({"v": SCHEMA_VERSION, "type": "end", "steps": 1}) + b"\x00", "undecodable"),  # trailing bytes
        (b"\x81\xa1v", "undecodable"),  # truncated
        (b"\x81\x91\x01\x01", "schema-version"),  # a list as a map key: a map without v
    ],
    ids=["nil", "string", "int-keys", "mixed-keys", "trailing", "truncated", "list-key"],
)
def test_odd_payload_reasons(payload, reason):
    assert _reason(payload) == reason


FLOAT_FIELDS = [
    (NodeInput, "y"),
    (NodeInput, "gamma"),
    (NodeInput, "u_prev"),
    (NodeInput, "vx_prev"),
    (NodeInput, "deadline"),
    (NodeState, "rho"),
    (NodeState, "gamma"),
    (NodeState, "innov"),
    (NodeState, "rho_cert"),
    (NodeState, "solve_ms"),
    (Truth, "u"),
    (Truth, "w"),
    (Truth, "vx"),
]
BY_TYPE = {type(m): m for m in EVERY_KIND}


@pytest.mark.parametrize("cls,name", FLOAT_FIELDS, ids=[f"{c.__name__}.{n}" for c, n in FLOAT_FIELDS])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf], ids=["nan", "inf", "-inf"])
def test_every_float_field_must_be_finite(cls, name, bad):
    d = raw_message(BY_TYPE[cls])
    (d["published"] if cls is NodeState and name in SET_FIELDS else d)[name] = bad
    with pytest.raises(BadMessage) as exc:
        decode(_pack(d))
    assert exc.value.reason == "invalid" and name in str(exc.value)


@pytest.mark.parametrize("name", ["xhat", "P", "sector"])
def test_every_float_list_entry_must_be_finite(name):
    d = raw_message(_state(sector=(0.5, 0.5)))
    target = d["published"] if name in SET_FIELDS else d
    target[name] = list(target[name])
    target[name][1] = math.nan
    assert _reason(_pack(d)) == "invalid"


@pytest.mark.parametrize("name", ["faults", "noise", "gamma", "y", "y_nofault", "r"])
def test_truth_map_values_must_be_finite(name):
    d = raw_message(truth())
    d[name] = {**d[name], "2": math.inf}
    assert _reason(_pack(d)) == "invalid"


@pytest.mark.parametrize(
    "cls,change",
    [
        (NodeState, {"step": True}),
        (NodeState, {"step": 2.0}),
        (NodeState, {"node": "2"}),
        (NodeState, {"late": 1}),
        (NodeState, {"dropped": -1}),
        (NodeState, {"drops": {"x" * 65: 1}}),
        (NodeState, {"used": [0]}),
        (NodeState, {"used": list(range(1, 258))}),
        (End, {"reason": "x" * 65}),
        (End, {"reason": b"done"}),
        (Ready, {"role": "router"}),
        (Truth, {"lost": [[1, 2, 3]]}),
        (Truth, {"alive": [-1]}),
        (Truth, {"dist_ok": "yes"}),
        (Truth, {"drops": {str(i): 1 for i in range(65)}}),
    ],
    ids=lambda v: v.__name__ if isinstance(v, type) else ",".join(v),
)
def test_types_and_sizes_are_strict(cls, change):
    d = raw_message(BY_TYPE[cls])
    d.update(change)
    assert _reason(_pack(d)) == "invalid"


def test_detail_is_bounded():
    """A forged value is quoted in the reason, but never at length."""
    for d in ({**raw_message(_state()), "type": "x" * 100_000}, {**raw_message(_state()), "v": "x" * 100_000}):
        with pytest.raises(BadMessage) as exc:
            decode(_pack(d))
        assert len(str(exc.value)) <= MAX_DETAIL + len(exc.value.reason) + 2


def test_detail_names_the_field_and_why():
    d = raw_message(_state())
    d["published"]["xhat"] = [0.0, math.nan, 0.0]
    with pytest.raises(BadMessage, match=r"^invalid: published.xhat\[1\]: Expected finite `float`$"):
        decode(_pack(d))
    d = raw_message(_state())
    d["published"]["P"] = [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    with pytest.raises(BadMessage, match=r"^invalid: published: P is not positive definite$"):
        decode(_pack(d))


# ---------------------------------------------------------------- constructing messages


def test_numpy_scalars_go_on_the_wire_as_numbers():
    """Roles compute with numpy: float64, int64 and bool_ values encode as the Python numbers they are."""
    m = _state(rho=np.float64(0.5), innov=np.float64(-1e-3), late=np.bool_(True), dropped=np.int64(3))
    back = decode(encode(m))
    assert back.published.rho == 0.5 and back.innov == -1e-3 and back.late is True and back.dropped == 3
    assert type(back.published.rho) is float and type(back.dropped) is int
    with pytest.raises(TypeError, match="ndarray"):
        encode(_state(xhat=np.zeros(3)))


def test_cross_field_checks_run_at_construction():
    with pytest.raises(ValueError, match="positive definite"):
        _state(P=[1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="noise: keys differ"):
        truth(noise={1: 0.0})
    with pytest.raises(ValueError):
        _state(set={"type": "box", "lo": [0.0], "hi": [1.0]})


def test_messages_are_frozen():
    with pytest.raises(AttributeError):
        End(steps=1).steps = 2


def test_model_copy_is_unchecked_and_model_dump_is_complete():
    m = truth()
    forged = m.model_copy(update={"noise": {9: 0.0}})  # as pydantic's: no validation (tests forge with it)
    assert forged.noise == {9: 0.0} and m.noise != forged.noise
    with pytest.raises(BadMessage):
        decode(encode(forged))
    with pytest.raises(AttributeError, match="nonsense"):
        m.model_copy(update={"nonsense": 1})
    py, js = m.model_dump(), m.model_dump(mode="json")
    assert list(py)[:2] == ["v", "type"] == list(js)[:2]
    assert set(py) == {"type", *Truth.__struct_fields__}
    assert py["lost"] == [(1, 2)] and js["lost"] == [[1, 2]]
    assert set(js) == set(py) and js["r"] == {str(i): v for i, v in m.r.items()} and truth(r={}, fault_ok={}).model_dump(mode="json")["r"] == {}
    py["x"][0] = 99.0  # a dump is a copy
    assert m.x[0] == 0.01
