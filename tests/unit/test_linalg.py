"""netsetest/linalg.py is numpy.linalg without its per-call set-up: on finite matrices of the estimator's sizes
(positive definite, indefinite, singular, badly scaled, tiny and huge) each function returns numpy.linalg's floats
bit for bit and raises LinAlgError exactly where numpy.linalg does, without a warning.  Bit for bit holds on any CPU:
both run the same LAPACK gufunc on the same matrix in one process, so whichever OpenBLAS kernel the CPU gets
(``OPENBLAS_CORETYPE``), both get it."""

from __future__ import annotations

import warnings
from fractions import Fraction

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


def _exactly_positive_definite(a: list[list[Fraction]]) -> bool:
    """Every leading principal minor of the rational symmetric ``a`` positive (Sylvester), by exact elimination."""
    m = [row[:] for row in a]
    for k in range(len(m)):
        if m[k][k] <= 0:
            return False
        for i in range(k + 1, len(m)):
            f = m[i][k] / m[k][k]
            for j in range(k, len(m)):
                m[i][j] -= f * m[k][j]
    return True


def _cover_gap(M: np.ndarray, P: np.ndarray, rho: float) -> list[list[Fraction]]:
    """M Mᵀ − ρP in exact rationals (every float is one)."""
    n = len(P)
    m = [[Fraction(float(v)) for v in row] for row in M]
    r = Fraction(rho)
    return [[sum((m[i][k] * m[j][k] for k in range(n)), Fraction(0)) - r * Fraction(float(P[i][j])) for j in range(n)] for i in range(n)]


@st.composite
def published_shapes(draw: st.DrawFn) -> tuple[np.ndarray, float]:
    """(P, ρ) as a node publishes them: P symmetric positive definite n×n (n 2–3, the estimator's state and its
    augmented one), eigenvalues spread over up to 10¹² and scaled by 10^k, in a random rotation; ρ in (10⁻³, 10³)."""
    n = draw(st.integers(2, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    spread = draw(st.floats(0.0, 12.0))
    lam = 10.0 ** (draw(st.integers(-8, 2)) + spread * rng.uniform(-0.5, 0.5, size=n))
    P = q @ np.diag(lam) @ q.T
    P = 0.5 * (P + P.T)
    return P, draw(st.floats(1e-3, 1e3))


@FUZZ
@given(published_shapes())
def test_the_covering_factor_covers_the_whole_ellipsoid_exactly(shape: tuple[np.ndarray, float]) -> None:
    """M Mᵀ ⪰ ρP in exact arithmetic: x̂ + M z, |z| ≤ 1, reaches every point of the published set, so a certificate
    proven over z holds on all of it (covering_factor's docstring: Cholesky's rounding bound, the scaling's)."""
    P, rho = shape
    M = linalg.covering_factor(P, rho)
    assert np.all(np.triu(M, 1) == 0.0)
    assert _exactly_positive_definite(_cover_gap(M, P, rho))


def test_the_plain_scaled_cholesky_factor_can_fall_short() -> None:
    """Why covering_factor widens: ρ^½ times the float Cholesky factor falls short of ρP in exact arithmetic on some
    published shapes (so the test above can fail), and the widening is far below a width's last printed digit."""
    rng = np.random.default_rng(7)
    short = 0
    for _ in range(200):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        P = q @ np.diag(10.0 ** rng.uniform(-6, 0, size=3)) @ q.T
        P = 0.5 * (P + P.T)
        rho = float(rng.uniform(0.1, 10.0))
        plain = np.sqrt(rho) * linalg.cholesky(P)
        short += not _exactly_positive_definite(_cover_gap(plain, P, rho))
        widened = linalg.covering_factor(P, rho)
        nz = plain != 0.0
        assert np.all(widened[~nz] == 0.0) and np.max(np.abs(widened[nz] / plain[nz] - 1.0)) < 1e-8  # (cond ≤ 10⁶: about γ cond)
    assert short > 0


def test_the_covering_factor_refuses_a_shape_it_cannot_bound() -> None:
    """A shape that is not positive definite, or so ill-conditioned that rounding could hide its smallest axis, is a
    LinAlgError (no factor is better than a short one)."""
    with pytest.raises(np.linalg.LinAlgError):
        linalg.covering_factor(np.diag([1.0, -1.0]), 1.0)
    with pytest.raises(np.linalg.LinAlgError):
        linalg.covering_factor(np.diag([1.0, 1e-17]), 1.0)
