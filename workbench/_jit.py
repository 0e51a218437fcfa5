"""Re-export of :mod:`workbench.integrate.jit` (the one JIT cache), for old imports."""

from .integrate.jit import cache_dir, compiled, have_compiler

__all__ = ["compiled", "cache_dir", "have_compiler"]
