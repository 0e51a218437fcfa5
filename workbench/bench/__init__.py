"""Benchmarks: ``workbench bench NAME [--quick] [--json]``, one module per benchmark.

Each benchmark measures against a baseline in the same run and returns a dict of plain
data (numbers, strings, lists, dicts; JSON-ready). Timing numbers are for this machine
at the time of the run; the ratios and accuracy numbers are what to compare between
runs. Nothing here is a test.

Every module ``workbench.bench.NAME`` exposes ``bench(quick: bool = False) -> dict``;
the modules are imported only when their benchmark runs (they pull in do-mpc, IPOPT,
compilers...).

* :mod:`.simulate` -- closed loop, 25 mm plant: compiled loop and CVODES vs scipy LSODA;
* :mod:`.sweep` -- 200 x 200 stability map vs a python-control loop;
* :mod:`.rls` -- RLS over 10^6 samples vs a numpy loop;
* :mod:`.greybox` -- 4 parameters from a 20 s, 1 kHz recording;
* :mod:`.mpc` -- NMPC solve times over a 20 s closed loop, vs do-mpc when installed;
* :mod:`.diagnose` -- a whole diagnosis of a 24 s, 1 kHz recording.

>>> from workbench import bench
>>> bench.NAMES
('simulate', 'sweep', 'rls', 'greybox', 'mpc', 'diagnose')

Skipped here: a benchmark times things (seconds even in quick mode) and its numbers
depend on the machine:

>>> result = bench.run("sweep", quick=True)          # doctest: +SKIP
"""

from __future__ import annotations

import importlib

from ..errors import InputError, WorkbenchError

__all__ = ["NAMES", "run", "load"]

#: The benchmarks, in the order ``workbench bench --help`` lists them.
NAMES: tuple[str, ...] = ("simulate", "sweep", "rls", "greybox", "mpc", "diagnose")


def load(name: str):
    """The ``bench(quick=False) -> dict`` function of the benchmark ``name``.

    Raises
    ------
    InputError
        ``name`` is not one of :data:`NAMES`.
    WorkbenchError
        Its module cannot be imported or has no ``bench`` function; the message names
        the cause (chained as ``__cause__``).
    """
    if name not in NAMES:
        raise InputError(f"no benchmark {name!r}; known: {', '.join(NAMES)}")
    try:
        return getattr(importlib.import_module(f"{__name__}.{name}"), "bench")
    except (ImportError, AttributeError) as exc:
        raise WorkbenchError(f"benchmark '{name}' is not available: {exc}") from exc


def run(name: str, quick: bool = False) -> dict:
    """Run the benchmark ``name`` (one of :data:`NAMES`) and return its result.

    Parameters
    ----------
    name : str
        Benchmark name, see :data:`NAMES`.
    quick : bool
        Shorter run (a smoke test; numbers not comparable with a full run).

    Returns
    -------
    dict
        The benchmark's result (plain data).
    """
    return load(name)(quick=quick)
