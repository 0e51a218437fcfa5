"""Compile CasADi Functions to C once and reuse the shared library.

CasADi's own ``jit`` option recompiles in every process. Here the generated C
source is hashed and the compiled library kept in a cache directory
(``$WORKBENCH_CACHE`` or ``~/.cache/workbench/jit``), so a second run, another
worker process or a Dask worker on the same machine loads it in milliseconds.
Without a C compiler the function is returned unchanged (the CasADi virtual
machine evaluates it, slower but identical).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

__all__ = ["compiled", "cache_dir", "have_compiler"]


def cache_dir() -> Path:
    root = os.environ.get("WORKBENCH_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "workbench" / "jit"
    return path


def have_compiler() -> bool:
    return shutil.which(os.environ.get("CC", "gcc")) is not None


def compiled(fun: ca.Function, flags: tuple[str, ...] = ("-O2",)) -> ca.Function:
    """``fun`` as a compiled external Function (cached by source hash).

    Parameters
    ----------
    fun : a CasADi Function that supports code generation (SX or MX without
        non-generatable nodes).
    flags : C compiler optimisation flags.
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
        digest = hashlib.sha256(source + " ".join(flags).encode()
                                + ca.__version__.encode()).hexdigest()[:20]
        target_dir = cache_dir()
        target = target_dir / f"{fun.name()}_{digest}.so"
        if not target.exists():
            target_dir.mkdir(parents=True, exist_ok=True)
            partial = Path(tmp, "out.so")
            cc = os.environ.get("CC", "gcc")
            cmd = [cc, "-shared", "-fPIC", *flags, "-o", str(partial), str(Path(tmp, src_name)), "-lm"]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                return fun          # keep working on the virtual machine
            # atomic publish: another process may race us to the same file
            fd, staged = tempfile.mkstemp(dir=target_dir, suffix=".so.part")
            os.close(fd)
            shutil.copyfile(partial, staged)
            os.replace(staged, target)
    return ca.external(fun.name(), str(target))
