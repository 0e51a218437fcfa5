"""Around the NMPC: a recorder of solve times, and do-mpc set up on the same problem
(the baseline of ``workbench bench mpc``)."""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from .controller import NMPC
from .model import V_SCALE, horizon_reference
from .results import StepInfo

__all__ = ["Recorder", "DoMPC"]


class Recorder:
    """Wraps a controller and keeps every update's wall time and (NMPC) StepInfo.

    Runs in :func:`workbench.simulate.closed_loop` like the controller it wraps.

    Attributes
    ----------
    times : list of float, s, wall time of each ``update``.
    infos : list of StepInfo (None for controllers without one).
    commands : list of float, V, the command returned (before the simulator clips it).
    """

    def __init__(self, controller) -> None:
        self.controller = controller
        self.sample_time = controller.sample_time
        self.times: list[float] = []
        self.infos: list[StepInfo | None] = []
        self.commands: list[float] = []

    @property
    def kind(self) -> str:
        return getattr(self.controller, "kind", type(self.controller).__name__)

    def reset(self):
        self.times.clear()
        self.infos.clear()
        self.commands.clear()
        return self.controller.reset()

    def update(self, state, r, y):
        t0 = time.perf_counter()
        new, u = self.controller.update(state, r, y)
        self.times.append(time.perf_counter() - t0)
        self.infos.append(getattr(new, "info", None))
        self.commands.append(float(u))
        return new, u


# ---------------------------------------------------------------------- do-mpc baseline
class DoMPC:
    """The same NMPC problem set up in do-mpc (optional baseline of ``workbench bench mpc``).

    do-mpc discretises the continuous model by its default orthogonal collocation
    (Radau, degree 2, one element per sample) and solves the NLP with IPOPT, its
    defaults (output silenced). Same horizon, scaled variables, cost (stage terms
    at nodes 1..N-1, terminal factor at N, command-move penalty including the last
    applied command) and limits (command range as bounds; stroke, pressure and speed
    as soft constraints with one slack per constraint over the horizon and the same
    L1 weight; ours adds a small quadratic slack term). The disturbance observer is
    not part of it: compare against ``disturbance_gain=0``.

    Needs ``do-mpc`` (5.1.2 works with CasADi 3.8); raises ImportError without it.
    do-mpc objects are mutable: the instance keeps the solver's memory itself.
    """

    def __init__(self, nmpc: NMPC) -> None:
        import warnings
        with warnings.catch_warnings():
            # do-mpc warns about its optional features (ONNX, OPC UA, torch) on import and
            # casadi about do-mpc's numpy calls on casadi values: noise for a baseline
            warnings.simplefilter("ignore")
            self._setup(nmpc)

    def _setup(self, nmpc: NMPC) -> None:
        import do_mpc
        self.version = getattr(do_mpc, "__version__", "?")
        self.nmpc = nmpc
        self.sample_time = nmpc.sample_time
        pb = nmpc._problem
        self._pb = pb
        model, syms = self._model(do_mpc, nmpc)
        mpc = do_mpc.controller.MPC(model)
        mpc.settings.n_horizon = pb.N
        mpc.settings.t_step = pb.T
        mpc.settings.store_full_solution = False
        mpc.settings.nl_cons_single_slack = True
        mpc.settings.supress_ipopt_output()
        self._cost_and_limits(mpc, *syms)
        self._reference(mpc)
        mpc.setup()
        self.mpc = mpc

    def _model(self, do_mpc, nmpc: NMPC):
        """The scaled continuous model z' = f(z sx, u_c + u_s w) / sx, the reference
        position r and rate vr as time-varying parameters; and the symbols z, r, vr."""
        pb = self._pb
        model = do_mpc.model.Model("continuous", "SX")
        z = model.set_variable("_x", "z", shape=(4, 1))
        w = model.set_variable("_u", "w")
        r = model.set_variable("_tvp", "r")
        vr = model.set_variable("_tvp", "vr")
        sx = ca.DM(pb.sx)
        m = nmpc.model
        model.set_rhs("z", m.f(z * sx, pb.u_c + pb.u_s * w, ca.DM(m.p0)) / sx)
        model.setup()
        return model, (z, r, vr)

    def _cost_and_limits(self, mpc, z, r, vr) -> None:
        """The NMPC's stage, terminal and move costs; command bounds; soft limits."""
        pb = self._pb
        wx, wv, wdu, rho1, _, lo, hi = pb.unpack(pb.P)
        wx_s, wv_s, tf = float(wx[0]), float(wv[0]), float(wx[-1] / wx[0])
        stage = 0.5 * (wx_s * (z[0] - r) ** 2 + wv_s * (z[1] - vr) ** 2)
        mpc.set_objective(lterm=stage, mterm=tf * stage)
        mpc.set_rterm(w=0.5 * float(wdu))
        mpc.bounds["lower", "_u", "w"] = pb.w_lo
        mpc.bounds["upper", "_u", "w"] = pb.w_hi
        names = {0: "stroke", 1: "speed", 2: "p_a", 3: "p_b"}
        for i, _ in pb.soft:
            mpc.set_nl_cons(f"{names[i]}_lo", float(lo[i]) - z[i], ub=0.0, soft_constraint=True,
                            penalty_term_cons=float(rho1))
            mpc.set_nl_cons(f"{names[i]}_hi", z[i] - float(hi[i]), ub=0.0, soft_constraint=True,
                            penalty_term_cons=float(rho1))

    def _reference(self, mpc) -> None:
        """The reference over the horizon from ``self._ref`` (now, previous), no preview."""
        pb, N = self._pb, self._pb.N
        tvp = mpc.get_tvp_template()
        self._ref = (0.0, None)

        def tvp_fun(t_now):
            r_now, r_prev = self._ref
            R, rate = horizon_reference(r_now, r_prev, pb.T, N, self.nmpc.reference_rate_limit)
            for k in range(N + 1):
                tvp["_tvp", k, "r"] = R[k] / pb.L
                tvp["_tvp", k, "vr"] = rate / V_SCALE
            return tvp

        mpc.set_tvp_fun(tvp_fun)

    @property
    def kind(self) -> str:
        return f"do-mpc {self.version} (IPOPT, N = {self._pb.N})"

    def reset(self):
        return None

    def update(self, state, r: float, y: dict):
        pb = self._pb
        z0 = np.array([y["x"], y["v"], y["p_a"], y["p_b"]]) / pb.sx
        if state is None:
            self.mpc.reset_history()
            self.mpc.x0 = z0
            self.mpc.u0 = np.zeros(1)
            self.mpc.set_initial_guess()
            self._ref = (float(r), None)
        else:
            self._ref = (float(r), state)
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            w = float(np.asarray(self.mpc.make_step(z0.reshape(-1, 1))).ravel()[0])
        return float(r), pb.u_c + pb.u_s * w
