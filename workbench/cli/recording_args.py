"""The recording options every command that reads recordings shares.

``--columns x=pos_mm:mm,t=time_ms:ms`` maps a logger's columns (and units) onto the
workbench's, ``--window T0:T1`` keeps a time window; both go to
:func:`workbench.recording.load_recording`, which also checks the recording's
plausibility (and, given the plant, the stroke and the valve's command range).
"""

from __future__ import annotations

import argparse
import math
from typing import Any

__all__ = ["add_recording_options", "load_from_args", "parse_window"]


def parse_window(text: str) -> tuple[float | None, float | None]:
    """``"T0:T1"`` (s; either side may be empty) -> ``(t0, t1)`` for argparse."""
    lo, colon, hi = str(text).partition(":")
    if not colon:
        raise argparse.ArgumentTypeError(f"expected T0:T1 in s (e.g. 2:10 or 5:), got {text!r}")
    out = []
    for part in (lo, hi):
        part = part.strip()
        if not part:
            out.append(None)
            continue
        try:
            value = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{part!r} is not a time in s") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{part!r} is not a finite time in s")
        out.append(value)
    if out[0] is not None and out[1] is not None and out[0] >= out[1]:
        raise argparse.ArgumentTypeError(f"the window {text!r} is empty: T0 < T1 is needed")
    return out[0], out[1]


def add_recording_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--columns`` and ``--window`` to a sub-command that reads recordings."""
    parser.add_argument(
        "--columns", metavar="MAP",
        help="map the file's columns onto t, u, x, p_a, ... with optional units, e.g. "
             "x=pos_mm:mm,t=time_ms:ms,u=cmd (units also from a '# units: x=mm' line or "
             "header cells like 'x [mm]'; converted to SI)")
    parser.add_argument(
        "--window", metavar="T0:T1", type=parse_window,
        help="use only the samples with T0 <= t <= T1, s (either side may be empty)")


def load_from_args(args: argparse.Namespace, path: Any, *, plant: Any = None,
                   required: tuple[str, ...] | None = None):
    """Load ``path`` with the sub-command's ``--columns`` and ``--window``.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments (``columns``, ``window`` are read when present).
    path : str or path-like
        The recording.
    plant : Plant or PlantParams, optional
        Check the position against the stroke and the command against the valve range.
    required : tuple of str, optional
        Columns the command needs (default ``t``, ``u``, ``x``).

    Returns
    -------
    Recording
    """
    from ..recording import load_recording
    return load_recording(path, columns=getattr(args, "columns", None),
                          window=getattr(args, "window", None), plant=plant,
                          required=required)
