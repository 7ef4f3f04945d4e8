"""The compiled polygon operations (netsetest/polygon_compiled.py, numba) are the plain-Python ones of
netsetest/polygon.py, step for step: on the adversarial polygons of tests/unit/test_polygon_exact.py (near-collinear,
near-axis, flat, slivers, rotated, 10⁻¹² to 10¹²) and its matrices, segments and slabs, the move, the cut and the
reduction return the same vertices on both backends, bit for bit (the same IEEE operations in the same order: numba
fuses no multiply-add without ``fastmath``; no BLAS is involved).  Where a kernel meets what floating point cannot
decide (an orientation inside Shewchuk's filter), it hands the operation to the plain-Python one, exact predicates
and all.  The property tests of soundness (test_polygon*.py) run on both backends; a whole run on both:
tests/inmemory/test_polygon_runs_same.py."""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_polygon_exact import FUZZ, car_like, matrices, polygons, segment_lists, slabs

from netsetest import polygon
from netsetest.extras import MissingExtra
from netsetest.polygon import Polygon

kernels = pytest.importorskip("netsetest.polygon_compiled", reason="the compiled polygon backend needs numba (the fast extra)")


@pytest.fixture(scope="module", autouse=True)
def _restore_backend() -> Iterator[None]:
    before = polygon._use("compiled")
    yield
    polygon._use(before)


def _both(op: Callable[[], Polygon | None]) -> tuple[object, object]:
    """``op``'s vertices on the compiled backend, then on the plain-Python one."""
    out = []
    for backend in polygon.BACKENDS:
        polygon._use(backend)
        got = op()
        out.append(None if got is None else got.points)
    polygon._use("compiled")
    return out[0], out[1]


@FUZZ
@given(st.data())
def test_the_compiled_move_is_the_plain_one(data: st.DataObject) -> None:
    v = data.draw(polygons())
    A = data.draw(st.one_of(matrices, car_like))
    t = np.array(data.draw(st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)))) * float(np.abs(v).max())
    segments = data.draw(segment_lists(v))
    compiled, plain = _both(lambda: Polygon(v).moved(A, t, segments))
    assert compiled == plain


@FUZZ
@given(st.data())
def test_the_compiled_cut_is_the_plain_one(data: st.DataObject) -> None:
    v = data.draw(polygons())
    c, lo, hi = data.draw(slabs(v))
    compiled, plain = _both(lambda: Polygon(v).cut(c, lo, hi))
    assert compiled == plain


@FUZZ
@given(st.data())
def test_the_compiled_step_is_the_plain_one(data: st.DataObject) -> None:
    """Move, cut by a slab, reduce to 4 to 24 vertices, as a node's step does."""
    v = data.draw(polygons())
    A = data.draw(st.one_of(matrices, car_like))
    segments = data.draw(segment_lists(v))
    c, lo, hi = data.draw(slabs(v))
    limit = data.draw(st.integers(4, polygon.MAX_VERTICES))

    def step() -> Polygon | None:
        cut = Polygon(v).moved(A, np.zeros(2), segments).cut(c, lo, hi)
        return None if cut is None else cut.reduced(limit)

    compiled, plain = _both(step)
    assert compiled == plain


def test_an_orientation_the_filter_cannot_decide_goes_to_the_exact_path() -> None:
    """det A = 2⁻⁵² exactly, inside the float filter's error bound: the kernel hands the move over (None), and the
    polygon's move is the plain-Python one (its exact orientation keeps the vertices counter-clockwise)."""
    A = np.array([[1.0, 1.0], [1.0, 1.0 + 2.0**-52]])
    square = Polygon.box(np.zeros(2), np.ones(2))
    segments = [np.array([0.1, 0.0])]
    assert kernels.moved(square._array(), A, np.zeros(2), np.array(segments), polygon._CONSTANTS) is None
    compiled, plain = _both(lambda: square.moved(A, np.zeros(2), segments))
    assert compiled == plain


def test_the_machine_code_is_cached_outside_the_temporary_directory() -> None:
    """numba's on-disk cache (cache=True) is beside the module (or NUMBA_CACHE_DIR, ~/.cache/numba), never in the
    system's temporary directory, which the suite keeps clean (tests/conftest.py)."""
    # where numba may put it: beside the kernels' module (a checkout or a site-packages that may itself lie anywhere,
    # under a CI machine's /tmp too), else NUMBA_CACHE_DIR, else the user's cache; never the temporary directory itself
    allowed = [(Path(kernels.__file__).parent / "__pycache__").resolve(), (Path.home() / ".cache" / "numba").resolve()]
    if os.environ.get("NUMBA_CACHE_DIR"):
        allowed.append(Path(os.environ["NUMBA_CACHE_DIR"]).resolve())
    for kernel in (kernels.moved, kernels.cut, kernels.reduced):
        where = Path(kernel._cache._cache_path).resolve()
        assert any(where.is_relative_to(a) for a in allowed), where
        assert where not in (Path(tempfile.gettempdir()).resolve(), Path("/tmp").resolve()), where


def test_an_unknown_backend_is_named_with_the_choices() -> None:
    with pytest.raises(polygon.BackendError, match="NETSETEST_POLYGON='fortran': the polygon backend is one of compiled, python"):
        polygon._use("fortran")


def test_the_cli_refuses_an_unknown_backend_before_any_command(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """A bad NETSETEST_POLYGON is one line and exit 2 before the command starts (not a failure in a run's first step)."""
    from netsetest.cli.main import main

    monkeypatch.setenv("NETSETEST_POLYGON", "fortran")
    monkeypatch.setattr(polygon, "_backend", None)
    assert main(["run", "topologies/paper6.toml", "--mode", "inmemory", "--steps", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["netsetest run: NETSETEST_POLYGON='fortran': the polygon backend is one of compiled, python"]


def test_the_compiled_backend_without_numba_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "numba", None)  # (importing it fails, as where it is not installed)
    monkeypatch.setattr(polygon, "_kernels", None)  # (not loaded yet)
    with pytest.raises(MissingExtra, match=r"NETSETEST_POLYGON=compiled needs numba: pip install 'netsetest\[fast\]'"):
        polygon._use("compiled")
