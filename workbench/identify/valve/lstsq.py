"""Small dense least squares with OpenBLAS held single-threaded (fast on a busy machine)."""

from __future__ import annotations

import os
from contextlib import contextmanager

import numpy as np

__all__ = ["serial_blas", "lstsq", "lstsq_equality", "constraint_rank"]


def _openblas_local_setters() -> list:
    """``openblas_set_num_threads_local`` of the OpenBLAS copies numpy and scipy load."""
    import ctypes
    import glob
    found = []
    for pkg in (np, __import__("scipy")):
        base = os.path.dirname(os.path.dirname(pkg.__file__))
        name = pkg.__name__
        for lib in glob.glob(os.path.join(base, f"{name}.libs", "*openblas*.so*")):
            try:
                fn = ctypes.CDLL(lib).openblas_set_num_threads_local
            except (OSError, AttributeError):
                continue
            fn.argtypes, fn.restype = [ctypes.c_int], ctypes.c_int
            found.append(fn)
    return found


_BLAS_SETTERS: list | None = None


@contextmanager
def serial_blas():
    """Run OpenBLAS single-threaded in this thread for the block (restored afterwards).

    The least-squares problems here are a few hundred by a few dozen: OpenBLAS's
    worker threads only add synchronisation, and on a loaded machine (more runnable
    processes than cores) they make one such solve 10 to 100 times slower. A no-op
    where the thread-local setter is not available.
    """
    global _BLAS_SETTERS
    if _BLAS_SETTERS is None:
        _BLAS_SETTERS = _openblas_local_setters()
    previous = [fn(1) for fn in _BLAS_SETTERS]
    try:
        yield
    finally:
        for fn, n in zip(_BLAS_SETTERS, previous):
            fn(n)


def lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    with serial_blas():
        sol, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
    return sol / scale


def lstsq_equality(A: np.ndarray, y: np.ndarray, C: np.ndarray) -> np.ndarray:
    """min |A c - y| subject to C c = 0, by the null space of C (columns scaled first).

    ``C`` must have full row rank (checked by the caller: it raises a clear error when
    the constraints are redundant or contradict each other).
    """
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    Cs = C / scale
    with serial_blas():
        q, _ = np.linalg.qr(Cs.T, mode="complete")
        null = q[:, C.shape[0]:]
        z, *_ = np.linalg.lstsq((A / scale) @ null, y, rcond=None)
    return (null @ z) / scale


def constraint_rank(C: np.ndarray) -> int:
    """Numerical row rank of a constraint matrix (columns scaled to unit norm)."""
    scale = np.linalg.norm(C, axis=0)
    scale[scale == 0.0] = 1.0
    with serial_blas():
        return int(np.linalg.matrix_rank(C / scale, tol=1e-10 * max(C.shape)))
