"""Result sets written whole or not at all, inputs never overwritten, SIGTERM as a stop.

Every command that writes more than one file writes them through :func:`result_set`:
the files are made in a hidden staging folder beside the output folder and moved into
place only when the whole computation has succeeded. A failure, Ctrl-C or SIGTERM
leaves the output folder exactly as it was (no new file, no half-written file).

>>> import tempfile, pathlib
>>> out = pathlib.Path(tempfile.mkdtemp()) / "run"
>>> with result_set(out) as stage:
...     _ = (stage / "a.txt").write_text("1")
...     _ = (stage / "b.txt").write_text("2")
>>> sorted(p.name for p in out.iterdir())
['a.txt', 'b.txt']
>>> try:
...     with result_set(out) as stage:
...         _ = (stage / "a.txt").write_text("changed")
...         raise RuntimeError("the computation failed")
... except RuntimeError:
...     pass
>>> (out / "a.txt").read_text()
'1'
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
import threading
from pathlib import Path
from typing import Iterable, Iterator

from .errors import InputError

__all__ = ["result_set", "check_output_dir", "check_not_input", "stop_workers", "Terminated",
           "sigterm_as_exception", "stop_on_signals", "interrupted", "reraise_interrupt",
           "write_json", "strict_json", "EXIT_INTERRUPTED", "EXIT_TERMINATED"]

#: Exit status after Ctrl-C (128 + SIGINT).
EXIT_INTERRUPTED = 130
#: Exit status after SIGTERM (128 + SIGTERM).
EXIT_TERMINATED = 143


class Terminated(BaseException):
    """SIGTERM arrived. A ``BaseException`` like ``KeyboardInterrupt``, so that no
    ``except Exception`` on the way can mistake it for a failed computation."""


def check_output_dir(out: str | os.PathLike, *, option: str = "--out") -> Path:
    """Validate an output folder *before* any computation; return it as a Path.

    Refused: an empty name, an existing non-folder, a path under an existing file, a
    folder (or its nearest existing parent) that is not writable.

    Raises
    ------
    InputError
        Naming the option and the reason.
    """
    text = os.fspath(out)
    if not str(text).strip():
        raise InputError(f"{option} must name a folder, got an empty string")
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise InputError(f"{option} {text} exists and is not a folder")
    parent = path
    while not parent.exists():
        if parent.parent == parent:
            break
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{option} {text} lies under {parent}, which is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{option} {text}: cannot write in {parent} (permission denied)")
    try:                        # the real test (root, ACLs, read-only mounts, full quota)
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise InputError(f"{option} {text}: cannot write in {parent} "
                         f"({exc.strerror or exc})") from None
    return path


def check_not_input(outputs: Iterable[str | os.PathLike],
                    inputs: Iterable[str | os.PathLike | None]) -> None:
    """Refuse to write any of ``outputs`` over one of ``inputs`` (paths compared resolved).

    Raises
    ------
    InputError
        Naming the file that would be overwritten.
    """
    ins = {}
    for p in inputs:
        if p is None:
            continue
        try:
            ins[Path(p).resolve()] = p
        except OSError:
            continue
    for o in outputs:
        try:
            r = Path(o).resolve()
        except OSError:
            continue
        if r in ins:
            raise InputError(f"the output {o} would overwrite the input {ins[r]}; choose "
                             f"another --out folder")


@contextlib.contextmanager
def result_set(out: str | os.PathLike, *,
               inputs: Iterable[str | os.PathLike | None] = ()) -> Iterator[Path]:
    """Stage a set of output files and move them into ``out`` only on success.

    Parameters
    ----------
    out : path-like
        The output folder (created on success if missing; existing files of the same
        names are replaced, other files in it are left alone).
    inputs : iterable of path-like
        Files the command read: writing a staged file over one of them is refused
        (:class:`~workbench.errors.InputError`), before anything is moved.

    Yields
    ------
    pathlib.Path
        The staging folder: write every result file there (sub-folders allowed).

    Notes
    -----
    The staging folder is a hidden sibling of ``out`` on the same file system, so the
    final moves are renames. If ``out`` does not exist, the whole staging folder is
    renamed into place in one step; otherwise each file is renamed over its old
    version. On any exception (including ``KeyboardInterrupt`` and :class:`Terminated`)
    the staging folder is removed and ``out`` is untouched.
    """
    out = check_output_dir(out)
    out_abs = out.resolve()
    parent = out_abs.parent
    parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out_abs.name}.partial-", dir=parent))
    try:
        yield stage
        reraise_interrupt()             # a stop swallowed by C code: commit nothing
        files = [p for p in stage.rglob("*") if p.is_file()]
        check_not_input([out_abs / p.relative_to(stage) for p in files], inputs)
        if not out_abs.exists():
            os.chmod(stage, 0o777 & ~_umask())
            os.rename(stage, out_abs)
            return
        for p in sorted(files):
            target = out_abs / p.relative_to(stage)
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(p, target)
    finally:
        if stage.exists():
            shutil.rmtree(stage, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ---------------------------------------------------------------------- signals
#: Signals received while :func:`stop_on_signals` is active (cleared on entering it).
_RECEIVED: list[int] = []
#: Nesting depth of :func:`stop_on_signals` (the handlers are installed once, outermost).
_DEPTH = [0]


def _signal_exception(signum: int) -> BaseException:
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _handler(signum, frame):  # noqa: ARG001 - signal handler signature
    _RECEIVED.append(signum)
    raise _signal_exception(signum)


@contextlib.contextmanager
def stop_on_signals(*, sigterm: bool = False) -> Iterator[None]:
    """Within the block, Ctrl-C (SIGINT) raises ``KeyboardInterrupt`` (and SIGTERM
    :class:`Terminated` if ``sigterm``) in the main thread, and the signal is
    *remembered*.

    C code that polls for signals (CasADi's CVODES, IDAS and IPOPT interfaces) turns
    the Python exception into its own error: a ``RuntimeError`` such as
    ``CVode returned "CV_RHSFUNC_FAIL"``, or an optimiser that just stops. The memory
    lets :func:`reraise_interrupt` and :func:`result_set` recover the stop, so that an
    interrupted computation is never taken for a failed one. Nested blocks share the
    outermost one's handlers; outside the main thread the block changes nothing. Only
    Python's own dispositions are replaced: SIGINT's ``default_int_handler`` and, with
    ``sigterm`` (the command line), SIGTERM's default. A signal that is ignored (a
    background job of a non-interactive shell) or that the application handles itself
    is left alone; so is SIGTERM in library calls (it still ends the process).
    """
    if threading.current_thread() is not threading.main_thread():
        yield                       # signals reach the main thread only
        return
    if _DEPTH[0] > 0:
        _DEPTH[0] += 1
        try:
            yield
        finally:
            _DEPTH[0] -= 1
        return
    _RECEIVED.clear()
    old = {}
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        old[signal.SIGINT] = signal.signal(signal.SIGINT, _handler)
    if sigterm and signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
        old[signal.SIGTERM] = signal.signal(signal.SIGTERM, _handler)
    _DEPTH[0] += 1
    try:
        yield
    finally:
        _DEPTH[0] -= 1
        for sig, h in old.items():
            signal.signal(sig, h)
        _RECEIVED.clear()           # outside a block nothing is remembered


def interrupted() -> int | None:
    """The signal (``signal.SIGINT`` or ``SIGTERM``) received within the current
    :func:`stop_on_signals` block, or None (always None outside a block)."""
    return _RECEIVED[0] if _RECEIVED and _DEPTH[0] > 0 else None


def reraise_interrupt(exc: BaseException | None = None) -> None:
    """Raise ``KeyboardInterrupt`` / :class:`Terminated` if a stop signal arrived.

    Call it first in every ``except`` clause that catches errors of a CasADi call (or
    any broad ``except Exception``): a Ctrl-C polled by CasADi comes back as an
    ordinary error, which must not be handled as a failed integration, a failed
    design or a reason to fall back to another method. Returns normally (and the
    caller handles ``exc``) when no signal arrived.

    >>> try:
    ...     raise RuntimeError("CVode returned CV_RHSFUNC_FAIL")
    ... except RuntimeError as exc:
    ...     reraise_interrupt(exc)          # no signal: nothing happens
    ...     handled = True
    >>> handled
    True
    """
    sig = interrupted()
    if sig is not None:
        raise _signal_exception(sig) from exc


@contextlib.contextmanager
def sigterm_as_exception() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (and Ctrl-C
    ``KeyboardInterrupt``), both remembered: :func:`stop_on_signals`."""
    with stop_on_signals(sigterm=True):
        yield


def write_json(path: str | os.PathLike, value, *, indent: int | None = 2,
               default=None) -> None:
    """Write ``value`` as strict JSON: NaN and inf become null (JSON has no such
    tokens; strict readers reject them), numpy scalars and arrays plain numbers/lists.

    The file is written whole or not at all (a temporary file renamed into place).
    ``default`` is passed to :func:`json.dumps` for objects JSON does not know.
    """
    import json
    from .params import atomic_write_text
    atomic_write_text(path, json.dumps(strict_json(value), indent=indent, allow_nan=False,
                                       default=default) + "\n")


def strict_json(value):
    """``value`` with non-finite floats as None and numpy values as Python ones, recursively."""
    import math
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return strict_json(value.tolist())          # numpy scalar or array
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def stop_workers(ex) -> None:
    """End the jobs of a :class:`concurrent.futures.ProcessPoolExecutor` ``ex`` now:
    queued ones cancelled, running workers killed and reaped.

    For a signal (Ctrl-C, a SIGTERM sent to the main process alone) or an error in the
    main process: leaving the executor's ``with`` block, or ``shutdown(wait=True)``,
    would wait for every running job to end (a diagnosis's refits: 8-17 s measured in
    session 9, minutes on a loaded machine) before the exit. The workbench's workers
    hold nothing to clean up (results come back through the executor's queue; the only
    file they write, the JIT cache, is compiled in a temporary folder and renamed into
    place), so SIGKILL is safe and, unlike SIGTERM, cannot be delayed by a long call in
    compiled code. ``_processes`` is the executor's own table of its workers (CPython;
    empty if that changes, and then only the queued jobs are cancelled)."""
    procs = list((getattr(ex, "_processes", None) or {}).values())
    ex.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.kill()
    for proc in procs:
        proc.join(timeout=5.0)
