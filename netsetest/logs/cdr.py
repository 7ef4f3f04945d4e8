"""Where a numeric field lies in a ROS 2 message's CDR payload, from rosbags' typestore, and reading it from many
payloads at once (numpy): the fast path of the bag stream (logs/readers.py, docs/your-log.md).

CDR, the encoding ROS 2 records, lays a message's fields out in order, each aligned to its own size, counted from the
payload's origin after the 4-byte encapsulation header; a string or a sequence carries its own length.  So a field is
at an offset that depends on the message only through the strings and sequences before it:

- **fixed**: nothing of variable length comes before it: one offset for every message of the type (``header.stamp``
  of a stamped message, ``data`` of a ``std_msgs/msg/Float64``);
- **tail**: everything from the last string or sequence to the message's end (the tail) has a fixed layout of L
  bytes, starting aligned to its first field's alignment a0 ≥ 4 with no field in it aligned wider.  A payload of n
  bytes holds the tail at T + 4 with n − 4 = T + L + p, T a multiple of a0 and p < 4 (rosbags accepts at most 3 bytes
  after the last field), so T = ⌊(n − 4 − L) / a0⌋·a0: every message of one size has the field at one offset
  (``angular_velocity.z`` of a ``sensor_msgs/msg/Imu`` after its header's frame_id, ``twist.twist.linear.x`` of a
  ``nav_msgs/msg/Odometry`` after two strings);
- **none**: a field between two strings or inside a sequence; rosbags' full deserialisation reads it.

The offsets are the typestore's layout (its field definitions, sizes and alignments); readers.py checks them against
rosbags' full deserialisation on the first message of every size of a connection and on every
:data:`~netsetest.logs.readers.BAG_CHECK_EVERY`-th message, and a mismatch is an error.  Only little-endian payloads
(what every ROS 2 middleware on x86 and ARM writes) are read here; a big-endian one goes to rosbags.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rosbags.interfaces import Typestore

ENCAPSULATION = 4  # bytes before the CDR payload: representation id (0x00 0x01: CDR, little-endian) and options
# the base types a mapped field may be (rosbags gives int or float), as little-endian numpy types
NUMERIC = {
    "float64": "<f8",
    "float32": "<f4",
    "int8": "i1",
    "int16": "<i2",
    "int32": "<i4",
    "int64": "<i8",
    "uint8": "u1",
    "uint16": "<u2",
    "uint32": "<u4",
    "uint64": "<u8",
}
VARIABLE = ""  # a leaf of variable length (a string, a sequence, an array of strings)


@dataclass(frozen=True)
class FieldAt:
    """A numeric field's place: ``fixed`` (offset from the payload's origin) or ``tail`` (offset from the tail's start),
    and its numpy type."""

    dtype: str
    fixed: int | None
    tail: int | None


@dataclass(frozen=True)
class Layout:
    """A message type's layout (module doc): each numeric leaf's place by its dotted path, and the tail's length and
    alignment (``tail_align`` 0: no tail whose place a payload's size gives)."""

    fields: dict[str, FieldAt]
    tail_len: int
    tail_align: int

    def offset(self, at: FieldAt, size: int) -> int | None:
        """The field's byte offset in a raw message (encapsulation included) of ``size`` bytes, or None: none that a
        message of that size can have."""
        if at.fixed is not None:
            off = ENCAPSULATION + at.fixed
        else:
            assert at.tail is not None and self.tail_align
            start = (size - ENCAPSULATION - self.tail_len) // self.tail_align * self.tail_align
            if start < 0:
                return None
            off = ENCAPSULATION + start + at.tail
        return off if off + np.dtype(at.dtype).itemsize <= size else None


def _leaves(ts: Typestore, fields: list[tuple[str, Any]], prefix: str) -> Iterator[tuple[str, str, int, int]]:
    """(dotted path, base type or VARIABLE or "" for a fixed block, size, alignment) of every leaf in CDR order."""
    from rosbags.interfaces import Nodetype
    from rosbags.serde.utils import SIZEMAP

    for name, (node, arg) in fields:
        path = prefix + name
        if node == Nodetype.NAME:
            yield from _leaves(ts, ts.get_msgdef(arg).fields, path + ".")
        elif node == Nodetype.BASE and arg[0] in SIZEMAP:
            yield path, arg[0], SIZEMAP[arg[0]], SIZEMAP[arg[0]]
        elif node == Nodetype.ARRAY and arg[0][0] == Nodetype.BASE and arg[0][1][0] in SIZEMAP:
            size = SIZEMAP[arg[0][1][0]]
            yield path, "[]", size * arg[1], size  # a fixed array of numbers: no field of a mapping's inside
        elif node == Nodetype.ARRAY and arg[0][0] == Nodetype.NAME:
            for i in range(arg[1]):
                yield from _leaves(ts, ts.get_msgdef(arg[0][1]).fields, f"{path}.{i}.")
        else:  # a string, a sequence, an array of strings: its length is the message's own
            yield path, VARIABLE, 0, 0


def _up(pos: int, align: int) -> int:
    return -(-pos // align) * align


def layout(ts: Typestore, msgtype: str) -> Layout:
    """The layout of ``msgtype`` as the typestore defines it (module doc)."""
    fixed: dict[str, FieldAt] = {}
    tail: dict[str, FieldAt] = {}
    pos: int | None = 0  # the next field's place while nothing variable came before it
    rel, a0, wide = 0, 0, False  # the tail so far: its length, its first field's alignment, a field aligned wider
    for path, base, size, align in _leaves(ts, ts.get_msgdef(msgtype).fields, ""):
        if base == VARIABLE:
            pos, tail, rel, a0, wide = None, {}, 0, 0, False
            continue
        if pos is not None:
            pos = _up(pos, align)
            if base in NUMERIC:
                fixed[path] = FieldAt(NUMERIC[base], pos, None)
            pos += size
            continue
        a0 = a0 or align
        wide |= align > a0
        rel = _up(rel, align)
        if base in NUMERIC:
            tail[path] = FieldAt(NUMERIC[base], None, rel)
        rel += size
    usable = pos is None and rel > 0 and a0 >= 4 and not wide  # p < 4 ≤ a0: the size gives the tail's start
    return Layout({**fixed, **(tail if usable else {})}, rel, a0 if usable else 0)


def read_fields(raws: list[bytes], size: int, offsets: list[tuple[int, str]]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Messages of ``size`` bytes each, their encapsulation checked and a field read at each (offset, numpy type):
    (little-endian CDR [bool], each field's values in its own type)."""
    names = ["e0", "e1", *(f"f{i}" for i in range(len(offsets)))]
    dt = np.dtype({"names": names, "formats": ["u1", "u1", *(d for _, d in offsets)], "offsets": [0, 1, *(o for o, _ in offsets)], "itemsize": size})
    rec = np.frombuffer(b"".join(raws), dtype=dt)
    little = (rec["e0"] == 0) & (rec["e1"] == 1)
    return little, [rec[f"f{i}"] for i in range(len(offsets))]


__all__ = ["ENCAPSULATION", "FieldAt", "Layout", "layout", "read_fields"]
