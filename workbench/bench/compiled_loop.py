"""The benchmark's fast path: the whole sampled-data PID loop as compiled code.

:class:`CompiledLoop` integrates each control period with fixed steps of one of
:mod:`workbench.integrate`'s steppers (:func:`workbench.integrate.step_function`)
and runs the plant file's PID (:func:`workbench.controllers.pd.pid_law`); with
``jit=True`` a small C driver runs every period and substep without Python, built
into the one JIT cache (:func:`workbench.integrate.jit.shared_library`). Only
``workbench bench simulate`` and the tests use it: the simulator of the package is
:func:`workbench.simulate.closed_loop` (CVODES).
"""

from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ..controllers.pd import PID, clip_and_quantise, pid_law
from ..errors import InputError, WorkbenchError
from ..integrate import jit as jit_cache
from ..integrate.steppers import METHODS, step_function
from ..plant import Plant
from ..simulate import Trajectory, _initial, _outputs, _units

__all__ = ["CompiledLoop"]


class CompiledLoop:
    """The whole sampled-data PID loop as compiled code (fast path for long runs).

    Each control period is integrated with ``substeps`` fixed steps of an L-stable
    one-step method, built symbolically (SX) from the plant's ``f`` with the
    parameters folded in as constants:

    * ``"ros4"`` (default): the 4-stage Rosenbrock method of order 4 of Hairer &
      Wanner (L-stable), exact Jacobian at every step, 3 evaluations of ``f``;
    * ``"rodas4"``: RODAS, 6 stages, order 4, L-stable and stiffly accurate (5 of ``f``);
    * ``"radau"``: 3-stage Radau IIA (order 5) with ``newton_iterations`` simplified
      Newton iterations in the eigenbasis of the Butcher matrix (one real and one
      complex n x n system per step, Jacobian once per step, stages started from
      the previous step's collocation polynomial);
    * ``"ros2"``: the 2-stage Rosenbrock ROS2 (order 2): cheap and inaccurate.

    Rosenbrock methods are linearly implicit: no iteration, a fixed cost per step.
    The n x n solves are LU factorisations written out in the expression (no
    pivoting: the iteration matrices c I - J, c ~ 1/h, are dominated by their
    diagonal), so one step is a single straight-line function. With ``jit=True`` the
    control law, the step and the outputs are generated as C, and a small C driver
    runs every period and substep without Python; the shared library is built with
    the system C compiler once and kept in the one JIT cache
    (:func:`workbench.integrate.jit.shared_library`; :attr:`compile_s` is the time
    that took). Without a working compiler (:attr:`native_error`), or
    with ``jit=False``, the same kernels run as a CasADi ``mapaccum`` in the virtual
    machine, identical up to rounding.

    The controller law (:func:`workbench.controllers.pd.pid_law`), clipping and
    DAC/ADC quantisation are those of :func:`workbench.simulate.closed_loop`.
    The steps are fixed, so the accuracy is measured, not controlled: on the 25 mm
    reference plant the default 14 ROS4 substeps per 10 ms stay within ~2e-5 m of
    scipy Radau (rtol 1e-9) over 24 s of steps (``workbench bench simulate``; the
    error is set by the pressure laws' kinks, choked/subsonic and the laminar patch,
    not by stiffness). Runs that bounce on the end stops (a discontinuous contact
    force) or with stick-slip friction need many more substeps, and 1 m lines (kHz
    acoustic modes) about 100: use :func:`workbench.simulate.closed_loop` there, or
    compare the two.
    A run whose states stop being finite raises :class:`WorkbenchError`.
    """

    def __init__(self, plant: Plant, controller, substeps: int = 14, jit: bool = False,
                 method: str = "ros4",
                 params: Sequence[float] | None = None,
                 position_resolution: float | None = None,
                 command_resolution: float | None = None,
                 newton_iterations: int = 3) -> None:
        if method not in METHODS:
            raise InputError(f"method must be one of {', '.join(map(repr, METHODS))}, "
                             f"got {method!r}")
        if not isinstance(controller, PID):
            raise InputError("the compiled loop runs the plant file's P/PD/PID controller only")
        if int(substeps) < 1 or int(newton_iterations) < 1:
            raise InputError("substeps and newton_iterations must be at least 1")
        self.method = method
        self.plant, self.controller, self.substeps = plant, controller, int(substeps)
        self.newton_iterations = int(newton_iterations)
        self.params = np.asarray(plant.p0 if params is None else params, dtype=float)
        if self.params.shape != plant.p0.shape:
            raise InputError(f"expected {len(plant.p0)} parameters, got {self.params.shape}")
        prm = plant.params
        pos_res = position_resolution or prm.get("controller.position_resolution")
        cmd_res = command_resolution or prm.get("controller.command_resolution")
        nx = len(plant.states)
        T = controller.sample_time
        h = T / self.substeps
        p = ca.DM(self.params)
        self._ctrl = _pid_kernel(plant, controller, pos_res, cmd_res)
        xo, uo = ca.SX.sym("x", nx), ca.SX.sym("u")
        self._out = ca.Function("wb_out", [xo, uo], [ca.densify(plant.h(xo, uo, p))])
        self._kernel = step_function(method, lambda z, u: plant.f(z, u, p), nx, h,
                                     self.newton_iterations)
        nz = self._kernel.size1_in(2)
        # one control period (the virtual-machine path, and for inspection)
        xc = ca.MX.sym("xc", nx + _NC)
        r = ca.MX.sym("r")
        u, cnext = self._ctrl(xc[:nx], xc[nx:], r)
        zk, aux, traj = xc[:nx], ca.MX.zeros(nz), []
        for _ in range(self.substeps):
            zk, aux = self._kernel(zk, u, aux)
            traj.append(zk)
        #: one period: ([x; controller state], r) -> ([x; controller state] next, states at
        #: the substeps (nx x substeps), command held)
        self.period = ca.Function("period", [xc, r], [ca.vertcat(zk, cnext), ca.horzcat(*traj), u])
        self._jit = bool(jit)
        self._loops: dict[int, ca.Function] = {}
        self._native: _NativeLoop | None | bool = None
        #: seconds spent generating, compiling and loading the C loop (a fraction of a
        #: second when the library was already in the cache, see :attr:`compile_cached`)
        self.compile_s = 0.0
        self.compile_cached = False
        #: why the C loop is not used, when ``jit=True`` but it could not be built
        self.native_error: str | None = None

    def compile(self) -> bool:
        """Build the C loop (or load it from the cache); False when that is not possible."""
        if self._native is None:
            import time
            t0 = time.perf_counter()
            try:
                self._native = _NativeLoop.build(self._ctrl, self._kernel, self._out,
                                                 self.substeps)
                self.compile_cached = self._native.cached
            except _NativeUnavailable as exc:
                self._native, self.native_error = False, str(exc)
            self.compile_s = time.perf_counter() - t0
        return bool(self._native)

    @property
    def native(self) -> bool:
        """Whether :meth:`run` executes the compiled C loop."""
        return self._jit and self.compile()

    def _loop(self, n: int) -> ca.Function:
        if n not in self._loops:
            self._loops[n] = self.period.mapaccum("loop", n, [0], [0])
        return self._loops[n]

    def run(self, reference, t_end: float, x0, every_substep: bool = False) -> Trajectory:
        """Simulate to ``t_end``: states at every control instant (or every substep).

        Parameters
        ----------
        reference : callable r(t) in m, sampled at the control instants.
        t_end : s, rounded down to whole control periods.
        x0 : full initial state, or a position (m) to start at rest.
        every_substep : report at every substep instead of every control instant.
        """
        T = self.controller.sample_time
        n = int(np.floor(t_end / T + 1e-9))
        if n < 1:
            raise InputError(f"t_end must cover at least one control period ({T:g} s)")
        t_ctrl = T * np.arange(n + 1)
        r_all = np.asarray(reference(t_ctrl), dtype=float).ravel()
        r = r_all[:n]
        state = _initial(self.plant, x0)
        nx, m = len(state), self.substeps
        xc0 = np.concatenate((state, np.zeros(_NC)))
        native = self._native if self.native else None
        if native:
            traj, u, xc_end = native(xc0, r, every_substep)
        else:
            xcs, traj, u = self._loop(n)(xc0, r.reshape(1, -1))
            xc_end = np.asarray(xcs)[:, -1]
            traj = np.asarray(traj).T                     # (n * m, nx)
            if not every_substep:
                traj = traj[m - 1::m]
            u = np.asarray(u).ravel()
        if not np.all(np.isfinite(traj)):
            raise WorkbenchError(f"the compiled loop ({self.method}, {m} substeps per period) "
                                 "diverged; use more substeps or simulate.closed_loop")
        states = np.vstack((state, traj))
        # the command the controller would apply at t_end, for a complete last row
        u_last = float(self._ctrl(xc_end[:nx], xc_end[nx:], r_all[n])[0])
        if every_substep:
            t = np.concatenate(([0.0], np.arange(1, n * m + 1) * (T / m)))
            u_full = np.concatenate((np.repeat(u, m), [u_last]))
            r_full = np.concatenate((np.repeat(r, m), [r_all[n]]))
        else:
            t = t_ctrl
            u_full = np.append(u, u_last)
            r_full = r_all
        if native:
            outs = native.outputs(states, u_full)
        else:
            outs = _outputs(self.plant, self.params, states, u_full)
        return Trajectory(time=t, states=states, inputs=u_full.reshape(-1, 1), outputs=outs,
                          state_names=self.plant.state_names,
                          output_names=self.plant.output_names, reference=r_full,
                          units=_units(self.plant),
                          info={"mode": "closed_loop", "method": f"{self.method}-compiled",
                                "substeps": m, "sample_time": T, "native": bool(native)})


#: controller state carried by the compiled loop: previous error, integral, started flag
_NC = 3


def _pid_kernel(plant: Plant, c, pos_res: float | None, cmd_res: float | None) -> ca.Function:
    """The PID law of :func:`workbench.simulate.closed_loop` as
    ``wb_ctrl(x, cstate, r) -> (u, cstate_next)`` (ADC step ``pos_res`` m, DAC step
    ``cmd_res`` V)."""
    nx = len(plant.states)
    xs = ca.SX.sym("x", nx)
    cs = ca.SX.sym("c", _NC)
    r = ca.SX.sym("r")
    ix = plant.state_index("x")
    y = xs[ix] if not pos_res else ca.floor(xs[ix] / pos_res + 0.5) * pos_res
    e = r - y
    e_prev = ca.if_else(cs[2] > 0, cs[0], e)
    u, integ = pid_law(e, e_prev, cs[1], c.kp, c.kd, c.ki, c.sample_time, c.u_center,
                       c.u_min, c.u_max)
    prm = plant.params
    u = clip_and_quantise(u, prm["valve.command_min"], prm["valve.command_max"], cmd_res)
    return ca.Function("wb_ctrl", [xs, cs, r],
                       [ca.densify(u), ca.densify(ca.vertcat(e, integ, 1.0))])


# -- the C loop
class _NativeUnavailable(Exception):
    """No C compiler, or the loop did not compile."""


def work_c(step: str) -> str:
    """C of the work buffers shared by ``wb_ctrl``, ``wb_<step>`` and ``wb_out`` (one
    allocation sized for the largest), used by the compiled loops of this package."""
    return _WORK_C.replace("wb_step_work", f"wb_{step}_work")


def outputs_c(name: str) -> str:
    """C of ``name(n, x, u, y)``: the plant outputs y (n x WB_NY) for n rows of states."""
    return _OUTPUTS_C.replace("wb_outputs", name)


_WORK_C = r"""typedef struct {
  const casadi_real** arg;
  casadi_real** res;
  casadi_int* iw;
  casadi_real* w;
} wb_work;

static void wb_grow(casadi_int* mx, casadi_int v) { if (v > *mx) *mx = v; }

static int wb_alloc(wb_work* m) {
  casadi_int na, nr, ni, nw, ma = 3, mr = 2, mi = 1, mw = 1;
  wb_ctrl_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  wb_step_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  wb_out_work(&na, &nr, &ni, &nw);
  wb_grow(&ma, na); wb_grow(&mr, nr); wb_grow(&mi, ni); wb_grow(&mw, nw);
  m->arg = (const casadi_real**) malloc(sizeof(casadi_real*) * ma);
  m->res = (casadi_real**) malloc(sizeof(casadi_real*) * mr);
  m->iw = (casadi_int*) malloc(sizeof(casadi_int) * mi);
  m->w = (casadi_real*) malloc(sizeof(casadi_real) * mw);
  return !m->arg || !m->res || !m->iw || !m->w;
}

static void wb_free(wb_work* m) {
  free((void*) m->arg); free(m->res); free(m->iw); free(m->w);
}

"""

_OUTPUTS_C = r"""/* The plant outputs y (n x WB_NY) for rows of states x (n x WB_NX) and commands u. */
CASADI_SYMBOL_EXPORT int wb_outputs(casadi_int n, const casadi_real* x, const casadi_real* u,
                                    casadi_real* y) {
  casadi_int k;
  wb_work m;
  int flag = wb_alloc(&m) ? 2 : 0;
  for (k = 0; k < n && !flag; ++k) {
    m.arg[0] = x + k * WB_NX; m.arg[1] = u + k; m.res[0] = y + k * WB_NY;
    if (wb_out(m.arg, m.res, m.iw, m.w, 0)) flag = 1;
  }
  wb_free(&m);
  return flag;
}
"""


_DRIVER_C = r"""
#include <stdlib.h>

/* workbench.bench.compiled_loop: n control periods, each wb_ctrl then WB_M x wb_step */
#define WB_NX %(nx)d
#define WB_NC %(nc)d
#define WB_NZ %(nz)d
#define WB_NY %(ny)d
#define WB_M %(m)d

%(work)s
/* Runs n periods from [x; controller state] xc0 with references r[0..n-1]. Writes the
   states after every substep (every != 0, n * WB_M rows) or every period (n rows) to
   traj, the commands to u_out and the final [x; controller state] to xc_end. */
CASADI_SYMBOL_EXPORT int wb_loop(casadi_int n, const casadi_real* xc0, const casadi_real* r,
                                 casadi_int every, casadi_real* traj, casadi_real* u_out,
                                 casadi_real* xc_end) {
  casadi_int i, k, s;
  casadi_real x[WB_NX], xn[WB_NX], c[WB_NC], cn[WB_NC], z[WB_NZ + 1], zn[WB_NZ + 1], u = 0.;
  wb_work m;
  int flag = wb_alloc(&m) ? 2 : 0;
  for (i = 0; i < WB_NX; ++i) x[i] = xc0[i];
  for (i = 0; i < WB_NC; ++i) c[i] = xc0[WB_NX + i];
  for (k = 0; k < n && !flag; ++k) {
    m.arg[0] = x; m.arg[1] = c; m.arg[2] = r + k;
    m.res[0] = &u; m.res[1] = cn;
    if (wb_ctrl(m.arg, m.res, m.iw, m.w, 0)) { flag = 1; break; }
    u_out[k] = u;
    for (i = 0; i < WB_NC; ++i) c[i] = cn[i];
    for (i = 0; i < WB_NZ; ++i) z[i] = 0.;
    for (s = 0; s < WB_M; ++s) {
      m.arg[0] = x; m.arg[1] = &u; m.arg[2] = z;
      m.res[0] = xn; m.res[1] = zn;
      if (wb_step(m.arg, m.res, m.iw, m.w, 0)) { flag = 1; break; }
      for (i = 0; i < WB_NX; ++i) x[i] = xn[i];
      for (i = 0; i < WB_NZ; ++i) z[i] = zn[i];
      if (every) for (i = 0; i < WB_NX; ++i) traj[(k * WB_M + s) * WB_NX + i] = x[i];
    }
    if (!every) for (i = 0; i < WB_NX; ++i) traj[k * WB_NX + i] = x[i];
  }
  for (i = 0; i < WB_NX; ++i) xc_end[i] = x[i];
  for (i = 0; i < WB_NC; ++i) xc_end[WB_NX + i] = c[i];
  wb_free(&m);
  return flag;
}

%(outputs)s"""


#: compiler flags of the C loop. C89 makes CasADi's fmin/fmax plain comparisons instead
#: of libm calls, and without semantic interposition they (and sign, fabs) are inlined
#: in the shared object (together ~1.6x faster); no errno, traps or signed zeros, and
#: x/c as x*(1/c) (last-bit changes only; not -ffast-math, whose shared objects switch
#: denormals off process-wide). The second set is the fallback for other compilers.
#: (``-shared -fPIC`` are added by :func:`workbench.integrate.jit.shared_library`.)
_CFLAGS = ("-O2", "-std=c89", "-fno-math-errno", "-fno-trapping-math", "-fno-signed-zeros",
           "-freciprocal-math", "-fno-semantic-interposition")
_CFLAGS_FALLBACK = ("-O2",)


class _NativeLoop:
    """The compiled loop: a shared library with ``wb_loop`` and ``wb_outputs``."""

    def __init__(self, path: str, nx: int, ny: int, m: int, cached: bool = False) -> None:
        import ctypes
        self.path, self.nx, self.ny, self.m, self.cached = path, nx, ny, m, cached
        self._lib = ctypes.CDLL(path)
        P = ctypes.POINTER(ctypes.c_double)
        n_t = ctypes.c_longlong
        self._loop = self._lib.wb_loop
        self._loop.argtypes = [n_t, P, P, n_t, P, P, P]
        self._loop.restype = ctypes.c_int
        self._out = self._lib.wb_outputs
        self._out.argtypes = [n_t, P, P, P]
        self._out.restype = ctypes.c_int
        self._P = P

    @classmethod
    def build(cls, ctrl: ca.Function, kernel: ca.Function, out: ca.Function,
              substeps: int) -> "_NativeLoop":
        """Generate the C of the kernels and the driver; build it into the JIT cache."""
        cg = ca.CodeGenerator("wb_loop.c", {"with_header": False})
        for fn in (ctrl, kernel, out):
            cg.add(fn)
        nx, nz, ny = kernel.size1_in(0), kernel.size1_in(2), out.size1_out(0)
        src = cg.dump() + _DRIVER_C % {"nx": nx, "nc": _NC, "nz": nz, "ny": ny, "m": substeps,
                                  "work": work_c("step"), "outputs": outputs_c("wb_outputs")}
        try:
            so, cached = jit_cache.shared_library("wb_loop", src, (_CFLAGS, _CFLAGS_FALLBACK))
        except jit_cache.CompileError as exc:
            raise _NativeUnavailable(str(exc)) from None
        try:
            return cls(str(so), nx, ny, substeps, cached)
        except (OSError, AttributeError) as exc:
            raise _NativeUnavailable(f"the C loop did not load: {exc}") from None

    def _ptr(self, a: np.ndarray):
        return a.ctypes.data_as(self._P)

    def __call__(self, xc0: np.ndarray, r: np.ndarray, every_substep: bool):
        """(states after each period or substep (rows, nx), commands (n,), final [x; c])."""
        n = len(r)
        traj = np.empty((n * self.m if every_substep else n, self.nx))
        u = np.empty(n)
        xc_end = np.empty(len(xc0))
        xc0 = np.ascontiguousarray(xc0, dtype=float)
        r = np.ascontiguousarray(r, dtype=float)
        flag = self._loop(n, self._ptr(xc0), self._ptr(r), int(bool(every_substep)),
                          self._ptr(traj), self._ptr(u), self._ptr(xc_end))
        if flag:
            raise WorkbenchError(f"the compiled loop failed (code {flag})")
        return traj, u, xc_end

    def outputs(self, states: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Plant outputs (rows, ny) for rows of states and commands."""
        states = np.ascontiguousarray(states, dtype=float)
        u = np.ascontiguousarray(u, dtype=float)
        y = np.empty((len(states), self.ny))
        if self._out(len(states), self._ptr(states), self._ptr(u), self._ptr(y)):
            raise WorkbenchError("the compiled outputs failed")
        return y
