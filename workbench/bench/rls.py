"""``workbench bench rls``: compiled RLS over 10^6 samples against a numpy per-sample loop.

Temporary: re-exports :func:`workbench.identify.rls.bench` until the benchmark itself
moves here (the identify re-layout replaces this module).
"""

from __future__ import annotations

from ..identify.rls import bench

__all__ = ["bench"]
