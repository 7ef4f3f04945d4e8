"""A step prepared before its readings came (``LocalEstimator.prepare``, what a node process computes while
the same-step exchange is on its way, docs/network.md) is the same step: bit for bit, on every node-step of
runs with a reference's readings and with k-of-N health, against the plain step and against the run's own;
and a run whose nodes prepare (``Node(early=True)``, as in a process) publishes what one whose nodes do not
publishes.  The Zenoh lockstep runs against in memory: tests/process/test_zenoh_lockstep.py."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from netsetest.config.schema import load_topology
import netsetest.runtime.inmemory as inmemory
from netsetest.estimator.sdp import LocalEstimator, NodeSet, UpdateInput
from netsetest.roles.node import Node
from netsetest.runtime.inmemory import run_inmemory
from netsetest.scenarios import TOPOLOGY_DIR

STEPS = 30


def _same(a: object, b: object, where: str) -> None:
    """Equal field by field, arrays bit for bit; the solver's own time left out (it is a measurement)."""
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), where
        for f in dataclasses.fields(a):
            if f.name != "solve_ms":
                _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for n, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{n}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b), where
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert a == b, where


@pytest.mark.parametrize("topology, case", [("paper6_max_faulty", None), ("paper6_reference", "saim"), ("paper6_reference", "nsnim")])
def test_a_prepared_step_is_the_same_step(topology: str, case: str | None) -> None:
    sc = load_topology(TOPOLOGY_DIR / f"{topology}.toml", case, STEPS)
    steps: list[tuple[int, NodeSet, UpdateInput, object]] = []
    run_inmemory(sc, "paper", "scheduled", 0, observer=lambda est, prev, inp, res, ms: steps.append((est.node_id, prev, inp, res)))
    plain = {i: LocalEstimator.for_node(sc, i, "scheduled") for i in sc.ids}
    prepared = {i: LocalEstimator.for_node(sc, i, "scheduled") for i in sc.ids}
    with_readings = 0
    for i, prev, inp, res in steps:
        a = plain[i].step(prev, inp)
        early = prepared[i].prepare(prev, dataclasses.replace(inp, readings={}))  # before any reading: none is read
        assert early.of(prev, inp)
        b = prepared[i].step(prev, inp, early)
        _same(b, a, f"node {i}, prepared")
        _same(a, res, f"node {i}, the run's")
        with_readings += bool(inp.readings)
    assert with_readings >= len(sc.ids) * (STEPS - 1) // 2  # most steps had their readings: the case this is about


def test_a_prepared_step_of_another_input_is_refused() -> None:
    sc = load_topology(TOPOLOGY_DIR / "paper6_max_faulty.toml", None, 3)
    steps: list[tuple[NodeSet, UpdateInput]] = []
    run_inmemory(sc, "paper", "scheduled", 0, observer=lambda est, prev, inp, res, ms: steps.append((prev, inp)) if est.node_id == 1 else None)
    prev, inp = steps[-1]
    early = LocalEstimator.for_node(sc, 1, "scheduled").prepare(prev, inp)
    assert early.of(prev, dataclasses.replace(inp, readings={}))
    assert not early.of(prev, dataclasses.replace(inp, y=inp.y + 1e-9))
    assert not early.of(prev, dataclasses.replace(inp, neigh={j: dataclasses.replace(s) for j, s in inp.neigh.items()}))  # other messages
    assert not early.of(dataclasses.replace(prev, rho=prev.rho * 2), inp)


@pytest.mark.parametrize("topology, case", [("paper6_max_faulty", "saim"), ("paper6_reference", "nsnim")])
def test_nodes_that_prepare_publish_what_nodes_that_do_not_publish(monkeypatch: pytest.MonkeyPatch, topology: str, case: str) -> None:
    sc = load_topology(TOPOLOGY_DIR / f"{topology}.toml", case, STEPS)
    plain = run_inmemory(sc, "worst", "scheduled", 3).parts["nodes"]
    prepared: list[int] = []
    prepare = LocalEstimator.prepare
    monkeypatch.setattr(LocalEstimator, "prepare", lambda est, prev, inp: prepared.append(est.node_id) or prepare(est, prev, inp))
    monkeypatch.setattr(inmemory, "Node", functools.partial(Node, early=True))
    early = run_inmemory(sc, "worst", "scheduled", 3).parts["nodes"]
    assert len(prepared) >= STEPS  # steps were prepared before their readings came (in memory: where a reader steps before its source)
    assert early.keys() == plain.keys()
    for i in plain:
        assert len(early[i]) == len(plain[i]) == STEPS + 1
        for a, b in zip(early[i], plain[i]):
            _same({k: v for k, v in a.items() if k != "solve_ms"}, {k: v for k, v in b.items() if k != "solve_ms"}, f"node {i} step {a['step']}")
