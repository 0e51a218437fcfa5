"""The sampled-data PID loop as compiled code, with steps chosen by a stated tolerance.

:class:`AdaptiveLoop` is :class:`.compiled_loop.CompiledLoop` with error control
instead of a fixed number of substeps: every control period is integrated by ROS4
steps whose size the embedded error estimate chooses (:mod:`workbench.integrate.adaptive`),
so the run takes few steps at rest and many through the transients and the kinks of
the valve law. With a C compiler the controller, the steps and the step-size
controller run in one C function (built into the one JIT cache); without one, the
same controller runs in Python on the same CasADi step (slow, identical results up
to rounding).
"""

from __future__ import annotations

import time
from typing import Sequence

import casadi as ca
import numpy as np

from ..controllers.pd import PID
from ..errors import InputError, WorkbenchError
from ..integrate import adaptive
from ..integrate import jit as jit_cache
from ..plant import Plant
from ..simulate import Trajectory, _initial, _outputs, _units
from .compiled_loop import _CFLAGS, _CFLAGS_FALLBACK, _NC, _pid_kernel, outputs_c, work_c

__all__ = ["AdaptiveLoop", "DEFAULT_TOLERANCE"]

#: default tolerance (-): the stated accuracy, 0.1 %, as the relative tolerance and, times
#: :meth:`Plant.state_scales` (stroke, 1 m/s, 1 bar, ...), the absolute one of every
#: state, on the local error of each step. The global error is measured, not promised:
#: on the 25 mm rig's 24 s step profile the position stays within ~1e-4 of the stroke
#: of scipy Radau at rtol 1e-9, with 1 m lines within ~1e-5 (``workbench bench simulate``).
DEFAULT_TOLERANCE = 1e-3


class AdaptiveLoop:
    """The whole sampled-data PID loop, error-controlled ROS4 steps, compiled to C.

    Parameters
    ----------
    plant : the plant (any states: lines, valve dynamics, friction...).
    controller : the plant file's :class:`~workbench.controllers.pd.PID`.
    tolerance : relative tolerance, and the absolute one per state scale (-); the
        local error of every step is within it (max norm).
    jit : run the C loop (falls back to Python when there is no compiler).
    params : plant parameters (default the plant's).
    position_resolution, command_resolution : ADC step (m), DAC step (V); default
        the plant file's.

    The controller law, clipping and quantisation are those of
    :func:`workbench.simulate.closed_loop`.
    """

    def __init__(self, plant: Plant, controller, tolerance: float = DEFAULT_TOLERANCE,
                 jit: bool = True, params: Sequence[float] | None = None,
                 position_resolution: float | None = None,
                 command_resolution: float | None = None) -> None:
        if not isinstance(controller, PID):
            raise InputError("the compiled loop runs the plant file's P/PD/PID controller only")
        tolerance = float(tolerance)
        if not 1e-12 <= tolerance <= 0.1:
            raise InputError(f"tolerance must be in [1e-12, 0.1], got {tolerance:g}")
        self.plant, self.controller, self.tolerance = plant, controller, tolerance
        self.params = np.asarray(plant.p0 if params is None else params, dtype=float)
        if self.params.shape != plant.p0.shape:
            raise InputError(f"expected {len(plant.p0)} parameters, got {self.params.shape}")
        prm = plant.params
        pos_res = position_resolution or prm.get("controller.position_resolution")
        cmd_res = command_resolution or prm.get("controller.command_resolution")
        nx = len(plant.states)
        p = ca.DM(self.params)
        self._ctrl = _pid_kernel(plant, controller, pos_res, cmd_res)
        xo, uo = ca.SX.sym("x", nx), ca.SX.sym("u")
        self._out = ca.Function("wb_out", [xo, uo], [ca.densify(plant.h(xo, uo, p))])
        self._step = adaptive.embedded_step_function(
            lambda z, u: plant.f(z, u, p), nx, tolerance * plant.state_scales(), tolerance)
        self._jit = bool(jit)
        self._native = None
        #: seconds spent generating, compiling and loading the C loop
        self.compile_s = 0.0
        self.compile_cached = False
        #: why the C loop is not used, when ``jit=True`` but it could not be built
        self.native_error: str | None = None

    def compile(self) -> bool:
        """Build the C loop (or load it from the cache); False when that is not possible."""
        if self._native is None:
            t0 = time.perf_counter()
            try:
                self._native = _NativeAdaptive.build(self._ctrl, self._step, self._out)
                self.compile_cached = self._native.cached
            except _Unavailable as exc:
                self._native, self.native_error = False, str(exc)
            self.compile_s = time.perf_counter() - t0
        return bool(self._native)

    @property
    def native(self) -> bool:
        """Whether :meth:`run` executes the compiled C loop."""
        return self._jit and self.compile()

    def run(self, reference, t_end: float, x0) -> Trajectory:
        """Simulate to ``t_end`` (s, whole control periods); states at the control instants.

        ``info`` of the result holds ``steps`` (accepted) and ``rejected``.
        """
        T = self.controller.sample_time
        n = int(np.floor(t_end / T + 1e-9))
        if n < 1:
            raise InputError(f"t_end must cover at least one control period ({T:g} s)")
        t_ctrl = T * np.arange(n + 1)
        r_all = np.asarray(reference(t_ctrl), dtype=float).ravel()
        state = _initial(self.plant, x0)
        nx = len(state)
        xc0 = np.concatenate((state, np.zeros(_NC)))
        if self.native:
            traj, u, xc_end, acc, rej = self._native(xc0, r_all[:n], T)
        else:
            traj, u, xc_end, acc, rej = self._python(xc0, r_all[:n], T)
        if not np.all(np.isfinite(traj)):
            raise WorkbenchError("the error-controlled loop diverged")
        states = np.vstack((state, traj))
        u_last = float(self._ctrl(xc_end[:nx], xc_end[nx:], r_all[n])[0])
        u_full = np.append(u, u_last)
        outs = (self._native.outputs(states, u_full) if self.native
                else _outputs(self.plant, self.params, states, u_full))
        return Trajectory(time=t_ctrl, states=states, inputs=u_full.reshape(-1, 1),
                          outputs=outs, state_names=self.plant.state_names,
                          output_names=self.plant.output_names, reference=r_all,
                          units=_units(self.plant),
                          info={"mode": "closed_loop", "method": "ros4-adaptive-compiled",
                                "tolerance": self.tolerance, "steps": int(acc),
                                "rejected": int(rej), "sample_time": T,
                                "native": bool(self.native)})

    def _python(self, xc0: np.ndarray, r: np.ndarray, T: float):
        """The same loop in Python (no C compiler)."""
        nx = len(self.plant.states)
        x, c = xc0[:nx].copy(), xc0[nx:].copy()
        traj, us = np.empty((len(r), nx)), np.empty(len(r))
        h, acc, rej = 0.25 * T, 0, 0
        for k, rk in enumerate(r):
            u, cn = self._ctrl(x, c, rk)
            us[k], c = float(u), np.asarray(cn, dtype=float).ravel()
            try:
                x, h, a, b = adaptive.advance(self._step, x, us[k], T, h)
            except FloatingPointError as exc:
                raise WorkbenchError(f"the error-controlled loop failed at t = {k * T:g} s: "
                                     f"{exc}") from None
            acc, rej = acc + a, rej + b
            traj[k] = x
        return traj, us, np.concatenate((x, c)), acc, rej


class _Unavailable(Exception):
    """No C compiler, or the loop did not compile."""


_DRIVER_C = r"""
#include <stdlib.h>

/* workbench.bench.adaptive_loop: n control periods, each wb_ctrl then error-controlled
   wb_astep steps to the end of the period */
#define WB_NX %(nx)d
#define WB_NC %(nc)d
#define WB_NY %(ny)d
#define WB_SAFETY %(safety)r
#define WB_FAC_MIN %(fac_min)r
#define WB_FAC_MAX %(fac_max)r
#define WB_MAX_STEPS %(max_steps)d

%(work)s
%(advance)s
/* n periods of length T from [x; controller state] xc0, references r[0..n-1]; states
   at the period ends to traj (n x WB_NX), commands to u_out, final [x; c] to xc_end,
   accepted and rejected steps to counts[0], counts[1], a failing period to counts[2]. */
CASADI_SYMBOL_EXPORT int wb_aloop(casadi_int n, const casadi_real* xc0, const casadi_real* r,
                                  casadi_real T, casadi_real* traj, casadi_real* u_out,
                                  casadi_real* xc_end, long long* counts) {
  casadi_int i, k;
  casadi_real x[WB_NX], c[WB_NC], cn[WB_NC], u = 0., h = 0.25 * T;
  wb_work m;
  int flag = wb_alloc(&m) ? 2 : 0;
  counts[0] = 0; counts[1] = 0;
  for (i = 0; i < WB_NX; ++i) x[i] = xc0[i];
  for (i = 0; i < WB_NC; ++i) c[i] = xc0[WB_NX + i];
  for (k = 0; k < n && !flag; ++k) {
    m.arg[0] = x; m.arg[1] = c; m.arg[2] = r + k;
    m.res[0] = &u; m.res[1] = cn;
    if (wb_ctrl(m.arg, m.res, m.iw, m.w, 0)) { flag = 1; break; }
    u_out[k] = u;
    for (i = 0; i < WB_NC; ++i) c[i] = cn[i];
    flag = wb_advance(&m, x, u, T, &h, counts, counts + 1);
    if (flag) { counts[2] = k; break; }
    for (i = 0; i < WB_NX; ++i) traj[k * WB_NX + i] = x[i];
  }
  for (i = 0; i < WB_NX; ++i) xc_end[i] = x[i];
  for (i = 0; i < WB_NC; ++i) xc_end[WB_NX + i] = c[i];
  wb_free(&m);
  return flag;
}

%(outputs)s"""


class _NativeAdaptive:
    """The compiled error-controlled loop: ``wb_aloop`` and ``wb_aoutputs``."""

    def __init__(self, path: str, nx: int, ny: int, cached: bool) -> None:
        import ctypes
        self.nx, self.ny, self.cached = nx, ny, cached
        lib = ctypes.CDLL(path)
        P = ctypes.POINTER(ctypes.c_double)
        n_t = ctypes.c_longlong
        self._loop = lib.wb_aloop
        self._loop.argtypes = [n_t, P, P, ctypes.c_double, P, P, P,
                               ctypes.POINTER(ctypes.c_longlong)]
        self._loop.restype = ctypes.c_int
        self._out = lib.wb_aoutputs
        self._out.argtypes = [n_t, P, P, P]
        self._out.restype = ctypes.c_int
        self._lib, self._P, self._ct = lib, P, ctypes

    @classmethod
    def build(cls, ctrl: ca.Function, step: ca.Function, out: ca.Function) -> "_NativeAdaptive":
        cg = ca.CodeGenerator("wb_aloop.c", {"with_header": False})
        for fn in (ctrl, step, out):
            cg.add(fn)
        nx, ny = step.size1_in(0), out.size1_out(0)
        src = cg.dump() + _DRIVER_C % {
            "nx": nx, "nc": _NC, "ny": ny, "safety": adaptive.SAFETY,
            "fac_min": adaptive.FAC_MIN, "fac_max": adaptive.FAC_MAX,
            "max_steps": adaptive.MAX_STEPS, "advance": adaptive.ADVANCE_C,
            "work": work_c("astep"), "outputs": outputs_c("wb_aoutputs")}
        try:
            so, cached = jit_cache.shared_library("wb_aloop", src, (_CFLAGS, _CFLAGS_FALLBACK))
        except jit_cache.CompileError as exc:
            raise _Unavailable(str(exc)) from None
        try:
            return cls(str(so), nx, ny, cached)
        except (OSError, AttributeError) as exc:
            raise _Unavailable(f"the C loop did not load: {exc}") from None

    def _ptr(self, a: np.ndarray):
        return a.ctypes.data_as(self._P)

    def __call__(self, xc0: np.ndarray, r: np.ndarray, T: float):
        n = len(r)
        traj, u, xc_end = np.empty((n, self.nx)), np.empty(n), np.empty(len(xc0))
        counts = np.zeros(3, dtype=np.int64)
        xc0 = np.ascontiguousarray(xc0, dtype=float)
        r = np.ascontiguousarray(r, dtype=float)
        flag = self._loop(n, self._ptr(xc0), self._ptr(r), float(T), self._ptr(traj),
                          self._ptr(u), self._ptr(xc_end),
                          counts.ctypes.data_as(self._ct.POINTER(self._ct.c_longlong)))
        if flag:
            raise WorkbenchError(f"the error-controlled loop failed at t = {counts[2] * T:g} s "
                                 f"(code {flag}: {'step size collapsed' if flag == 3 else 'step'})")
        return traj, u, xc_end, int(counts[0]), int(counts[1])

    def outputs(self, states: np.ndarray, u: np.ndarray) -> np.ndarray:
        states = np.ascontiguousarray(states, dtype=float)
        u = np.ascontiguousarray(u, dtype=float)
        y = np.empty((len(states), self.ny))
        if self._out(len(states), self._ptr(states), self._ptr(u), self._ptr(y)):
            raise WorkbenchError("the compiled outputs failed")
        return y
