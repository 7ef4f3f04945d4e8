"""A truth's node maps are keyed by int node id in the message and in a loaded record, by the id's string in the
record's file (netsetest/records/truth.py): the record's list of them is the message's, and an existing record
loads with int keys."""

import typing
from pathlib import Path

import pytest

from netsetest.messages import NodeId, Truth
from netsetest.records.record import load_record
from netsetest.records.truth import TRUTH_NODE_MAPS, truth_entry, truth_json

FIXTURES = Path(__file__).parent.parent / "fixtures" / "records_v0"


def _keyed_by_node(annotation: object) -> bool:
    hint = typing.get_args(annotation)[0] if typing.get_origin(annotation) is typing.Annotated else annotation
    return typing.get_origin(hint) is dict and typing.get_args(hint)[0] == NodeId


def test_the_records_node_maps_are_the_messages() -> None:
    hints = typing.get_type_hints(Truth, include_extras=True)
    assert set(TRUTH_NODE_MAPS) == {name for name, hint in hints.items() if _keyed_by_node(hint)}


def test_truth_json_is_the_inverse_of_truth_entry() -> None:
    raw = {"step": 3, "x": [0.1, 0.2], "faults": {"1": 0.5, "12": -0.5}, "y": {"1": 0.1}, "drops": {"stale": 2}}
    entry = truth_entry(raw)
    assert entry["faults"] == {1: 0.5, 12: -0.5} and entry["y"] == {1: 0.1} and entry["drops"] == {"stale": 2}
    assert truth_json(entry) == raw
    with pytest.raises(ValueError):
        truth_entry({"step": 0, "faults": {"x": 0.0}})


@pytest.mark.parametrize("path", sorted(FIXTURES.glob("*")), ids=lambda p: p.name)
def test_an_existing_record_loads_with_int_keys(path: Path) -> None:
    if path.suffix == ".mcap":
        pytest.importorskip("mcap")
    rec = load_record(str(path))
    assert rec.truth and all(set(t["faults"]) == set(rec.meta.node_ids) for t in rec.truth)
    assert all(isinstance(i, int) for t in rec.truth for name in TRUTH_NODE_MAPS for i in t.get(name, {}))
