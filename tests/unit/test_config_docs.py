"""docs/configuration.md documents what a user writes: every field of a topology and of a sensor profile
(the msgspec schema), and every fault kind with each of its fields: `node_dir` and the fault kinds' fields
were once left for the user to find in the code."""

from __future__ import annotations

import re
from pathlib import Path
from typing import get_args

import msgspec
import pytest

from netsetest.config.schema import FAULT_FIELDS, FAULT_FIELDS_OF, ConfigError, FaultSpec, NodeProfile, TopologyFile, load_topology

ROOT = Path(__file__).resolve().parents[2]
DOC = (ROOT / "docs" / "configuration.md").read_text()


def _fault_section() -> str:
    start = DOC.index("### A sensor's fault: `[fault]`")
    return DOC[start : DOC.index("\n## ", start)]


@pytest.mark.parametrize("cls", [TopologyFile, NodeProfile])
def test_every_field_is_documented(cls: type[msgspec.Struct]) -> None:
    missing = [f.encode_name for f in msgspec.structs.fields(cls) if f"`{f.encode_name}" not in DOC and f"[{f.encode_name}]" not in DOC]
    assert not missing, f"{cls.__name__}: fields not in docs/configuration.md: {missing}"


def test_every_fault_kind_and_its_fields_are_documented() -> None:
    kinds = get_args(msgspec.structs.fields(FaultSpec)[0].type)
    assert set(kinds) == set(FAULT_FIELDS_OF) and set(FAULT_FIELDS) == {f.name for f in msgspec.structs.fields(FaultSpec)} - {"kind"}
    rows = {m[1]: m[2] for m in re.finditer(r'^\| `"([a-z]+)"`[^|]*\| ([^|]*) \|', _fault_section(), re.M)}
    assert set(rows) == set(kinds), rows
    for kind, fields in FAULT_FIELDS_OF.items():
        assert set(re.findall(r"`([a-z]+)\b", rows[kind])) == set(fields), (kind, rows[kind])


def test_a_field_of_another_fault_kind_is_refused(tmp_path: Path) -> None:
    """`points` under kind = "square" was silently ignored (the truth had the square fault only)."""
    (tmp_path / "topologies").mkdir()
    (tmp_path / "topologies" / "t.toml").write_text((ROOT / "topologies" / "paper6.toml").read_text())
    (tmp_path / "nodes").mkdir()
    for prof in (ROOT / "nodes").glob("*.toml"):
        (tmp_path / "nodes" / prof.name).write_text(prof.read_text())
    yaw1 = tmp_path / "nodes" / "yaw1.toml"
    yaw1.write_text(yaw1.read_text().replace("end = 70", "end = 70\npoints = [[0, 0.0], [5, 0.1]]"))
    with pytest.raises(ConfigError, match=r"yaw1\.toml: fault: points: not a field of a 'square' fault") as exc:
        load_topology(tmp_path / "topologies" / "t.toml")
    assert len(str(exc.value).splitlines()) == 1
