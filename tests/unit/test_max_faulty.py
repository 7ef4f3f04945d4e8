"""`[network] max_faulty`: the k-of-N health declaration as a topology states it (docs/network.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.bus import keys
from netsetest.config.schema import ConfigError, load_topology
from netsetest.runtime.security import grants

ROOT = Path(__file__).resolve().parents[2]


def _topology(tmp_path: Path, network: str, yaw1_C: str | None = None) -> Path:
    text = (ROOT / "topologies" / "paper6.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{tmp_path}"')
    for prof in (ROOT / "nodes").glob("yaw?.toml"):
        body = prof.read_text()
        if yaw1_C is not None and prof.name == "yaw1.toml":
            body = body.replace("C = [0.0, 0.12]", f"C = {yaw1_C}")
        (tmp_path / prof.name).write_text(body)
    (tmp_path / "t.toml").write_text(text + "\n[network]\n" + network + "\n")
    return tmp_path / "t.toml"


def test_the_bundled_declaration() -> None:
    sc = load_topology("paper6_max_faulty")
    assert sc.max_faulty == 4 and sc.health_declared and sc.references() == ()
    assert all(sc.publishes_reading(i) for i in sc.ids)
    assert sc.reading_sources(3) == (1, 2, 4, 5, 6)
    assert sc.health_holds({1: 0.1, 2: 0.1, 3: 0.0, 4: 0.2, 5: 0.0, 6: -0.1})
    assert not sc.health_holds({1: 0.1, 2: 0.1, 3: 0.01, 4: 0.2, 5: 0.0, 6: -0.1})  # five faulty


def test_every_node_may_publish_its_reading_and_receive_everyone_elses() -> None:
    sc = load_topology("paper6_max_faulty")
    g = grants(sc, "r")
    for i in sc.ids:
        assert keys.reading("r", i) in g[f"node-{i}"].publish
        assert {k for k in g[f"node-{i}"].receive if k.endswith("/reading")} == {keys.reading("r", j) for j in sc.ids if j != i}


@pytest.mark.parametrize(
    ("network", "C", "why"),
    [
        ("max_faulty = 6", None, r"must be less than the number of nodes \(6\)"),
        ("max_faulty = -1", None, "max_faulty"),
        ("max_faulty = 2", "[0.01, 0.12]", "the same combination of the state"),
    ],
)
def test_a_declaration_that_cannot_hold_is_refused(tmp_path: Path, network: str, C: str | None, why: str) -> None:
    with pytest.raises(ConfigError, match=why):
        load_topology(_topology(tmp_path, network, C))


def test_readings_off_turns_the_declaration_off(tmp_path: Path) -> None:
    sc = load_topology(_topology(tmp_path, "max_faulty = 4\nreadings = false"))
    assert sc.max_faulty == 4 and not sc.health_declared and not any(sc.publishes_reading(i) for i in sc.ids)
