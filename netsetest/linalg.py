"""numpy.linalg's small dense routines without their per-call set-up: the same LAPACK gufuncs, so the same floats.

At the estimator's sizes (2×2 to 6×6) ``np.linalg.cholesky``, ``solve``, ``inv``, ``eigvalsh`` and ``eigh`` spend
more time checking and converting their arguments than in LAPACK; a step makes about eight such calls.  These call
the very gufuncs numpy.linalg calls (``numpy.linalg._umath_linalg``, numpy's own build), on one float64 matrix, and
raise :class:`numpy.linalg.LinAlgError` where numpy.linalg does.  A routine that fails fills its whole output with
NaN (that is how numpy.linalg's own error check learns of it), so the failure is read off the output's first entry;
on a non-finite input, whose output starts with NaN too, these raise where numpy.linalg returns the NaN (every
caller treats LinAlgError as no answer).  tests/unit/test_linalg.py holds each to numpy.linalg, bit for bit and
error for error, on finite inputs.
"""

from __future__ import annotations

import numpy as np
from numpy.linalg import LinAlgError
from numpy.linalg import _umath_linalg as _lapack  # numpy.linalg's own gufuncs (a private module of numpy's)


def _square(a: np.ndarray) -> np.ndarray:
    """``a`` as a float64 square matrix (LinAlgError otherwise, as numpy.linalg's check)."""
    a = a if type(a) is np.ndarray and a.dtype == np.float64 else np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise LinAlgError(f"a square matrix is required, not one of shape {a.shape}")
    return a


def cholesky(a: np.ndarray) -> np.ndarray:
    """The lower Cholesky factor L of a, L Lᵀ = a (np.linalg.cholesky); LinAlgError where a is not positive definite."""
    a = _square(a)
    with np.errstate(all="ignore"):
        r = _lapack.cholesky_lo(a, signature="d->d")
    if r.size and r[0, 0] != r[0, 0]:
        raise LinAlgError("Matrix is not positive definite")
    return r


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with a x = b (np.linalg.solve; b a vector (n,) or a matrix (n, k)); LinAlgError where a is singular."""
    a = _square(a)
    b = b if type(b) is np.ndarray and b.dtype == np.float64 else np.asarray(b, dtype=np.float64)
    with np.errstate(all="ignore"):
        x = _lapack.solve1(a, b, signature="dd->d") if b.ndim == 1 else _lapack.solve(a, b, signature="dd->d")
    if x.size and x.flat[0] != x.flat[0]:
        raise LinAlgError("Singular matrix")
    return x


def inv(a: np.ndarray) -> np.ndarray:
    """a⁻¹ (np.linalg.inv); LinAlgError where a is singular."""
    a = _square(a)
    with np.errstate(all="ignore"):
        r = _lapack.inv(a, signature="d->d")
    if r.size and r[0, 0] != r[0, 0]:
        raise LinAlgError("Singular matrix")
    return r


def eigvalsh(a: np.ndarray) -> np.ndarray:
    """The eigenvalues of the symmetric a, ascending, from its lower triangle (np.linalg.eigvalsh)."""
    a = _square(a)
    with np.errstate(all="ignore"):
        w = _lapack.eigvalsh_lo(a, signature="d->d")
    if w.size and w[0] != w[0]:
        raise LinAlgError("Eigenvalues did not converge")
    return w


def eigh(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues (ascending) and eigenvectors (the columns) of the symmetric a, from its lower triangle
    (np.linalg.eigh)."""
    a = _square(a)
    with np.errstate(all="ignore"):
        w, v = _lapack.eigh_lo(a, signature="d->dd")
    if w.size and w[0] != w[0]:
        raise LinAlgError("Eigenvalues did not converge")
    return w, v


__all__ = ["LinAlgError", "cholesky", "eigh", "eigvalsh", "inv", "solve"]
