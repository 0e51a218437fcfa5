"""Benchmarks: ``workbench bench NAME [--quick] [--json]``, one module per benchmark.

Each benchmark measures ours and the strongest plain baselines in the same run
(interleaved, so load from other processes falls on all alike) and returns a dict of
plain data (JSON-ready) with a common core (:mod:`.timing`)::

    {"benchmark", "median_s", "cpu_median_s", "spread": {"repeats", "wall_s", "cpu_s"},
     "error" or "cost", "baselines": {name: {"median_s", "error", "ratio",
     "description", "available", ...}}, "machine", ...}

``ratio`` is the baseline's median over ours (> 1: ours faster); a baseline that
needs the ``bench`` extra (numba, osqp, do-mpc) and cannot run says so
(``available: false`` and ``reason``). Timing numbers are for this machine and its
load at the time of the run; the ratios and the errors are what to compare between
runs. Nothing here is a test.

Every module ``workbench.bench.NAME`` exposes ``bench(quick: bool = False) -> dict``;
the modules are imported only when their benchmark runs.

* :mod:`.simulate` -- 24 s closed loop, 4 states and 22 (lines, valve), by accuracy
  (:mod:`.adaptive_loop`) vs CVODES in a ``mapaccum`` and a compiled RK4
  (:mod:`.baselines_simulate`) at the same 0.1 % bound;
* :mod:`.sweep` -- 200 x 200 stability map vs a batched numpy/CasADi script and a point
  loop, both with the model built once (:mod:`.baselines_sweep`);
* :mod:`.rls` -- RLS over 10^6 samples vs a numba loop of the same recursion;
* :mod:`.greybox` -- 4 parameters from a 20 s, 1 kHz recording vs scipy ``least_squares``
  on CVODES single-shooting replays (:mod:`.baselines_greybox`);
* :mod:`.mpc` -- NMPC per sample vs a plain Gauss-Newton RTI, IPOPT (Gauss-Newton,
  warm) and do-mpc, all in lockstep (:mod:`.baselines_mpc`);
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
