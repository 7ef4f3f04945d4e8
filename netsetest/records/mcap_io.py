"""The run record as MCAP (https://mcap.dev): JSON messages with JSON Schemas, so Foxglove opens it.

Channels (message encoding ``json``, schema encoding ``jsonschema``), log time = k·τs in nanoseconds:

    /run/meta            once, t = 0: the record's ``meta`` (settings, graph)
    /vehicle/truth       per step: the record's truth entry (x = [β, r], faults, u, w, Vx, noise, γ, y,
                         assumption flags, lost links, alive nodes)
    /node/<i>/input      per step: what node i measured (y, y without fault, γ) and the vehicle's u, Vx
    /node/<i>/state      per published step: the record's node entry (x̂, P, ρ, status, sector, E,
                         contained, assumptions_ok, contested, …) plus the bounds of β, r and f (the published set's: the row's `bounds`) and the time t
    /node/<i>/drops      per published step: neighbours used, expected but missing, late (real time)
    /run/verdict         once, at the last step: the summary (violations, misses, per-node table)

:class:`McapRecordWriter` streams a run (one call per message, the file flushed after each, unindexed so
that nothing waits for a chunk to fill); :func:`write_mcap` converts a loaded record (chunked, zstd,
indexed).  :func:`read_mcap` returns the same document a JSON record holds (derived fields dropped), so
``load_record`` reads both; a streamed file cut short (a killed run) reads as a partial record.  Non-finite numbers are written as ``null`` (JSON has no NaN).
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader
from mcap.stream_reader import CRCValidationError
from zstandard import ZstdError
from mcap.writer import CompressionType, Writer

from netsetest.records.files import open_locked
from netsetest.records.meta import RunMeta
from netsetest.records.summary import RunSummary
from netsetest.records.truth import truth_json
from netsetest.proven import proven_sets

if TYPE_CHECKING:
    from netsetest.records.record import Record

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
PROFILE = ""  # no ROS profile: plain JSON channels
NS_PER_S = 1_000_000_000

TOPIC_META = "/run/meta"
TOPIC_TRUTH = "/vehicle/truth"
TOPIC_VERDICT = "/run/verdict"
COMPONENTS = (("beta", 0), ("r", 1), ("fault", 2))  # name and index in x̂ = [β, r, f]
DERIVED_STATE_FIELDS = frozenset({"t"} | {f"{n}_{s}" for n, _ in COMPONENTS for s in ("lower", "upper")})
DERIVED_TRUTH_FIELDS = frozenset({"t"})


def state_topic(node: int | str) -> str:
    return f"/node/{node}/state"


def input_topic(node: int | str) -> str:
    return f"/node/{node}/input"


def drops_topic(node: int | str) -> str:
    return f"/node/{node}/drops"


# ------------------------------------------------------------------------------------ schemas

_NUM = {"type": ["number", "null"]}
_INT = {"type": "integer"}
_BOOL = {"type": "boolean"}
_IDS = {"type": "array", "items": _INT}
_NUMBERS = {"type": "array", "items": {"type": "number"}}
_PROVEN_SET = {  # netsetest/proven.py's ProvenSet: absent parts are left out
    "type": "object",
    "properties": {
        "xhat": {**_NUMBERS, "description": "[β rad, r rad/s, f rad/s]"},
        "P": {**_NUMBERS, "description": "3×3 shape matrix, row-major"},
        "rho": {"type": "number"},
        "region": {**_NUMBERS, "description": "the region of (β, r): polygon vertices counter-clockwise, [β₁, r₁, β₂, r₂, …]"},
        "fault": {**_NUMBERS, "description": "[lo, hi]: the fault range the set is cut by"},
        "set": {"type": "object", "description": "a set estimator's own set (netsetest/sets.py set_to_wire); the ellipsoid encloses it"},
    },
    "required": ["xhat", "P", "rho"],
}
_PER_NODE_NUM = {"type": "object", "additionalProperties": _NUM, "description": "node id → value"}
_PER_NODE_BOOL = {"type": "object", "additionalProperties": _BOOL, "description": "node id → flag"}


def _schema(title: str, description: str, properties: dict[str, Any], required: list[str]) -> dict[str, Any]:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": required,
    }


SCHEMAS: dict[str, dict[str, Any]] = {
    "netsetest.RunMeta": _schema(
        "netsetest.RunMeta",
        "Run settings and graph",
        {
            "run_id": {"type": "string"},
            "topology": {"type": "string"},
            "case": {"type": "string"},
            "signals": {"type": "string"},
            "variant": {"type": "string"},
            "seed": _INT,
            "steps": _INT,
            "tau_s": {"type": "number", "description": "sampling period [s]"},
            "mode": {"type": "string"},
            "clock": {"type": "string"},
            "node_ids": _IDS,
            "in_weights": {"type": "object", "description": "node i → {in-neighbour j → a_ij}"},
        },
        ["run_id", "tau_s", "node_ids"],
    ),
    "netsetest.Truth": _schema(
        "netsetest.Truth",
        "The vehicle's truth of step k and which assumptions held",
        {
            "step": _INT,
            "t": {"type": "number", "description": "k·τs [s]"},
            "x": {"type": "array", "items": {"type": "number"}, "description": "[β rad, r rad/s]"},
            "faults": _PER_NODE_NUM,
            "u": {"type": "number", "description": "steering angle [rad]"},
            "w": {"type": "number", "description": "disturbance (wind)"},
            "vx": {"type": "number", "description": "speed [m/s]"},
            "noise": _PER_NODE_NUM,
            "gamma": _PER_NODE_NUM,
            "y": _PER_NODE_NUM,
            "y_nofault": _PER_NODE_NUM,
            "sector_ok": {**_PER_NODE_BOOL, "description": "node id → the paper's fixed sector |C̄x̄| ≤ r_max/h1 held"},
            "noise_ok": _PER_NODE_BOOL,
            "dist_ok": _BOOL,
            "r": {**_PER_NODE_NUM, "description": "node id → the sensor's true input C̄x̄"},
            "fault_ok": {**_PER_NODE_BOOL, "description": "node id → the declared fault bound held"},
            "lost": {"type": "array", "items": _IDS, "description": "[from j, to i]: j's previous message to i lost"},
            "alive": _IDS,
            "e": {
                "type": ["array", "null"],
                "items": {"type": "number"},
                "description": "model mismatch of k → k+1: x_{k+1} − (Ā x_k + B̄ u_k + D̄ w_k) [rad, rad/s]; null after the last step",
            },
            "mismatch_ok": {**_BOOL, "description": "e_k within the declared [model_uncertainty] (none declared: e_k = 0)"},
            "health_ok": {**_BOOL, "description": "at most max_faulty sensors faulty in every k-of-N group at this step (none declared: true)"},
            "speed": {"type": ["number", "null"], "description": "the car's speed v_k [m/s] (null: the T-S plant)"},
            "ay": {"type": ["number", "null"], "description": "mean lateral acceleration of k → k+1 [m/s²] (null: the T-S plant, the last step)"},
            "envelope_ok": {**_BOOL, "description": "k → k+1 inside the declared [envelope] (none declared: true)"},
            "x_acc": {
                "type": ["array", "null"],
                "items": {"type": "number"},
                "description": "a recorded drive's reference: the truth lies in x ± x_acc [rad, rad/s] (null: x is the truth)",
            },
            "f_acc": {**_PER_NODE_NUM, "description": "node id → a recorded drive's fault known to ± this (absent: exactly)"},
            "reference": {**_BOOL, "description": "false: a recorded drive without its reference at this step (x unknown)"},
            "no_reading": {**_IDS, "description": "nodes without a reading at this step (a recorded drive's gap)"},
            "fault_unknown": {**_IDS, "description": "among them, those whose fault's truth nothing of the step tells (not declared healthy)"},
        },
        ["step", "x", "faults"],
    ),
    "netsetest.NodeInput": _schema(
        "netsetest.NodeInput",
        "What node i measured at step k",
        {"step": _INT, "t": {"type": "number"}, "node": _INT, "y": _NUM, "y_nofault": _NUM, "gamma": _NUM, "u": _NUM, "vx": _NUM},
        ["step", "node"],
    ),
    "netsetest.NodeState": _schema(
        "netsetest.NodeState",
        "The set node i proves at step k (its ellipsoid {x: (x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ} ∩ its region ∩ its fault range) and its check",
        {
            "step": _INT,
            "t": {"type": "number"},
            "published": {**_PROVEN_SET, "description": "the set the node published (netsetest/proven.py)"},
            "continues": {**_PROVEN_SET, "description": "the set the node continues from, where not the published one"},
            "status": {"type": "string"},
            "rho_cert": _NUM,
            "solve_ms": _NUM,
            "used": _IDS,
            "missing": _IDS,
            "late": _BOOL,
            "readings": {**_IDS, "description": "nodes whose reading of this step the published set or the one the node continues from used (docs/network.md)"},
            "health": {**_BOOL, "description": "either set used the k-of-N interval of the step's readings ([network] max_faulty)"},
            "sets": {**_IDS, "description": "in-neighbours whose published set of the step before cut this step's sets (docs/network.md)"},
            "sector": {
                "type": ["array", "null"],
                "items": {"type": "number"},
                "description": "[h1, h] of this step's sector (null: the sensor models no saturation)",
            },
            "sector_basis": {"type": "string", "description": "none | measurement | fault-bound | assumed"},
            "E": {**_NUM, "description": "eᵀP⁻¹e (contained while ≤ ρ); null if the truth is unknown"},
            "judged": {**_BOOL, "description": "the collector judged this set (false: contested copies or unknown truth)"},
            "contained": {"type": ["boolean", "null"], "description": "null where not judged"},
            "missed": {
                "type": ["boolean", "null"],
                "description": "the set proven apart from the truth (a point truth: not contained; a recorded drive's reference box: disjoint); null where not judged",
            },
            "inconsistent": {**_BOOL, "description": "without a reference, the node's own reading contradicted its declared bounds (docs/your-log.md)"},
            "continues_contained": {"type": ["boolean", "null"], "description": "the set the node continues from held the truth; null where not judged"},
            "assumptions_ok": _BOOL,
            "contested": {**_BOOL, "description": "more than one copy matched the truth: not judged"},
            "not_judged_why": {"type": ["string", "null"], "description": "contested | truth unknown; null where judged"},
            "not_covered_cause": {"type": ["string", "null"], "description": "why the guarantee did not apply (docs/coverage.md); null where it did"},
            "inherited_from": {"type": ["array", "null"], "description": "[node, step, why] of the input a not-covered step rests on"},
            "fdi": {"type": ["string", "null"], "description": "detected | healthy | undecided: the fault interval against 0 (docs/fdi.md)"},
            "bounds": {
                "type": "array",
                "items": {"type": "array", "items": {"type": "number"}},
                "description": "[[lo, hi] ×3] of β, r, f: the published set's",
            },
            "cuts": {
                "type": "array",
                "items": {"type": "array", "items": {"type": "string"}},
                "description": "[names ×3] of β, r, f: the cuts that narrowed the published interval (docs/estimator.md, One step)",
            },
            **{f"{n}_{s}": {"type": "number", "description": f"{s} bound of {n} of the published set"} for n, _ in COMPONENTS for s in ("lower", "upper")},
        },
        ["step", "published", "status"],
    ),
    "netsetest.NodeDrops": _schema(
        "netsetest.NodeDrops",
        "Neighbour messages node i used, missed or was late with at step k",
        {"step": _INT, "t": {"type": "number"}, "node": _INT, "used": _IDS, "missing": _IDS, "late": _BOOL, "missing_count": _INT},
        ["step", "node"],
    ),
    "netsetest.Verdict": _schema(
        "netsetest.Verdict",
        "The run's summary: violations, misses after broken assumptions, per-node table",
        {
            "violations_total": _INT,
            "misses_assumption_broken_total": _INT,
            "steps_completed": _INT,
            "nodes_missing": _IDS,
            "nodes_rejoined": _IDS,
            "nodes": {"type": "array", "items": {"type": "object"}},
        },
        ["violations_total", "nodes"],
    ),
}

TOPIC_SCHEMA = {TOPIC_META: "netsetest.RunMeta", TOPIC_TRUTH: "netsetest.Truth", TOPIC_VERDICT: "netsetest.Verdict"}


def schema_of(topic: str) -> str:
    """The schema name of a topic."""
    if topic in TOPIC_SCHEMA:
        return TOPIC_SCHEMA[topic]
    kind = topic.rsplit("/", 1)[-1]
    return {"state": "netsetest.NodeState", "input": "netsetest.NodeInput", "drops": "netsetest.NodeDrops"}[kind]


def _finite(v: Any) -> Any:
    """JSON-safe copy: NaN and ±inf become None (JSON has neither)."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    return v


# ------------------------------------------------------------------------------------ writing


class McapRecordWriter:
    """Writes a run as MCAP, one call per record part: ``meta`` first, ``truth``/``state`` per step, then
    ``summary`` and ``close``.  ``indexed``: chunked, compressed and indexed (for a finished record);
    otherwise every message reaches the file at once (a stream that a crash leaves readable up to there),
    and a run that finishes (summary, close) is rewritten indexed unless ``index_at_close`` is False."""

    def __init__(self, path: str | Path, indexed: bool = False, index_at_close: bool = True) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh: IO[bytes] = open_locked(self.path)
        self._writer = Writer(
            self._fh,
            compression=CompressionType.ZSTD if indexed else CompressionType.NONE,
            use_chunking=indexed,
        )
        self._writer.start(profile=PROFILE, library="netsetest")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._tau_s = 1.0
        self._t0_ns = 0  # the run's start on the wall clock (meta "started_ns"): Foxglove shows real dates
        self._last_ns = 0
        self._closed = False
        self._indexed, self._finished = indexed or not index_at_close, False  # not index_at_close: leave the stream

    def _channel(self, topic: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            name = schema_of(topic)
            sid = self._schemas.get(name)
            if sid is None:
                sid = self._schemas[name] = self._writer.register_schema(name=name, encoding=SCHEMA_ENCODING, data=json.dumps(SCHEMAS[name]).encode())
            cid = self._channels[topic] = self._writer.register_channel(topic, MESSAGE_ENCODING, sid)
        return cid

    def _write(self, topic: str, log_ns: int, msg: dict) -> None:
        data = json.dumps(_finite(msg), separators=(",", ":"), allow_nan=False).encode()
        self._writer.add_message(self._channel(topic), log_time=log_ns, data=data, publish_time=log_ns)
        self._last_ns = max(self._last_ns, log_ns)

    def _time(self, step: int) -> tuple[float, int]:
        t = step * self._tau_s
        return t, self._t0_ns + round(t * NS_PER_S)

    def _flush(self) -> None:
        self._fh.flush()

    def meta(self, meta: RunMeta) -> None:
        self._tau_s = meta.tau_s
        started = meta.started_ns
        self._t0_ns = started if isinstance(started, int) and 0 <= started < MAX_LOG_NS else 0
        self._write(TOPIC_META, self._t0_ns, meta.to_dict())
        self._flush()

    def truth(self, entry: dict) -> None:
        t, ns = self._time(int(entry["step"]))
        entry = truth_json(entry)
        self._write(TOPIC_TRUTH, ns, {**entry, "t": t})
        for node, y in entry.get("y", {}).items():
            self._write(
                input_topic(node),
                ns,
                {
                    "step": entry["step"],
                    "t": t,
                    "node": int(node),
                    "y": y,
                    "y_nofault": entry.get("y_nofault", {}).get(node),
                    "gamma": entry.get("gamma", {}).get(node),
                    "u": entry.get("u"),
                    "vx": entry.get("vx"),
                },
            )
        self._flush()

    def state(self, node: int, entry: dict) -> None:
        t, ns = self._time(int(entry["step"]))
        msg = {**entry, "t": t}
        if "bounds" in entry:  # the published set (a set estimator's; the SDP's ellipsoid ∩ fault range ∩ region)
            lo, hi = np.asarray(entry["bounds"], dtype=float).T
        else:  # records before the bounds were written: the ellipsoid, the fault within the step's fault range
            lo, hi = proven_sets(entry)[0].bounds()
        for name, j in COMPONENTS:
            msg[f"{name}_lower"], msg[f"{name}_upper"] = float(lo[j]), float(hi[j])
        self._write(state_topic(node), ns, msg)
        missing = list(entry.get("missing", []))
        self._write(
            drops_topic(node),
            ns,
            {
                "step": entry["step"],
                "t": t,
                "node": node,
                "used": list(entry.get("used", [])),
                "missing": missing,
                "late": bool(entry.get("late", False)),
                "missing_count": len(missing),
            },
        )
        self._flush()

    def summary(self, summary: RunSummary) -> None:
        self._write(TOPIC_VERDICT, self._last_ns, summary.to_dict())
        self._flush()
        self._finished = True

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._fh.close()
        if self._finished and not self._indexed:
            # the run is over: the stream (readable after a crash) becomes a chunked, indexed file, which
            # Foxglove opens without reading it all; replaced in one rename, never half-written
            parts, _ = read_mcap(self.path)
            save_mcap(self.path, RunMeta.from_dict(parts["meta"]), parts["truth"], parts["nodes"], RunSummary.from_dict(parts["summary"]))


MAX_LOG_NS = 2**63  # MCAP log times are unsigned 64-bit nanoseconds; a meta start beyond is ignored


def save_mcap(path: str | Path, meta: RunMeta, truth: list[dict], nodes: dict[str, list[dict]], summary: RunSummary | None) -> None:
    """Write a whole record as an indexed MCAP file, in time order (never a half-written file at ``path``)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".part")
    w = McapRecordWriter(tmp, indexed=True)
    try:
        w.meta(meta)
        by_step: dict[int, list[tuple[int, dict]]] = {}
        for node_key, entries in nodes.items():
            for e in entries:
                by_step.setdefault(int(e["step"]), []).append((int(node_key), e))
        truth_by_step = {int(t["step"]): t for t in truth}
        for k in sorted(set(by_step) | set(truth_by_step)):
            if k in truth_by_step:
                w.truth(truth_by_step[k])
            for node, e in sorted(by_step.get(k, []), key=lambda ne: ne[0]):
                w.state(node, e)
        if summary is not None:  # a partial record stays one (the reader refuses it)
            w.summary(summary)
    finally:
        w.close()
    tmp.replace(path)


def write_mcap(record: Record, path: str | Path) -> None:
    """Convert a loaded :class:`~netsetest.records.record.Record` (any format) to MCAP."""
    save_mcap(path, record.meta, record.truth, record.raw_nodes, record.summary)


# ------------------------------------------------------------------------------------ reading


class McapReadError(Exception):
    """An MCAP file that is not a readable netsetest record (the caller adds the path)."""


def read_mcap(path: str | Path) -> tuple[dict, bool]:
    """The parts ``meta``, ``truth``, ``nodes``, ``summary`` of an MCAP record, as a JSON record holds
    them, and whether the record is partial: a file cut short (a killed run: the streamed file is
    flushed after every message) gives what precedes the cut and no summary.  MCAP has no checksum
    per unchunked message, so a file damaged in the middle reads the same way, up to the damage.  Raises
    :class:`McapReadError` for a file without the meta message (foreign, or cut before it), and for a
    damaged chunk of a finished (chunked, compressed) record: one that does not decompress or whose
    checksum does not match is damage, never a cut."""
    meta: dict | None = None
    summary: dict | None = None
    truth: list[dict] = []
    nodes: dict[str, list[dict]] = {}
    cut: str | None = None
    with open(path, "rb") as fh:
        try:
            reader = NonSeekingReader(fh, validate_crcs=True)  # a chunk's CRC: damage inside a chunk is found
            for _schema_rec, channel, message in reader.iter_messages(log_time_order=False):  # file order: stream, no buffering
                topic = channel.topic
                if topic == TOPIC_META:
                    meta = json.loads(message.data)
                elif topic == TOPIC_TRUTH:
                    d = json.loads(message.data)
                    truth.append({k: v for k, v in d.items() if k not in DERIVED_TRUTH_FIELDS})
                elif topic == TOPIC_VERDICT:
                    summary = json.loads(message.data)
                elif topic.startswith("/node/") and topic.endswith("/state"):
                    d = json.loads(message.data)
                    node = topic.split("/")[2]
                    nodes.setdefault(node, []).append({k: v for k, v in d.items() if k not in DERIVED_STATE_FIELDS})
        except (CRCValidationError, ZstdError) as exc:  # before ValueError (CRCValidationError is one)
            raise McapReadError(f"damaged record (a compressed chunk is corrupt: {type(exc).__name__}: {exc})") from None
        except (McapError, EOFError, ValueError, KeyError, AssertionError, struct.error) as exc:
            cut = f"{type(exc).__name__}: {exc}"  # a killed writer; what precedes is the record so far
    if meta is None:
        why = f"not a readable MCAP file ({cut})" if cut else f"no {TOPIC_META} message"
        raise McapReadError(f"{why} (not a netsetest record, or cut before its first message)")
    truth.sort(key=lambda e: e["step"])
    for entries in nodes.values():
        entries.sort(key=lambda e: e["step"])
    for i in meta.get("node_ids", []):  # a node that never published has no channel, but an entry list
        nodes.setdefault(str(i), [])
    return {"meta": meta, "truth": truth, "nodes": nodes, "summary": summary}, summary is None
