"""An indexed MCAP bag's messages walked chunk by chunk (logs/readers.py ``_mcap_messages``, docs/your-log.md) are
rosbags' ``messages()``, the same messages in the same order: on the example bag, on a bag of several chunks whose
messages are out of log-time order inside each chunk, for a subset of its topics; and where rosbags' order needs its
heap (chunks that overlap in time) or the storage is not MCAP, rosbags reads the bag itself."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from netsetest.logs.readers import _mcap_messages

TS = get_typestore(Stores.ROS2_HUMBLE)
EXAMPLE_LOGS = Path(__file__).resolve().parents[2] / "examples" / "logs"
CHUNK_BYTES = 2**20  # rosbags' MCAP writer closes a chunk past this
PAYLOAD = 4_000  # characters of one message's string: a few hundred messages per chunk
RECORD = 9 + 22 + 4 + 4 + PAYLOAD + 1  # its MCAP record: opcode and length, message header, CDR header, string length, text, NUL
PER_CHUNK = CHUNK_BYTES // RECORD + 1  # the messages of one chunk (closed by the first that passes CHUNK_BYTES)


def _both(bag: Path, topics: set[str] | None = None) -> tuple[list, list | None]:
    """rosbags' messages of ``topics`` (all: None) as (topic, log time, payload), and the chunk walk's (None: not taken)."""
    with AnyReader([bag], default_typestore=TS) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        want = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages(connections=conns)]
        fast = _mcap_messages(reader, conns)
        return want, None if fast is None else [(c.topic, t, bytes(raw)) for c, t, raw in fast]


def _write(bag: Path, stamps: list[tuple[str, int]], storage: StoragePlugin = StoragePlugin.MCAP) -> None:
    """A bag of std_msgs/msg/String messages of PAYLOAD bytes, in the order and at the log times of ``stamps``."""
    string = TS.types["std_msgs/msg/String"]
    with Writer(bag, version=8, storage_plugin=storage) as w:
        conns = {topic: w.add_connection(topic, "std_msgs/msg/String", typestore=TS) for topic in sorted({s for s, _ in stamps})}
        for k, (topic, t) in enumerate(stamps):
            w.write(conns[topic], t, bytes(TS.serialize_cdr(string(data=f"{k:08d}".ljust(PAYLOAD, "x")), "std_msgs/msg/String")))


def test_the_example_bag_walks_as_rosbags_reads_it() -> None:
    want, got = _both(EXAMPLE_LOGS / "drive_mcap")
    assert got is not None and got == want and len(want) > 0


def test_several_chunks_out_of_order_inside_each() -> None:
    """Inside each chunk (a second of log time) the log times are shuffled; the chunks follow each other in time, one
    ending at the log time the next starts with (ties: file order, as rosbags' heap gives): the walk sorts each chunk
    stably, as rosbags does, for every topic and for one."""
    rng = np.random.default_rng(0)
    per_chunk = PER_CHUNK
    stamps = []
    for c in range(4):
        times = (c * 1_000_000 + rng.integers(0, 1_000_000, per_chunk)).tolist()
        times[-1] = (c + 1) * 1_000_000  # the chunk's end: the next one's start
        stamps += [(("/a", "/b", "/c")[k % 3], int(t)) for k, t in enumerate(times)]
        stamps[-per_chunk] = (stamps[-per_chunk][0], c * 1_000_000 if c else 0)
    with tempfile.TemporaryDirectory(prefix="netsetest-bag-") as tmp:
        bag = Path(tmp) / "bag"
        _write(bag, stamps)
        with AnyReader([bag], default_typestore=TS) as reader:
            assert len(reader.readers[0].storage.storages[0].chunks) >= 4  # (the writer's chunks, as the test means them)
        for topics in (None, {"/b"}):
            want, got = _both(bag, topics)
            assert got is not None and got == want and len(want) == sum(topics is None or s in topics for s, _ in stamps)


@pytest.mark.parametrize("storage", ["overlap", "sqlite3"])
def test_rosbags_reads_what_the_walk_does_not(storage: str) -> None:
    """Chunks that overlap in log time (the second holds times before the first's end): only rosbags' heap gives its
    order, so rosbags reads the bag; a sqlite3 bag likewise."""
    per_chunk = PER_CHUNK
    stamps = [("/a", 1_000 + 10 * k) for k in range(per_chunk)] + [("/a", 1_005 + 10 * k) for k in range(per_chunk)]
    with tempfile.TemporaryDirectory(prefix="netsetest-bag-") as tmp:
        bag = Path(tmp) / "bag"
        _write(bag, stamps, StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP)
        want, got = _both(bag)
        assert got is None and [t for _, t, _ in want] == sorted(t for _, t in stamps)
