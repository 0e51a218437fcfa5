"""The plain baseline of ``workbench bench greybox``: scipy ``least_squares`` on CVODES.

What a competent user writes for the same problem (the same recording, the same four
parameters, the same plant equations ``plant.f``/``plant.h``) without the workbench's
estimator: *single shooting* -- replay the recorded command open loop with CasADi's
CVODES from an initial state that is fitted too, and hand the noise-normalised output
residuals to :func:`scipy.optimize.least_squares` (MINPACK Levenberg-Marquardt,
``method="lm"``, scipy's default tolerances). Parameters are fitted as
``log(value / start)`` (positive, scale-free), the initial state scaled by the plant's
state scales.

Choices, each measured on the 20 s recording of the bench (2 cores, loaded machine;
``/tmp`` scratch scripts of the session that wrote this module):

* *CVODES restarted at every command step.* The command is piecewise constant; one
  CasADi integrator per run of equal commands (with an output grid at the samples)
  restarts the BDF method at each discontinuity. One integrator over the whole record
  with the command as its piecewise-constant ``u`` does not restart: the replay of the
  true parameters then drifts 0.24 mm from the recording in 20 s at rtol 1e-9 (18
  noise levels rms; the fit converges to a wrong local minimum, errors 1e-3), and
  tighter tolerances fail at the first steps.
* *Tolerances rtol = atol = 1e-8* (states scaled to about 1): at 1e-6 the integration
  error biases the estimates by up to 1.5 standard deviations (sonic conductance), at
  1e-7 by 0.16, at 1e-8 by 0.05 of the estimate at 1e-10.
* *Finite-difference Jacobian* (forward differences, relative step 1e-4, well above the
  integration noise of 1e-8 and well below the parameters' curvature scale): eight
  extra replays (0.07 s each) cost 0.6 s per Jacobian, CasADi's forward sensitivities
  through CVODES (the augmented 36-state system) 1.0 s, and both reach the same
  estimates (to 1e-9 relative) in the same 6-7 iterations: finite differences are the
  stronger baseline here (``jacobian="sensitivities"`` runs the other).

It stops at scipy's default tolerances (ftol = xtol = gtol = 1e-8): on the bench's
20 s recording after 7 residual evaluations, with every estimate within 0.1 of a
standard deviation of the workbench's multiple-shooting estimate (the same maximum-
likelihood estimate; largest relative error from the truth 8.2e-6 against 8.6e-6).
"""

from __future__ import annotations

import time
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from ..errors import InputError, WorkbenchError
from ..output import reraise_interrupt

__all__ = ["DESCRIPTION", "RTOL", "ATOL", "DIFF_STEP", "fit"]

#: Relative and absolute CVODES tolerances (on states scaled by ``plant.state_scales()``).
RTOL: float = 1e-8
ATOL: float = 1e-8
#: Relative step of the forward-difference Jacobian (on the fitted, scaled variables).
DIFF_STEP: float = 1e-4

DESCRIPTION = ("scipy least_squares (MINPACK Levenberg-Marquardt, default tolerances) on "
               "a single-shooting replay: CasADi CVODES restarted at every command step "
               "(rtol = atol = 1e-8 on scaled states), the same 4 parameters (log-scaled) "
               "and the initial state fitted, residuals normalised by the sensor noise, "
               "forward-difference Jacobian (faster here than CVODES forward "
               "sensitivities at the same iterations)")


def _runs(u: np.ndarray) -> np.ndarray:
    """Start indices of the runs of equal commands in ``u`` (and ``len(u)`` last)."""
    return np.r_[0, np.flatnonzero(np.diff(u) != 0.0) + 1, len(u)]


class _Replay:
    """Outputs at the samples as a function of z = [log(theta / start), state0 / scale]."""

    def __init__(self, plant, names: Sequence[str], t: np.ndarray, u: np.ndarray,
                 signals: Sequence[str], rtol: float, atol: float) -> None:
        nx = len(plant.state_names)
        self.scale = plant.state_scales()
        idx = [plant.param_index(n) for n in names]
        self.start = plant.p0[idx]
        xs, th, us = ca.SX.sym("xs", nx), ca.SX.sym("th", len(names)), ca.SX.sym("u")
        p = ca.SX(ca.DM(plant.p0))
        for j, i in enumerate(idx):
            p[i] = self.start[j] * ca.exp(th[j])
        sc = ca.DM(self.scale)
        dae = {"x": xs, "p": ca.vertcat(th, us), "ode": plant.f(xs * sc, us, p) / sc}
        dt = float(t[1] - t[0])
        opts = {"abstol": atol, "reltol": rtol, "max_num_steps": 100000}
        integrators: dict[int, ca.Function] = {}
        z = ca.MX.sym("z", len(names) + nx)
        state, cols = z[len(names):], [z[len(names):]]
        uu = u[:-1]                       # u[k] holds over [t_k, t_k+1)
        b = _runs(uu)
        for a, e in zip(b[:-1], b[1:]):
            m = int(e - a)
            if m not in integrators:
                integrators[m] = ca.integrator(f"F{m}", "cvodes", dae, 0.0,
                                               list(dt * np.arange(1, m + 1)), opts)
            xf = integrators[m](x0=state, p=ca.vertcat(z[:len(names)], float(uu[a])))["xf"]
            cols.append(xf)
            state = xf[:, -1]
        X = ca.horzcat(*cols) * sc
        n = len(t)
        pz = ca.MX(ca.DM(plant.p0))
        for j, i in enumerate(idx):
            pz[i] = self.start[j] * ca.exp(z[j])
        Y = plant.h.map(n)(X, ca.DM(u.reshape(1, -1)), ca.repmat(pz, 1, n))
        rows = [plant.output_index(s) for s in signals]
        self._z, self._y = z, Y[rows, :]
        self.outputs = ca.Function("replay", [z], [self._y])
        self._jacobian: ca.Function | None = None
        self.segments = len(b) - 1
        self.integrators = len(integrators)

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """d vec(outputs') / dz by CVODES forward sensitivities (built on first use)."""
        if self._jacobian is None:
            self._jacobian = ca.Function("replay_jac", [self._z],
                                         [ca.jacobian(ca.vec(self._y.T), self._z)])
        return np.asarray(self._jacobian(z))


def _check(plant, recording, names: Sequence[str], noise: Mapping[str, float],
           signals: Sequence[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validated (t, u, measured outputs (nsig, N)); InputError naming the bad input."""
    t = np.asarray(recording.t, dtype=float)
    if len(t) < 3:
        raise InputError(f"recording: needs at least 3 samples, got {len(t)}")
    dt = np.diff(t)
    if not np.allclose(dt, dt[0], rtol=1e-6, atol=0.0) or dt[0] <= 0:
        raise InputError("recording: the baseline needs a uniform sample time")
    for name in names:
        if name not in plant.param_names:
            raise InputError(f"names: the plant has no parameter {name!r}")
        if not plant.p0[plant.param_index(name)] > 0:
            raise InputError(f"names: start value of {name!r} must be > 0 (log scale)")
    ymeas = []
    for s in signals:
        if not (s in noise and float(noise[s]) > 0):
            raise InputError(f"noise: needs a positive standard deviation for {s!r}")
        ymeas.append(np.asarray(recording[s], dtype=float))
    return t, np.asarray(recording["u"], dtype=float), np.vstack(ymeas)


def fit(plant, recording, names: Sequence[str], noise: Mapping[str, float],
        signals: Sequence[str] = ("x", "p_a", "p_b"), rtol: float = RTOL,
        atol: float = ATOL, jacobian: str = "differences",
        diff_step: float = DIFF_STEP) -> dict[str, Any]:
    """Fit ``names`` of ``plant`` (start values) to ``recording`` by single shooting.

    Parameters
    ----------
    plant : workbench.Plant
        The model, with the start values of the parameters (all > 0).
    recording : workbench.recording.Recording
        Uniformly sampled, with ``u`` (V) and the ``signals``.
    names : sequence of str
        Plant parameters to fit (dotted names).
    noise : mapping
        Standard deviation of each signal's sensor noise (SI): the residual weights.
    signals : sequence of str
        Measured outputs compared (default x (m), p_a, p_b (Pa)).
    rtol, atol : float
        CVODES tolerances (atol on states scaled by ``plant.state_scales()``).
    jacobian : {"differences", "sensitivities"}
        Forward differences (scipy, ``diff_step``) or CVODES forward sensitivities.
    diff_step : float
        Relative step of the forward differences (on the scaled variables).

    Returns
    -------
    dict
        ``estimates`` {name: value (SI)}, ``x0`` (initial state, SI), ``cost``
        (0.5 sum of squared normalised residuals), ``nfev`` (residual evaluations,
        finite-difference ones included), ``njev``, ``status``, ``message``,
        ``setup_s`` (building the replay, s), ``segments``, ``integrators``.
    """
    if jacobian not in ("differences", "sensitivities"):
        raise InputError(f"jacobian must be 'differences' or 'sensitivities', got {jacobian!r}")
    from scipy.optimize import least_squares
    t, u, ymeas = _check(plant, recording, names, noise, signals)
    sig = np.array([float(noise[s]) for s in signals]).reshape(-1, 1)
    t0 = time.perf_counter()
    rep = _Replay(plant, names, t, u, signals, rtol, atol)
    setup = time.perf_counter() - t0
    x0 = plant.initial_state(float(np.clip(recording["x"][0], 0.0, plant.stroke)),
                             p_a=float(recording["p_a"][0]), p_b=float(recording["p_b"][0]),
                             u0=float(u[0]))
    z0 = np.r_[np.zeros(len(names)), x0 / rep.scale]
    counts = [0, 0]

    def residuals(z):
        counts[0] += 1
        try:
            y = np.asarray(rep.outputs(z))
        except RuntimeError as exc:
            reraise_interrupt(exc)
            raise WorkbenchError(f"baseline replay failed: {str(exc).splitlines()[-1]}") from None
        return ((y - ymeas) / sig).ravel()

    def jac(z):
        counts[1] += 1
        return np.asarray(rep.jacobian(z)) / np.repeat(sig.ravel(), len(t))[:, None]

    if jacobian == "sensitivities":
        res = least_squares(residuals, z0, jac=jac, method="lm")
    else:
        res = least_squares(residuals, z0, jac="2-point", method="lm", diff_step=diff_step)
    k = len(names)
    return {"estimates": {n: float(rep.start[j] * np.exp(res.x[j])) for j, n in enumerate(names)},
            "x0": (res.x[k:] * rep.scale).tolist(), "cost": float(res.cost),
            "nfev": counts[0], "njev": counts[1], "status": int(res.status),
            "message": str(res.message), "setup_s": setup, "segments": rep.segments,
            "integrators": rep.integrators}
