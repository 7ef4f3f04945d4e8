"""Reading the mapped signals of a drive log, each format through the field's own library (the ``logs`` extra).

- CSV and Parquet: pyarrow, batch by batch, the time column and the mapped columns only;
- ASAM MDF4: asammdf, the mapped channels only (each with its own time base);
- ROS 2 bags (MCAP or sqlite3, a bag directory or its one storage file): rosbags, which needs no ROS install,
  the mapped topics only, each message's field (``angular_velocity.z`` of a ``sensor_msgs/msg/Imu``,
  ``twist.twist.linear.x`` of a ``nav_msgs/msg/Odometry``, ``data`` of a ``std_msgs/msg/Float64``), stamped by
  its header where it has one, else by its log time.

What a role holds is the mapped channels' samples (16 bytes each), never the whole log.  Every channel is
then cleaned by one set of stated rules (:func:`clean`, docs/your-log.md): a NaN or infinite sample is no
sample (dropped: the step takes the newest finite one within the gap tolerance, else the measurement is
missing), stamps are put in time order (a log is written in the order messages arrived), two samples with
one stamp and the same value are one, and with different values an error (which one the sensor measured is
unknown); then a physical range per kind of signal catches a wrong unit.  Anything wrong is a
:class:`LogError`: one line naming the file, the signal and why.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from netsetest.config.logmap import LogMapping, SignalMap, log_format
from netsetest.extras import require

BATCH_ROWS = 65_536  # rows a CSV or Parquet batch holds (pyarrow's default block is about this)
# the physical range of each kind of signal, SI: a sample beyond it is a wrong unit (deg/s read as rad/s), not a car
PLAUSIBLE = {
    "speed": 500.0 / 3.6,  # m/s
    "steering": 1.0,  # rad of road-wheel angle (models/manoeuvres.py STEERING_MAX_RAD)
    "yaw rate": 5.0,  # rad/s: 286 °/s, a car spinning
    "reference β": 1.5,  # rad
    "reference r": 5.0,
}


class LogError(Exception):
    """A drive log or its mapping cannot give the run's signals; the message says which file, signal and why."""


@dataclass(frozen=True)
class Channel:
    """One signal's samples: stamps t_ns (int64 ns, sorted, unique; the channel's offset applied) and SI values."""

    t_ns: np.ndarray
    v: np.ndarray


def _kind(sig: SignalMap) -> str:
    return "yaw rate" if sig.name.startswith("yaw rate") else sig.name


def clean(path: Path, sig: SignalMap, t_ns: np.ndarray, raw: np.ndarray) -> Channel:
    """A channel's samples under the stated rules (module doc), in SI units."""
    t_ns, v = np.asarray(t_ns, dtype=np.int64) + sig.offset_ns, np.asarray(raw, dtype=float) * sig.scale
    finite = np.isfinite(v)
    t_ns, v = t_ns[finite], v[finite]
    order = np.argsort(t_ns, kind="stable")
    t_ns, v = t_ns[order], v[order]
    same = np.flatnonzero(t_ns[1:] == t_ns[:-1])
    if same.size:
        differ = same[v[same] != v[same + 1]]
        if differ.size:
            i = int(differ[0])
            raise LogError(
                f"{path}: {sig.name} ({sig.channel}): two samples at t = {t_ns[i] / 1e9:.9g} s differ ({v[i]:g}, {v[i + 1]:g}): which one was measured is unknown"
            )
        keep = np.ones(t_ns.size, dtype=bool)
        keep[same + 1] = False
        t_ns, v = t_ns[keep], v[keep]
    if not v.size:
        raise LogError(f"{path}: {sig.name} ({sig.channel}): no finite sample")
    limit = PLAUSIBLE[_kind(sig)]
    worst = int(np.argmax(np.abs(v)))
    if abs(v[worst]) > limit:
        raise LogError(
            f"{path}: {sig.name} ({sig.channel}): {v[worst]:.4g} (SI) at t = {t_ns[worst] / 1e9:.6g} s is beyond any road car's "
            f"(|{_kind(sig)}| ≤ {limit:.4g}): is the mapping's unit, ratio or sign right?"
        )
    return Channel(t_ns, v)


def read_signals(log: Path, mapping: LogMapping) -> dict[str, Channel]:
    """Every mapped signal of ``log``, cleaned, by :attr:`SignalMap.name`; LogError otherwise."""
    try:
        fmt = log_format(log, mapping)
    except ValueError as exc:
        raise LogError(str(exc)) from None
    raw = {"csv": _table, "parquet": _table, "mdf4": _mdf4, "rosbag": _rosbag}[fmt](log, mapping, fmt)
    return {sig.name: clean(log, sig, *raw[sig.name]) for sig in mapping.signals}


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
                head = fh.readline().decode("utf-8", "replace").strip().split(",")
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


def _table(log: Path, mapping: LogMapping, fmt: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """CSV or Parquet: one time column (``[log] time``) for every signal."""
    require("pyarrow", f"reading a {fmt} drive log", extra="logs")
    columns = list(dict.fromkeys([mapping.time, *(s.channel for s in mapping.signals)]))
    parts: dict[str, list[np.ndarray]] = {c: [] for c in columns}
    for batch in _batches(log, fmt, columns):
        for c in columns:
            parts[c].append(batch.column(c).to_numpy(zero_copy_only=False).astype(float))
    cols = {c: np.concatenate(p) if p else np.empty(0) for c, p in parts.items()}
    t = cols[mapping.time]
    if not np.all(np.isfinite(t)):
        raise LogError(f"{log}: time column {mapping.time!r} has a value that is not a number")
    t_ns = np.round(t * (mapping.time_scale * 1e9)).astype(np.int64)
    return {s.name: (t_ns, cols[s.channel]) for s in mapping.signals}


# ---------------------------------------------------------------- ASAM MDF4 (asammdf)


def _mdf4(log: Path, mapping: LogMapping, fmt: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    require("asammdf", "reading an MDF4 drive log")
    from asammdf import MDF

    try:
        mdf = MDF(log)
    except Exception as exc:  # asammdf raises many kinds on a damaged file: each is "cannot read"
        raise LogError(f"{log}: cannot read it as MDF4: {str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__}") from None
    try:
        names = set(mdf.channels_db)
        out = {}
        for s in mapping.signals:
            if s.channel not in names:
                raise LogError(f"{log}: no channel {s.channel!r} for {s.name} (channels: {', '.join(sorted(names)[:12])})")
            try:
                sig = mdf.get(s.channel)
            except Exception as exc:  # a damaged block reads as any exception: "cannot read"
                raise LogError(f"{log}: cannot read channel {s.channel!r}: {str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__}") from None
            out[s.name] = (np.round(np.asarray(sig.timestamps, dtype=float) * 1e9).astype(np.int64), np.asarray(sig.samples, dtype=float))
        return out
    finally:
        mdf.close()


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


DEFAULT_FIELD = "data"  # a std_msgs number's field, for a topic mapped without one


def _rosbag(log: Path, mapping: LogMapping, fmt: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    require("rosbags", "reading a ROS 2 bag")
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    bag = log if log.is_dir() else log.parent  # a bag directory, or its one storage file beside metadata.yaml
    by_topic: dict[str, list[SignalMap]] = {}
    for s in mapping.signals:
        by_topic.setdefault(s.channel, []).append(s)
    stamps: dict[str, list[int]] = {s.name: [] for s in mapping.signals}
    values: dict[str, list[float]] = {s.name: [] for s in mapping.signals}
    try:
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            topics = {c.topic for c in reader.connections}
            for topic in by_topic:
                if topic not in topics:
                    raise LogError(f"{log}: the bag has no topic {topic} (topics: {', '.join(sorted(topics)[:12])})")
            conns = [c for c in reader.connections if c.topic in by_topic]
            for conn, t_log, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                t = _stamp(msg, t_log)
                for s in by_topic[conn.topic]:
                    stamps[s.name].append(t)
                    values[s.name].append(_field(msg, s.field or DEFAULT_FIELD, log, conn.topic))
    except LogError:
        raise
    except Exception as exc:  # rosbags raises its own and the storage's errors on a damaged bag: each is "cannot read"
        raise LogError(f"{log}: cannot read it as a ROS 2 bag: {str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__}") from None
    return {n: (np.asarray(stamps[n], dtype=np.int64), np.asarray(values[n], dtype=float)) for n in stamps}


def log_span_s(ch: Channel) -> tuple[float, float]:
    """A channel's first and last stamp in seconds."""
    return float(ch.t_ns[0]) / 1e9, float(ch.t_ns[-1]) / 1e9


__all__ = ["PLAUSIBLE", "Channel", "LogError", "clean", "log_span_s", "read_signals"]
