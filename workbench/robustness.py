"""Monte Carlo robustness: validate controllers on plants drawn from uncertainty ranges.

The default ranges are paper 002's uncertain quantities and the issue's spreads:
the polytropic (heat) coefficient 1.0 .. 1.4, a discharge factor 0.7 .. 1.3 on the
valve's sonic conductance, the moving mass x0.5 .. x2 and the supply pressure +-1 bar.
Draws are uniform, seeded and shared by all controllers (common random numbers), so
pass rates compare controllers on the same plants.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from .errors import InputError
from .plant import Plant

__all__ = ["Uncertainty", "DEFAULT_UNCERTAINTY", "RobustnessResult", "draw_plants", "monte_carlo"]


@dataclass(frozen=True)
class Uncertainty:
    """One uncertain parameter: ``key`` (dotted), ``low``/``high`` and how they apply:
    ``"factor"`` multiplies the nominal value, ``"offset"`` adds to it (SI), ``"value"``
    replaces it."""

    key: str
    low: float
    high: float
    mode: str = "factor"

    def __post_init__(self) -> None:
        if self.mode not in ("factor", "offset", "value"):
            raise InputError(f"uncertainty {self.key}: mode must be factor, offset or value")
        if not self.low <= self.high:
            raise InputError(f"uncertainty {self.key}: low must not exceed high")

    def apply(self, nominal: float, draw: float) -> float:
        v = self.low + (self.high - self.low) * draw
        return nominal * v if self.mode == "factor" else nominal + v if self.mode == "offset" else v


DEFAULT_UNCERTAINTY = (
    Uncertainty("gas.polytropic_index", 1.0, 1.4, "value"),
    Uncertainty("valve.sonic_conductance", 0.7, 1.3, "factor"),
    Uncertainty("load.mass", 0.5, 2.0, "factor"),
    Uncertainty("supply.pressure", -1e5, 1e5, "offset"),
)


def draw_plants(plant: Plant, n: int, seed: int = 0,
                uncertainty=DEFAULT_UNCERTAINTY) -> list[tuple[dict, Plant]]:
    """``n`` plants with the uncertain parameters drawn uniformly (seeded)."""
    if n < 1:
        raise InputError("n must be >= 1")
    rng = np.random.default_rng(seed)
    u = rng.random((n, len(uncertainty)))
    out = []
    for row in u:
        changes = {unc.key: float(unc.apply(plant.params[unc.key], d))
                   for unc, d in zip(uncertainty, row)}
        out.append((changes, plant.with_params(**changes)))
    return out


@dataclass(frozen=True)
class RobustnessResult:
    """Pass/fail of every controller on every drawn plant."""

    draws: tuple[dict, ...]
    passed: Mapping[str, tuple[bool, ...]]
    failed_checks: Mapping[str, tuple[tuple[str, ...], ...]]
    seed: int
    first_error: Mapping[str, str] = None

    def pass_rate(self, name: str) -> float:
        return float(np.mean(self.passed[name]))

    def table(self) -> list[tuple[str, float, int, str]]:
        """Rows (controller, pass rate, runs, most frequent failing check)."""
        rows = []
        for name, res in self.passed.items():
            counts: dict[str, int] = {}
            for checks in self.failed_checks[name]:
                for c in checks:
                    counts[c] = counts.get(c, 0) + 1
            worst = max(counts, key=counts.get) if counts else ""
            rows.append((name, self.pass_rate(name), len(res), worst))
        return rows


def monte_carlo(plant: Plant, controllers: Mapping[str, Callable[[Plant], object]], n: int = 20,
                seed: int = 0, uncertainty=DEFAULT_UNCERTAINTY, spec=None, reference=None,
                progress: bool | None = None) -> RobustnessResult:
    """Validate each controller (built by ``controllers[name](drawn_plant)``; a design
    may re-tune on the plant it is given or ignore it) on ``n`` drawn plants."""
    from tqdm.auto import tqdm
    from .validate import validate, validation_profile
    ref = reference if reference is not None else validation_profile(plant)
    draws = draw_plants(plant, n, seed, uncertainty)
    passed = {k: [] for k in controllers}
    failed = {k: [] for k in controllers}
    errors: dict[str, str] = {}
    bar = tqdm(total=n * len(controllers), desc="robustness", disable=not progress, leave=False)
    for _, p in draws:
        for name, make in controllers.items():
            v = validate(p, make(p), spec=spec, reference=ref, progress=False)
            passed[name].append(bool(v.passed))
            failed[name].append(tuple(c.name for c in v.failed))
            if v.error:
                errors.setdefault(name, v.error)
            bar.update()
    bar.close()
    return RobustnessResult(draws=tuple(d for d, _ in draws),
                            passed={k: tuple(v) for k, v in passed.items()},
                            failed_checks={k: tuple(v) for k, v in failed.items()}, seed=seed,
                            first_error=errors)
