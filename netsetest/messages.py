"""Every message the roles exchange, defined once: msgspec Structs, msgpack on the wire.

A payload is a msgpack map with ``v`` (schema version) and ``type``; :func:`decode` validates it
(types, dimensions, finite numbers, step ≥ 0, bounded lists and maps, a Truth whose maps are non-empty
and keyed by the same node ids) and raises :class:`BadMessage` otherwise.  :class:`RunScope` checks a
decoded message against the run (its node ids, its last step); the receiving role applies it and its
own context checks (is the sender a real neighbour, is the step plausible).  Both buses encode and
decode every message, so the in-memory run exercises the same wire format as the Zenoh run.

The types and ranges (``msgspec.Meta`` on each field) are checked when a payload is decoded, not when a
role constructs a message; the cross-field checks (``__post_init__``: P symmetric positive definite, a
set that parses, Truth's maps over the same nodes) run on both.  A role that built a message outside
the ranges would see it dropped as ``invalid`` by every receiver, as both buses decode what they carry.
"""

from __future__ import annotations

import copy
import re
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, Self, Union

import msgspec
import numpy as np

try:  # CPython's own BLAKE2, which hashlib.blake2b is: importing hashlib would also load OpenSSL (+3.5 MB in every node)
    from _blake2 import blake2b
except ImportError:  # another interpreter
    from hashlib import blake2b
from msgspec import Meta, Struct, field

from netsetest.polygon import REGION_NOT_FINITE, REGION_NOT_NUMBERS, REGION_REASONS, REGION_VERTICES
from netsetest.proven import ProvenSet, continued_set
from netsetest.sets import CUT_NAMES, CutName
from netsetest.validation import FINITE_BOUND_TEXT, FLOAT_MAX, Finite, Positive, split_error

# 3: a truth's maps are keyed by node id (int keys: msgpack allows them); 2: a state carries its sets as ProvenSets
# (published, continues); 1 had seven set fields
SCHEMA_VERSION: Final = 3

FiniteF = Finite  # msgspec decodes strictly: no "0.1" or True for a number
Step = Annotated[int, Meta(ge=0)]
NodeId = Annotated[int, Meta(ge=1)]
Gamma = Annotated[float, Meta(gt=0, le=1)]
PositiveF = Positive
Vec2 = Annotated[list[FiniteF], Meta(min_length=2, max_length=2)]
MAX_NODES = 256  # a network larger than this is not a yaw-rate sensor network: bounds every list and map
MAX_REASON = 64  # characters of a drop-reason key or an End reason
MAX_DROP_REASONS = 64  # entries of a drop-counter map
IdList = Annotated[list[NodeId], Meta(max_length=MAX_NODES)]
NodeMap = Annotated[dict[NodeId, FiniteF], Meta(min_length=1, max_length=MAX_NODES)]  # node id → value (records keep JSON's string keys: records/record.py)
ReadingMap = Annotated[dict[NodeId, FiniteF], Meta(max_length=MAX_NODES)]  # a step's readings: a node without one is absent
FlagMap = Annotated[dict[NodeId, bool], Meta(min_length=1, max_length=MAX_NODES)]
Reason = Annotated[str, Meta(max_length=MAX_REASON)]
Drops = Annotated[dict[Reason, Annotated[int, Meta(ge=0)]], Meta(max_length=MAX_DROP_REASONS)]
SectorH1 = Annotated[float, Meta(gt=0, le=1)]
SectorH = Annotated[float, Meta(ge=0, le=FLOAT_MAX)]
DIGEST_BYTES = 16  # a state copy's identity (not a security mechanism: the transport authenticates)
CutNames = Annotated[list[CutName], Meta(max_length=len(CUT_NAMES))]  # the cuts that narrowed one published interval
Digest = Annotated[str, Meta(pattern=f"^[0-9a-f]{{{2 * DIGEST_BYTES}}}$")]


class BadMessage(ValueError):
    """A payload that failed decoding or validation; ``reason`` is short enough for a counter key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def _schema_version() -> Literal[3]:
    return SCHEMA_VERSION


class _Msg(Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, omit_defaults=True, tag_field="type"):
    """Base of every message: ``v`` is the schema version, ``type`` (the msgspec tag) its kind.

    Fields at their default may be left out of the payload (a NodeState without a set carries no
    ``set`` key; every receiver, the pydantic-based version before this one included, fills in the same
    defaults).  msgspec omits a value if it *is* the default object (an empty list or dict, None, a
    bool), so a decoded 0.0 may be sent again.  ``v`` is always sent: a default_factory's result is
    never omitted (tests/unit/test_messages_wire.py checks every kind's payload for ``v``).
    """

    v: Literal[3] = field(default_factory=_schema_version)

    @property
    def type(self) -> str:
        return self.__struct_config__.tag  # type: ignore[return-value]  # msgspec types the tag as str | int | None; ours are the class's str tags

    def model_dump(self, mode: Literal["python", "json"] = "python") -> dict[str, Any]:
        """Every field as a dict, ``v`` and ``type`` first (as the previous version sent them); ``json``:
        JSON types only (tuples as lists)."""
        d: dict[str, Any] = {"v": self.v, "type": self.type}
        d.update((f, getattr(self, f)) for f in self.__struct_fields__)
        if mode == "json":  # every field, defaults included (records and echo show them), as JSON types
            return msgspec.json.decode(msgspec.json.encode(d, enc_hook=_enc_hook))
        return copy.deepcopy(d)

    def model_copy(self, update: dict[str, Any] | None = None) -> Self:
        """A copy with ``update`` applied, unchecked (as pydantic's): tests forge messages with it."""
        new = copy.copy(self)
        for name, value in (update or {}).items():
            if name not in self.__struct_fields__:
                raise AttributeError(f"{type(self).__name__} has no field {name!r}")
            msgspec.structs.force_setattr(new, name, value)
        return new


class Ready(_Msg, tag="ready", frozen=True, kw_only=True):
    """A role announces it is subscribed (Zenoh start-up barrier).

    ``seen_all``: this role has heard Ready from every other role, so its subscriptions are known to
    them and theirs to it (a Ready travels on the same link after the subscriber declarations).

    ``acked`` (the collector's, during the run): the newest step whose truth it has taken in; in lockstep
    the vehicle publishes step k + ACK_WINDOW only once step k is acknowledged (roles/vehicle.py).
    """

    role: Literal["vehicle", "node", "collector"]
    node: NodeId | None = None
    seen_all: bool = False
    acked: Step | None = None


class NodeInput(_Msg, tag="input", frozen=True, kw_only=True):
    """Vehicle → node i at step k: ỹ_i,k and γ_i,k; u and Vx of step k−1; which neighbour messages to expect.

    ``expect_from``: in-neighbours j ≠ i whose step k−1 message node i should wait for (alive, not lost);
    ``lost_from``: in-neighbours whose step k−1 message is lost by the scheduled packet-loss model.
    ``y`` None: no reading at this step (a gap in a recorded drive, docs/your-log.md): a node running a set
    estimator publishes its prediction-only set (status ``no-reading``), an SDP node publishes nothing for it and
    resumes at its next reading (estimator/rejoin.py), every node at step 0 publishes its prior; ``unread``: the
    nodes without a reading at this step (whose readings of the step no one waits for).
    """

    step: Step
    node: NodeId
    y: FiniteF | None
    gamma: Gamma
    u_prev: FiniteF | None = None
    vx_prev: PositiveF | None = None
    expect_from: IdList = []
    lost_from: IdList = []
    deadline: FiniteF | None = None  # real-time clock: wall-clock time (s since epoch) the step is due
    unread: IdList = []


# what a node's published set is (NodeState.status); resume: its first after steps without a reading; no-reading: a
# step without the node's reading (a gap in a recorded drive): its last set moved through the model and the declared
# bounds alone (a set estimator's), or at step 0 the prior (Assumption 1), for every estimator
NodeStatus = Literal["init", "init-prior", "ok", "fallback", "rejoin", "resume", "no-reading"]


class NodeState(_Msg, tag="state", frozen=True, kw_only=True):
    """Node i → neighbours and collector: the set it proves at step k (``published``) and y̌_i,k.

    ``published`` (netsetest/proven.py): the SDP's ellipsoid {x̄: (x̄ − x̂)ᵀP⁻¹(x̄ − x̂) ≤ ρ} ∩ its region of x ∩ its
    fault range, or a set estimator's own set with the ellipsoid through its hull's corners; neighbours use the
    ellipsoid alone.  ``continues``: the ellipsoid the node continues from where that set is not the published one
    (the objective bank's x̂, P of the trace recursion, cut by the step's readings; without the published fault
    range, which rests on the step's own facts and is proved again at the next step); the set is that ellipsoid ∩
    the published region (:attr:`continued`: a node keeps one region, so the wire sends it once, not twice, in
    every message to every neighbour).  None: the published set itself.  The collector judges both sets (a miss
    on a covered node-step is a violation), the second also as the next step's prior."""

    step: Step
    node: NodeId
    published: ProvenSet
    gamma: Gamma
    innov: FiniteF | None  # ỹ_i,k − C̄ x̂; None: the node had no reading at this step (neighbours use nothing of it)
    status: NodeStatus  # init: prior ⊕ ỹ₀; init-prior: the prior
    continues: ProvenSet | None = None
    rho_cert: FiniteF | None = None
    solve_ms: Annotated[float, Meta(ge=0, le=FLOAT_MAX)] = 0.0
    used: IdList = []  # neighbours j ≠ i whose message entered this step
    missing: IdList = []  # expected neighbours whose message did not arrive in time
    late: bool = False  # real-time clock: finished after its deadline
    dropped: Annotated[int, Meta(ge=0)] = 0  # messages this node has dropped so far
    drops: Drops = {}  # the same, by reason (cumulative)
    # the own sensor's sector of this step, (h1_k, h_k): φ = σ(r) − h1·r ∈ [0, h·r]; h = 0: no saturation
    # at this step; None: the sensor models no saturation.  sector_basis: what it rests on (estimator/sector.py)
    sector: tuple[SectorH1, SectorH] | None = None
    sector_basis: Literal["none", "measurement", "fault-bound", "assumed"] = "none"
    # the exact copy of every state this step used, as (node, state_digest of the copy): the in-neighbours'
    # states and the node's own previous one (the collector judges those copies: docs/coverage.md)
    inputs: Annotated[list[tuple[NodeId, Digest]], Meta(max_length=MAX_NODES + 1)] = []
    # the readings of this very step the published set or the one the node continues from used, as
    # (node, ỹ, γ): the collector checks them against the truth and puts their noise and zero-fault
    # declarations into the step's cone
    readings: Annotated[list[tuple[NodeId, FiniteF, Gamma]], Meta(max_length=MAX_NODES)] = []
    health: bool = False  # either set used the k-of-N interval of the step's readings and its own ([network] max_faulty)
    # the in-neighbours whose published set of the step before (its region, its fault range: the whole set) cut this
    # step's sets (docs/network.md, *What a node takes from its network*): among ``used``; the collector requires each such copy to hold
    # the truth of its step
    sets: IdList = []
    # status "resume": the step of the node's own set this one was carried from through the steps without a reading
    resumed_from: Step | None = None
    # per coordinate β, r, f: the cuts that narrowed the published interval, in order (docs/estimator.md, "One step";
    # an empty list each: the solve's ellipsoid, or a set estimator's own set, alone; [] all three)
    cuts: Annotated[list[CutNames], Meta(max_length=3)] = []

    def __post_init__(self) -> None:
        c = self.continues
        if c is not None and (c.region is not None or c.fault is not None or c.set is not None):
            raise ValueError("continues: an ellipsoid alone (its region is the published set's)")
        if len(self.cuts) not in (0, 3):
            raise ValueError("cuts: one list of names per coordinate β, r, f (or none)")
        if self.sets and not set(self.sets) <= set(self.used):
            raise ValueError("sets: a neighbour's set the step did not receive (not in used)")
        if (self.status == "resume") != (self.resumed_from is not None) or (self.resumed_from is not None and self.resumed_from >= self.step):
            raise ValueError("resumed_from: the earlier step a resumed state was carried from (and only a resumed state has one)")
        if self.status == "no-reading" and self.innov is not None or self.innov is None and self.status not in WITHOUT_READING:
            raise ValueError("innov: None exactly where the node had no reading (status no-reading, or a set estimator's fallback)")

    @property
    def continued(self) -> ProvenSet:
        """The whole set the node continues from (the published one unless ``continues`` is sent)."""
        return continued_set(self.published, self.continues)


WITHOUT_READING = ("no-reading", "fallback")  # the statuses of a state without a reading (innov None)


def state_digest(st: NodeState) -> str:
    """The identity of a state copy: every field a receiver's step takes from it (the sets, the innovation,
    γ, the sector).  Two copies with the same digest are one."""
    cont = None if st.continues is None else st.continues.digest_content()
    content = [st.step, st.node, st.published.digest_content(), cont, st.gamma, st.innov, st.sector, st.sector_basis]
    return blake2b(msgspec.msgpack.encode(content), digest_size=DIGEST_BYTES).hexdigest()


class Truth(_Msg, tag="truth", frozen=True, kw_only=True):
    """Vehicle → collector only: the truth of step k and which assumptions held."""

    step: Step
    x: Vec2
    faults: NodeMap  # node id → f_i,k
    u: FiniteF
    w: FiniteF
    vx: FiniteF
    noise: NodeMap  # v_i,k
    gamma: NodeMap
    y: ReadingMap
    y_nofault: ReadingMap
    sector_ok: FlagMap  # |C̄_i x̄_i,k| ≤ r_max/h1 of the profile (the paper's fixed sector)
    r: Annotated[dict[NodeId, FiniteF], Meta(max_length=MAX_NODES)] = {}  # C̄_i x̄_i,k: the collector checks each node's published sector with it
    fault_ok: Annotated[dict[NodeId, bool], Meta(max_length=MAX_NODES)] = {}  # the declared fault bound held: |f_k − f_k−1| ≤ δ_i, |f_k| ≤ F_i
    noise_ok: FlagMap  # v_i,k² ≤ R_i
    dist_ok: bool  # w_k² ≤ W
    lost: Annotated[list[tuple[NodeId, NodeId]], Meta(max_length=MAX_NODES * MAX_NODES)] = []  # (j, i): j's k−1 message to i lost
    alive: IdList = []  # nodes the vehicle heard from at step k−1
    drops: Drops = {}  # messages the vehicle has dropped so far, by reason
    e: Vec2 | None = None  # model mismatch of k → k+1: x_{k+1} − (Ā x_k + B̄ u_k + D̄ w_k) (None: last step, older records)
    mismatch_ok: bool = True  # e_k within the declared [model_uncertainty] (none declared: e_k = 0)
    health_ok: bool = True  # at most max_faulty sensors faulty in every k-of-N group at step k (none declared: True)
    # the car's speed v_k [m/s] and the lateral acceleration the tyres carry over k → k+1 [m/s²] (models/envelope.py;
    # None: the T-S plant, the last step, older records), and whether that transition stayed inside the
    # declared [envelope] (none declared: True)
    speed: FiniteF | None = None
    ay: FiniteF | None = None
    envelope_ok: bool = True
    # a recorded drive (docs/your-log.md): the truth is known only to lie in a box: x ± x_acc (None: x is the truth
    # itself), each node's fault f ± f_acc (absent: exact); reference False: no reference at this step, x unknown
    x_acc: Vec2 | None = None
    f_acc: Annotated[dict[NodeId, Annotated[float, Meta(ge=0, le=FLOAT_MAX)]], Meta(max_length=MAX_NODES)] = {}
    reference: bool = True
    # nodes without a reading at this step (a gap in a recorded drive): absent from y and y_nofault (Scenario.silent_without_reading)
    no_reading: IdList = []
    # among them, those whose fault nothing of the step tells (the logged sensor not declared healthy: its reading less
    # the reference is what bounds it): their fault's truth is unknown, so no set is proven to hold it
    fault_unknown: IdList = []

    def __post_init__(self) -> None:
        if self.x_acc is not None and min(self.x_acc) < 0:
            raise ValueError("x_acc: half-widths must not be negative")
        ids = set(self.faults)
        for name in ("noise", "gamma", "sector_ok", "noise_ok"):
            if set(getattr(self, name)) != ids:
                raise ValueError(f"{name}: keys differ from the keys of faults")
        read = ids - set(self.no_reading)
        if len(read) != len(ids) - len(self.no_reading) or len(set(self.no_reading)) != len(self.no_reading):
            raise ValueError("no_reading: nodes of the step")
        if not set(self.fault_unknown) <= set(self.no_reading) or len(set(self.fault_unknown)) != len(self.fault_unknown):
            raise ValueError("fault_unknown: nodes without a reading at the step")
        for name in ("y", "y_nofault"):
            if set(getattr(self, name)) != read:
                raise ValueError(f"{name}: keys differ from the nodes with a reading")
        for name in ("r", "fault_ok", "f_acc"):  # absent ({}) in records written before the derived sector, and in a model's run
            if getattr(self, name) and set(getattr(self, name)) != ids:
                raise ValueError(f"{name}: keys differ from the keys of faults")

    def node_ids(self) -> set[int]:
        return set(self.faults)


class Reading(_Msg, tag="reading", frozen=True, kw_only=True):
    """Reference node j → every other node, at step k before j estimates: the ỹ_j,k and γ_j,k it
    measured (the same-step exchange phase, docs/network.md).  The receiver computes the interval of
    C_j x_k from them and j's sensor data in the topology."""

    step: Step
    node: NodeId
    y: FiniteF
    gamma: Gamma


class End(_Msg, tag="end", frozen=True, kw_only=True):
    """Vehicle → all: the run is over after ``steps`` steps (or aborted with a reason)."""

    steps: Step
    reason: Reason = "done"


Message = Union[Ready, NodeInput, NodeState, Truth, End, Reading]


@dataclass(frozen=True)
class RunScope:
    """What a message may name in this run: its node ids and steps 0..``steps``.

    Schema-valid but absurd for the run (a step after the last, a node the topology does not have, a
    Truth about other nodes) is a corrupt or hostile message: :meth:`reject` names why, the role drops it.
    """

    ids: frozenset[int]
    steps: int

    def beyond(self, step: int) -> str | None:
        """Why a payload naming ``step`` is dropped whatever else it holds (:meth:`reject`'s first test), or
        None: a subscription's screen (netsetest/bus/base.py), which drops it undecoded."""
        return "step-beyond-run" if step > self.steps else None

    def reject(self, msg: Message) -> str | None:
        """A drop reason, or None when the message fits the run."""
        step = msg.steps if isinstance(msg, End) else getattr(msg, "step", None)
        if step is not None and step > self.steps:
            return "step-beyond-run"
        ids = self.ids
        if type(msg) is Reading:  # the most frequent message (every reading to every node of a network): one id
            return None if msg.node in ids else "unknown-node"
        if type(msg) is NodeState:  # every state to every out-neighbour and the collector: no set built per message
            return None if self._knows_every_node_of(msg) else "unknown-node"
        named: set[int] = set()
        if isinstance(msg, (NodeInput, Ready)) and msg.node is not None:
            named.add(msg.node)
        if isinstance(msg, NodeInput):
            named.update(msg.expect_from, msg.lost_from)
        elif isinstance(msg, Truth):
            if msg.node_ids() != self.ids:
                return "truth-wrong-nodes"
            named.update(msg.alive, *msg.lost)
        return "unknown-node" if not named <= ids else None

    def _knows_every_node_of(self, st: NodeState) -> bool:
        """Every node a state names (its sender, used, missing, sets, readings) is one of the run's."""
        ids = self.ids
        return st.node in ids and ids.issuperset(st.used) and ids.issuperset(st.missing) and ids.issuperset(st.sets) and all(r[0] in ids for r in st.readings)


def _enc_hook(obj: object) -> object:
    """numpy scalars (a role's float64 or bool_ results) go on the wire as the Python numbers they are."""
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"cannot encode {type(obj).__name__} in a message")


class _Header(Struct):
    """What :func:`decode` reads first: a map, and its ``v``.  A missing ``v`` must be rejected, while a
    constructed message gets ``v`` by default, so the version is checked before the typed decode."""

    v: Any = None


class _StepHeader(Struct):
    """What a transport reads of a payload before decoding it (:func:`peek_step`): the step it names.
    Every other field is skipped unread (not built, not validated)."""

    step: Any = None


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_enc_hook)
_STEP = msgspec.msgpack.Decoder(_StepHeader)
_HEADER = msgspec.msgpack.Decoder(_Header)
_DECODER = msgspec.msgpack.Decoder(Message)
MAX_DETAIL = 200  # characters of a BadMessage's detail: a forged value must not make a log line huge
_FINITE = re.compile(rf"`float` (?:>= -|<= ){re.escape(FINITE_BOUND_TEXT)}")


def _detail(exc: msgspec.ValidationError) -> str:
    """msgspec's "Expected `float` >= 0 - at `$.xhat[1]`" as "xhat[1]: Expected `float` >= 0"."""
    msg, loc = split_error(exc)
    text = _FINITE.sub("finite `float`", msg)
    return (f"{loc}: {text}" if loc else text)[:MAX_DETAIL]


_REGION_AT = re.compile(r"(?:^|\.)region(?:\[\d+\])?$")  # a published set's region, or one of its coordinates


def _reason(exc: msgspec.ValidationError) -> str:
    """The drop reason of a payload that failed validation: a region's own (polygon.REGION_REASONS: its check names
    it first, through the set's __post_init__; or msgspec's on the region field: its length, a coordinate not
    finite, not numbers), else ``invalid``."""
    msg, loc = split_error(exc)
    head = msg.split(":", 1)[0]
    if head in REGION_REASONS:
        return head
    if _REGION_AT.search(loc):
        return REGION_VERTICES if "length" in msg else REGION_NOT_FINITE if _FINITE.search(msg) else REGION_NOT_NUMBERS
    return "invalid"


def _version_of_odd_payload(payload: bytes) -> object:
    """``v`` of a msgpack value that is not a map with string keys; BadMessage unless it is a map."""
    try:
        raw = msgspec.msgpack.decode(payload)
    except msgspec.DecodeError as exc:  # e.g. a map used as a key
        raise BadMessage("undecodable", str(exc)[:MAX_DETAIL]) from None
    if not isinstance(raw, dict):
        raise BadMessage("not-a-map")
    if raw.get("v") == SCHEMA_VERSION:
        raise BadMessage("invalid", "field names must be strings")
    return raw.get("v")


def encode(msg: Message) -> bytes:
    return _ENCODER.encode(msg)


# What msgspec's decoders raise on hostile bytes besides DecodeError: invalid UTF-8 in a string
# (UnicodeDecodeError, a ValueError), nesting deeper than the interpreter's stack (RecursionError), and a
# validator of ours (ValueError). None of them may leave decode(): a role would crash on one message.
_HOSTILE = (ValueError, RecursionError, OverflowError, TypeError)


def decode(payload: bytes) -> Message:
    """The message in ``payload``; raises :class:`BadMessage` and nothing else, whatever the bytes."""
    try:
        return _decode(payload)
    except BadMessage:
        raise
    except _HOSTILE as exc:
        raise BadMessage("undecodable", f"{type(exc).__name__}: {exc}"[:MAX_DETAIL]) from None


def peek_step(payload: bytes) -> int | None:
    """The step ``payload`` names (its ``step``, an integer ≥ 0), read without decoding the rest; None if it
    names none or the bytes are no map.  Never raises.  It says nothing of the payload's validity: a
    transport uses it only to drop, undecoded, a copy its role could not use whatever the rest holds (a
    step the role has passed, or after the run), and decodes whatever it keeps (:func:`decode`)."""
    try:
        step = _STEP.decode(payload).step
    except (msgspec.DecodeError, *_HOSTILE):
        return None
    return step if type(step) is int and step >= 0 else None


def _decode(payload: bytes) -> Message:
    try:
        version = _HEADER.decode(payload).v
    except msgspec.ValidationError:  # not a map with string keys: say which
        version = _version_of_odd_payload(payload)
    except msgspec.DecodeError as exc:
        raise BadMessage("undecodable", str(exc)[:MAX_DETAIL]) from None
    if version != SCHEMA_VERSION:
        raise BadMessage("schema-version", f"got {version!r}, expected {SCHEMA_VERSION}"[:MAX_DETAIL])
    try:
        return _DECODER.decode(payload)
    except msgspec.ValidationError as exc:
        raise BadMessage(_reason(exc), _detail(exc)) from None
    except msgspec.DecodeError as exc:  # e.g. nested too deeply for the typed decoder
        raise BadMessage("undecodable", str(exc)[:MAX_DETAIL]) from None
