"""Run the blocks of a stability map: in this process, on forked local workers, or on Dask.

Each block is a dict of arrays (positions, parameter columns, gains, sample times)
evaluated by the plant's :class:`~workbench.stability.kernel._Sweeper`, which every
process builds once per plant spec (:func:`sweeper_for`) and keeps. Forked workers
inherit the parent's sweeper (compiled before the fork); Dask workers build their
own from the scattered spec.
"""

from __future__ import annotations

import os
import pickle
import sys

from ..errors import WorkbenchError
from .kernel import _Sweeper

__all__ = ["sweeper_for", "evaluate_block", "run_blocks"]

#: One sweeper per plant spec and process.
_SWEEPERS: dict = {}


def sweeper_for(spec: tuple) -> _Sweeper:
    """The sweeper of ``spec`` (the arguments of :class:`_Sweeper`), built on first use."""
    key = pickle.dumps(spec)
    sw = _SWEEPERS.get(key)
    if sw is None:
        sw = _SWEEPERS[key] = _Sweeper(*spec)
    return sw


def evaluate_block(spec: tuple, inputs: dict) -> dict:
    """Worker entry point (module level, so Dask and forked workers can call it)."""
    return sweeper_for(spec).evaluate(**inputs)


def run_blocks(spec: tuple, tasks: list[dict], scheduler, workers: int | None,
               progress: bool | None, npoints: int, connect_timeout: str) -> list[dict]:
    """Evaluate every block of ``tasks``; results in the order of ``tasks``.

    Parameters
    ----------
    spec : tuple
        The plant spec (see :func:`sweeper_for`).
    tasks : list of dict
        Keyword arguments of :meth:`_Sweeper.evaluate`, one dict per block.
    scheduler : str or distributed.Client or None
        Dask scheduler address or client; None: local processes.
    workers : int or None
        Local worker processes (None: all cores; 1: in this process).
    progress : bool or None
        Show a progress bar (None: when stderr is a terminal).
    npoints : int
        Points in all blocks (the progress bar's total).
    connect_timeout : str
        How long to wait for a Dask scheduler (``"10s"``).
    """
    from tqdm.auto import tqdm
    show = sys.stderr.isatty() if progress is None else bool(progress)
    bar = tqdm(total=npoints, desc="stability map", unit="pt", disable=not show, leave=False)
    try:
        if scheduler is not None:
            return _run_dask(spec, tasks, scheduler, bar, connect_timeout)
        nproc = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
        if nproc > 1 and len(tasks) > 1 and _can_fork():
            return _run_forked(spec, tasks, nproc, bar)
        results: list = [None] * len(tasks)
        for i, t in enumerate(tasks):
            results[i] = evaluate_block(spec, t)
            bar.update(len(t["kp"]))
        return results
    finally:
        bar.close()


def _can_fork() -> bool:
    import multiprocessing as mp
    return "fork" in mp.get_all_start_methods()


def _run_forked(spec, tasks, nproc, bar):
    """Blocks on ``nproc`` forked processes that inherit the (compiled) sweeper."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    ctx = mp.get_context("fork")
    sweeper_for(spec)._fun("point")                        # compile before the fork
    results: list = [None] * len(tasks)
    with ProcessPoolExecutor(max_workers=min(nproc, len(tasks)), mp_context=ctx) as ex:
        futs = {ex.submit(evaluate_block, spec, t): i for i, t in enumerate(tasks)}
        for fut in as_completed(futs):
            i = futs[fut]
            results[i] = fut.result()
            bar.update(len(tasks[i]["kp"]))
    return results


def _run_dask(spec, tasks, scheduler, bar, connect_timeout):
    """Blocks on a Dask cluster (``scheduler``: address or ``distributed.Client``)."""
    try:
        from distributed import Client, as_completed
    except ImportError as exc:          # pragma: no cover - dependency of the project
        raise WorkbenchError("a Dask scheduler was given but 'distributed' is not installed") from exc
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=connect_timeout) if own else scheduler
    except (OSError, TimeoutError) as exc:
        raise WorkbenchError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    try:
        spec_f = client.scatter(spec, broadcast=True)
        futs = [client.submit(evaluate_block, spec_f, t, pure=False) for t in tasks]
        index = {f.key: i for i, f in enumerate(futs)}
        results: list = [None] * len(tasks)
        for fut in as_completed(futs):
            i = index[fut.key]
            results[i] = fut.result()
            bar.update(len(tasks[i]["kp"]))
        return results
    finally:
        if own:
            client.close()
