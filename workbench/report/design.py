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

__all__ = ["step", "run_design", "json_default"]


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
