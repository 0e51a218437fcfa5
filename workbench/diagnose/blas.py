"""One BLAS thread while a diagnosis runs (its parallelism is its worker processes).

The refits hand scipy's least squares residual vectors of 10^4 - 10^5 elements; on
them a multi-threaded OpenBLAS costs far more than it saves: measured on the 2-core
machine under load, 1000 norms and J'r products of an 18 000-element residual took
0.57 CPU s with OpenBLAS's default threads and 0.010 s with one, and the whole
single-effect diagnosis of ``workbench bench diagnose`` 23.0 CPU s against 15.1 with
the same findings to the last digit (two worker processes, each spinning up BLAS
threads, oversubscribe two cores). :func:`single_thread` sets the thread count of the
OpenBLAS libraries numpy and scipy ship (the way threadpoolctl does, by their
exported ``*_set_num_threads`` functions) and puts it back afterwards; where there
is no such library (another BLAS, another platform) it does nothing.
"""

from __future__ import annotations

import ctypes
import glob
import os
from contextlib import contextmanager
from typing import Iterator

__all__ = ["single_thread"]


def _libraries() -> list[tuple[ctypes.CDLL, str]]:
    """(library, symbol prefix) of each OpenBLAS shipped with numpy and scipy (already
    loaded by their import: loading them again returns the same handle)."""
    import numpy
    import scipy
    found = []
    for pkg in (numpy, scipy):
        root = os.path.dirname(os.path.dirname(pkg.__file__))
        for path in sorted(glob.glob(os.path.join(root, f"{pkg.__name__}.libs", "*openblas*"))):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for prefix in ("scipy_openblas", "openblas"):
                for suffix in ("64_", ""):
                    get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                    put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                    if get is not None and put is not None:
                        found.append((get, put))
                        break
                else:
                    continue
                break
    return found


@contextmanager
def single_thread() -> Iterator[None]:
    """Within the block, the OpenBLAS of numpy and scipy use one thread (worker
    processes forked in it inherit that); the previous counts are restored after it."""
    try:
        libs = _libraries()
        before = [int(get()) for get, _ in libs]
        for _, put in libs:
            put(1)
    except (OSError, AttributeError, ValueError):      # pragma: no cover - other BLAS
        libs, before = [], []
    try:
        yield
    finally:
        for (_, put), n in zip(libs, before):
            put(max(n, 1))
