"""Running a design script: named steps, and a failure report when a step breaks.

A design script does its work inside ``with step("gain limits"):`` blocks and keeps
the report sections it has finished in a list. :func:`run_design` calls it; if
anything raises, the output folder still gets a complete report (HTML + PDF) that
names the step and the error, with the finished sections -- never a half file.

Progress goes to stderr (the results a script prints stay on stdout): every step
announces itself, a step that took longer than :data:`PROGRESS_INTERVAL` says when
it is done, and a loop inside a step reports ``label k/N`` through :func:`progress`
at least every :data:`PROGRESS_INTERVAL` seconds, so a long step is never silent.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator, TypeVar

from .output import write_failure
from .provenance import provenance

__all__ = ["step", "progress", "say", "run_design", "json_default", "write_summary",
           "design_arguments",
           "PROGRESS_INTERVAL"]

#: Seconds of work after which a design tells how far it is (issue 15: no silent step).
PROGRESS_INTERVAL = 2.0

_T = TypeVar("_T")


def say(text: str) -> None:
    """One progress line on stderr, ``[HH:MM:SS] text``, flushed at once."""
    print(f"[{time.strftime('%H:%M:%S')}] {text}", file=sys.stderr, flush=True)


class step:
    """Context manager that announces the step on stderr and tags an exception with
    its name; a step longer than :data:`PROGRESS_INTERVAL` also says when it is done."""

    def __init__(self, name: str, quiet: bool = False) -> None:
        self.name = name
        self.quiet = quiet
        self._start = time.perf_counter()
        if not quiet:
            say(f"{name} ...")

    def __enter__(self) -> "step":
        return self

    def __exit__(self, etype, exc, tb) -> bool:
        elapsed = time.perf_counter() - self._start
        if exc is None and not self.quiet and elapsed > PROGRESS_INTERVAL:
            say(f"{self.name}: done in {elapsed:.1f} s")
        if exc is not None and not hasattr(exc, "design_step"):
            try:
                exc.design_step = self.name
            except AttributeError:      # exceptions without a __dict__
                pass
        return False


def progress(items: Iterable[_T], label: str, total: int | None = None,
             interval: float = PROGRESS_INTERVAL) -> Iterator[_T]:
    """Yield ``items``, printing ``label k/N (t s)`` on stderr as they are done.

    A line is printed when an item finishes and :data:`PROGRESS_INTERVAL` seconds
    (``interval``) have passed since the last line, and after the last item if any
    line was printed or the loop took longer than ``interval``: a loop of quick items
    stays quiet, a slow one is never silent for longer than one item.

    Parameters
    ----------
    items : iterable
        The work items.
    label : str
        What is counted (``"draw"``, ``"bandwidth"``).
    total : int, optional
        Number of items (default ``len(items)`` when it has one).
    interval : float
        Seconds between lines, s.

    Examples
    --------
    >>> for lam in progress([20, 40, 80], "bandwidth"):
    ...     pass                                   # each item's work
    """
    if total is None:
        try:
            total = len(items)             # type: ignore[arg-type]
        except TypeError:
            total = None
    of = "" if total is None else f"/{total}"
    start = last = time.perf_counter()
    shown, k = 0, 0                        # the count of the last line printed
    for k, item in enumerate(items, 1):
        yield item
        now = time.perf_counter()
        if now - last >= interval:
            say(f"  {label} {k}{of} ({now - start:.1f} s)")
            last, shown = now, k
    elapsed = time.perf_counter() - start
    if k and shown != k and (shown or elapsed > interval):
        say(f"  {label} {k}{of} ({elapsed:.1f} s)")


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


def write_summary(out, summary: dict, line: str, html, pdf) -> None:
    """Write a design's ``out/summary.json`` (strict JSON, whole or not at all) and print
    its result line and the report's two paths."""
    from ..output import write_json
    write_json(Path(out) / "summary.json", summary, indent=1, default=json_default)
    print(f"{line}\n  report: {html}\n          {pdf}")


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
