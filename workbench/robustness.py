"""Monte Carlo robustness: validate controllers on plants drawn from uncertainty ranges.

Two sets of ranges come with the workbench, both from paper 002's uncertain quantities
and the issue's spreads of mass and supply:

* :data:`DEFAULT_UNCERTAINTY` -- the spread a rig engineer meets: the polytropic (heat)
  coefficient 1.0 .. 1.4, a discharge factor 0.7 .. 1.3 on the valve's sonic
  conductance, the moving mass x0.5 .. x2 and the supply pressure +-1 bar.
* :data:`PAPER_002_UNCERTAINTY` -- paper 002's bounds as they stand: the heat
  coefficient kappa 1 .. 1.3997 and the bound parameter gamma = kappa Cd theta
  0.075 .. 1.3297, which lumps heat coefficient, discharge coefficient and
  temperature into one factor on the valve-flow term of the chamber balance
  dp/dt = kappa/V (R T q - p dV/dt). Relative to the plant file's nominal flow term
  kappa0 C0 it sets the sonic conductance C = C0 gamma kappa0 / kappa (mode ``"flow"``);
  at its low end the valve passes a thirteenth of its nominal flow, so controllers are
  expected to fail there on settling time: the pass rate says how far down they hold.

Draws are uniform, seeded and shared by all controllers (common random numbers), so
pass rates compare controllers on the same plants. Runs may go to forked worker
processes (``workers``); results do not depend on how many.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from .errors import InputError
from .output import reraise_interrupt, stop_on_signals, stop_workers

if TYPE_CHECKING:                   # imported lazily: `workbench --help` stays fast
    from .plant import Plant

__all__ = ["Uncertainty", "DEFAULT_UNCERTAINTY", "PAPER_002_UNCERTAINTY", "Outcome",
           "RobustnessResult", "draw_plants", "monte_carlo", "validation_outcome"]

_MODES = ("factor", "offset", "value", "flow")


@dataclass(frozen=True)
class Uncertainty:
    """One uncertain parameter: ``key`` (dotted), ``low``/``high`` and how they apply:
    ``"factor"`` multiplies the nominal value, ``"offset"`` adds to it (SI), ``"value"``
    replaces it, ``"flow"`` (only for ``valve.sonic_conductance``) is paper 002's
    combined factor on the flow term kappa C, so C = C0 g kappa0 / kappa with kappa the
    drawn polytropic index (its nominal value if that is not drawn)."""

    key: str
    low: float
    high: float
    mode: str = "factor"

    def __post_init__(self) -> None:
        if self.mode not in _MODES:
            raise InputError(f"uncertainty {self.key}: mode must be one of {', '.join(_MODES)}, "
                             f"got {self.mode!r}")
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            raise InputError(f"uncertainty {self.key}: low and high must be finite numbers")
        if not self.low <= self.high:
            raise InputError(f"uncertainty {self.key}: low must not exceed high")
        if self.mode == "flow" and self.key != "valve.sonic_conductance":
            raise InputError(f"uncertainty {self.key}: mode 'flow' applies to "
                             "valve.sonic_conductance only")
        if self.mode in ("factor", "flow") and self.low <= 0.0:
            raise InputError(f"uncertainty {self.key}: a {self.mode} must be > 0")

    def value(self, draw: float) -> float:
        """The drawn quantity for a uniform draw in [0, 1] (the factor, offset or value)."""
        return self.low + (self.high - self.low) * draw

    def apply(self, nominal: float, draw: float, kappa_ratio: float = 1.0) -> float:
        """Parameter value for a uniform ``draw`` in [0, 1]; ``kappa_ratio`` = kappa0 / kappa
        (mode ``"flow"`` only)."""
        v = self.value(draw)
        if self.mode == "factor":
            return nominal * v
        if self.mode == "offset":
            return nominal + v
        if self.mode == "flow":
            return nominal * v * kappa_ratio
        return v


DEFAULT_UNCERTAINTY = (
    Uncertainty("gas.polytropic_index", 1.0, 1.4, "value"),
    Uncertainty("valve.sonic_conductance", 0.7, 1.3, "factor"),
    Uncertainty("load.mass", 0.5, 2.0, "factor"),
    Uncertainty("supply.pressure", -1e5, 1e5, "offset"),
)

PAPER_002_UNCERTAINTY = (
    Uncertainty("gas.polytropic_index", 1.0, 1.3997, "value"),
    Uncertainty("valve.sonic_conductance", 0.075, 1.3297, "flow"),
    Uncertainty("load.mass", 0.5, 2.0, "factor"),
    Uncertainty("supply.pressure", -1e5, 1e5, "offset"),
)


def _check_uncertainty(plant: Plant, uncertainty: Sequence[Uncertainty]) -> None:
    if not uncertainty:
        raise InputError("give at least one uncertain parameter")
    keys = [u.key for u in uncertainty]
    dup = sorted({k for k in keys if keys.count(k) > 1})
    if dup:
        raise InputError(f"uncertain parameters given twice: {', '.join(dup)}")
    missing = [k for k in keys if k not in plant.params]
    if missing:
        hint = (f" (its valve law is {plant.params.get('valve.law', 'iso6358')!r})"
                if any(k.startswith("valve.") for k in missing) else "")
        raise InputError(f"the plant has no parameter {', '.join(missing)}{hint}")


def draw_plants(plant: Plant, n: int, seed: int = 0,
                uncertainty: Sequence[Uncertainty] = DEFAULT_UNCERTAINTY
                ) -> list[tuple[dict, Plant]]:
    """``n`` plants with the uncertain parameters drawn uniformly (seeded).

    Returns (changes, plant) pairs; ``changes`` maps each key to its drawn value (SI).
    """
    if not (isinstance(n, (int, np.integer)) and n >= 1):
        raise InputError(f"n must be an integer >= 1, got {n!r}")
    _check_uncertainty(plant, uncertainty)
    rng = np.random.default_rng(seed)
    u = rng.random((n, len(uncertainty)))
    kappa0 = float(plant.params["gas.polytropic_index"])
    out = []
    for row in u:
        changes = {unc.key: float(unc.apply(plant.params[unc.key], d))
                   for unc, d in zip(uncertainty, row) if unc.mode != "flow"}
        ratio = kappa0 / changes.get("gas.polytropic_index", kappa0)
        for unc, d in zip(uncertainty, row):
            if unc.mode == "flow":
                changes[unc.key] = float(unc.apply(plant.params[unc.key], d, ratio))
        out.append((changes, plant.with_params(**changes)))
    return out


@dataclass(frozen=True)
class Outcome:
    """One controller on one drawn plant: pass/fail, the failed checks' names, a score
    (lower is better, e.g. IAE in m s; NaN when there is none) and a solver error."""

    passed: bool
    failed: tuple[str, ...] = ()
    score: float = math.nan
    error: str | None = None


def validation_outcome(spec=None, reference=None) -> Callable[[Plant, object], Outcome]:
    """The default judge: :func:`workbench.validate.validate` on the standard profile
    (or ``reference``), scored by the IAE (m s) when the whole profile was simulated."""
    from .validate import validate

    def judge(plant: Plant, controller) -> Outcome:
        v = validate(plant, controller, spec=spec, reference=reference, progress=False)
        complete = v.metrics.simulated_time >= v.metrics.duration - 1e-9
        return Outcome(bool(v.passed), tuple(c.name for c in v.failed),
                       float(v.metrics.iae) if complete else math.nan, v.error)
    return judge


@dataclass(frozen=True)
class RobustnessResult:
    """Pass/fail of every controller on every drawn plant.

    ``draws[i]`` are the drawn values of plant i; ``passed[name][i]``,
    ``failed_checks[name][i]`` and ``scores[name][i]`` are controller ``name`` on it.
    """

    draws: tuple[dict, ...]
    passed: Mapping[str, tuple[bool, ...]]
    failed_checks: Mapping[str, tuple[tuple[str, ...], ...]]
    seed: int
    first_error: Mapping[str, str] = field(default_factory=dict)
    scores: Mapping[str, tuple[float, ...]] = field(default_factory=dict)
    uncertainty: tuple[Uncertainty, ...] = DEFAULT_UNCERTAINTY

    def _known(self, name: str) -> None:
        if name not in self.passed:
            raise InputError(f"no controller {name!r}; have {', '.join(self.passed)}")

    def pass_rate(self, name: str) -> float:
        self._known(name)
        return float(np.mean(self.passed[name]))

    def pass_interval(self, name: str, z: float = 1.96) -> tuple[float, float]:
        """Wilson score interval of the pass rate (default 95 %): how sure the rate is
        from this many draws."""
        self._known(name)
        k, n = float(np.sum(self.passed[name])), len(self.passed[name])
        p = k / n
        den = 1.0 + z * z / n
        mid = (p + z * z / (2 * n)) / den
        half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
        return max(0.0, mid - half), min(1.0, mid + half)

    def table(self) -> list[tuple[str, float, int, float, float, str]]:
        """Rows (controller, pass rate, runs, median score, worst score, most frequent
        failing check). Scores are NaN when no run has one."""
        rows = []
        for name, res in self.passed.items():
            counts: dict[str, int] = {}
            for checks in self.failed_checks[name]:
                for c in checks:
                    counts[c] = counts.get(c, 0) + 1
            worst = max(counts, key=counts.get) if counts else ""
            sc = np.array(self.scores.get(name, ()), dtype=float)
            sc = sc[np.isfinite(sc)]
            med = float(np.median(sc)) if len(sc) else math.nan
            mx = float(np.max(sc)) if len(sc) else math.nan
            rows.append((name, self.pass_rate(name), len(res), med, mx, worst))
        return rows

    def drawn(self, key: str) -> np.ndarray:
        """The drawn values of ``key`` over the plants."""
        if key not in self.draws[0]:
            raise InputError(f"{key!r} was not drawn; drawn: {', '.join(self.draws[0])}")
        return np.array([d[key] for d in self.draws], dtype=float)

    def flow_factors(self, plant: Plant) -> np.ndarray:
        """Each draw's factor on the valve-flow term kappa C relative to ``plant``'s
        (paper 002's bound parameter); parameters not drawn keep ``plant``'s values."""
        k0 = float(plant.params["gas.polytropic_index"])
        c0 = float(plant.params["valve.sonic_conductance"])
        return np.array([d.get("gas.polytropic_index", k0) * d.get("valve.sonic_conductance", c0)
                         / (k0 * c0) for d in self.draws], dtype=float)

    def to_csv_text(self, plant: Plant) -> str:
        """One row per draw: its drawn values and flow factor (relative to ``plant``),
        then per controller passed (0/1), score and the failed checks (``;``-joined)."""
        import csv
        import io
        keys = list(self.draws[0])
        names = list(self.passed)
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["draw", *keys, "flow_factor"]
                   + [f"{n}_{c}" for n in names for c in ("passed", "score", "failed")])
        ff = self.flow_factors(plant)
        for i, d in enumerate(self.draws):
            row = [i, *(repr(d[k]) for k in keys), repr(float(ff[i]))]
            for n in names:
                sc = self.scores.get(n, [math.nan] * len(self.draws))[i]
                row += [int(self.passed[n][i]), repr(float(sc)), ";".join(self.failed_checks[n][i])]
            w.writerow(row)
        return buf.getvalue()

    def to_dict(self) -> dict:
        return {"seed": self.seed,
                "uncertainty": [{"key": u.key, "low": u.low, "high": u.high, "mode": u.mode}
                                for u in self.uncertainty],
                "draws": list(self.draws),
                "controllers": {name: {"pass_rate": self.pass_rate(name),
                                       "passed": list(self.passed[name]),
                                       "failed_checks": [list(c) for c in self.failed_checks[name]],
                                       "scores": [float(v) if math.isfinite(v) else None
                                                  for v in self.scores.get(name, ())],
                                       "first_error": self.first_error.get(name)}
                                for name in self.passed}}


# Work shared with forked workers (set before the fork, read by index in the child).
_JOBS: dict = {}


def _run_one(i: int, name: str) -> Outcome:
    plants, controllers, judge = _JOBS["plants"], _JOBS["controllers"], _JOBS["judge"]
    try:
        controller = controllers[name](plants[i])
    except InputError:
        raise
    except Exception as exc:          # a design that cannot be built on this draw fails it
        reraise_interrupt(exc)        # ... but an interrupted one is not a result
        return Outcome(False, ("design",), math.nan, f"{type(exc).__name__}: {exc}")
    try:
        return judge(plants[i], controller)
    except InputError:
        raise
    except Exception as exc:          # a run the judge could not finish fails the draw
        reraise_interrupt(exc)        # ... but an interrupted one is not a result
        return Outcome(False, ("run",), math.nan, f"{type(exc).__name__}: {exc}")


def _quiet_worker() -> None:
    """In a forked worker: the parent handles Ctrl-C (a terminal sends it to the whole
    process group) and stops its workers with SIGTERM, which ends them silently."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _run_jobs(jobs: list[tuple[int, str]], nproc: int, results: dict, bar) -> None:
    """Run the jobs here or in forked workers. On Ctrl-C, SIGTERM or any error the
    queued jobs are cancelled and the workers stopped at once (no waiting for them)."""
    import multiprocessing as mp
    if not (nproc > 1 and len(jobs) > 1 and "fork" in mp.get_all_start_methods()):
        for job in jobs:
            results[job] = _run_one(*job)
            bar.update()
        return
    from concurrent.futures import ProcessPoolExecutor, as_completed
    ex = ProcessPoolExecutor(max_workers=min(nproc, len(jobs)),
                             mp_context=mp.get_context("fork"), initializer=_quiet_worker)
    try:
        futs = {ex.submit(_run_one, i, name): (i, name) for i, name in jobs}
        for f in as_completed(futs):
            results[futs[f]] = f.result()
            bar.update()
    except BaseException:
        stop_workers(ex)                   # a signal or an error: no waiting for the jobs
        raise
    ex.shutdown(wait=True)


def monte_carlo(plant: Plant, controllers: Mapping[str, Callable[[Plant], object]], n: int = 20,
                seed: int = 0, uncertainty: Sequence[Uncertainty] = DEFAULT_UNCERTAINTY,
                spec=None, reference=None, judge: Callable[[Plant, object], Outcome] | None = None,
                workers: int | None = 1, progress: bool | None = None) -> RobustnessResult:
    """Judge each controller on ``n`` plants drawn from ``uncertainty``.

    Parameters
    ----------
    plant : the nominal plant (with whatever unmodelled effects the runs should have).
    controllers : {name: factory}; ``factory(drawn_plant)`` returns the controller for
        that plant (a design may re-tune on the plant it is given or ignore it).
    n, seed : number of draws, random seed (same draws for every controller).
    uncertainty : the ranges (default :data:`DEFAULT_UNCERTAINTY`).
    spec, reference : of the default judge, :func:`validation_outcome`.
    judge : ``judge(plant, controller) -> Outcome``, for loops that are not position
        loops (e.g. force tracking); replaces ``spec`` and ``reference``.
    workers : processes (forked; None = all cores). Each controller should be built
        (and compiled) before the call so the workers inherit it.
    progress : progress bar (None: automatic).
    """
    from tqdm.auto import tqdm
    if not controllers:
        raise InputError("give at least one controller")
    if judge is None:
        from .validate import validation_profile
        ref = reference if reference is not None else validation_profile(plant)
        judge = validation_outcome(spec=spec, reference=ref)
    elif spec is not None or reference is not None:
        raise InputError("give either judge or spec/reference, not both")
    draws = draw_plants(plant, n, seed, uncertainty)
    plants = [p for _, p in draws]
    names = list(controllers)
    jobs = [(i, name) for i in range(n) for name in names]
    results: dict[tuple[int, str], Outcome] = {}
    nproc = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    bar = tqdm(total=len(jobs), desc="robustness", leave=False,
               disable=None if progress is None else not progress)   # None: on a terminal
    _JOBS.update(plants=plants, controllers=dict(controllers), judge=judge)
    try:
        with stop_on_signals():
            _run_jobs(jobs, nproc, results, bar)
    finally:
        _JOBS.clear()
        bar.close()
    errors: dict[str, str] = {}
    for i, name in jobs:                               # first error in draw order
        if results[(i, name)].error:
            errors.setdefault(name, results[(i, name)].error)
    return RobustnessResult(
        draws=tuple(d for d, _ in draws),
        passed={k: tuple(results[(i, k)].passed for i in range(n)) for k in names},
        failed_checks={k: tuple(results[(i, k)].failed for i in range(n)) for k in names},
        seed=seed, first_error=errors,
        scores={k: tuple(results[(i, k)].score for i in range(n)) for k in names},
        uncertainty=tuple(uncertainty))


# --------------------------------------------------------------------------- ranges by name

#: Built-in uncertainty ranges by name (``workbench robustness --ranges NAME``).
UNCERTAINTY_SETS = {"usual": DEFAULT_UNCERTAINTY, "paper002": PAPER_002_UNCERTAINTY}


def parse_vary(text: str) -> Uncertainty:
    """``KEY=LOW:HIGH[:MODE]`` (MODE factor, offset, value or flow; default factor)."""
    key, sep, rng = text.partition("=")
    parts = rng.split(":")
    if not sep or not key.strip() or len(parts) not in (2, 3):
        raise InputError(f"--vary {text!r}: expected KEY=LOW:HIGH[:MODE], "
                         "e.g. load.mass=0.5:2:factor")
    try:
        low, high = float(parts[0]), float(parts[1])
    except ValueError:
        raise InputError(f"--vary {text!r}: LOW and HIGH must be numbers") from None
    return Uncertainty(key.strip(), low, high, parts[2].strip() if len(parts) == 3 else "factor")


def figure_axes(res: RobustnessResult, plant: Plant) -> list[tuple[np.ndarray, str]]:
    """Two axes to show the draws on: the flow factor when kappa or C was drawn, the
    mass factor when the mass was, then the other drawn keys (relative to nominal
    where the nominal is not zero); a constant axis when fewer than two were drawn."""
    drawn = list(res.draws[0])
    axes: list[tuple[np.ndarray, str]] = []
    if {"gas.polytropic_index", "valve.sonic_conductance"} & set(drawn):
        axes.append((res.flow_factors(plant), "flow factor kappa C / (kappa0 C0)"))
        drawn = [k for k in drawn if k not in ("gas.polytropic_index", "valve.sonic_conductance")]
    for key in sorted(drawn, key=lambda k: k != "load.mass"):
        nominal = float(plant.params[key])
        if nominal != 0.0:
            axes.append((res.drawn(key) / nominal, f"{key} / nominal"))
        else:
            axes.append((res.drawn(key), key))
    while len(axes) < 2:
        axes.append((np.zeros(len(res.draws)), "(nothing else drawn)"))
    return axes[:2]


_figure_axes = figure_axes          # former private name
