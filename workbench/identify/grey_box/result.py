"""The grey-box estimate with its confidence, fits and verdict: :class:`GreyBoxResult`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ...plant import Plant

__all__ = ["GreyBoxResult"]


@dataclass(frozen=True, eq=False)
class GreyBoxResult:
    """Estimated parameters with their confidence, and the fit before and after.

    Learned values end in ``_``. Arrays are in the order of :attr:`names`, SI units.

    Attributes
    ----------
    names : tuple of str
        Dotted parameter names.
    units : tuple of str
    nominal : (n,) start values (the plant's).
    bounds : (n, 2) lower and upper bounds used.
    values_ : (n,) estimates.
    std_ : (n,) standard deviations (inf when not identifiable).
    ci95_ : (n, 2) 95 % confidence intervals.
    correlation_ : (n, n) correlation matrix of the estimates.
    identifiable_ : (n,) bool, std below half the parameter's size.
    at_bound_ : (n,) bool, the estimate sits on a bound (its interval is then not
        meaningful).
    fit_before, fit_after : tuple of dict
        Per recording, NRMSE fit (%) of each compared signal: nominal plant and
        estimated plant, from fresh CVODES simulations (closed loop on the recorded
        ``r`` with the plant's controller when both exist, else open loop on ``u``;
        ``method["replay"]``), from the recording's first sample and from the
        estimated initial state respectively.
    fit_ms_ : tuple of dict
        Per recording, fit (%) of the estimated model's own trajectory in the fit (the
        multiple-shooting solution: continuous, from the estimated initial state,
        fixed-step integration). An open-loop replay of a position drive integrates
        every small difference, so on closed-loop data ``fit_after`` can drift while
        this stays at the noise level.
    x0_ : tuple of (nx,) arrays, the estimated initial state of each recording.
    noise : tuple of dict, per recording the noise standard deviation (SI) assumed
        for each signal (estimated from the data unless given).
    residual_rms_ : tuple of dict, per recording the RMS of the residuals (SI) of the
        estimated model (discrete model, multiple-shooting solution).
    whiteness_ : tuple of dict, per recording the fraction of residual
        autocorrelation lags (1..25) outside the 99 % band (about 0.01 when white).
    integration_error_ : tuple of dict, per recording the RMS difference (SI) between
        the fixed-step model used in the fit and CVODES (same parameters), each shooting
        interval integrated by CVODES from its node.
    residuals_ : tuple of dict, per recording and signal the residual (SI) measured
        minus estimated model (the multiple-shooting solution, a continuous model
        trajectory from the estimated initial state), one value per sample.
    cost : float, final cost 0.5 sum(r^2) / n (about 0.5 when the residuals are at
        the noise level).
    iterations : int. success : bool.
    status : str, IPOPT's return status, or ``Parameters_Converged`` when the run was
        stopped (or accepted after IPOPT gave up) because the parameters no longer moved
        beyond a fraction of their standard deviation (see the module notes on kinks).
    wall_time : float, s.
    poor_fit : bool. message : str, the verdict in words.
    plant_ : Plant, the plant with the estimated values (friction form as given; with
        line dynamics, ``lines.segments`` is fixed to the number used in the fit).
    method : dict, settings used (scheme, substeps, shooting interval, ...).
    trajectories_before, trajectories_after : tuple of Trajectory (CVODES replays).
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    nominal: np.ndarray
    bounds: np.ndarray
    values_: np.ndarray
    std_: np.ndarray
    ci95_: np.ndarray
    correlation_: np.ndarray
    identifiable_: np.ndarray
    at_bound_: np.ndarray
    fit_before: tuple[dict[str, float], ...]
    fit_after: tuple[dict[str, float], ...]
    fit_ms_: tuple[dict[str, float], ...]
    x0_: tuple[np.ndarray, ...]
    noise: tuple[dict[str, float], ...]
    residual_rms_: tuple[dict[str, float], ...]
    whiteness_: tuple[dict[str, float], ...]
    integration_error_: tuple[dict[str, float], ...]
    residuals_: tuple[dict[str, np.ndarray], ...]
    cost: float
    iterations: int
    status: str
    success: bool
    wall_time: float
    poor_fit: bool
    message: str
    plant_: Plant = field(repr=False, compare=False)
    method: Mapping[str, Any] = field(default_factory=dict)
    sources: tuple[str, ...] = ()
    trajectories_before: tuple = field(default=(), repr=False, compare=False)
    trajectories_after: tuple = field(default=(), repr=False, compare=False)

    def value(self, name: str) -> float:
        """Estimate of one parameter by name (SI)."""
        return float(self.values_[self._index(name)])

    def _index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"'{name}' was not estimated; estimated: "
                           f"{', '.join(self.names)}") from None

    @property
    def estimates(self) -> dict[str, float]:
        """Estimates by name (SI)."""
        return {n: float(v) for n, v in zip(self.names, self.values_)}

    def within_ci(self, truth: Mapping[str, float] | Sequence[float]) -> np.ndarray:
        """Whether each true value lies in its 95 % interval."""
        if isinstance(truth, Mapping):
            tv = np.array([float(truth[n]) for n in self.names])
        else:
            tv = np.asarray(truth, dtype=float)
        return (tv >= self.ci95_[:, 0]) & (tv <= self.ci95_[:, 1])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (SI; inf and nan as None)."""
        def num(v):
            v = float(v)
            return v if math.isfinite(v) else None

        def fits(seq):
            return [{k: num(v) for k, v in d.items()} for d in seq]

        params = {}
        for i, n in enumerate(self.names):
            params[n] = {
                "value": num(self.values_[i]), "std": num(self.std_[i]),
                "ci95": [num(self.ci95_[i, 0]), num(self.ci95_[i, 1])],
                "nominal": num(self.nominal[i]),
                "bounds": [num(self.bounds[i, 0]), num(self.bounds[i, 1])],
                "unit": self.units[i], "identifiable": bool(self.identifiable_[i]),
                "at_bound": bool(self.at_bound_[i]),
            }
        return {
            "parameters": params,
            "correlation": [[num(c) for c in row] for row in self.correlation_],
            "recordings": list(self.sources),
            "fit_before": fits(self.fit_before),
            "fit_after": fits(self.fit_after),
            "fit_ms": fits(self.fit_ms_),
            "noise": fits(self.noise),
            "residual_rms": fits(self.residual_rms_),
            "residual_whiteness": fits(self.whiteness_),
            "integration_error": fits(self.integration_error_),
            "x0": [dict(zip(self.plant_.state_names, map(num, x))) for x in self.x0_],
            "cost": num(self.cost), "iterations": int(self.iterations),
            "status": self.status, "success": bool(self.success),
            "wall_time_s": num(self.wall_time),
            "poor_fit": bool(self.poor_fit), "message": self.message,
            "method": dict(self.method),
        }

    def table(self) -> str:
        """The estimates as a text table, with fits and the verdict."""
        rows = [("parameter", "nominal", "estimate", "std", "95 % interval", "unit", "")]
        for i, n in enumerate(self.names):
            flag = []
            if not self.identifiable_[i]:
                flag.append("not identifiable")
            if self.at_bound_[i]:
                flag.append("at bound")
            rows.append((n, f"{self.nominal[i]:.5g}", f"{self.values_[i]:.6g}",
                         f"{self.std_[i]:.2g}",
                         f"[{self.ci95_[i, 0]:.5g}, {self.ci95_[i, 1]:.5g}]",
                         self.units[i], ", ".join(flag)))
        widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
        lines = ["  ".join(r[c].ljust(widths[c]) for c in range(len(r))).rstrip() for r in rows]
        lines.insert(1, "-" * len(lines[0]))
        for k, (fb, fa) in enumerate(zip(self.fit_before, self.fit_after)):
            src = self.sources[k] if k < len(self.sources) else f"recording {k + 1}"
            sig = ", ".join(f"{s} {fb.get(s, float('nan')):.1f} -> {fa.get(s, float('nan')):.1f} %"
                            for s in fa)
            lines.append(f"fit {src}: {sig}")
        lines.append(f"IPOPT: {self.status}, {self.iterations} iterations, cost {self.cost:.4g}, "
                     f"{self.wall_time:.1f} s")
        lines.append(("POOR FIT: " if self.poor_fit else "") + self.message)
        return "\n".join(lines)
