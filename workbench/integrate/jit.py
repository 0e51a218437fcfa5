"""The one JIT cache: compile C once, keep the shared library, reuse it.

CasADi's own ``jit`` option recompiles in every process. Here generated C source
is hashed (with the compiler flags and the CasADi version) and the compiled
library kept in a cache directory (``$WORKBENCH_CACHE`` or
``~/.cache/workbench/jit``), so a second run, another worker process or a Dask
worker on the same machine loads it in milliseconds.

* :func:`compiled`: a CasADi Function as a compiled external Function; without a
  C compiler the Function is returned unchanged (the CasADi virtual machine
  evaluates it, slower but identical).
* :func:`shared_library`: any C source (e.g. the benchmark loop's driver) built
  into the same cache under the same hash scheme.
"""

from __future__ import annotations

import hashlib
import os
import shlex
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Sequence

import casadi as ca

__all__ = ["compiled", "cache_dir", "have_compiler", "c_compiler", "shared_library",
           "source_digest", "CompileError", "MINMAX", "inline_minmax"]

#: IEEE fmax / fmin (a NaN operand gives the other) as expressions the compiler inlines
MINMAX = """/* workbench: fmax / fmin inlined (IEEE semantics: a NaN operand gives the other) */
#define WB_FMAX(x, y) ((x) != (x) ? (y) : (y) != (y) ? (x) : (x) > (y) ? (x) : (y))
#define WB_FMIN(x, y) ((x) != (x) ? (y) : (y) != (y) ? (x) : (x) < (y) ? (x) : (y))
"""


def inline_minmax(src: str) -> str:
    """CasADi's generated ``casadi_fmax`` / ``casadi_fmin`` call libm's fmax / fmin, a
    function call each; the same semantics as :data:`MINMAX`, which the compiler
    inlines. Unchanged where the runtime's text differs (then only slower)."""
    out = src.replace("return fmax(x, y);", "return WB_FMAX(x, y);")
    out = out.replace("return fmin(x, y);", "return WB_FMIN(x, y);")
    return MINMAX + out if out != src else src


class CompileError(RuntimeError):
    """No C compiler, or the source did not compile."""


def cache_dir() -> Path:
    """The cache directory: ``$WORKBENCH_CACHE`` or ``~/.cache/workbench/jit``."""
    root = os.environ.get("WORKBENCH_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "workbench" / "jit"
    return path


def c_compiler() -> list[str] | None:
    """The C compiler command: ``$CC`` (split like a shell), else gcc, cc or clang."""
    cc = os.environ.get("CC")
    if cc:
        return shlex.split(cc)
    for name in ("gcc", "cc", "clang"):
        path = shutil.which(name)
        if path:
            return [path]
    return None


def have_compiler() -> bool:
    """Whether :func:`c_compiler` finds a compiler on the PATH."""
    cc = c_compiler()
    return cc is not None and shutil.which(cc[0]) is not None


def source_digest(source: bytes, flags: Sequence[str]) -> str:
    """The cache key of a C source built with ``flags``: 20 hex digits of SHA-256."""
    return hashlib.sha256(source + " ".join(flags).encode()
                          + ca.__version__.encode()).hexdigest()[:20]


def shared_library(name: str, source: str | bytes,
                   flag_sets: Sequence[Sequence[str]] = (("-O2",),),
                   libs: Sequence[str] = ()) -> tuple[Path, bool]:
    """Build C ``source`` into ``cache_dir()/{name}_{digest}.so`` unless it is there.

    Parameters
    ----------
    name : stem of the library file.
    source : the C source.
    flag_sets : compiler flag sets, tried in turn until one compiles (the first one
        names the cache entry); ``-shared -fPIC`` and ``-lm`` are always added.
    libs : libraries (paths of static archives, or ``-l`` flags) linked after the
        source, in this order; part of the cache key.

    Returns
    -------
    (path of the library, whether it was already in the cache)

    Raises
    ------
    CompileError
        No C compiler, or no flag set compiled the source.
    """
    src = source.encode() if isinstance(source, str) else source
    target_dir = cache_dir()
    target = target_dir / f"{name}_{source_digest(src, [*flag_sets[0], *libs])}.so"
    if target.exists():
        return target, True
    cc = c_compiler()
    if cc is None:
        raise CompileError("no C compiler found (set CC)")
    target_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="wb_jit_") as tmp:
        c_file, partial = Path(tmp, f"{name}.c"), Path(tmp, "out.so")
        c_file.write_bytes(src)
        err = "?"
        for flags in flag_sets:
            cmd = [*cc, "-shared", "-fPIC", *flags, "-o", str(partial), str(c_file), *libs, "-lm"]
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True)
            except OSError as exc:
                raise CompileError(f"the C compiler failed: {exc}") from None
            if proc.returncode == 0:
                break
            err = (proc.stderr.strip().splitlines() or ["?"])[-1]
        else:
            raise CompileError(f"{name}: the C source did not compile: {err}")
        # atomic publish: another process may race us to the same file
        fd, staged = tempfile.mkstemp(dir=target_dir, suffix=".so.part")
        os.close(fd)
        shutil.copyfile(partial, staged)
        os.replace(staged, target)
    return target, False


def compiled(fun: ca.Function, flags: tuple[str, ...] = ("-O2",)) -> ca.Function:
    """``fun`` as a compiled external Function (cached by source hash).

    Parameters
    ----------
    fun : a CasADi Function that supports code generation (SX or MX without
        non-generatable nodes).
    flags : C compiler optimisation flags.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x")
    >>> f = compiled(ca.Function("sq", [x], [x * x]))
    >>> float(f(3.0))
    9.0
    """
    if not have_compiler():
        return fun
    with tempfile.TemporaryDirectory(prefix="wb_jit_") as tmp:
        src_name = f"{fun.name()}.c"
        # CodeGenerator writes under a path prefix: no chdir, so threads may compile
        # at the same time
        gen = ca.CodeGenerator(src_name, {"with_header": False})
        gen.add(fun)
        gen.generate(tmp + os.sep)
        source = Path(tmp, src_name).read_bytes()
    try:
        target, _ = shared_library(fun.name(), source, (tuple(flags),))
    except CompileError:
        return fun          # keep working on the virtual machine
    return ca.external(fun.name(), str(target))
