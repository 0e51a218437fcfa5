"""Running a design script: named steps, and a failure report when a step breaks.

A design script does its work inside ``with step("gain limits"):`` blocks and keeps
the report sections it has finished in a list. :func:`run_design` calls it; if
anything raises, the output folder still gets a complete report (HTML + PDF) that
names the step and the error, with the finished sections -- never a half file.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable

from .output import write_failure
from .provenance import provenance

__all__ = ["step", "run_design", "json_default", "design_arguments"]


class step:
    """Context manager that prints the step and tags an exception with its name."""

    def __init__(self, name: str, quiet: bool = False) -> None:
        self.name = name
        if not quiet:
            print(f"[{time.strftime('%H:%M:%S')}] {name} ...", flush=True)

    def __enter__(self) -> "step":
        return self

    def __exit__(self, etype, exc, tb) -> bool:
        if exc is not None and not hasattr(exc, "design_step"):
            try:
                exc.design_step = self.name
            except AttributeError:      # exceptions without a __dict__
                pass
        return False


def run_design(title: str, out: str | Path, plant_file: str | Path | None,
               body: Callable[[list], int]) -> int:
    """``body(done)`` -> exit code; on an exception write a failure report, return 1.

    ``done`` is the list the body appends finished report sections to.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    done: list = []
    try:
        return int(body(done))
    except Exception as exc:   # noqa: BLE001 - any failure must still leave a report
        name = getattr(exc, "design_step", "start")
        write_failure(out, title, exc, step=name, partial_sections=done,
                      provenance=provenance(plant_file=plant_file,
                                            command_line=" ".join(sys.argv)))
        print(f"design FAILED at step '{name}': {exc}\n  report: {out / 'report.html'}",
              file=sys.stderr)
        return 1


def json_default(o):
    """``json.dumps(default=...)`` for NumPy scalars and arrays in design summaries."""
    import numpy as np
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, (np.floating, np.integer)):
        value = o.item()
        return None if isinstance(value, float) and not np.isfinite(value) else value
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def design_arguments(description: str, default_out: str | Path, quick_help: str,
                     argv=None):
    """The command line every design script shares: ``--quick`` and ``--out DIR``.

    ``--out`` is validated before any work (:func:`workbench.output.check_output_dir`):
    an empty name, a file, a path under a file or an unwritable folder ends the
    program with exit 2 and one line naming it.

    Returns
    -------
    (argparse.Namespace, pathlib.Path)
        The parsed arguments and the output folder.
    """
    import argparse

    from ..errors import InputError
    from ..output import check_output_dir
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--quick", action="store_true", help=f"smoke mode: {quick_help}")
    ap.add_argument("--out", default=str(default_out),
                    help=f"output folder (default {default_out})")
    args = ap.parse_args(argv)
    try:
        out = check_output_dir(args.out)          # a bad --out is refused before any work
    except InputError as exc:
        ap.error(str(exc))
    return args, out
