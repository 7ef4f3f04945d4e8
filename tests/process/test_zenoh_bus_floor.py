"""Zenoh's floor (bench/bus_floor.py): a bare bus process between a router opened as ``netsetest run`` opens it
(or the open peer mesh) and the node's world receives and sends exactly the node's messages per step, measures
itself and leaves no process behind."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest_bench.bus_floor import FIGURES, floor_run, median_node, ring_payloads
from netsetest_bench.topologies import ring_topology
from netsetest.config.schema import load_topology
from zenoh_helpers import child_pids

pytestmark = pytest.mark.zenoh


@pytest.mark.parametrize("secured", [True, False], ids=["secured", "insecure"])
@pytest.mark.timeout(180)
def test_the_bare_bus_receives_and_sends_the_nodes_messages(secured: bool, tmp_path: Path) -> None:
    topo = ring_topology(tmp_path, 6, 8)
    sc = load_topology(str(topo))
    payloads = ring_payloads(sc, median_node(sc))
    before = child_pids()
    r = floor_run(topo, payloads, secured, tmp_path)
    assert "error" not in r, r
    assert r["secured"] is secured and r["steps"] == sc.steps - 1  # the window: steps 2..8 (WARM_STEPS = 2)
    assert r["sent"] == 1.0
    # its input and one state per in-neighbour each step (the states of a step at the window's edges may be
    # taken from their channels on either side of it)
    per_step = 1 + len(payloads.others)
    assert abs(r["received"] - per_step) <= per_step / r["steps"] + 1e-9
    assert all(r[key] > 0 for key, _, unit in FIGURES if unit == "µs" and key != "rest_us")
    assert r["process_us"] == pytest.approx(r["thread_us"] + r["threads_us"])
    assert child_pids() <= before, "the bare process was left behind"
