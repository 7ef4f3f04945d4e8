"""The cut of a certified set by a proven interval of cᵀx̄ (netsetest/estimator/slab.py): the size cut of a
published set (c = e₃, docs/estimator.md "One step") and a reading's cut of the recursion (c = C̄ⱼ, docs/network.md).

- The cut ellipsoid contains every point of the certified ellipsoid inside the interval (random
  ellipsoids, a coordinate and random directions, points on the boundary of both and inside), and its
  own certificate holds.
- It narrows cᵀx̄ towards the interval and never widens it; an interval that does not cut the ellipsoid
  (or is empty) leaves the set alone.
"""

from __future__ import annotations

import numpy as np
import pytest

from netsetest.estimator.slab import cut
from netsetest.sets import Slab


def _points(rng: np.random.Generator, xhat: np.ndarray, P: np.ndarray, rho: float, n: int) -> np.ndarray:
    """Points of the ellipsoid {(x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ}: half on its boundary, half inside."""
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u[n // 2 :] *= rng.uniform(size=(n - n // 2, 1)) ** (1 / 3)
    return xhat + u @ np.linalg.cholesky(rho * P).T


@pytest.mark.parametrize("direction", ["fault", "random"])
@pytest.mark.parametrize("seed", range(8))
def test_the_cut_contains_the_ellipsoid_inside_the_interval(seed: int, direction: str) -> None:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3))
    P, xhat, rho = A @ A.T + 0.05 * np.eye(3), rng.normal(size=3), float(rng.uniform(0.5, 2.0))
    c = np.array([0.0, 0.0, 1.0]) if direction == "fault" else rng.normal(size=3)
    half, xc = np.sqrt(rho * c @ P @ c), float(c @ xhat)
    if direction == "fault":
        lo, hi = xc - half * rng.uniform(0.5, 1.5), xc + half * rng.uniform(0.0, 0.6)  # cuts off the top
    else:  # both faces inside: a shallow cut across a short axis may gain nothing in the trace
        lo, hi = xc - half * rng.uniform(0.2, 0.5), xc + half * rng.uniform(0.0, 0.3)
    weights = np.array([1.0, 1.0, float(rng.choice([1.0, 30.0]))])
    out = cut(xhat, P, rho, Slab(c, lo, hi), weights)
    assert out is not None
    centre, P_new, rho_c = out
    assert np.isfinite(rho_c)
    X = _points(rng, xhat, P, rho, 40000)
    X = X[(X @ c >= lo) & (X @ c <= hi)]
    # points on the interval's faces inside the ellipsoid
    for face in (lo, hi):
        Y = _points(rng, xhat, P, rho, 20000)
        Y += np.outer(face - Y @ c, c) / float(c @ c)  # moved along c onto the face cᵀx = face
        inside = np.einsum("ij,jk,ik->i", Y - xhat, np.linalg.inv(rho * P), Y - xhat) <= 1.0
        X = np.vstack([X, Y[inside]])
    E = np.einsum("ij,jk,ik->i", X - centre, np.linalg.inv(P_new), X - centre)
    assert E.max() <= rho * (1 + 1e-9)
    new_half = np.sqrt(rho * c @ P_new @ c)
    assert new_half < half
    slack = 1e-8 * half  # the certificate's relative widening
    assert c @ centre - new_half >= xc - half - slack and c @ centre + new_half <= xc + half + slack


def test_an_interval_that_does_not_cut_leaves_the_set_alone() -> None:
    P, xhat = np.diag([1.0, 2.0, 0.5]), np.array([0.1, -0.2, 0.3])
    half, e3 = np.sqrt(0.5), np.array([0.0, 0.0, 1.0])
    assert cut(xhat, P, 1.0, Slab(e3, xhat[2] - 2 * half, xhat[2] + 2 * half), None) is None  # wider than the set
    assert cut(xhat, P, 1.0, Slab(e3, xhat[2] + 2 * half, xhat[2] + 3 * half), None) is None  # disjoint: not a cut
    assert cut(xhat, P, 1.0, Slab(e3, -np.inf, np.inf), None) is None
