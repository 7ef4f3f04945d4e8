"""Reading the mapped signals of a drive log as a stream, each format through the field's own library (the ``logs`` extra).

- CSV and Parquet: pyarrow, batch by batch, the time column and the mapped columns only;
- ASAM MDF4: asammdf, the mapped channels only, each with its own time base, fragment by fragment
  (``iter_get``), merged in time;
- ROS 2 bags (MCAP or sqlite3, a bag directory or its one storage file): rosbags, which needs no ROS install,
  the mapped topics only, each message's field (``angular_velocity.z`` of a ``sensor_msgs/msg/Imu``,
  ``twist.twist.linear.x`` of a ``nav_msgs/msg/Odometry``, ``data`` of a ``std_msgs/msg/Float64``), stamped by
  its header where it has one, else by its log time; rosbags gives the raw payloads, and the stamp and fields are
  read at the offsets its typestore's layout gives (logs/cdr.py), a batch of messages at once, checked against its
  full deserialisation on the first message of every size and every :data:`BAG_CHECK_EVERY`-th (:class:`_Topic`).

A role never holds the log: :class:`SampleStream` reads it a chunk at a time and holds only the samples not yet
used, the few seconds the file may hold out of time order (``[log] reorder_s``) and a step's worth ahead.  Every
channel is cleaned by one set of stated rules as it streams (docs/your-log.md): a NaN or infinite sample is no
sample (dropped: the step takes the newest finite one within the gap tolerance, else the measurement is missing);
stamps are put in time order within the reorder window (a later sample stamped before one already used is an
error naming the window); two samples with one stamp and the same value are one, and with different values an
error (which one the sensor measured is unknown); and a physical range per kind of signal catches a wrong unit.
:func:`scan_signals` reads the whole log once so (the run's import: every rule checked before the run starts, and
what the steps need, per signal: first and last stamps, value range, the gaps longer than the tolerance).
Anything wrong is a :class:`LogError`: one line naming the file, the signal and why.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from itertools import islice
from operator import attrgetter, itemgetter
from pathlib import Path
from typing import Any

import numpy as np

from netsetest.config.logmap import LogMapping, SignalMap, log_format
from netsetest.extras import require
from netsetest.logs.cdr import FieldAt, Layout, layout, read_fields

BATCH_ROWS = 16_384  # rows a CSV or Parquet batch holds: what the stream reads ahead at most, per pull
BAG_CHUNK = 4_096  # messages of a bag per pull: ~15 ms of rosbags' reading, so that a real-time vehicle's step is never late for it
BAG_CHECK_EVERY = 256  # of a connection's messages read at their CDR offsets, every this-many-th is also deserialised by rosbags and compared
MDF_FRAGMENT_BYTES = 1 << 18  # asammdf's read fragment: a channel's samples per pull (a few thousand)
MAX_GAPS = 4_096  # gaps longer than the tolerance a scan keeps per signal (an input needs none inside the run)
NEVER = np.iinfo(np.int64).max
_CONN, _LOG_TIME, _RAW, _CONN_ID = itemgetter(0), itemgetter(1), itemgetter(2), attrgetter("id")  # of rosbags' (connection, log time, raw payload)
# the physical range of each kind of signal, SI: a sample beyond it is a wrong unit (deg/s read as rad/s), not a car
PLAUSIBLE = {
    "speed": 500.0 / 3.6,  # m/s
    "steering": 1.0,  # rad of road-wheel angle (models/manoeuvres.py STEERING_MAX_RAD)
    "yaw rate": 5.0,  # rad/s: 286 °/s, a car spinning
    "reference β": 1.5,  # rad
    "reference r": 5.0,
}

Chunk = list[tuple[str, np.ndarray, np.ndarray]]  # (signal name, raw stamps [ns, int64, no offset], raw values) in file order


class LogError(Exception):
    """A drive log or its mapping cannot give the run's signals; the message says which file, signal and why."""


def _kind(sig: SignalMap) -> str:
    return "yaw rate" if sig.name.startswith("yaw rate") else sig.name


def _why(exc: Exception) -> str:
    return str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__


class SampleStream:
    """The mapped signals' cleaned samples (module doc), released in time order per signal once final: no sample
    stamped at or before :meth:`horizon` can come later.  :meth:`pull` reads one chunk; :meth:`take` hands over what
    was released since the last take."""

    def __init__(self, path: Path, signals: list[SignalMap], chunks: Iterator[Chunk], reorder_ns: int) -> None:
        self.path, self.chunks, self.reorder = path, chunks, reorder_ns
        self.sigs = {s.name: s for s in signals}
        self.pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {n: [] for n in self.sigs}
        self.out: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {n: [] for n in self.sigs}
        self.last: dict[str, tuple[int, float] | None] = dict.fromkeys(self.sigs)  # the newest released sample
        self.closed = dict.fromkeys(self.sigs, -NEVER)  # the horizon each signal was released up to: nothing may come at or before it
        self.raw_max = -NEVER  # the latest raw stamp read, any signal
        self.done = False

    def horizon(self, name: str) -> int:
        """Every sample of ``name`` stamped at or before this [ns] is released (the whole log: ``NEVER``)."""
        if self.done:
            return NEVER
        return self.raw_max - self.reorder + self.sigs[name].offset_ns

    def pull(self) -> bool:
        """Read one chunk and release what became final; False once the log is read (everything released)."""
        if self.done:
            return False
        try:
            chunk = next(self.chunks)
        except StopIteration:
            self.done = True
            self._release()
            return False
        for name, t_raw, raw in chunk:
            if t_raw.size:
                self.raw_max = max(self.raw_max, int(t_raw.max()))
                self._add(self.sigs[name], t_raw, raw)
        self._release()
        return True

    def take(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(stamps, values) released for ``name`` since the last take, in time order."""
        parts, self.out[name] = self.out[name], []
        if not parts:
            return np.empty(0, dtype=np.int64), np.empty(0)
        return parts[0] if len(parts) == 1 else (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))

    def _add(self, sig: SignalMap, t_raw: np.ndarray, raw: np.ndarray) -> None:
        t, v = np.asarray(t_raw, dtype=np.int64) + sig.offset_ns, np.asarray(raw, dtype=float) * sig.scale
        finite = np.isfinite(v)
        if not finite.all():
            t, v = t[finite], v[finite]
        if not v.size:
            return
        limit = PLAUSIBLE[_kind(sig)]
        beyond = np.flatnonzero(np.abs(v) > limit)
        if beyond.size:
            i = int(beyond[0])
            raise LogError(
                f"{self.path}: {sig.name} ({sig.channel}): {v[i]:.4g} (SI) at t = {t[i] / 1e9:.6g} s is beyond any road car's "
                f"(|{_kind(sig)}| ≤ {limit:.4g}): is the mapping's unit, ratio or sign right?"
            )
        last = self.last[sig.name]
        late = np.flatnonzero((t <= self.closed[sig.name]) & (t != (last[0] if last is not None else NEVER)))  # a copy of the last: _unique
        if late.size:
            i = int(late[0])
            raise LogError(
                f"{self.path}: {sig.name} ({sig.channel}): a sample at t = {t[i] / 1e9:.9g} s comes after the log reached "
                f"t = {(self.raw_max + sig.offset_ns) / 1e9:.9g} s, more than [log] reorder_s = {self.reorder / 1e9:g} s out of time order: "
                "raise reorder_s (the reader holds that much of the log)"
            )
        self.pending[sig.name].append((t, v))

    def _release(self) -> None:
        for name, parts in self.pending.items():
            h = self.closed[name] = self.horizon(name)
            if not parts:
                continue
            t = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
            v = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
            ready = t <= h
            if not ready.any():
                self.pending[name] = [(t, v)]
                continue
            self.pending[name] = [(t[~ready], v[~ready])] if not ready.all() else []
            t, v = t[ready], v[ready]
            order = np.argsort(t, kind="stable")
            t, v = self._unique(self.sigs[name], t[order], v[order])
            if t.size:
                self.out[name].append((t, v))
                self.last[name] = (int(t[-1]), float(v[-1]))

    def _unique(self, sig: SignalMap, t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sorted samples with one per stamp (an equal copy dropped, a differing one an error), the newest released
        sample included in the comparison."""
        last = self.last[sig.name]
        if last is not None:
            t, v = np.concatenate([[last[0]], t]), np.concatenate([[last[1]], v])
        same = np.flatnonzero(t[1:] == t[:-1])
        if same.size:
            differ = same[v[same] != v[same + 1]]
            if differ.size:
                i = int(differ[0])
                raise LogError(
                    f"{self.path}: {sig.name} ({sig.channel}): two samples at t = {t[i] / 1e9:.9g} s differ ({v[i]:g}, {v[i + 1]:g}): "
                    "which one was measured is unknown"
                )
            keep = np.ones(t.size, dtype=bool)
            keep[same + 1] = False
            t, v = t[keep], v[keep]
        return (t[1:], v[1:]) if last is not None else (t, v)


def read_chunks(log: Path, mapping: LogMapping) -> Iterator[Chunk]:
    """Every mapped signal's raw samples (stamps without their offset, values without their scale), in file order, a
    chunk at a time, by the reader of the log's format (LogError: a format it cannot be, a file it cannot read)."""
    try:
        fmt = log_format(log, mapping)
    except ValueError as exc:
        raise LogError(str(exc)) from None
    reader = {"csv": _table, "parquet": _table, "mdf4": _mdf4, "rosbag": _rosbag}[fmt]
    return reader(log, mapping, fmt)


def open_stream(log: Path, mapping: LogMapping) -> SampleStream:
    """The stream of every mapped signal of ``log`` (LogError: a format it cannot be, a file it cannot read)."""
    return SampleStream(log, mapping.signals, read_chunks(log, mapping), round(mapping.reorder_s * 1e9))


@dataclass(frozen=True)
class SignalScan:
    """One signal over the whole log (cleaned): how many samples, the first and last stamps [ns], the value range,
    and the gaps (a, b) between consecutive samples further apart than the tolerance (at most :data:`MAX_GAPS`;
    ``more_gaps``: there were more)."""

    count: int
    first_ns: int
    last_ns: int
    lo: float
    hi: float
    gaps: tuple[tuple[int, int], ...]
    more_gaps: bool


def scan_signals(log: Path, mapping: LogMapping, tolerance_ns: int) -> dict[str, SignalScan]:
    """Read the whole log once through :class:`SampleStream` (every rule checked) and summarise each signal; a
    signal without a finite sample is a LogError."""
    stream = open_stream(log, mapping)
    acc: dict[str, dict[str, Any]] = {n: {"count": 0, "first": None, "last": None, "lo": np.inf, "hi": -np.inf, "gaps": [], "more": False} for n in stream.sigs}
    while True:
        more = stream.pull()
        for name, a in acc.items():
            t, v = stream.take(name)
            if not t.size:
                continue
            a["count"] += t.size
            a["lo"], a["hi"] = min(a["lo"], float(v.min())), max(a["hi"], float(v.max()))
            joined = t if a["last"] is None else np.concatenate([[a["last"]], t])
            if a["first"] is None:
                a["first"] = int(t[0])
            a["last"] = int(t[-1])
            wide = np.flatnonzero(np.diff(joined) > tolerance_ns)
            room = MAX_GAPS - len(a["gaps"])
            a["gaps"] += [(int(joined[i]), int(joined[i + 1])) for i in wide[:room]]
            a["more"] |= wide.size > room
        if not more:
            break
    out = {}
    for name, a in acc.items():
        sig = stream.sigs[name]
        if not a["count"]:
            raise LogError(f"{log}: {sig.name} ({sig.channel}): no finite sample")
        out[name] = SignalScan(a["count"], a["first"], a["last"], a["lo"], a["hi"], tuple(a["gaps"]), a["more"])
    return out


# ---------------------------------------------------------------- CSV and Parquet (pyarrow)


def _batches(log: Path, fmt: str, columns: list[str]) -> Iterator[Any]:
    import pyarrow as pa
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    try:
        if fmt == "parquet":
            pf = pq.ParquetFile(log)
            have = pf.schema_arrow.names
            _columns_present(log, columns, have)
            yield from pf.iter_batches(batch_size=BATCH_ROWS, columns=columns)
        else:
            with open(log, "rb") as fh:
                head = fh.readline().decode("utf-8").strip().split(",")  # not text: UnicodeDecodeError, "cannot read it as csv"
            _columns_present(log, columns, [h.strip().strip('"') for h in head])
            convert = pcsv.ConvertOptions(include_columns=columns, column_types={c: pa.float64() for c in columns})
            reader = pcsv.open_csv(log, read_options=pcsv.ReadOptions(block_size=1 << 20), convert_options=convert)
            yield from reader
    except (pa.ArrowException, OSError, UnicodeDecodeError) as exc:  # a truncated or corrupted file, an unreadable value
        raise LogError(f"{log}: cannot read it as {fmt}: {str(exc).splitlines()[0][:200]}") from None


def _columns_present(log: Path, want: list[str], have: list[str]) -> None:
    missing = [c for c in want if c not in have]
    if missing:
        raise LogError(f"{log}: no column {missing[0]!r} (columns: {', '.join(have[:12])}{' …' if len(have) > 12 else ''})")


def _table(log: Path, mapping: LogMapping, fmt: str) -> Iterator[Chunk]:
    """CSV or Parquet: one time column (``[log] time``) for every signal, a batch of rows per chunk."""
    require("pyarrow", f"reading a {fmt} drive log", extra="logs")
    columns = list(dict.fromkeys([mapping.time, *(s.channel for s in mapping.signals)]))
    for batch in _batches(log, fmt, columns):
        t = batch.column(mapping.time).to_numpy(zero_copy_only=False).astype(float)
        if not np.all(np.isfinite(t)):
            raise LogError(f"{log}: time column {mapping.time!r} has a value that is not a number")
        t_ns = np.round(t * (mapping.time_scale * 1e9)).astype(np.int64)
        yield [(s.name, t_ns, batch.column(s.channel).to_numpy(zero_copy_only=False).astype(float)) for s in mapping.signals]


# ---------------------------------------------------------------- ASAM MDF4 (asammdf)


def _mdf4(log: Path, mapping: LogMapping, fmt: str) -> Iterator[Chunk]:
    """Each mapped channel fragment by fragment, merged in time: the channel whose next sample is earliest gives its
    samples up to the others' next one (plus half the reorder window, so that a chunk is not a single sample)."""
    require("asammdf", "reading an MDF4 drive log")
    from asammdf import MDF

    try:
        mdf = MDF(log)
    except Exception as exc:  # asammdf raises many kinds on a damaged file: each is "cannot read"
        raise LogError(f"{log}: cannot read it as MDF4: {_why(exc)}") from None
    try:
        mdf.configure(read_fragment_size=MDF_FRAGMENT_BYTES)
        names = set(mdf.channels_db)
        for s in mapping.signals:
            if s.channel not in names:
                raise LogError(f"{log}: no channel {s.channel!r} for {s.name} (channels: {', '.join(sorted(names)[:12])})")
        its = {s.name: (s.channel, mdf.iter_get(s.channel)) for s in mapping.signals}
        heads: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        slack = round(mapping.reorder_s * 1e9) // 2
        for name in its:
            _next_fragment(log, its, heads, name)
        while heads:
            name = min(heads, key=lambda n: int(heads[n][0][0]))
            t, v = heads[name]
            others = min((int(heads[n][0][0]) for n in heads if n != name), default=NEVER - slack)
            cut = max(1, int(np.searchsorted(t, others + slack, side="right")))
            yield [(name, t[:cut], v[:cut])]
            if cut < t.size:
                heads[name] = (t[cut:], v[cut:])
            else:
                _next_fragment(log, its, heads, name)
    finally:
        mdf.close()


def _next_fragment(log: Path, its: dict[str, tuple[str, Iterator[Any]]], heads: dict[str, tuple[np.ndarray, np.ndarray]], name: str) -> None:
    """The channel's next non-empty fragment into ``heads`` (removed at its end)."""
    channel, it = its[name]
    heads.pop(name, None)
    while True:
        try:
            sig = next(it)
        except StopIteration:
            return
        except Exception as exc:  # a damaged block reads as any exception: "cannot read"
            raise LogError(f"{log}: cannot read channel {channel!r}: {_why(exc)}") from None
        if len(sig.timestamps):
            heads[name] = (np.round(np.asarray(sig.timestamps, dtype=float) * 1e9).astype(np.int64), np.asarray(sig.samples, dtype=float))
            return


# ---------------------------------------------------------------- ROS 2 bags (rosbags)


def _field(msg: object, path: str, log: Path, topic: str) -> float:
    value: Any = msg
    for part in path.split("."):
        if not hasattr(value, part):
            raise LogError(f"{log}: topic {topic}: its {type(msg).__name__} has no field {path!r}")
        value = getattr(value, part)
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        raise LogError(f"{log}: topic {topic}: field {path!r} is no number ({type(value).__name__})")
    return float(value)


def _stamp(msg: object, t_log: int) -> int:
    """The message's header stamp (ns) where it has one, else its log time."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return t_log
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _same(a: float, b: float) -> bool:
    return a == b or (a != a and b != b)  # NaN read both ways is NaN (dropped later either way)


DEFAULT_FIELD = "data"  # a std_msgs number's field, for a topic mapped without one
STAMP_FIELDS = ("header.stamp.sec", "header.stamp.nanosec")  # a header-stamped type's stamp, as _stamp reads it


class _Topic:
    """One connection of the bag and the signals mapped on it.  Its messages' stamps and fields are read at their CDR
    offsets (logs/cdr.py) where its type's layout gives them; rosbags deserialises in full the messages of a size not
    yet seen (their offsets then checked against it), every :data:`BAG_CHECK_EVERY`-th message (checked likewise), and
    every message whose fields have no offset (a mismatch: LogError, never a value)."""

    def __init__(self, reader: Any, conn: Any, sigs: list[SignalMap], log: Path) -> None:
        self.reader, self.conn, self.sigs, self.log = reader, conn, sigs, log
        self.paths = [s.field or DEFAULT_FIELD for s in sigs]
        self.getters: list[Callable[[object], float]] | None = None  # after the first message's fields were checked
        self.sizes: set[int] = set()  # sizes whose offsets rosbags' deserialisation confirmed
        self.count = 0  # messages of the connection so far
        self.stamped = any(name == "header" for name, _ in reader.typestore.get_msgdef(conn.msgtype).fields)
        self.places = self._places()

    def _places(self) -> tuple[Layout, list[FieldAt]] | None:
        """The layout and, in order, the stamp's seconds and nanoseconds (if the type has a header) and each mapped
        field; None: some have no offset."""
        ts = self.reader.typestore
        lay = layout(ts, self.conn.msgtype)
        ats = [lay.fields.get(p) for p in ((*STAMP_FIELDS, *self.paths) if self.stamped else self.paths)]
        return None if any(a is None for a in ats) else (lay, [a for a in ats if a is not None])

    def _full(self, raw: bytes, t_log: int) -> tuple[int, list[float]]:
        """rosbags' reading of one message: its stamp and mapped fields."""
        msg = self.reader.deserialize(raw, self.conn.msgtype)
        if self.getters is None:  # a connection has one message type: its fields are checked on its first message
            values = [_field(msg, p, self.log, self.conn.topic) for p in self.paths]
            self.getters = [attrgetter(p) for p in self.paths]
            return _stamp(msg, t_log), values
        return _stamp(msg, t_log), [float(get(msg)) for get in self.getters]

    def read(self, raws: list[bytes], t_log: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        """Stamps [ns] and each mapped field's values of the connection's next messages (in file order)."""
        n = len(raws)
        stamps, values = t_log.copy(), [np.empty(n) for _ in self.sigs]
        for i in self._at_offsets_checked(raws, t_log, stamps, values) if self.places is not None and n else range(n):
            stamps[i], row = self._full(raws[i], int(t_log[i]))
            for v, x in zip(values, row):
                v[i] = x
        self.count += n
        return stamps, values

    def _at_offsets_checked(self, raws: list[bytes], t_log: np.ndarray, stamps: np.ndarray, values: list[np.ndarray]) -> list[int]:
        """Read the messages at their offsets, size by size, the first of a size not seen and every
        :data:`BAG_CHECK_EVERY`-th checked; the ones left for rosbags (a big-endian payload, a size no offset fits)."""
        n = len(raws)
        sizes = np.fromiter(map(len, raws), np.int64, n)
        one = bool((sizes == sizes[0]).all())  # the usual: a connection's messages all of one size
        left: list[int] = []
        check = set(range(-self.count % BAG_CHECK_EVERY, n, BAG_CHECK_EVERY))
        for size in [int(sizes[0])] if one else np.unique(sizes).tolist():
            sel = np.arange(n) if one else np.flatnonzero(sizes == size)
            read = self._at_offsets(raws if one else [raws[i] for i in sel.tolist()], size, sel, stamps, values)
            left += sel[~read].tolist()
            if size not in self.sizes and read.any():  # a size not seen: its first message confirms the offsets
                check.add(int(sel[read][0]))
        for i in sorted(check.difference(left)):
            self._check(i, raws[i], int(t_log[i]), stamps, values)
        return left

    def _at_offsets(self, raws: list[bytes], size: int, sel: np.ndarray, stamps: np.ndarray, values: list[np.ndarray]) -> np.ndarray:
        """Read messages of one size at their offsets into ``stamps`` and ``values`` at ``sel``; which ones were (a
        little-endian payload large enough for every field)."""
        assert self.places is not None
        lay, ats = self.places
        offsets = [lay.offset(a, size) for a in ats]
        if any(o is None for o in offsets):
            return np.zeros(sel.size, dtype=bool)
        little, cols = read_fields(raws, size, [(o, a.dtype) for o, a in zip(offsets, ats) if o is not None])
        if self.stamped:  # the header's stamp first
            stamps[sel] = cols[0].astype(np.int64) * 1_000_000_000 + cols[1]
            cols = cols[2:]
        for v, c in zip(values, cols):
            v[sel] = c
        return little

    def _check(self, i: int, raw: bytes, t_log: int, stamps: np.ndarray, values: list[np.ndarray]) -> None:
        """rosbags' full deserialisation of message ``i`` against what its offsets gave (a mismatch is an error); its
        size confirmed."""
        stamp, row = self._full(raw, t_log)
        got = [("header.stamp", stamp, int(stamps[i]))] + [(p, x, float(v[i])) for p, x, v in zip(self.paths, row, values)]
        for what, want, fast in got:
            if not _same(want, fast):
                raise LogError(
                    f"{self.log}: topic {self.conn.topic}: message {self.count + i} ({len(raw)} bytes): {what} read at its offset in the "
                    f"{self.conn.msgtype} layout is {fast!r}, rosbags reads {want!r}: the payload is not laid out as its type says"
                )
        self.sizes.add(len(raw))


_MCAP_MESSAGE = 0x05  # the MCAP opcode of a message record: channel u16, sequence u32, log time u64, publish time u64, data
_MCAP_RECORD = struct.Struct("<BQ")  # a record's opcode and length
_MCAP_MESSAGE_HEAD = struct.Struct("<HIQQ")
_MCAP_CHUNK_CRC_AT = 9 + 24  # a chunk record's uncompressed CRC: after its opcode, length, start and end times, size
_MCAP_CHUNK_DATA_AT = 9 + 40  # its compressed data: after the CRC, the compression's name (+ its length) and the data's size


def _mcap_messages(reader: Any, connections: list[Any]) -> Iterator[tuple[Any, int, bytes]] | None:
    """rosbags' ``reader.messages(connections=…)`` of a bag whose storage is indexed MCAP with chunks that do not
    overlap in time, read the way rosbags' McapReader reads them (the chunk index it read, its decompress with the
    chunk's CRC, each chunk's messages sorted by log time, stably) but walked with one struct per record instead of
    a file object, a tuple and a heap entry each: the same messages, in the same order, at a fifth of rosbags' CPU
    (docs/your-log.md).  None where that does not hold: rosbags reads the bag then (sqlite3, per-message compression,
    an unindexed file, chunks that overlap in time, several bags)."""
    from rosbags.rosbag2.storage_mcap import McapReader, decompress

    bags = getattr(reader, "readers", [])
    storage = getattr(bags[0], "storage", None) if len(bags) == 1 else None
    files = getattr(storage, "storages", [storage])  # a bag directory's storage files, or the one file
    if not all(isinstance(f, McapReader) and f.chunks for f in files) or bags[0].compression_mode == "message":
        return None
    plans = []
    for f in files:
        ids = {x.id: c for x in f.connections if (c := _same_connection(x, connections)) is not None}
        chunks = sorted((c for c in f.chunks if any(c.channel_count.get(i, 0) for i in ids)), key=attrgetter("chunk_start_offset"))
        if any(b.message_start_time < a.message_end_time for a, b in zip(chunks, chunks[1:])):
            return None  # rosbags merges them by log time: only its heap gives that order
        plans.append((f, ids, chunks))

    def walk() -> Iterator[tuple[Any, int, bytes]]:
        for f, ids, chunks in plans:
            for c in chunks:
                f.bio.seek(c.chunk_start_offset + _MCAP_CHUNK_CRC_AT)
                (crc,) = struct.unpack("<I", f.bio.read(4))
                f.bio.seek(c.chunk_start_offset + _MCAP_CHUNK_DATA_AT + len(c.compression))
                buf = decompress(f.bio.read(c.compressed_size), c.compression, c.uncompressed_size, crc)
                found, pos, end = [], 0, len(buf)
                while pos < end:
                    op, size = _MCAP_RECORD.unpack_from(buf, pos)
                    if pos + 9 + size > end:
                        raise ValueError(f"a record of chunk {c.chunk_start_offset} runs past its end")
                    if op == _MCAP_MESSAGE:
                        channel, _, t, _ = _MCAP_MESSAGE_HEAD.unpack_from(buf, pos + 9)
                        if channel in ids and c.message_start_time <= t <= c.message_end_time:
                            found.append((ids[channel], t, buf[pos + 31 : pos + 9 + size]))
                    pos += 9 + size
                found.sort(key=_LOG_TIME)
                yield from found

    return walk()


def _same_connection(x: Any, connections: list[Any]) -> Any:
    """The connection of ``connections`` a storage's connection ``x`` is, as rosbags' DirectoryReader.messages matches
    them (topic, type, its serialisation, its digest where both have one; None: none)."""
    return next(
        (c for c in connections if (c.topic, c.msgtype, c.ext) == (x.topic, x.msgtype, x.ext) and (not x.digest or not c.digest or c.digest == x.digest)),
        None,
    )


def _rosbag(log: Path, mapping: LogMapping, fmt: str) -> Iterator[Chunk]:
    """The mapped topics' messages in the bag's order, :data:`BAG_CHUNK` per chunk, each connection's read by
    :class:`_Topic`."""
    require("rosbags", "reading a ROS 2 bag")
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = log if log.is_dir() else log.parent  # a bag directory, or its one storage file beside metadata.yaml
    by_topic: dict[str, list[SignalMap]] = {}
    for s in mapping.signals:
        by_topic.setdefault(s.channel, []).append(s)
    try:
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            topics = {c.topic for c in reader.connections}
            for topic in by_topic:
                if topic not in topics:
                    raise LogError(f"{log}: the bag has no topic {topic} (topics: {', '.join(sorted(topics)[:12])})")
            conns = {c.id: _Topic(reader, c, by_topic[c.topic], log) for c in reader.connections if c.topic in by_topic}
            wanted = [t.conn for t in conns.values()]
            messages = _mcap_messages(reader, wanted) or reader.messages(connections=wanted)
            while batch := list(islice(messages, BAG_CHUNK)):
                ids = np.fromiter(map(_CONN_ID, map(_CONN, batch)), np.int64, len(batch))  # (maps: zip(*batch) costs more than the decoding)
                t, raws = np.fromiter(map(_LOG_TIME, batch), np.int64, len(batch)), list(map(_RAW, batch))
                chunk: Chunk = []
                for cid, conn in conns.items():
                    idx = np.flatnonzero(ids == cid)
                    stamps, values = conn.read([raws[i] for i in idx.tolist()] if idx.size < len(batch) else raws, t[idx])
                    chunk += [(s.name, stamps, v) for s, v in zip(conn.sigs, values)]
                yield chunk
    except LogError:
        raise
    except Exception as exc:  # rosbags raises its own and the storage's errors on a damaged bag: each is "cannot read"
        raise LogError(f"{log}: cannot read it as a ROS 2 bag: {_why(exc)}") from None


__all__ = ["BAG_CHECK_EVERY", "PLAUSIBLE", "Chunk", "LogError", "SampleStream", "SignalScan", "open_stream", "read_chunks", "scan_signals"]
