"""What every command module of :mod:`workbench.cli` shares.

Kept free of heavy imports: the parsers are built from this module at every start.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Iterable

__all__ = ["EPILOG", "prepare_output", "positive_int", "nonnegative_int", "finite_float"]

#: Epilog of every command's ``--help``.
EPILOG = "Units are SI (m, Pa absolute, kg, s, V) unless an option says otherwise."


def prepare_output(out: str | os.PathLike, files: Iterable[str],
                   inputs: Iterable[str | os.PathLike | None] = (), *,
                   option: str = "--out") -> Path:
    """Validate an output folder before any computation and return it.

    Refused (:class:`~workbench.errors.InputError` naming ``option``): an empty name, an
    existing file, a path under a file, a folder that cannot be written, and a result
    file (``files``, names inside the folder) that would overwrite one of ``inputs``.
    """
    from ..output import check_not_input, check_output_dir
    path = check_output_dir(out, option=option)
    check_not_input([path / f for f in files], inputs)
    return path


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def finite_float(text: str) -> float:
    """argparse type: a finite number (no nan, no inf)."""
    import math
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value
