"""The benchmark's ring variants (netsetest_bench/topologies.py) are the topologies they claim to be: the
real-time figures per variant (``realtime_fit``) measure a reference's readings, k-of-N health per group of
six sensors and the car, and nothing else."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest_bench.topologies import FAULTY_PROFILES, ring_topology
from netsetest.config.schema import Scenario, load_topology


@pytest.mark.parametrize("n", [6, 13, 14, 32])
def test_ring_variants(tmp_path: Path, n: int) -> None:
    plain = load_topology(ring_topology(tmp_path, n, 5))
    ref = load_topology(ring_topology(tmp_path, n, 5, variant="reference"))
    faulty = load_topology(ring_topology(tmp_path, n, 5, variant="max_faulty"))
    car = load_topology(ring_topology(tmp_path, n, 5, variant="car"))
    assert plain.references() == () and not plain.health_declared and plain.plant == "ts"
    assert ref.references() == (3,) and all(ref.reading_sources(i) == (3,) for i in ref.ids if i != 3)
    assert faulty.health_declared and all(6 <= len(g.nodes) < 12 for g in faulty.health_groups)
    assert sorted(i for g in faulty.health_groups for i in g.nodes) == faulty.ids  # every node in one group
    for g in faulty.health_groups:  # a node reads its group's readings; the declaration holds on the profiles' faults
        assert all(faulty.reading_sources(i) == tuple(j for j in g.nodes if j != i) for i in g.nodes)
        assert g.max_faulty == sum((i - 1) % 6 + 1 in FAULTY_PROFILES for i in g.nodes) < len(g.nodes)
    assert car.plant == "single-track" and car.uncertainty is not None
    for sc in (ref, faulty, car):  # the same ring: only what the variant names differs
        assert [n_.in_weights for n_ in sc.nodes] == [n_.in_weights for n_ in plain.nodes]


def test_the_two_groups_variant_is_issue_34s_ring(tmp_path: Path) -> None:
    """12 nodes: nodes 2, 3, 5, 10 with at most 2 faulty and 1, 4, 9, 12 with at most 3 (the other nodes in no group);
    24 nodes: the same groups in each block of twelve.  Each declaration holds on the profiles' faults."""
    ring12 = load_topology(ring_topology(tmp_path, 12, 5, variant="two_groups"))
    assert [(g.nodes, g.max_faulty) for g in ring12.health_groups] == [((2, 3, 5, 10), 2), ((1, 4, 9, 12), 3)]
    ring24 = load_topology(ring_topology(tmp_path, 24, 5, variant="two_groups"))
    assert [g.nodes for g in ring24.health_groups] == [(2, 3, 5, 10, 14, 15, 17, 22), (1, 4, 9, 12, 13, 16, 21, 24)]
    for g in ring24.health_groups:
        assert g.max_faulty == sum((i - 1) % 6 + 1 in FAULTY_PROFILES for i in g.nodes) < len(g.nodes)


def test_the_issue_34_fixture_is_the_benchmarks_ring(tmp_path: Path) -> None:
    """tests/fixtures/ring12_two_groups.toml (run it: ``netsetest run tests/fixtures/ring12_two_groups.toml --signals
    worst``, then ``netsetest exact``) is the 12-node ring the benchmark's exact part measures."""
    fixture = load_topology(Path(__file__).resolve().parents[1] / "fixtures" / "ring12_two_groups.toml", "saim")
    bench = load_topology(ring_topology(tmp_path, 12, 80, "saim", variant="two_groups"), "saim")
    assert fixture.health_groups == bench.health_groups and fixture.steps == bench.steps == 80

    def nodes(sc: Scenario) -> list[tuple]:
        return [(n.id, n.in_weights, n.sensor.C.tolist(), n.sensor.Ds, n.fault_size, n.fault_rate) for n in sc.nodes]

    assert nodes(fixture) == nodes(bench)
