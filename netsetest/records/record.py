"""The run record: JSON Lines written as the run goes, so that a crash leaves a loadable partial record;
or the same content as MCAP (``.mcap`` suffix, :mod:`netsetest.records.mcap_io`, for Foxglove).

One JSON object per line (``format = "netsetest-record"``, ``version = 2``), gzip-compressed when the
file name ends in ``.gz``; the collector writes through a :class:`RecordSink` and flushes after every
step::

    {"kind": "meta", "format": "netsetest-record", "version": 2, "meta": {...}}      first line
    {"kind": "state", "node": i, "entry": {...}}     the node-state entries of step k, then
    {"kind": "truth", "entry": {...}}                the truth of step k: the step is complete
    ...
    {"kind": "summary", "summary": {...}}            last line, once the run is over

``meta``: run settings (topology, case, signals, variant, seed, steps, tau_s, mode, clock, node ids,
in-neighbour weights {i: {j: a_ij}}, run id).  Truth entry of step k: x = [β, r], faults {i: f_i}, u,
w, vx, noise {i}, gamma {i}, y {i}, y_nofault {i}, sector_ok {i}, r {i} = C̄x̄, fault_ok {i}, noise_ok {i},
dist_ok, lost [[j, i]], alive [i], drops {reason: n}, e [2] | null (model mismatch of k → k+1), mismatch_ok, speed, ay, envelope_ok (models/envelope.py);
a recorded drive's also x_acc, f_acc {i}, reference, no_reading [i] (nodes without a reading: absent from y, y_nofault) and fault_unknown [i] (among them, those whose
fault's truth nothing of the step tells).  State entry: step, xhat [3], P [9, row-major], rho,
published (the set the node proves, netsetest/proven.py: {xhat [3], P [9, row-major], rho, region [β₁, r₁, …],
fault [lo, hi], set}, absent parts left out), continues (the set it continues from, where not the published one),
status (no-reading: the step had no reading of the node's), resumed_from (status resume: the step of the own set it was carried from), rho_cert, solve_ms, used, missing, late, dropped, drops {reason: n}, sector [h1, h] | null,
sector_basis, E = eᵀP⁻¹e of the published ellipsoid (null when the truth of the step is unknown), contained (the
truth in the published set, whose per-coordinate bounds [[lo, hi] ×3] are in ``bounds``; a set estimator's
ellipsoid is the enclosing one its neighbours use), continues_contained, assumptions_ok (every assumption in the step's dependency cone held), inconsistent (present
where, without a reference, the node's own reading contradicted its declared bounds), contested (more
than one copy matched the truth: not judged).  ``summary``: the
per-node table and totals (the same object ``--summary-json`` writes; in code a
:class:`~netsetest.records.summary.RunSummary`, converted at this boundary).

Every line carries its number (``seq``, from 0), so a dropped, repeated or moved line makes the record
*damaged* (RecordError naming the line), not silently different; in every record the truth steps and each
node's state steps must strictly increase.  A file without the summary line (the collector, the vehicle
or the parent was killed) loads as a partial record: ``partial`` is true, ``summary`` None,
``last_complete_step`` the last step whose truth line was written, the states of the step being written
are left out, and an incomplete last line is ignored (an MCAP file loads only complete, with its verdict
message).  A run stopped before its last step (Ctrl-C: the collector writes what it has, and a summary)
is partial as well, with its summary.
:func:`load_record` also reads state entries written before issue 28 (the published ellipsoid as xhat, P, rho,
with fault_range, own_xhat, own_P and own_region beside it: :func:`proven_sets`), and version 1 records (one JSON
document with ``meta``, ``truth``, ``nodes``, ``summary``; optionally gzip-compressed).
:meth:`Record.fault_rows` gives the fault bounds.
"""

from __future__ import annotations

import gzip
import json
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Literal, Protocol, cast, get_args

import msgspec
import numpy as np

from netsetest.extras import require
from netsetest.models.sensor import NA
from netsetest.records.errors import RecordError
from netsetest.records.files import open_locked
from netsetest.records.meta import RunMeta
from netsetest.proven import ProvenSet, proven_sets
from netsetest.records.summary import RunSummary
from netsetest.records.truth import truth_entry, truth_json

FORMAT = "netsetest-record"
VERSION = 2
LEGACY_VERSION = 1  # one JSON document per run, written at the end
GZIP_MAGIC = b"\x1f\x8b"
MCAP_SUFFIX = ".mcap"  # open_sink/save_record/load_record dispatch on it (netsetest.records.mcap_io)
MAX_STEP = 10**9  # a step number beyond this is no run's (and would overflow the tools' integer arrays)
RECORD_SUFFIXES = (".json", ".jsonl", ".json.gz", ".jsonl.gz", MCAP_SUFFIX)  # what a record file may be named
SEQ = "seq"  # every line's number, from 0 (the meta line); records written before it have none


class RecordSink(Protocol):
    """Where the collector streams the record: :class:`JsonlSink`, an MCAP writer (``mcap_io.McapRecordWriter``),
    :class:`MemorySink`.

    Call order: ``meta`` once, then per step the ``state`` entries and the ``truth`` entry (which
    completes the step), ``summary`` once at the end, ``close``.
    """

    def meta(self, meta: RunMeta) -> None: ...
    def truth(self, entry: dict) -> None: ...
    def state(self, node: int, entry: dict) -> None: ...
    def summary(self, summary: RunSummary) -> None: ...
    def close(self) -> None: ...


class JsonlSink:
    """The record file: one JSON object per line, flushed at the end of every step."""

    def __init__(self, path: str | Path) -> None:
        path = Path(path)
        raw = open_locked(path)
        self._fh: IO[bytes] = cast(IO[bytes], gzip.GzipFile(fileobj=raw, mode="wb")) if path.suffix == ".gz" else raw
        self._raw = raw
        self._seq = 0

    def _line(self, obj: dict) -> None:
        obj[SEQ] = self._seq  # the loader finds a dropped, repeated or moved line by it
        self._seq += 1
        self._fh.write(json.dumps(obj, separators=(",", ":"), allow_nan=True).encode() + b"\n")

    def _flush(self) -> None:
        if isinstance(self._fh, gzip.GzipFile):
            self._fh.flush(zlib.Z_SYNC_FLUSH)  # a complete deflate block: readable up to here
        self._fh.flush()
        self._raw.flush()

    def meta(self, meta: RunMeta) -> None:
        self._line({"kind": "meta", "format": FORMAT, "version": VERSION, "meta": meta.to_dict()})
        self._flush()

    def truth(self, entry: dict) -> None:
        self._line({"kind": "truth", "entry": truth_json(entry)})
        self._flush()

    def state(self, node: int, entry: dict) -> None:
        self._line({"kind": "state", "node": node, "entry": entry})

    def summary(self, summary: RunSummary) -> None:
        self._line({"kind": "summary", "summary": summary.to_dict()})
        self._flush()

    def close(self) -> None:
        if not self._raw.closed:
            self._fh.close()
            self._raw.close()


@dataclass
class MemorySink:
    """Keeps the record in memory (in-memory runs and tests): ``parts()`` as the record has them."""

    meta_doc: RunMeta = field(default_factory=RunMeta)
    truth_entries: list[dict] = field(default_factory=list)
    node_entries: dict[str, list[dict]] = field(default_factory=dict)
    summary_doc: RunSummary | None = None

    def meta(self, meta: RunMeta) -> None:
        self.meta_doc = meta
        self.node_entries = {str(i): [] for i in meta.node_ids}

    def truth(self, entry: dict) -> None:
        self.truth_entries.append(entry)

    def state(self, node: int, entry: dict) -> None:
        self.node_entries.setdefault(str(node), []).append(entry)

    def summary(self, summary: RunSummary) -> None:
        self.summary_doc = summary

    def close(self) -> None:
        pass

    def parts(self) -> dict:
        return {"truth": self.truth_entries, "nodes": self.node_entries}


class TeeSink:
    """Writes every call to several sinks."""

    def __init__(self, *sinks: RecordSink) -> None:
        self.sinks = sinks

    def meta(self, meta: RunMeta) -> None:
        for s in self.sinks:
            s.meta(meta)

    def truth(self, entry: dict) -> None:
        for s in self.sinks:
            s.truth(entry)

    def state(self, node: int, entry: dict) -> None:
        for s in self.sinks:
            s.state(node, entry)

    def summary(self, summary: RunSummary) -> None:
        for s in self.sinks:
            s.summary(summary)

    def close(self) -> None:
        for s in self.sinks:
            s.close()


def open_sink(path: str | Path) -> RecordSink:
    """The streaming writer of a record file, by its suffix: MCAP for ``.mcap``, else JSON Lines."""
    if Path(path).suffix == MCAP_SUFFIX:
        require("mcap", "an MCAP record")
        from netsetest.records.mcap_io import McapRecordWriter

        return McapRecordWriter(path)
    return JsonlSink(path)


@dataclass
class NodeTrack:
    """One node's published ellipsoids, aligned by ``steps``."""

    id: int
    steps: np.ndarray  # (K,)
    xhat: np.ndarray  # (K, 3)
    P: np.ndarray  # (K, 3, 3)
    rho: np.ndarray  # (K,)
    E: np.ndarray  # (K,) eᵀP⁻¹e, NaN where the truth of that step is unknown
    contained: np.ndarray  # (K,) bool: judged and inside (False where not judged: see ``judged``)
    assumptions_ok: np.ndarray  # (K,) bool
    status: list[str]
    solve_ms: np.ndarray  # (K,)
    published: list[ProvenSet]  # (K) the set the node proved (xhat, P, rho above are its ellipsoids, as arrays)
    continues: list[ProvenSet | None]  # (K) the set it continued from where not the published one
    set_bounds: np.ndarray | None = None  # (K, 3, 2) the published set's per-coordinate bounds (None: older SDP records, the ellipsoid's)
    judged: np.ndarray | None = None  # (K,) bool: the collector judged the step (None: all were, older records)
    fdi: list[str | None] | None = None  # (K,) detected | healthy | undecided (docs/fdi.md; None: older records)
    continues_contained: np.ndarray | None = None  # (K,) bool: the set the node continues from held the truth (None: older records)
    missed_flags: np.ndarray | None = None  # (K,) bool: the set proven apart from the truth (None: records before issue 42, not contained)
    cuts: list[tuple[tuple[str, ...], ...] | None] | None = None  # (K) per coordinate, the cuts the node named (None: older records)

    @property
    def missed(self) -> np.ndarray:
        """(K,) bool: judged and proven to miss the truth (a model's run: judged and not contained; a recorded drive's
        reference: disjoint from its box, docs/your-log.md)."""
        judged = self.judged if self.judged is not None else ~np.isnan(self.E)
        return self.missed_flags & judged if self.missed_flags is not None else judged & ~self.contained

    @property
    def undecided(self) -> np.ndarray:
        """(K,) bool: judged, neither contained nor missed (a reference's box overlapping the set)."""
        judged = self.judged if self.judged is not None else ~np.isnan(self.E)
        return judged & ~self.contained & ~self.missed

    def was_judged(self, n: int) -> bool:
        return bool(self.judged[n]) if self.judged is not None else True

    def bounds(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower/upper bound of component ``index`` (0 β, 1 r, 2 f) of the published set: a set estimator's set,
        the SDP's ellipsoid ∩ its fault range ∩ its region of x (as the collector wrote them; records before it did:
        ProvenSet.bounds of the recorded sets)."""
        if self.set_bounds is not None:
            return self.set_bounds[:, index, 0].copy(), self.set_bounds[:, index, 1].copy()
        lo, hi = (np.array([p.bounds()[side][index] for p in self.published], dtype=float) for side in (0, 1))
        return lo, hi

    def interval_cuts(self, index: int) -> list[tuple[str, ...] | None]:
        """Per step, the cuts that narrowed component ``index``'s published interval, as the node sent them (NodeState.cuts;
        empty: its solve's ellipsoid or its method's own set alone; None: a record before states carried them)."""
        if self.cuts is None:
            return [None] * len(self.steps)
        return [None if c is None else c[index] for c in self.cuts]

    def ellipsoid_bounds(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower/upper bound of component ``index`` of the published ellipsoid alone, x̂ ∓ √(ρ P_ii): the paper's own
        set (a set estimator's: the ellipsoid around its set)."""
        half = np.sqrt(self.rho * self.P[:, index, index])
        return self.xhat[:, index] - half, self.xhat[:, index] + half

    @property
    def has_fault_range(self) -> bool:
        """Some published set of the node was cut by a fault range (a declared bound, the k-of-N pin, the region)."""
        return any(p.fault is not None for p in self.published)


@dataclass
class Record:
    path: str
    meta: RunMeta
    truth: list[dict]
    nodes: dict[int, NodeTrack]
    summary: RunSummary | None  # None in a partial record
    raw_nodes: dict[str, list[dict]]
    partial: bool = False  # the run did not finish: no summary line (cut short), or stopped before its last step (interrupted)
    last_complete_step: int = -1  # last step whose truth (and states) were written

    def truth_at(self, step: int) -> dict | None:
        return self._truth_by_step.get(step)

    def __post_init__(self) -> None:
        self._truth_by_step = {t["step"]: t for t in self.truth}

    def fault_rows(self, node: int) -> list[dict]:
        """Per step: fault estimate and bounds of node ``node``, with the true fault."""
        tr = self.nodes[node]
        lo, hi = tr.bounds(2)
        raw = self.raw_nodes.get(str(node), [])
        rows = []
        for n, k in enumerate(tr.steps):
            t = self.truth_at(int(k))
            rows.append(
                {
                    "step": int(k),
                    "fault_estimate": float(tr.xhat[n, 2]),
                    "fault_lower": float(lo[n]),
                    "fault_upper": float(hi[n]),
                    "fault_true": None if t is None or node not in t["faults"] else float(t["faults"][node]),
                    "E": None if np.isnan(tr.E[n]) else float(tr.E[n]),
                    "judged": tr.was_judged(n),
                    "contained": bool(tr.contained[n]) if tr.was_judged(n) else None,
                    "missed": bool(tr.missed[n]) if tr.was_judged(n) else None,
                    "undecided": bool(tr.undecided[n]) if tr.was_judged(n) else None,
                    "continues_contained": bool(tr.continues_contained[n]) if tr.was_judged(n) and tr.continues_contained is not None else None,
                    "status": tr.status[n],
                    "fdi": tr.fdi[n] if tr.fdi is not None else None,
                    "cause": None if tr.assumptions_ok[n] or n >= len(raw) else not_covered_cause(raw[n]),
                    "inconsistent": n < len(raw) and bool(raw[n].get("inconsistent", False)),  # its own data prove an assumption broken
                }
            )
        return rows

    def state_rows(self, node: int) -> list[dict]:
        """Per step: fault rows plus the state estimates, bounds and true values."""
        tr = self.nodes[node]
        rows = self.fault_rows(node)
        for comp, name in ((0, "beta"), (1, "r")):
            lo, hi = tr.bounds(comp)
            for n, row in enumerate(rows):
                t = self.truth_at(row["step"])
                row[f"{name}_estimate"] = float(tr.xhat[n, comp])
                row[f"{name}_lower"] = float(lo[n])
                row[f"{name}_upper"] = float(hi[n])
                row[f"{name}_true"] = None if t is None else float(t["x"][comp])
        own = "ellipsoid" if self.meta.estimators.get(node, "sdp") == "sdp" else "set"  # what the solve published
        for comp, name in ((0, "beta"), (1, "r"), (2, "fault")):
            for row, cuts in zip(rows, tr.interval_cuts(comp)):
                row[f"{name}_cuts"] = None if cuts is None else list(cuts)
                row[f"{name}_rests_on"] = _rests_on(comp, cuts, own)
        for n, row in enumerate(rows):  # both sets the collector judged, whole (continues: None where it is the published one)
            cont = tr.continues[n]
            row["published"] = msgspec.to_builtins(tr.published[n])
            row["continues"] = None if cont is None else msgspec.to_builtins(cont)
        return rows


def not_covered_cause(entry: dict) -> str:
    """Why a recorded node-step is outside the guarantee, in words: its cause, and for an inherited one the
    input it rests on (docs/coverage.md); "not covered" where an older record names none."""
    cause, origin = entry.get("not_covered_cause"), entry.get("inherited_from")
    if isinstance(origin, list) and len(origin) == 3:
        return f"inherited: node {origin[0]} step {origin[1]} {origin[2]}"
    return cause if isinstance(cause, str) else "not covered"


def _rests_on(index: int, cuts: tuple[str, ...] | None, own: str) -> str:
    """In a word, what a published interval rests on, from the cuts the node named: ``region`` (β, r: the region cut
    it), ``fault range`` (f: a cut narrowed it), else ``own`` (the solve's ellipsoid, a set estimator's set);
    ``unknown`` in a record before states named them."""
    if cuts is None:
        return "unknown"
    if index < NA - 1:
        return "region" if "region" in cuts else own
    return "fault range" if cuts else own


def _read(path: Path) -> bytes:
    """The file's bytes, gunzipped when compressed; a truncated gzip stream gives what it holds."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise RecordError(f"{path}: file not found") from None
    except OSError as exc:
        raise RecordError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if data[:2] != GZIP_MAGIC:
        return data
    d = zlib.decompressobj(wbits=31)
    try:
        out = d.decompress(data)
    except zlib.error as exc:
        raise RecordError(f"{path}: not a readable record (corrupt gzip: {exc})") from None
    return out


def check_record_path(path: str | Path | None) -> None:
    """Before a run: raise :class:`~netsetest.extras.MissingExtra` if the record's format cannot be written."""
    if path is not None and Path(path).suffix == MCAP_SUFFIX:
        require("mcap", "an MCAP record")


def _read_mcap(path: Path) -> Record:
    """An MCAP record; a file cut short (a killed run) loads as a partial record, as JSON Lines do."""
    require("mcap", "an MCAP record")
    from netsetest.records.mcap_io import McapReadError, read_mcap

    try:
        doc, partial = read_mcap(path)
    except FileNotFoundError:
        raise RecordError(f"{path}: file not found") from None
    except OSError as exc:
        raise RecordError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except McapReadError as exc:
        raise RecordError(f"{path}: {exc}") from None
    last = max((t["step"] for t in doc["truth"] if isinstance(t, dict) and isinstance(t.get("step"), int)), default=-1)
    return _build(path, doc["meta"], doc["truth"], doc["nodes"], doc["summary"], partial=partial, last_complete=last)


def load_record(path: str | Path) -> Record:
    path = Path(path)
    if path.suffix == MCAP_SUFFIX:
        return _read_mcap(path)
    data = _read(path)
    head = data.lstrip()[:200]
    if head.startswith(b'{"kind"') or head.startswith(b'{ "kind"'):
        return _load_lines(path, data)
    return _load_document(path, data)


def _load_lines(path: Path, data: bytes) -> Record:
    """Version 2: JSON Lines; without the summary line a partial record."""
    objs = _entries(path, data)
    meta = _header(path, objs)
    _check_sequence(path, objs)
    truth, nodes, summary = _body(path, objs, meta.get("node_ids", []))
    last = _check_order(path, truth, nodes)
    if summary is None:  # a partial record: the states of the step being written when it stopped are not a step
        nodes = {i: [e for e in es if e["step"] <= last] for i, es in nodes.items()}
    return _build(path, meta, truth, nodes, summary, partial=summary is None, last_complete=last)


def _entries(path: Path, data: bytes) -> list[dict]:
    """Every line as its record entry; the last line cut short (the writer died writing it) left out."""
    lines = data.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    objs: list[dict] = []
    for n, line in enumerate(lines):
        try:
            obj = json.loads(line)
        except ValueError:
            if n == len(lines) - 1:
                break  # the line being written when the writer died
            raise RecordError(f"{path}: malformed record (line {n + 1} is not JSON)") from None
        if not isinstance(obj, dict) or "kind" not in obj:
            raise RecordError(f"{path}: malformed record (line {n + 1} is not a record entry)")
        objs.append(obj)
    return objs


def _header(path: Path, objs: list[dict]) -> dict:
    """The meta line's meta, checked: this format and version, a dict."""
    if not objs or objs[0].get("kind") != "meta" or objs[0].get("format") != FORMAT:
        raise RecordError(f"{path}: not a netsetest record (no meta line)")
    if objs[0].get("version") != VERSION:
        raise RecordError(f"{path}: record version {objs[0].get('version')!r}, this netsetest reads {VERSION} and {LEGACY_VERSION}")
    meta = objs[0].get("meta")
    if not isinstance(meta, dict):
        raise RecordError(f"{path}: malformed record (meta must be a dict)")
    return meta


def _body(path: Path, objs: list[dict], node_ids: object) -> tuple[list[dict], dict[str, list[dict]], dict | None]:
    """The lines after the meta line: the truth entries, each node's states (``node_ids``: meta's, checked), the
    summary (None: a partial record)."""
    if not isinstance(node_ids, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in node_ids):
        raise RecordError(f"{path}: malformed record (meta.node_ids must be a list of node ids)")
    truth: list[dict] = []
    nodes: dict[str, list[dict]] = {str(i): [] for i in node_ids}
    summary: dict | None = None
    try:
        for n, obj in enumerate(objs[1:], start=2):
            kind = obj["kind"]
            if summary is not None:
                raise RecordError(f"{path}: damaged record (line {n}: a {kind!r} line after the summary)")
            if kind == "truth":
                truth.append(obj["entry"])
            elif kind == "state":
                nodes.setdefault(str(int(obj["node"])), []).append(obj["entry"])
            elif kind == "summary":
                summary = obj["summary"]
            else:
                raise RecordError(f"{path}: malformed record (line {n}: unknown kind {kind!r})")
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise RecordError(f"{path}: malformed record ({type(exc).__name__}: {exc})") from None
    return truth, nodes, summary


def _check_sequence(path: Path, objs: list[dict]) -> None:
    """Every line carries its number (``seq``): a dropped, repeated or moved line is damage, not a record."""
    if SEQ not in objs[0]:
        return  # written before line numbers: the order checks below are all there is
    for n, obj in enumerate(objs):
        seq = obj.get(SEQ)
        if seq != n:
            what = "missing" if seq is None else f"{seq!r}"
            raise RecordError(f"{path}: damaged record (line {n + 1}: sequence number {what}, expected {n}: a line was dropped, repeated or moved)")


def _check_order(path: Path, truth: list, nodes: dict[str, list]) -> int:
    """The truth steps and each node's state steps strictly increase (integers); the last truth step."""

    def steps(entries: list, what: str) -> list[int]:
        out: list[int] = []
        for e in entries:
            k = e.get("step") if isinstance(e, dict) else None
            if not isinstance(k, int) or isinstance(k, bool) or not 0 <= k <= MAX_STEP:
                raise RecordError(f"{path}: malformed record ({what}: step {k!r} is not a step number)")
            if out and k <= out[-1]:
                raise RecordError(f"{path}: damaged record ({what}: step {k} after step {out[-1]}: a line was repeated or moved)")
            out.append(k)
        return out

    last = (steps(truth, "truth") or [-1])[-1]
    for i, entries in nodes.items():
        steps(entries, f"node {i}")
    return last


def _load_document(path: Path, data: bytes) -> Record:
    """Version 1: one JSON document written at the end of the run."""
    try:
        doc = json.loads(data)
    except ValueError as exc:
        raise RecordError(f"{path}: not a readable record ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise RecordError(f"{path}: not a netsetest record (format field missing or wrong)")
    if doc.get("version") != LEGACY_VERSION:
        raise RecordError(f"{path}: record version {doc.get('version')!r}, this netsetest reads {VERSION} and {LEGACY_VERSION}")
    for name, kind in (("meta", dict), ("truth", list), ("nodes", dict), ("summary", dict)):
        if not isinstance(doc.get(name), kind):
            raise RecordError(f"{path}: malformed record ({name} must be a {kind.__name__})")
    last = _check_order(path, doc["truth"], {str(i): es if isinstance(es, list) else [None] for i, es in doc["nodes"].items()})
    return _build(path, doc["meta"], doc["truth"], doc["nodes"], doc["summary"], partial=False, last_complete=last)


def _build(path: Path, meta: dict, truth: list, raw_nodes: dict, summary: object, partial: bool, last_complete: int) -> Record:
    """``summary``: the summary object as the file holds it (None: a partial record)."""
    if not (summary is None or isinstance(summary, dict)):
        raise RecordError(f"{path}: malformed record (summary must be a dict)")
    try:
        typed = None if summary is None else RunSummary.from_dict(summary)
        return record_from_parts(RunMeta.from_dict(meta), truth, raw_nodes, typed, str(path), partial, last_complete)
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise RecordError(f"{path}: malformed record ({type(exc).__name__}: {exc})") from None


def _set_bounds(entries: list[dict]) -> np.ndarray | None:
    """(K, 3, 2) from the entries' ``bounds`` (every entry has them since the SDP publishes its region; before, a
    set estimator's node's), else None."""
    if not entries or any("bounds" not in e for e in entries):
        return None
    b = np.array([e["bounds"] for e in entries], dtype=float)
    if b.shape != (len(entries), 3, 2):
        raise ValueError(f"state bounds: expected [[lo, hi] ×3] per entry, got shape {b.shape}")
    return b


def _cuts(entries: list[dict]) -> list[tuple[tuple[str, ...], ...] | None] | None:
    """Per entry, the cuts of β, r, f its state named (None where a row has none: older records)."""
    if not any("cuts" in e for e in entries):
        return None
    out: list[tuple[tuple[str, ...], ...] | None] = []
    for e in entries:
        c = e.get("cuts")
        if c is not None and not (isinstance(c, list) and len(c) == NA and all(isinstance(n, list) and all(isinstance(x, str) for x in n) for n in c)):
            raise ValueError(f"state cuts: expected [names ×3] per entry, got {c!r}")
        out.append(None if c is None else tuple(tuple(n) for n in c))
    return out


def _tracked_sets(entries: list[dict]) -> dict[str, Any]:
    """NodeTrack's sets of the entries: each step's published set and the one continued from, and the published
    ellipsoids as arrays (xhat, P, rho)."""
    try:
        sets = [proven_sets(e) for e in entries]
    except msgspec.ValidationError as exc:
        raise ValueError(f"a state's set: {exc}") from None
    pub = [p for p, _ in sets]
    return {
        "xhat": np.array([p.xhat for p in pub], dtype=float).reshape(-1, NA),
        "P": np.array([p.P for p in pub], dtype=float).reshape(-1, NA, NA),
        "rho": np.array([p.rho for p in pub], dtype=float),
        "published": pub,
        "continues": [c for _, c in sets],
    }


FdiStatus = Literal["detected", "healthy", "undecided"]  # a node-step's fault detection (roles/fdi.py, docs/fdi.md)
FDI_VALUES: tuple[FdiStatus, ...] = get_args(FdiStatus)


def _fdi(v: object) -> str | None:
    if v is not None and v not in FDI_VALUES:
        raise ValueError(f"fdi: expected one of {', '.join(FDI_VALUES)}, got {v!r}")
    return v


def record_from_parts(
    meta: RunMeta,
    truth: list[dict],
    nodes: dict[str, list[dict]],
    summary: RunSummary | None,
    path: str = "",
    partial: bool = False,
    last_complete_step: int | None = None,
) -> Record:
    """A :class:`Record` from the parts a run returns (or a file holds); raises KeyError/TypeError/ValueError
    on malformed entries.  ``last_complete_step`` defaults to the last step of ``truth``."""
    tracks = {int(key): _track(int(key), entries) for key, entries in nodes.items()}
    for t in truth:
        if not isinstance(t, dict) or not isinstance(t.get("step"), int):
            raise ValueError("a truth entry without a step")
    truth = [truth_entry(t) for t in truth]
    if last_complete_step is None:
        last_complete_step = max((t["step"] for t in truth), default=-1)
    # a run stopped early (Ctrl-C: the collector writes what it has, summary included) is partial too
    stopped = summary is not None and meta.steps is not None and summary.steps_completed < meta.steps
    return Record(path, meta, truth, tracks, summary, nodes, partial or stopped, last_complete_step)


def _track(node: int, entries: list[dict]) -> NodeTrack:
    """One node's state lines as its track (KeyError/TypeError/ValueError on a malformed entry)."""
    return NodeTrack(
        id=node,
        steps=np.array([e["step"] for e in entries], dtype=int),
        **_tracked_sets(entries),
        E=np.array([np.nan if e["E"] is None else e["E"] for e in entries], dtype=float),
        contained=np.array([e["contained"] is True for e in entries], dtype=bool),
        assumptions_ok=np.array([bool(e["assumptions_ok"]) for e in entries], dtype=bool),
        status=[e["status"] for e in entries],
        solve_ms=np.array([e["solve_ms"] for e in entries], dtype=float),
        set_bounds=_set_bounds(entries),
        # records before "judged" wrote contained: true on unjudged rows too; say where they could not be
        judged=np.array([e.get("judged", e.get("E") is not None and not e.get("contested", False)) for e in entries], dtype=bool),
        fdi=[_fdi(e.get("fdi")) for e in entries],
        continues_contained=_flags(entries, "continues_contained", lambda v: v is not False),
        missed_flags=_flags(entries, "missed", lambda v: v is True),
        cuts=_cuts(entries),
    )


def _flags(entries: list[dict], key: str, flag: Callable[[object], bool]) -> np.ndarray | None:
    """A per-step flag the state lines carry since some version (None: a record older than it)."""
    if not any(key in e for e in entries):
        return None
    return np.array([flag(e.get(key)) for e in entries], dtype=bool)


def save_record(path: str | Path, meta: RunMeta, truth: list[dict], nodes: dict[str, list[dict]], summary: RunSummary | None) -> None:
    """Write a whole record (e.g. one kept in memory) in the streamed layout, step by step (``.mcap``: an
    indexed MCAP file); without a summary (a partial record) it stays partial (MCAP: not loadable)."""
    path = Path(path)
    if path.suffix == MCAP_SUFFIX:
        require("mcap", "an MCAP record")
        from netsetest.records.mcap_io import save_mcap

        save_mcap(path, meta, truth, nodes, summary)
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    by_step: dict[int, list[tuple[int, dict]]] = {}
    for key, entries in nodes.items():
        for e in entries:
            by_step.setdefault(e["step"], []).append((int(key), e))
    truth_at = {t["step"]: t for t in truth}
    sink = JsonlSink(path)
    try:
        sink.meta(meta)
        for k in sorted(set(by_step) | set(truth_at)):
            for node, e in sorted(by_step.get(k, []), key=lambda ne: ne[0]):
                sink.state(node, e)
            if k in truth_at:
                sink.truth(truth_at[k])
        if summary is not None:
            sink.summary(summary)
    finally:
        sink.close()


@dataclass(frozen=True)
class Mismatch:
    """A plant's model mismatch e_k (plant − T-S model) against the declared bound (docs/plant.md)."""

    steps: np.ndarray  # (K,)
    e: np.ndarray  # (K, 2) e_β [rad], e_r [rad/s]
    radius: np.ndarray | None  # (2,) the bound's half-width per component (a box's, or the box around an ellipsoid); None: no bound declared
    size: np.ndarray | None  # (K,) e_k in the bound's own norm, ‖G⁻¹e_k‖ (box: ∞-norm); ≤ 1 inside


def mismatch(rec: Record) -> Mismatch | None:
    """The record's e_k when its truth carries a non-zero model mismatch (a plant other than the T-S
    model), else None."""
    rows = [(e["step"], e["e"]) for e in rec.truth if e.get("e") is not None]
    if not rows or not any(any(v) for _, v in rows):
        return None
    steps, e = np.array([k for k, _ in rows], dtype=float), np.array([v for _, v in rows], dtype=float)
    unc = rec.meta.model_uncertainty
    if not isinstance(unc, dict):
        return Mismatch(steps, e, None, None)
    G, box = np.asarray(unc["G"], dtype=float), unc["kind"] == "box"
    radius = np.abs(G).sum(axis=1) if box else np.linalg.norm(G, axis=1)
    zeta = np.linalg.solve(G, e.T)  # e = G ζ
    return Mismatch(steps, e, radius, np.abs(zeta).max(axis=0) if box else np.sqrt((zeta * zeta).sum(axis=0)))
