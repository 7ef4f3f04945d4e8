"""The plain-float polygon code (issue 28's speed-up, issue 45's plain floats end to end) keeps every set:
in whole runs (paper6 NSNIM and SAIM, paper signals and worst-case ones, paper6_reference, paper6_car_max_faulty, paper6_max_faulty), every call of the moves, cuts,
reductions and ellipse cuts returns what the numpy code before it returned on the same input
(tests/polygon_reference.py), to the roundings of the operation (polygon_reference.bound), both ways: the fast set
holds the numpy one shrunk by that bound, and is no larger than it grown by it.  Not bit for bit: the ellipse cut's
slab ends are numpy's 2-vector products there, which OpenBLAS's kernel rounds by CPU (tests/unit/test_polygon_same.py
says how); tests/unit/test_polygon_same.py does the same on random polygons."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from typing import Any

import numpy as np
import polygon_reference as ref
import pytest

from netsetest.config.schema import Case, load_topology
from netsetest import polygon
from netsetest.models.signals import SignalKind
from netsetest.polygon import Polygon
from netsetest.runtime.inmemory import run_inmemory

pytestmark = pytest.mark.blas  # (.ci/run runs it under every OpenBLAS kernel the CPU runs)

STEPS = 20
RUNS: list[tuple[str, Case, SignalKind, int]] = [
    ("paper6", "nsnim", "paper", 0),
    ("paper6", "saim", "paper", 0),
    ("paper6", "saim", "worst", 3),
    ("paper6_reference", "nsnim", "paper", 0),
    ("paper6_reference", "saim", "worst", 11),
    ("paper6_car_max_faulty", "saim", "paper", 0),
    ("paper6_max_faulty", "nsnim", "worst", 10),
]


def _checked(calls: Counter[str], name: str, new: Callable[..., Any], old: Callable[..., Any]) -> Callable[..., Any]:
    """``new`` that also runs ``old`` on the same input (the polygon as the reference's) and asserts the same set, to the
    operation's rounding."""

    def both(region: Polygon, *args: Any, **kwargs: Any) -> Any:
        got = new(region, *args, **kwargs)
        args = tuple(np.asarray(a, dtype=float) if isinstance(a, tuple) else a for a in args)  # (a direction as plain floats: the numpy code's array)
        want = old(ref.Polygon(region.vertices.copy()), *args, **kwargs)
        why = ref.differs(got, want, ref.bound(name, region.vertices, *args, **kwargs))
        assert why is None, f"{name}{args!r} on {region.vertices.tolist()!r}: {why}"
        calls[name] += 1
        return got

    return both


@pytest.mark.parametrize(("topology", "case", "signals", "seed"), RUNS)
def test_every_region_operation_of_a_run_returns_what_the_numpy_code_did(
    monkeypatch: pytest.MonkeyPatch, topology: str, case: Case, signals: SignalKind, seed: int
) -> None:
    calls: Counter[str] = Counter()
    for name in ("moved", "cut", "reduced"):
        monkeypatch.setattr(Polygon, name, _checked(calls, name, getattr(Polygon, name), getattr(ref.Polygon, name)))
    monkeypatch.setattr(Polygon, "ellipse_cut", _checked(calls, "ellipse_cut", Polygon.ellipse_cut, ref.ellipse_cut))
    run_inmemory(load_topology(topology, case, STEPS), signals, "scheduled", seed)
    nodes = len(load_topology(topology, case, STEPS).ids)
    assert calls["moved"] >= nodes * (STEPS - 1) and calls["reduced"] >= nodes * STEPS  # every node, every step
    assert calls["cut"] > 0 and calls["ellipse_cut"] > 0  # (most ellipse cuts return the region at once: no cut)


def _same_on_both(calls: Counter[str], name: str, op: Callable[..., Any]) -> Callable[..., Any]:
    """``op`` on the compiled backend that also runs it on the plain-Python one and asserts the same vertices."""

    def both(region: Polygon, *args: Any, **kwargs: Any) -> Any:
        got = op(region, *args, **kwargs)
        polygon._use("python")
        want = op(Polygon._of(region.points), *args, **kwargs)
        polygon._use("compiled")
        assert (got and got.points) == (want and want.points), f"{name}{args!r} on {region.points!r}"
        calls[name] += 1
        return got

    return both


@pytest.mark.parametrize(("topology", "case", "signals", "seed"), [RUNS[0], RUNS[2], RUNS[6]])
def test_every_region_operation_of_a_run_is_the_same_compiled(
    monkeypatch: pytest.MonkeyPatch, topology: str, case: Case, signals: SignalKind, seed: int
) -> None:
    """The compiled moves, cuts and reductions (netsetest/polygon_compiled.py) return the plain-Python ones' vertices
    bit for bit on every call of a run (tests/unit/test_polygon_compiled.py on adversarial polygons)."""
    pytest.importorskip("numba", reason="the compiled polygon backend needs numba (the fast extra)")
    calls: Counter[str] = Counter()
    for name in ("moved", "cut", "reduced"):
        monkeypatch.setattr(Polygon, name, _same_on_both(calls, name, getattr(Polygon, name)))
    before = polygon._use("compiled")
    try:
        run_inmemory(load_topology(topology, case, STEPS), signals, "scheduled", seed)
    finally:
        polygon._use(before)
    nodes = len(load_topology(topology, case, STEPS).ids)
    assert calls["moved"] >= nodes * (STEPS - 1) and calls["reduced"] >= nodes * STEPS and calls["cut"] > 0
