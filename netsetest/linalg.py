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
