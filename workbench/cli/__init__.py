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

    0 success, 2 an error the user can fix (message on stderr), 1 a broken command
    module, 130 interrupted.
    """
    try:
        parser = build_parser()
    except CommandModuleError as exc:
        print(f"workbench: error: {exc}", file=sys.stderr)
        return EXIT_BROKEN
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WorkbenchError as exc:
        print(f"workbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:          # output piped into e.g. `head`: not an error
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
