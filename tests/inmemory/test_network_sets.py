"""What a node takes from its network (issue 44, docs/network.md): its in-neighbours' published sets and the bounded
readings.  They narrow what a node publishes where its own data say little; a false declared bound, or a neighbour
whose set missed, takes the node-steps that rest on it out of the guarantee, attributed, never a violation."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from netsetest_bench.topologies import ring_topology
from netsetest.config.schema import load_topology
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]


def _published(res) -> dict[int, list[dict]]:
    assert res.parts is not None
    return {int(i): entries for i, entries in res.parts["nodes"].items()}


@pytest.mark.parametrize("seed", [0, 1])
def test_a_false_bound_is_attributed_to_it_never_a_violation(seed: int) -> None:
    """Sensor 2's declared size made false (0.02 against its fault of 0.1745 from step 20): every node reads its reading
    with it and node 2 cuts its own sets by it, so sets miss; each such node-step is out of the guarantee, attributed
    to node 2's bound (its own steps: 'fault bound'; the others': inherited from node 2, through its reading or its
    set), and nothing is a violation."""
    sc = load_topology("paper6", "saim", 40)
    sc = dataclasses.replace(sc, nodes=[dataclasses.replace(n, fault_size=0.02) if n.id == 2 else n for n in sc.nodes])
    assert sc.bound_relied(2) and all(2 in sc.bounded_sources(i) for i in sc.ids if i != 2)
    s = run_inmemory(sc, "worst", seed=seed).summary
    assert s.violations_total == 0
    assert s.misses_assumption_broken_total > 0  # the false bound did mislead them
    assert s.misses_assumption_broken_total == s.node_steps_evaluated - s.node_steps_contained
    assert s.node_steps_not_covered.get("fault bound", 0) > 0  # node 2's own steps
    origins = {(o.node, o.why) for o in s.inherited_from}
    assert (2, "fault bound") in origins, s.inherited_from  # the others', through its reading


def test_a_neighbours_set_that_missed_uncovers_the_step_that_rests_on_it(tmp_path: Path) -> None:
    """The directed ring with node 12's declared size made false (SAIM: its sector, so its region, rests on it) and no
    bounded reading: node 12's region misses the truth once its fault is on, and every step of node 1 (its
    out-neighbour) whose sets its set cut is inherited from node 12 ('missed the truth', or its sector where that broke
    first); nothing is a violation."""
    sc = load_topology(ring_topology(tmp_path, 12, 40, "saim", variant="near_reference"), "saim")
    sc = dataclasses.replace(sc, bounded_readings=False, nodes=[dataclasses.replace(n, fault_size=0.01) if n.id == 12 else n for n in sc.nodes])
    assert 12 in sc.node(1).in_weights and sc.neighbour_sets
    res = run_inmemory(sc, "worst", seed=0)
    s = res.summary
    assert s.violations_total == 0 and s.misses_assumption_broken_total == s.node_steps_evaluated - s.node_steps_contained
    node12 = _published(res)[12]
    missed = {e["step"] for e in node12 if e["contained"] is False}
    assert missed, "node 12's false bound never made its set miss: the test shows nothing"
    rows = {e["step"]: e for e in _published(res)[1]}
    leaning = [k for k in sorted(missed) if k + 1 in rows and 12 in rows[k + 1]["sets"]]
    assert leaning, "node 1 never rested on a set of node 12 that missed"
    for k in leaning:  # (node 12's sector, derived from the same false bound, may break first: its innovation's fact)
        assert rows[k + 1]["assumptions_ok"] is False and rows[k + 1]["inherited_from"][:2] == [12, k], rows[k + 1]["inherited_from"]
        assert rows[k + 1]["inherited_from"][2] in ("missed the truth", "sector")
    assert any(rows[k + 1]["inherited_from"][2] == "missed the truth" for k in leaning)


@pytest.fixture
def ring(tmp_path: Path):
    return load_topology(ring_topology(tmp_path, 8, 30, "saim", variant="near_reference"), "saim")


def test_the_neighbours_sets_and_readings_narrow_what_a_ring_publishes(ring) -> None:
    """The directed ring with a reference (node 3) read by its out-neighbours only: with the neighbours' sets and the
    bounded readings every node downstream of the reference publishes a narrower yaw rate than without them; every
    node-step covered, no violation; states name the neighbours whose sets cut them."""
    off = dataclasses.replace(ring, neighbour_sets=False, bounded_readings=False)
    with_, without = run_inmemory(ring, "worst", seed=0), run_inmemory(off, "worst", seed=0)
    for res in (with_, without):
        assert res.summary.violations_total == 0 and res.summary.node_steps_covered == res.summary.node_steps_evaluated

    def r_width(res, i: int) -> float:
        entries = [e for e in _published(res)[i] if e["step"] >= 10]
        return float(np.mean([e["bounds"][1][1] - e["bounds"][1][0] for e in entries]))

    far = [i for i in ring.ids if i not in (3, *[j for j in ring.ids if 3 in ring.node(j).in_weights])]  # not the reference's readers
    assert far and all(r_width(with_, i) < 0.9 * r_width(without, i) for i in far), {i: (r_width(with_, i), r_width(without, i)) for i in far}
    assert any(e["sets"] for i in far for e in _published(with_)[i])


def test_the_header_exact_network_and_the_report_say_what_each_node_rests_on(ring, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The run's header names, per node, the in-neighbours whose published sets its sets may rest on (and the
    reference's reading where it reads it); `netsetest exact --network` measures the same record against each node's
    network limit, with no published interval narrower than it, and the report page shows that ratio beside exact's."""
    import json

    from netsetest.cli.main import main
    from netsetest.records.report_html import _exact_html
    from netsetest.roles.judge import network_rests
    from netsetest.runtime.report import network_lines

    path = tmp_path / "ring.json"
    res = run_inmemory(ring, "worst", seed=0, record=str(path))
    rests = {n.id: n.rests_on for n in res.summary.nodes}
    for i in ring.ids:
        others = sorted(j for j in ring.node(i).in_weights if j != i)
        assert f"the published sets of {', '.join(map(str, others))}" in rests[i], (i, rests[i])
    readers = [j for j in ring.ids if 3 in ring.node(j).in_weights and j != 3]
    assert readers and all("the reading of 3 (fault-free)" in rests[j] for j in readers)
    assert all("the reading of 3" not in rests[j] for j in ring.ids if j not in (3, *readers))  # its readers only
    header = network_lines(res.summary)
    assert header and all(any(ln.startswith(f"  node {i}: ") for ln in header) for i in ring.ids[:8])
    out_json = tmp_path / "exact.json"
    assert main(["exact", str(path), "--network", "--json", str(out_json)]) == 0
    assert "the network limit" in capsys.readouterr().out
    doc = json.loads(out_json.read_text())
    net = doc["network"]
    assert max(max(d.values()) for d in net["delays"].values()) >= 2  # a directed ring: some data travel more than a hop
    assert all(x["narrower"] == 0 for per in net["ratios"]["nodes"].values() for x in per.values())  # sound: never below the limit
    assert all(x["width_ratio"] is None or x["width_ratio"] >= 1 - 1e-9 for per in net["ratios"]["nodes"].values() for x in per.values())
    assert "width / network" in _exact_html(doc)
    paper6 = load_topology("paper6", "saim")  # every node reads every bounded reading in its step: no neighbour's set cuts
    assert all(paper6.reads_everyone(i) for i in paper6.ids)
    for i in paper6.ids:
        words = network_rests(paper6, i)
        assert "published sets" not in words and ("its own declared fault bound" in words) == paper6.bound_relied(i), (i, words)
