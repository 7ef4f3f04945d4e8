"""The exact plausibility tests a node applies to a neighbour's state (netsetest.roles.plausibility)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from netsetest.estimator.sector import Sector
from netsetest.models.sensor import Sensor
from netsetest.roles.plausibility import innovation_interval, innovation_possible, states_disjoint


def _spd(rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    a = rng.normal(size=(3, 3))
    return scale * (a @ a.T + 0.1 * np.eye(3))


def _sensor(rng: np.random.Generator, saturated: bool) -> Sensor:
    C = rng.normal(size=2)
    if not saturated:
        return Sensor(C=C, Ds=float(rng.uniform(0.3, 0.7)), Dv=float(rng.uniform(1e-3, 0.1)), R=float(rng.uniform(0.5, 3)))
    return Sensor(
        C=C,
        Ds=float(rng.uniform(0.3, 0.7)),
        Dv=float(rng.uniform(1e-3, 0.1)),
        R=float(rng.uniform(0.5, 3)),
        saturated=True,
        r_max=float(rng.uniform(0.02, 1.0)),
        h1=float(rng.uniform(0.5, 0.95)),
        h2=float(rng.uniform(1.0, 1.5)),
    )


def _interval_cases(seed: int) -> Iterator[tuple[Sensor, np.ndarray, np.ndarray, float, float]]:
    """200 random (sensor, x̂, P, ρ, γ) per kind of sensor, unsaturated then saturated, from ``seed``."""
    rng = np.random.default_rng(seed)
    for saturated in (False, True):
        for _ in range(200):
            s = _sensor(rng, saturated)
            yield s, rng.normal(size=3), _spd(rng), float(rng.uniform(0.2, 2)), float(rng.uniform(0.8, 1.2))


@pytest.mark.parametrize("saturated", [False, True])
def test_every_honest_innovation_is_possible(saturated: bool) -> None:
    """A sensor whose truth lies in its published ellipsoid, with noise within its bound and the sector
    condition holding, always produces an innovation inside the interval."""
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(3000):
        s = _sensor(rng, saturated)
        xhat, P, rho = rng.normal(size=3) * 0.3, _spd(rng, 0.05), float(rng.uniform(0.2, 2.0))
        z = rng.normal(size=3)
        z *= rng.uniform() ** (1 / 3) / np.linalg.norm(z)  # |z| ≤ 1
        x = xhat + np.sqrt(rho) * np.linalg.cholesky(P) @ z  # in the ellipsoid
        if not s.sector_holds(x):
            continue
        gamma = float(rng.uniform(0.1, 1.0))
        v = float(rng.uniform(-1, 1) * np.sqrt(s.R))
        y = s.measure(x, gamma, v)
        assert innovation_possible(s, xhat, P, rho, gamma, None, y - float(s.Cbar @ xhat))
        checked += 1
    assert checked > 1000


@pytest.mark.parametrize("saturated", [False, True])
def test_interval_is_exactly_what_the_estimator_facts_admit(saturated: bool) -> None:
    """The ends are reached by admissible (s, v, φ) of the S-procedure facts; a hair beyond is rejected."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        s = _sensor(rng, saturated)
        xhat, P, rho, gamma = rng.normal(size=3), _spd(rng), float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.1, 1.0))
        lo, hi = innovation_interval(s, xhat, P, rho, gamma, None)
        cx = float(s.Cbar @ xhat)
        c = float(np.sqrt(rho * s.Cbar @ P @ s.Cbar))
        noise = abs(s.Dv) * np.sqrt(s.R)
        # y̌(s, φ, v) = (γ h1 − 1) cx + γ h1 c s + γ φ + Dv v with φ ∈ sector [0, h r], r = cx + c s
        cands = []
        for sj in (-1.0, 1.0):
            r = cx + c * sj
            for phi in (0.0, (s.h2 - s.h1) * r):
                for v in (-noise, noise):
                    cands.append((gamma * s.h1 - 1.0) * cx + gamma * s.h1 * c * sj + gamma * phi + v)
        assert min(cands) == pytest.approx(lo, rel=1e-12, abs=1e-14) and max(cands) == pytest.approx(hi, rel=1e-12, abs=1e-14)
        width = hi - lo
        assert innovation_possible(s, xhat, P, rho, gamma, None, lo) and innovation_possible(s, xhat, P, rho, gamma, None, hi)
        assert not innovation_possible(s, xhat, P, rho, gamma, None, hi + 1e-6 * width)
        assert not innovation_possible(s, xhat, P, rho, gamma, None, lo - 1e-6 * width)


def test_disjoint_only_when_provably_so() -> None:
    rng = np.random.default_rng(3)
    eye = np.eye(3)
    assert states_disjoint(np.zeros(3), eye, 1.0, np.array([2.5, 0.0, 0.0]), eye, 1.0)
    assert not states_disjoint(np.zeros(3), eye, 1.0, np.array([1.9, 0.0, 0.0]), eye, 1.0)
    assert not states_disjoint(np.zeros(3), eye, 1.0, np.array([0.0, 0.0, 50.0]), eye, 1.0)  # f is not shared
    grid = np.stack(np.meshgrid(np.linspace(-3, 3, 241), np.linspace(-3, 3, 241)), -1).reshape(-1, 2)
    said_disjoint = 0
    for _ in range(150):
        x1, x2 = rng.normal(size=3), rng.normal(size=3)
        P1, P2 = _spd(rng, 0.1), _spd(rng, 0.1)
        r1, r2 = float(rng.uniform(0.2, 1.5)), float(rng.uniform(0.2, 1.5))
        disjoint = states_disjoint(x1, P1, r1, x2, P2, r2)

        def inside(x, P, r):
            d = grid - x[:2]
            return np.einsum("ni,ij,nj->n", d, np.linalg.inv(r * P[:2, :2]), d) <= 1.0

        both = inside(x1, P1, r1) & inside(x2, P2, r2)
        if disjoint:
            said_disjoint += 1
            assert not both.any(), "called disjoint, but a common point exists"
    assert said_disjoint > 20


def test_interval_uses_the_published_sector_of_the_step() -> None:
    """With a neighbour's per-step sector (h1_k, h_k) the interval is what the estimator's facts for that
    sector admit (h2 = h1_k + h_k), not the profile's fixed one; h = 0 (no saturation proven) narrows it."""
    rng = np.random.default_rng(17)
    for _ in range(200):
        s = _sensor(rng, True)
        sec = Sector(float(rng.uniform(0.3, 1.0)), float(rng.uniform(0.0, 0.8)) if rng.uniform() < 0.7 else 0.0, "measurement")
        xhat, P, rho, gamma = rng.normal(size=3), _spd(rng), float(rng.uniform(0.2, 2.0)), float(rng.uniform(0.1, 1.0))
        lo, hi = innovation_interval(s, xhat, P, rho, gamma, sec)
        cx = float(s.Cbar @ xhat)
        c = float(np.sqrt(rho * s.Cbar @ P @ s.Cbar))
        noise = abs(s.Dv) * np.sqrt(s.R)
        cands = [
            (gamma * sec.h1 - 1.0) * cx + gamma * sec.h1 * c * sj + gamma * phi + v
            for sj in (-1.0, 1.0)
            for phi in (0.0, sec.h * (cx + c * sj))
            for v in (-noise, noise)
        ]
        assert min(cands) == pytest.approx(lo, rel=1e-12, abs=1e-14) and max(cands) == pytest.approx(hi, rel=1e-12, abs=1e-14)
        assert (lo, hi) != innovation_interval(s, xhat, P, rho, gamma, None)
        width = hi - lo
        assert not innovation_possible(s, xhat, P, rho, gamma, sec, hi + 1e-6 * width)
        assert not innovation_possible(s, xhat, P, rho, gamma, sec, lo - 1e-6 * width)


def _grid_disjoint(x1, P1, r1, x2, P2, r2) -> bool:
    """The λ-grid test alone (states_disjoint without its shortcut), as the reference."""
    from netsetest.roles.plausibility import DISJOINT_MARGIN, LAMBDA_GRID

    A1, A2, d = r1 * P1[:2, :2], r2 * P2[:2, :2], x2[:2] - x1[:2]
    vals = [d @ np.linalg.solve(A1 / (1 - lam) + A2 / lam, d) for lam in LAMBDA_GRID]
    return max(vals) > 1.0 + DISJOINT_MARGIN


def test_shortcut_decides_as_the_grid() -> None:
    """states_disjoint's cheap bound dᵀ(A₁+A₂)⁻¹d ≤ 1 only skips pairs the λ grid would not call disjoint:
    same answer on random pairs at every distance, many of them near the boundary."""
    rng = np.random.default_rng(5)
    answers = set()
    for _ in range(400):
        x1 = rng.normal(size=3)
        P1, P2 = _spd(rng, 0.1), _spd(rng, 0.1)
        r1, r2 = float(rng.uniform(0.2, 1.5)), float(rng.uniform(0.2, 1.5))
        direction = rng.normal(size=3)
        x2 = x1 + direction * rng.uniform(0.0, 3.0) / np.linalg.norm(direction[:2])
        got = states_disjoint(x1, P1, r1, x2, P2, r2)
        assert got == _grid_disjoint(x1, P1, r1, x2, P2, r2)
        answers.add(got)
    assert answers == {True, False}


def test_scalar_interval_matches_numpy() -> None:
    """innovation_interval's scalar arithmetic equals the matrix formula (C̄x̂, √(ρ C̄PC̄ᵀ)) to rounding."""
    for s, xhat, P, rho, gamma in _interval_cases(9):
        cx = float(s.Cbar @ xhat)
        c = float(np.sqrt(rho * s.Cbar @ P @ s.Cbar))
        noise = abs(s.Dv) * np.sqrt(s.R)
        lo_ref = gamma * min(s.h1 * (cx - c), s.h2 * (cx - c)) - noise - cx
        hi_ref = gamma * max(s.h1 * (cx + c), s.h2 * (cx + c)) + noise - cx
        lo, hi = innovation_interval(s, xhat, P, rho, gamma, None)
        assert lo == pytest.approx(lo_ref, rel=1e-12, abs=1e-14) and hi == pytest.approx(hi_ref, rel=1e-12, abs=1e-14)


def test_overlap_bound_in_floats_is_the_arrays_bound_bit_for_bit() -> None:
    """The shortcut's plain-float bound rounds as the array formula it replaced (ρP[:2, :2] summed, d over
    β, r), so every node decides exactly as before: equal, not close, on random pairs."""
    from netsetest.roles.plausibility import _overlap_bound

    rng = np.random.default_rng(11)
    for _ in range(300):
        x1, x2 = rng.normal(size=3), rng.normal(size=3)
        P1, P2 = _spd(rng, 0.1), _spd(rng, 0.1)
        r1, r2 = float(rng.uniform(0.2, 1.5)), float(rng.uniform(0.2, 1.5))
        A, d = r1 * P1[:2, :2] + r2 * P2[:2, :2], x2[:2] - x1[:2]
        a, b, c, e = (float(v) for v in A.ravel())
        ref = (float(d[0]) ** 2 * e - float(d[0]) * float(d[1]) * (b + c) + float(d[1]) ** 2 * a) / (a * e - b * c)
        assert _overlap_bound(P1.tolist(), r1, P2.tolist(), r2, float(x2[0]) - float(x1[0]), float(x2[1]) - float(x1[1])) == ref


def test_interval_unrolled_rounds_as_before() -> None:
    """innovation_interval unrolled rounds exactly as the loops it replaced (every node's decision unchanged)."""
    for s, xhat, P, rho, gamma in _interval_cases(13):
        cb = (float(s.C[0]), float(s.C[1]), float(s.Ds))
        x = [float(a) for a in xhat]
        Pl = P.tolist()
        cx = cb[0] * x[0] + cb[1] * x[1] + cb[2] * x[2]
        Pc = [Pl[i][0] * cb[0] + Pl[i][1] * cb[1] + Pl[i][2] * cb[2] for i in range(3)]
        c = math.sqrt(max(rho * (cb[0] * Pc[0] + cb[1] * Pc[1] + cb[2] * Pc[2]), 0.0))
        noise = abs(s.Dv) * math.sqrt(s.R)
        lo = gamma * min(s.h1 * (cx - c), s.h2 * (cx - c)) - noise - cx
        hi = gamma * max(s.h1 * (cx + c), s.h2 * (cx + c)) + noise - cx
        assert innovation_interval(s, xhat, P, rho, gamma, None) == (lo, hi)
        assert innovation_interval(s, list(xhat), P.tolist(), rho, gamma, None) == (lo, hi)  # lists as arrays
