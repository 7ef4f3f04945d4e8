"""The typed run metadata (records/meta.py): the record's meta object is its exact dict form, an older
record's meta loads with defaults, a wrong type is a malformed record naming the field."""

from __future__ import annotations

import pytest

from netsetest.config.schema import load_topology
from netsetest.records.meta import DEFAULT_TAU_S, RunMeta
from netsetest.runtime.inmemory import run_meta


def test_the_runs_meta_round_trips() -> None:
    meta = run_meta(load_topology("paper6_car"), "inmemory", "lockstep", "worst", "scheduled", 7, "r1")
    d = meta.to_dict()
    assert "security" not in d and d["seed"] == 7 and d["node_ids"] == [1, 2, 3, 4, 5, 6] and d["plant"] == "single-track/2"
    assert d["model_uncertainty"]["kind"] == "box"
    assert RunMeta.from_dict(d) == meta
    secured = meta.with_security("mtls+acl")
    assert secured.to_dict()["security"] == "mtls+acl" and RunMeta.from_dict(secured.to_dict()) == secured


def test_an_older_records_meta_takes_defaults_and_unknown_keys_are_ignored() -> None:
    meta = RunMeta.from_dict({"case": "saim", "node_ids": [1, 2], "tau_s": None, "a_later_field": 1})
    assert meta.case == "saim" and meta.node_ids == [1, 2] and meta.tau_s == DEFAULT_TAU_S and meta.plant == "ts"
    assert meta.estimators == {} and meta.seed is None


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("tau_s", "0.1"),
        ("seed", True),
        ("seed", 1.5),
        ("node_ids", [1, "2"]),
        ("estimators", [1]),
        ("case", 3),
    ],
)
def test_a_wrong_type_is_refused_naming_the_field(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=f"meta.{field}"):
        RunMeta.from_dict({field: value})
