"""netsetest/linalg.py is numpy.linalg without its per-call set-up: on finite matrices of the estimator's sizes
(positive definite, indefinite, singular, badly scaled, tiny and huge) each function returns numpy.linalg's floats
bit for bit and raises LinAlgError exactly where numpy.linalg does, without a warning.  Bit for bit holds on any CPU:
both run the same LAPACK gufunc on the same matrix in one process, so whichever OpenBLAS kernel the CPU gets
(``OPENBLAS_CORETYPE``), both get it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_polygon_exact import FUZZ

from netsetest import linalg

pytestmark = pytest.mark.blas  # (.ci/run runs it under every OpenBLAS kernel the CPU runs)


@st.composite
def square(draw: st.DrawFn) -> np.ndarray:
    """An n×n float64 matrix (n 1–6): symmetric positive definite, symmetric indefinite or singular, or general;
    scaled by 10^k (k −150…150)."""
    n = draw(st.integers(1, 6))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    root = rng.normal(size=(n, n))
    kind = draw(st.sampled_from(["spd", "symmetric", "singular", "general", "near-singular"]))
    if kind == "spd":
        a = root @ root.T + 10.0 ** draw(st.integers(-12, 0)) * np.eye(n)
    elif kind == "symmetric":
        a = root + root.T
    elif kind == "singular":
        a = root @ np.diag([0.0, *np.ones(n - 1)]) @ root.T  # rank n − 1 (n = 1: zero)
    elif kind == "near-singular":
        a = root @ root.T
        a[-1] = a[0] * (1.0 + 1e-15) if n > 1 else a[-1]
    else:
        a = root
    return a * 10.0 ** draw(st.integers(-150, 150))


def _both(name: str, *args: np.ndarray) -> tuple[object, object]:
    """numpy.linalg's and netsetest.linalg's answer (or the exception's type), warnings as errors."""
    out = []
    for module in (np.linalg, linalg):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            try:
                out.append(getattr(module, name)(*args))
            except np.linalg.LinAlgError:
                out.append(np.linalg.LinAlgError)
    return out[0], out[1]


def _same(a: object, b: object) -> bool:
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    return a is b


@FUZZ
@given(square())
def test_cholesky_eigvalsh_eigh_and_inv_are_numpys(a: np.ndarray) -> None:
    for name in ("cholesky", "eigvalsh", "eigh", "inv"):
        want, got = _both(name, a)
        assert _same(want, got), name


@FUZZ
@given(square(), st.integers(0, 3), st.integers(0, 2**32 - 1))
def test_solve_is_numpys_for_a_vector_and_a_matrix(a: np.ndarray, columns: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    b = rng.normal(size=len(a)) if columns == 0 else rng.normal(size=(len(a), columns))
    want, got = _both("solve", a, b)
    assert _same(want, got)


def test_the_failures_raise_as_numpys_do() -> None:
    indefinite = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(np.linalg.LinAlgError):
        linalg.cholesky(indefinite)
    for name, args in (("solve", (np.zeros((2, 2)), np.ones(2))), ("inv", (np.zeros((2, 2)),)), ("cholesky", (np.ones((2, 3)),))):
        with pytest.raises(np.linalg.LinAlgError):
            getattr(linalg, name)(*args)
