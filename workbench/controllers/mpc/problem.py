"""The NMPC's optimal control problem, discretised: scaling, limits, weights, the
interval maps, the force observer, and the solvers built on them.

Built once per :class:`~workbench.controllers.mpc.NMPC` (it is immutable; the
compiled functions live here). The settings that may change without a rebuild are
packed into one vector ``P`` (see :meth:`Problem.unpack`), a parameter of every
compiled function.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .limits import FIRST_INTERVAL, interior_points
from .model import (NMPC_STATES, Q_SCALE, V_SCALE, friction_velocity, interior_map,
                    interval_maps, planning_model)
from .nlp import IpoptSolver
from .qp import sqp_step

__all__ = ["Problem"]


class Problem:
    """The discretised problem and its compiled functions (built once per NMPC).

    Parameters
    ----------
    c : NMPC
        The controller's settings (checked).

    Attributes
    ----------
    N, T, L : horizon, sample time (s), stroke (m).
    sx : (nx,) scales of x, v, p_a, p_b (m, m/s, Pa, Pa) and of the lumped lines'
        node pressures and flows (Pa, kg/s); nx 4 or 8, ``lines`` (8); u_c, u_s : command centre
        and span, V; w_lo, w_hi : scaled command range.
    lo, hi : scaled limits by state index; soft : (state index, slack index) of each
        soft limit; ns : number of slacks (stroke, pressure, speed).
    model : the model planned with (:func:`.model.planning_model`: without deadband
        and null offset); valve : its DeadbandInverse (plan -> valve command, V), or
        None.
    friction_width, substeps : m/s, tanh width of the predicted dry friction (None
        without), and the RK4 substeps per interval (:func:`.model.friction_velocity`:
        the NMPC's ``substeps``, more to resolve the friction).
    P : settings vector. F, Fj : interval map and its Jacobians (:mod:`.model`).
    points : the RK4 substep ends limited inside each interval
        (:func:`.limits.interior_points`; empty: limits at the nodes only).
    Fi, m_int : the states at those m_int points of an interval and their Jacobians
        (:func:`.model.interior_map`; None, 0: none).
    first_interior : the first interval whose interior points are limited
        (:data:`.limits.FIRST_INTERVAL`).
    n_rows : rows of the condensed QP.
    step : the SQP step function (:func:`.qp.sqp_step`).
    """

    def __init__(self, c) -> None:
        self.c = c
        # plans in the deadband-compensated command (model.planning_model)
        self.model, self.valve = planning_model(c.model)
        #: states predicted: x, v, p_a, p_b (measured), then the lumped lines' (estimated)
        self.nx = len(self.model.state_names)
        self.lines = self.nx > len(NMPC_STATES)
        self._scaling(self.model)
        self._limits(c)
        self.P = self._settings_vector(c)
        #: m/s, tanh width of the predicted dry friction (None: none), and the RK4
        #: substeps per interval that resolve it (:func:`.model.friction_velocity`)
        self.friction_width, self.substeps = friction_velocity(self.model, self.T, c.substeps,
                                                               c.friction_width)
        self.F, self.Fj = interval_maps(self.model, self.sx, self.u_c, self.u_s, self.T,
                                        self.substeps, c.sensitivities, self.friction_width)
        # limits also between the nodes, at RK4 substep ends at most LIMIT_SPACING apart
        # (not for IPOPT: cold-started, it did not converge in 300 iterations with them)
        self.points = (interior_points(self.T, self.substeps)
                       if c.interior_limits and c.mode != "ipopt" else ())
        self.Fi = interior_map(self.model, self.sx, self.u_c, self.u_s, self.T, self.substeps,
                               c.sensitivities, self.points,
                               self.friction_width) if self.points else None
        self.m_int = len(self.points)
        #: first interval with interior rows (:data:`.limits.FIRST_INTERVAL`)
        self.first_interior = FIRST_INTERVAL if self.m_int else 0
        #: rows of the condensed QP: lower and upper per soft limit, node and interior point
        self.n_rows = 2 * len(self.soft) * (self.N + (self.N - self.first_interior) * self.m_int)
        self.mass = float(self.model.params["load.mass"])
        # N, bound of the force estimate (anti wind-up)
        self.d_max = 0.5 * (self.p_sup - self.p_atm) * self.model.area_a
        self.step = sqp_step(self)
        self._ipopt: IpoptSolver | None = None
        #: the lumped lines' filter (:func:`.lines.line_filter`), None without lines
        self.line_step = self._line_step(c) if self.lines else None

    def _line_step(self, c):
        """The line-state filter, compiled to C with ``jit``."""
        from .lines import line_filter
        f = line_filter(self, c.pressure_noise)
        if c.jit:
            from ...integrate.jit import compiled
            f = compiled(f)
        return f

    def measured_state(self, zm: np.ndarray, state) -> tuple[np.ndarray, np.ndarray | None]:
        """(scaled state the plan starts from, line covariance) from the measured x, v,
        p_a, p_b (scaled) and the previous sample's memory (None: the first sample):
        with lumped lines their states estimated (:mod:`.lines`; at rest at the first
        sample and after a step that is not finite, as the compiled sample does), else
        ``zm``."""
        if not self.lines:
            return zm, None
        from .lines import line_start
        if state is None or getattr(state, "line_cov", None) is None:
            return line_start(zm, self.nx)
        z, Pl = self.line_step(np.asarray(state.z, dtype=float), float(state.u_prev),
                               float(state.d), zm[:len(NMPC_STATES)], state.line_cov)
        z, Pl = np.asarray(z, dtype=float).ravel(), np.asarray(Pl, dtype=float).ravel()
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(Pl))):
            return line_start(zm, self.nx)             # a failed step: the lines at rest
        return z, Pl

    def _scaling(self, m) -> None:
        """Horizon, sample time and the scales of states and command."""
        prm = m.params
        self.N = int(self.c.horizon)
        self.T = float(self.c.sample_time)
        self.L = L = float(m.stroke)
        self.p_sup = p_sup = float(prm["supply.pressure"])
        self.p_atm = float(prm["gas.atmospheric_pressure"])
        self.u_c = float(prm["valve.command_center"])
        self.u_s = float(prm["valve.command_span"])
        self.w_lo = (float(prm["valve.command_min"]) - self.u_c) / self.u_s
        self.w_hi = (float(prm["valve.command_max"]) - self.u_c) / self.u_s
        lines = [p_sup if n[7] == "p" else Q_SCALE for n in m.state_names[len(NMPC_STATES):]]
        self.sx = np.array([L, V_SCALE, p_sup, p_sup, *lines])

    def _limits(self, c) -> None:
        """Scaled limits of the constrained states and their slacks."""
        L, p_sup, p_atm = self.L, self.p_sup, self.p_atm
        mg = float(c.stroke_margin)
        pm = float(c.pressure_margin) / p_sup
        self.lo = {0: mg / L, 2: p_atm / p_sup + pm, 3: p_atm / p_sup + pm}
        self.hi = {0: (L - mg) / L, 2: 1.0 - pm, 3: 1.0 - pm}
        # soft constraints: (state index, slack index); slacks: stroke, pressure, speed
        self.soft = [(0, 0), (2, 1), (3, 1)]
        if c.max_speed is not None:
            self.lo[1], self.hi[1] = -c.max_speed / V_SCALE, c.max_speed / V_SCALE
            self.soft.append((1, 2))
        self.ns = 1 + max(j for _, j in self.soft)

    def _settings_vector(self, c) -> np.ndarray:
        """P: weights of the 1/2-sum-of-squares cost in scaled variables, slack weights,
        limits and the observer gain (the layout :meth:`unpack` reads)."""
        N, nx = self.N, self.nx
        wx = (self.L / c.position_tolerance) ** 2
        wv = (V_SCALE / c.velocity_tolerance) ** 2
        tf = float(c.terminal_factor)
        return np.concatenate([
            [wx] * (N - 1) + [tf * wx], [wv] * (N - 1) + [tf * wv],
            [(self.u_s / c.command_rate_tolerance) ** 2, *c.slack_weights],
            [self.lo.get(i, -1e3) for i in range(nx)], [self.hi.get(i, 1e3) for i in range(nx)],
            [c.disturbance_gain]])

    def command(self, w: float) -> float:
        """Valve command (V) for the scaled planned command ``w``."""
        u = self.u_c + self.u_s * w
        return u if self.valve is None else self.valve(u)

    def unpack(self, P):
        """(wx (N,), wv (N,), wdu, rho1, rho2, lo (4,), hi (4,)) from the settings vector."""
        N, nx = self.N, self.nx
        return (P[:N], P[N:2 * N], P[2 * N], P[2 * N + 1], P[2 * N + 2],
                P[2 * N + 3:2 * N + 3 + nx], P[2 * N + 3 + nx:2 * N + 3 + 2 * nx])

    def estimate(self, zprev, wprev, dprev, x0, est, gain):
        """Disturbance force (N) from the velocity the model predicted for this sample.

        d_k = d_{k-1} + gain m (v_pred - v_meas) / T, v_pred from the previous measured
        state and the command applied since; bounded by +-d_max. ``est`` 0 keeps
        d_{k-1}. Works on numbers and on CasADi MX alike.
        """
        vpred = self.F(zprev, wprev, dprev)[1]
        d = dprev + est * gain * self.mass * (vpred - x0[1]) * V_SCALE / self.T
        return ca.fmin(ca.fmax(d, -self.d_max), self.d_max)

    @property
    def ipopt(self) -> IpoptSolver:
        """The IPOPT solver of the full NLP, built on first use."""
        if self._ipopt is None:
            self._ipopt = IpoptSolver(self)
        return self._ipopt

