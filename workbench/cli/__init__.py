"""Command line: ``workbench COMMAND ...`` (also ``python -m workbench``).

One module per command group, each with ``register(subparsers) -> None`` that adds its
parser(s) and sets the handler (``func``); the handlers only call the library:

* :mod:`.plant` -- ``check``, ``linearize``;
* :mod:`.simulate` -- ``simulate`` (:func:`workbench.replay.replay`);
* :mod:`.stability` -- ``limits``, ``map``;
* :mod:`.identify` -- ``identify arx|rls|valve|valve-table|greybox``;
* :mod:`.diagnose` -- ``diagnose``;
* :mod:`.robustness` -- ``robustness``;
* :mod:`.bench` -- ``bench`` (:mod:`workbench.bench`).

Every error a user can cause (a bad file, a bad argument) is reported in one readable
line, exit 2. A command module that fails to import is a :class:`CommandModuleError`
(exit 1, its traceback in the message), never a silently missing command.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import traceback
from typing import Sequence

from ..errors import WorkbenchError

__all__ = ["main", "build_parser", "CommandModuleError", "COMMAND_GROUPS"]

#: Command-group modules of this package, in the order ``--help`` lists them.
COMMAND_GROUPS = ("plant", "simulate", "stability", "identify", "diagnose", "robustness",
                  "design", "bench")

#: Exit code of a broken installation (a command module that cannot be loaded).
EXIT_BROKEN = 1


class CommandModuleError(WorkbenchError):
    """A command module of :mod:`workbench.cli` failed to import or to register."""


def _register(group: str, subparsers) -> None:
    """Import ``workbench.cli.<group>`` and call its ``register(subparsers)``.

    Any failure (import, missing ``register``, an error while registering) is a
    :class:`CommandModuleError` naming the module, with the traceback in the message.
    """
    module_name = f"{__name__}.{group}"
    try:
        importlib.import_module(module_name).register(subparsers)
    except Exception as exc:            # any failure: a broken module, not a missing command
        from ..output import reraise_interrupt
        reraise_interrupt(exc)          # numpy turns a Ctrl-C in its import into ImportError
        cause = "".join(traceback.format_exception(exc)).rstrip()
        raise CommandModuleError(f"the command module {module_name} cannot be loaded "
                                 f"({type(exc).__name__}: {exc}); its commands are "
                                 f"unavailable. Cause:\n{cause}") from exc


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``workbench`` (also used by the tests to check ``--help``).

    Raises
    ------
    CommandModuleError
        A command module failed to import (the message holds the traceback).
    """
    from .. import __version__
    from .common import EPILOG
    p = argparse.ArgumentParser(
        prog="workbench",
        description="Design and validation workbench for electropneumatic servodrives.",
        epilog=EPILOG)
    p.add_argument("--version", action="version", version=f"workbench {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for group in COMMAND_GROUPS:
        _register(group, sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``workbench`` with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    0 success, 2 an error the user can fix (one line on stderr), 1 a broken command
    module, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM). An interrupted or
    terminated command that writes through :func:`workbench.output.result_set` writes
    nothing (its result set is never moved into place), also when the signal arrived
    inside C code that reported it as an ordinary failure.

    Called as the program (``argv`` None), a stopped run ends the process at once with
    130 / 143: a Ctrl-C that hit an extension module's start-up code can leave the
    interpreter set to re-raise SIGINT at exit (exit status -2 instead of 130).
    """
    try:
        code = _main(argv)
    except KeyboardInterrupt:           # before the signal handlers were installed
        print("workbench: interrupted (Ctrl-C)", file=sys.stderr)
        code = 130
    if argv is None and code in (130, 143):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _main(argv: Sequence[str] | None) -> int:
    """:func:`main` without the process exit: signals as exceptions, remembered."""
    from ..output import (EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated, interrupted,
                          stop_on_signals)
    name = "workbench"
    try:
        with stop_on_signals(sigterm=True):
            try:
                parser = build_parser()
            except CommandModuleError as exc:
                print(f"workbench: error: {exc}", file=sys.stderr)
                return EXIT_BROKEN
            try:
                _refuse_nul(sys.argv[1:] if argv is None else argv)
                args = parser.parse_args(argv)
            except SystemExit as exc:       # --help (0) or a bad argument (2, one line)
                if isinstance(exc.code, str):
                    print(exc.code, file=sys.stderr)
                return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
            name = " ".join(["workbench", args.command]
                            + ([args.method] if getattr(args, "method", None) else []))
            try:
                code = _run(args, name)
            except Exception:
                if interrupted() is None:        # a bug: its traceback is the report
                    raise
                code = None                      # e.g. SystemError from a C call it hit
            if interrupted() is not None:        # swallowed by C code, surfaced here
                raise Terminated() if interrupted() == signal.SIGTERM else KeyboardInterrupt()
            return code
    except KeyboardInterrupt:
        print(f"{name}: interrupted (Ctrl-C)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        print(f"{name}: terminated (SIGTERM)", file=sys.stderr)
        return EXIT_TERMINATED


def _run(args: argparse.Namespace, name: str) -> int:
    """Call the command's handler; a user's error is one line on stderr, exit 2; an
    :class:`~workbench.errors.InputWarning` (part of an input left out) one line
    ``NAME: warning: ...``, every time it occurs (each names its own file)."""
    import warnings

    from ..errors import InputWarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, InputWarning):
            print(f"{name}: warning: {message}", file=sys.stderr, flush=True)
        else:
            shown(message, category, filename, lineno, file, line)

    try:
        with warnings.catch_warnings():
            shown = warnings.showwarning
            warnings.simplefilter("always", InputWarning)
            warnings.showwarning = show
            return int(args.func(args) or 0)
    except WorkbenchError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:          # output piped into e.g. `head`: not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:           # a full disk, a vanished folder: no traceback
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"{name}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except UnicodeDecodeError as exc:  # a loader that read text without saying which file
        print(f"{name}: error: {_undecodable(args) or 'an input file'} is not UTF-8 text "
              f"(byte 0x{exc.object[exc.start]:02x} at offset {exc.start}); save it as "
              f"UTF-8", file=sys.stderr)
        return 2


def _undecodable(args: argparse.Namespace) -> str | None:
    """The first file named in ``args`` that is not UTF-8 text, or None."""
    values = []
    for v in vars(args).values():
        values += v if isinstance(v, list) else [v]
    for v in values:
        if isinstance(v, str) and os.path.isfile(v):
            try:
                with open(v, encoding="utf-8") as fh:
                    while fh.read(1 << 20):
                        pass
            except UnicodeDecodeError:
                return v
            except OSError:
                continue
    return None


def _refuse_nul(argv: Sequence[str]) -> None:
    """A NUL character cannot be in a file name or a number: refuse it up front."""
    for a in argv:
        if "\x00" in a:
            raise SystemExit(f"workbench: error: argument {a!r} contains a NUL character")
