"""`[network] max_faulty`: the k-of-N health declaration as a topology states it (docs/network.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.bus import keys
from netsetest.config.schema import ConfigError, HealthGroup, load_topology
from netsetest.runtime.security import grants

ROOT = Path(__file__).resolve().parents[2]


def _topology(tmp_path: Path, network: str, yaw1_C: str | None = None) -> Path:
    text = (ROOT / "topologies" / "paper6.toml").read_text().replace('node_dir = "../nodes"', f'node_dir = "{tmp_path}"')
    for prof in (ROOT / "nodes").glob("yaw?.toml"):
        body = prof.read_text()
        if yaw1_C is not None and prof.name == "yaw1.toml":
            body = body.replace("C = [0.0, 0.12]", f"C = {yaw1_C}")
        (tmp_path / prof.name).write_text(body)
    (tmp_path / "t.toml").write_text(text + "\n[network]\nbounded_readings = false\n" + network + "\n")  # the k-of-N exchange alone
    return tmp_path / "t.toml"


def test_the_bundled_declaration() -> None:
    sc = load_topology("paper6_max_faulty")
    assert sc.health_groups == (HealthGroup((1, 2, 3, 4, 5, 6), 4),) and sc.health_declared and sc.references() == ()
    assert sc.health_label == "max_faulty = 4"
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
        ("max_faulty = 6", None, r"must be less than the number of its nodes \(6\)"),
        ("max_faulty = -1", None, "max_faulty"),
        ("max_faulty = 2", "[0.01, 0.12]", "the same combination of the state"),
    ],
)
def test_a_declaration_that_cannot_hold_is_refused(tmp_path: Path, network: str, C: str | None, why: str) -> None:
    with pytest.raises(ConfigError, match=why):
        load_topology(_topology(tmp_path, network, C))


@pytest.mark.parametrize("declaration", ["max_faulty = 4", "GROUPS"])
def test_readings_off_with_a_declaration_is_refused(tmp_path: Path, declaration: str) -> None:
    """``readings = false`` with ``[[network.health_groups]]`` once loaded and ignored the groups silently:
    refused in one line naming the declaration (the nodes could not use it without the readings)."""
    network = "readings = false\n" + (GROUPS if declaration == "GROUPS" else declaration)
    with pytest.raises(ConfigError, match="k-of-N declaration rests on the readings' exchange, which readings = false turns off") as exc:
        load_topology(_topology(tmp_path, network))
    assert len(str(exc.value).splitlines()) == 1 and ("health_groups" if declaration == "GROUPS" else "max_faulty") in str(exc.value)
    sc = load_topology(_topology(tmp_path, "max_faulty = 4"))
    off = sc.alone()  # the benchmark's nodes alone: no reading, so no declaration in use
    assert off.health_groups and not off.health_declared and not any(off.publishes_reading(i) for i in off.ids)
    assert off.health_group(1) is None and off.reading_sources(1) == ()


def test_readings_off_with_a_reading_scope_is_refused(tmp_path: Path) -> None:
    """``reading_scope`` says who receives the readings; with ``readings = false`` there are none: refused in one line
    rather than ignored (issue 44's [network] options, docs/configuration.md)."""
    with pytest.raises(ConfigError, match="network.reading_scope: 'neighbours' says who receives the readings, which readings = false") as exc:
        load_topology(_topology(tmp_path, 'readings = false\nreading_scope = "neighbours"'))
    assert len(str(exc.value).splitlines()) == 1
    assert load_topology(_topology(tmp_path, 'reading_scope = "neighbours"')).reading_scope == "neighbours"


GROUPS = "[[network.health_groups]]\nnodes = [1, 2, 3]\nmax_faulty = 2\n[[network.health_groups]]\nnodes = [4, 5, 6]\nmax_faulty = 2"


def test_health_groups(tmp_path: Path) -> None:
    """Per group: a node reads its group's readings only (the ACL grants those), and the assumption holds
    when every group has at most its m faulty."""
    sc = load_topology(_topology(tmp_path, GROUPS))
    assert sc.health_groups == (HealthGroup((1, 2, 3), 2), HealthGroup((4, 5, 6), 2)) and sc.health_declared
    assert sc.reading_sources(1) == (2, 3) and sc.reading_sources(5) == (4, 6)
    assert sc.health_label == "max_faulty = 2 of nodes 1, 2, 3; max_faulty = 2 of nodes 4, 5, 6"
    g = grants(sc, "r")
    assert {k for k in g["node-5"].receive if k.endswith("/reading")} == {keys.reading("r", 4), keys.reading("r", 6)}
    assert sc.health_holds({1: 0.1, 2: 0.1, 3: 0.0, 4: 0.2, 5: 0.3, 6: 0.0})  # 2 and 2
    assert not sc.health_holds({1: 0.1, 2: 0.1, 3: 0.1, 4: 0.0, 5: 0.0, 6: 0.0})  # 3 of the first group
    assert not sc.group_health_holds(2, {1: 0.1, 2: 0.1, 3: 0.1, 4: 0.0}) and sc.group_health_holds(5, {1: 0.1, 2: 0.1, 3: 0.1, 4: 0.0})


def test_a_node_in_no_group_reads_none(tmp_path: Path) -> None:
    sc = load_topology(_topology(tmp_path, "[[network.health_groups]]\nnodes = [1, 2, 3]\nmax_faulty = 1"))
    assert sc.health_group(4) is None and sc.reading_sources(4) == () and not sc.publishes_reading(4)
    assert sc.publishes_reading(1) and sc.reading_sources(2) == (1, 3)
    assert sc.health_holds({1: 0.1, 2: 0.0, 3: 0.0, 4: 0.5, 5: 0.5, 6: 0.5})  # 4–6 are in no group


@pytest.mark.parametrize(
    ("network", "why"),
    [
        ("max_faulty = 1\n" + GROUPS, "give one"),
        ("[[network.health_groups]]\nnodes = [1, 2, 9]\nmax_faulty = 1", "no node with id 9"),
        ("[[network.health_groups]]\nnodes = [1, 2, 3]\nmax_faulty = 3", r"health_groups\[0\]: max_faulty must be less than the number of its nodes \(3\)"),
        (
            "[[network.health_groups]]\nnodes = [1, 2]\nmax_faulty = 1\n[[network.health_groups]]\nnodes = [2, 3]\nmax_faulty = 1",
            "node 2 is in it twice or in two groups",
        ),
        ("[[network.health_groups]]\nnodes = [1]\nmax_faulty = 0", "nodes"),
    ],
)
def test_a_group_that_cannot_hold_is_refused(tmp_path: Path, network: str, why: str) -> None:
    with pytest.raises(ConfigError, match=why):
        load_topology(_topology(tmp_path, network))
