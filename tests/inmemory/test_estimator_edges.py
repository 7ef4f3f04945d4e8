"""No crash at the edges of the estimator: profiles outside the documented ranges are rejected at load
(exit 2, naming the field); profiles at the corners of the ranges run to the end with every node-step
contained, flagged as a fallback, or outside the guarantee (a broken assumption) — never a crash."""

from __future__ import annotations

import dataclasses
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.estimator.certificate import FallbackUnavailable, fallback_shape, publishable
from netsetest.estimator.sdp import Blend, NodeSet, LocalEstimator, UpdateInput
from netsetest.runtime.inmemory import run_inmemory

ROOT = Path(__file__).resolve().parents[2]
STEPS = 6


def _network(tmp_path: Path, edits: dict[str, str], nodes: str = "all") -> Path:
    """A copy of paper6 whose node profiles (all, or only yaw3) have ``edits`` (TOML key → value text)."""
    (tmp_path / "nodes").mkdir()
    (tmp_path / "topologies").mkdir()
    for f in (ROOT / "nodes").glob("*.toml"):
        text = f.read_text()
        if nodes == "all" or f.stem == nodes:
            for key, val in edits.items():
                text, n = re.subn(rf"^{key} = .*$", f"{key} = {val}", text, flags=re.M)
                assert n == 1, (key, f)
        (tmp_path / "nodes" / f.name).write_text(text)
    shutil.copy(ROOT / "topologies" / "paper6.toml", tmp_path / "topologies" / "paper6.toml")
    return tmp_path / "topologies" / "paper6.toml"


# the issue's values, and more: each rejected at load with the field named
REJECTED = {
    "Dv = 0": ({"Dv": "0.0"}, "Dv"),
    "C = [1e6, 1e6]": ({"C": "[1e6, 1e6]"}, "C"),
    "Ds = 1e-9": ({"Ds": "1e-9"}, "Ds"),
    "Dv = 1e300": ({"Dv": "1e300"}, "Dv"),
    "R = 5e-324": ({"R": "5e-324"}, "R"),
    "Ds = 1e300": ({"Ds": "1e300"}, "Ds"),
    "C = 1e300": ({"C": "[1e300, 0.0]"}, "C"),
    "Dv < 0": ({"Dv": "-0.01"}, "Dv"),
    "R = 1e300": ({"R": "1e300"}, "R"),
    "P0 = 1e-300": ({"P0": "1e-300"}, "P0"),
    "P0 = 1e300": ({"P0": "1e300"}, "P0"),
    "P0 ill-conditioned matrix": ({"P0": "[[1e7, 0, 0], [0, 1, 0], [0, 0, 1]]"}, "P0"),
    "rho = 1e-300": ({"rho": "1e-300"}, "rho"),
    "x0_hat = 1e300": ({"x0_hat": "[1e300, 0.0, 0.0]"}, "x0_hat"),
    "noise_frequency = 1e300": ({"noise_frequency": "1e300"}, "noise_frequency"),
    "h1 = 1e-9": ({"h1": "1e-9"}, "h1"),
    "r_max = inf": ({"r_max": "inf"}, "r_max"),
    "gamma_min = 1e-9": ({"gamma_min": "1e-9"}, "gamma_min"),
}


@pytest.mark.parametrize("name", list(REJECTED))
def test_out_of_range_profile_exit_2(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    edits, field = REJECTED[name]
    topo = _network(tmp_path, edits, nodes="yaw3")
    assert main(["run", str(topo), "--mode", "inmemory", "--steps", "2", "--quiet", "--case", "saim"]) == 2
    err = capsys.readouterr().err
    assert "yaw3.toml" in err and re.search(rf"\b{field}\b", err), err
    assert "Traceback" not in err


# the corners of the ranges (several at once where they interact)
CORNERS = {
    "C = ±1e3": {"C": "[-1e3, 1e3]"},
    "|Ds| = 1e-6": {"Ds": "-1e-6"},
    "Ds = 1e3, C = 1e3": {"Ds": "1e3", "C": "[1e3, 1e3]"},
    "Dv = 1e-9, R = 1e-12": {"Dv": "1e-9", "R": "1e-12"},
    "Dv = 1e3, R = 1e6": {"Dv": "1e3", "R": "1e6"},
    "P0 = 1e-9, rho = 1e-6": {"P0": "1e-9", "rho": "1e-6"},
    "P0 = 1e6, rho = 1e6": {"P0": "1e6", "rho": "1e6"},
    "x0_hat = 1e3": {"x0_hat": "[1e3, -1e3, 1e3]"},
    "h1 = 1e-3, h2 = 1e3": {"h1": "1e-3", "h2": "1e3"},
    "r_max = 1e3": {"r_max": "1e3"},
    "gamma_min = 1e-3": {"gamma_min": "1e-3"},
}


@pytest.mark.slow
@pytest.mark.parametrize("case", ["nsnim", "saim"])
@pytest.mark.parametrize("name", list(CORNERS))
def test_corner_profile_runs_contained_or_flagged(name: str, case: str, tmp_path: Path) -> None:
    sc = load_topology(_network(tmp_path, CORNERS[name]), case, STEPS)
    res = run_inmemory(sc)
    s = res.summary
    assert s.steps_completed == STEPS and s.violations_total == 0 and s.nodes_missing == []
    for node, entries in res.parts["nodes"].items():
        assert len(entries) == STEPS + 1, node
        for e in entries:
            P = np.asarray(e["published"]["P"]).reshape(3, 3)
            assert publishable(np.asarray(e["published"]["xhat"]), P), (node, e["step"])
            assert e["contained"] or e["status"] == "fallback" or not e["assumptions_ok"], (node, e)


# ------------------------------------------------------------------------------ fallback_shape itself


def _estimator_data(sc, node: int = 3):
    n = sc.node(node)
    est = LocalEstimator.for_node(sc, node)
    alpha = sc.model.weights(sc.vx(0))
    data = est.step_data(NodeSet(n.x0_hat, n.P0, n.rho), UpdateInput(alpha, 0.03, 0.01, 1.0, {}), None)
    return est, n, Blend.of(sc.model, alpha), data


def test_fallback_shape_is_scale_free_and_spd() -> None:
    sc = load_topology(ROOT / "topologies" / "paper6.toml", "saim", 2)
    est, n, blend, data = _estimator_data(sc)
    shape = fallback_shape(data.Mi, dataclasses.replace(data.own, sensor=n.sensor, gamma=0.8), sc.W, blend.abar, blend.dbar)
    assert publishable(np.zeros(3), shape)
    # scaling every term (here through Mi and a sensor with scaled Dv·√R, r_max) by c scales the shape by c²
    for c in (1e-100, 1e100):
        sens = type(n.sensor)(n.sensor.C, n.sensor.Ds, n.sensor.Dv * c, n.sensor.R, True, n.sensor.r_max * c, n.sensor.h1, n.sensor.h2)
        big = fallback_shape(data.Mi * c, dataclasses.replace(data.own, sensor=sens, gamma=0.8), sc.W * c * c, blend.abar, blend.dbar)
        assert np.all(np.isfinite(big))
        np.testing.assert_allclose(big / (c * c), shape, rtol=1e-9)


def test_fallback_shape_refuses_what_it_cannot_represent() -> None:
    sc = load_topology(ROOT / "topologies" / "paper6.toml", "nsnim", 2)
    est, n, blend, data = _estimator_data(sc)
    for bad in (np.inf, np.nan):
        with np.errstate(invalid="ignore"), pytest.raises(FallbackUnavailable):
            fallback_shape(data.Mi * bad, dataclasses.replace(data.own, sensor=n.sensor, gamma=1.0), sc.W, blend.abar, blend.dbar)
    with pytest.raises(FallbackUnavailable):  # finite terms whose squares overflow
        fallback_shape(data.Mi * 1e200, dataclasses.replace(data.own, sensor=n.sensor, gamma=1.0), sc.W, blend.abar, blend.dbar)


def test_publishable() -> None:
    assert publishable(np.zeros(3), np.eye(3))
    assert not publishable(np.array([0.0, np.nan, 0.0]), np.eye(3))
    assert not publishable(np.zeros(3), np.diag([1.0, 1.0, np.inf]))
    assert not publishable(np.zeros(3), np.diag([1.0, 1.0, -1e-30]))
    assert not publishable(np.zeros(3), np.diag([1.0, 1.0, 1e-15]))  # degenerate: condition number 1e15
    assert not publishable(np.zeros(3), np.array([[1.0, 0.1, 0], [0.0, 1.0, 0], [0, 0, 1.0]]))  # not symmetric
