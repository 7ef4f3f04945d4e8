"""numpy.linalg's small dense routines without their per-call set-up: the same LAPACK gufuncs, so the same floats.

At the estimator's sizes (2×2 to 6×6) ``np.linalg.cholesky``, ``solve``, ``inv``, ``eigvalsh`` and ``eigh`` spend
more time checking and converting their arguments than in LAPACK; a step makes about eight such calls.  These call
the very gufuncs numpy.linalg calls (``numpy.linalg._umath_linalg``, numpy's own build), on one float64 matrix, and
raise :class:`numpy.linalg.LinAlgError` where numpy.linalg does.  A routine that fails fills its whole output with
NaN (that is how numpy.linalg's own error check learns of it), so the failure is read off the output's first entry;
on a non-finite input, whose output starts with NaN too, these raise where numpy.linalg returns the NaN (every
caller treats LinAlgError as no answer).  tests/unit/test_linalg.py holds each to numpy.linalg, bit for bit and
error for error, on finite inputs: on any CPU, since it is the same LAPACK call, run by whichever OpenBLAS kernel the
CPU gets (which floats that gives differs between kernels in the last bits; that both agree does not).

:func:`covering_factor` is the one routine of its own: a Cholesky factor widened by a stated rounding bound, so that
the map it gives covers the whole ellipsoid a certificate is proven over.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.linalg import LinAlgError
from numpy.linalg import _umath_linalg as _lapack  # numpy.linalg's own gufuncs (a private module of numpy's)

U = 2.0**-53  # the unit roundoff of float64


def _square(a: np.ndarray) -> np.ndarray:
    """``a`` as a float64 square matrix (LinAlgError otherwise, as numpy.linalg's check)."""
    a = a if type(a) is np.ndarray and a.dtype == np.float64 else np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise LinAlgError(f"a square matrix is required, not one of shape {a.shape}")
    return a


def _run(gufunc: np.ufunc, signature: str, failure: str, *args: np.ndarray) -> np.ndarray:
    """``gufunc`` on ``args`` with LAPACK's invalid flag quiet; LinAlgError(``failure``) where its (first) output is
    NaN: the routine failed."""
    with np.errstate(all="ignore"):
        out = gufunc(*args, signature=signature)
    first = out[0] if isinstance(out, tuple) else out
    if first.size and first.flat[0] != first.flat[0]:
        raise LinAlgError(failure)
    return out


def cholesky(a: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor L of a, L Lᵀ = a (np.linalg.cholesky); LinAlgError where a is not positive definite."""
    return _run(_lapack.cholesky_lo, "d->d", "Matrix is not positive definite", _square(a))


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with a x = b (np.linalg.solve; b a vector (n,) or a matrix (n, k)); LinAlgError where a is singular."""
    b = b if type(b) is np.ndarray and b.dtype == np.float64 else np.asarray(b, dtype=np.float64)
    return _run(_lapack.solve1 if b.ndim == 1 else _lapack.solve, "dd->d", "Singular matrix", _square(a), b)


def inv(a: np.ndarray) -> np.ndarray:
    """a⁻¹ (np.linalg.inv); LinAlgError where a is singular."""
    return _run(_lapack.inv, "d->d", "Singular matrix", _square(a))


def eigvalsh(a: np.ndarray) -> np.ndarray:
    """The eigenvalues of the symmetric a, ascending, from its lower triangle (np.linalg.eigvalsh)."""
    return _run(_lapack.eigvalsh_lo, "d->d", "Eigenvalues did not converge", _square(a))


def eigh(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues (ascending) and eigenvectors (the columns) of the symmetric a, from its lower triangle
    (np.linalg.eigh)."""
    return _run(_lapack.eigh_lo, "d->dd", "Eigenvalues did not converge", _square(a))  # type: ignore[return-value]  # the gufunc's two outputs


__all__ = ["LinAlgError", "cholesky", "eigh", "eigvalsh", "inv", "solve"]


COVER_SAFETY = 2.0  # :func:`covering_factor` doubles its error bound: it covers the rounding of F, μ and e themselves
COVER_TIGHT = 1e-11  # the determinant's bound is used alone where it widens by this (relative, squared) at most
EIG_MARGIN = 16.0  # eigvalsh's error, taken as EIG_MARGIN n u ‖P‖_F (LAPACK's bound p(n) u ‖P‖₂, p(n) modest)


def covering_factor(P: np.ndarray, rho: float) -> np.ndarray:
    """M (n, n) with M Mᵀ ⪰ ρP exactly (P symmetric positive definite, as published): the map x = x̂ + M z, |z| ≤ 1,
    covers the whole set {(x − x̂)ᵀP⁻¹(x − x̂) ≤ ρ}, so a certificate proven over z holds for every point of it.

    ρ^½ times P's Cholesky factor L̂ alone can fall short of ρP by rounding: L̂ L̂ᵀ = P + ΔP with
    |ΔP| ≤ γ_{n+1} |L̂||L̂|ᵀ (Higham, Accuracy and Stability of Numerical Algorithms, Thm 10.3, for any order of the
    inner products), and the scaling rounds each entry once more. So L̂ is widened by c ≥ ρ^½:
    ‖ΔP‖₂ + the scaling's error ≤ e = (γ_{n+1} + 3u) F with F = ‖L̂‖_F² (≥ ‖ |L̂||L̂|ᵀ ‖₂); λ_min(P) ≥ λ_lo; then
    c² (P − e I) ⪰ ρP for c² ≥ ρ / (1 − e / λ_lo), taken with COVER_SAFETY in e and the scalar rounded up.
    λ_lo = Π L̂_ii² / F^{n−1} − γ_{n+1} F (det = Π λ ≤ λ_min λ_max^{n−1}, then Weyl), or, where that widens by
    more than COVER_TIGHT, eigvalsh's smallest less its error bound, if larger. c/ρ^½ − 1: median 4·10⁻¹³, at most 2·10⁻¹⁰ over
    the paper runs' steps (40 steps of paper6 NSNIM, paper6_max_faulty and paper6_reference SAIM, worst-case signals).
    LinAlgError where P is not positive definite or too ill-conditioned for either bound."""
    L = cholesky(0.5 * (P + P.T))  # L̂ L̂ᵀ = P + ΔP (P symmetric: the symmetrisation is exact)
    rows = L.tolist()
    n = len(rows)
    gamma = (n + 1) * U / (1.0 - (n + 1) * U)  # γ_{n+1}
    F = sum(v * v for row in rows for v in row)  # ‖L̂‖_F²
    det = math.prod(rows[i][i] for i in range(n)) ** 2  # det(L̂ L̂ᵀ)
    e = COVER_SAFETY * (gamma + 3.0 * U) * F
    lam_lo = det / F ** (n - 1) - gamma * F
    if not e < COVER_TIGHT * lam_lo:  # (the determinant's bound is loose where two axes are short)
        lam_lo = max(lam_lo, float(eigvalsh(P)[0]) - EIG_MARGIN * n * U * math.sqrt(sum(v * v for v in P.flat)) - gamma * F)
        if not e < 0.5 * lam_lo:
            raise LinAlgError("the shape is too ill-conditioned to cover it with its Cholesky factor")
    c = math.sqrt(rho / (1.0 - e / lam_lo)) * (1.0 + 4.0 * U)  # (the division, root and product round by 2.5u at most)
    return c * L
