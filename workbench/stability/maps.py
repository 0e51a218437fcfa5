"""Stability maps: sweep two parameters, colour the plane by the largest closed-loop pole.

Every point of a map is the *exact* sampled-data loop: the plant's equilibrium at
the swept parameters, its tangent model from CasADi, ZOH discretisation at the
controller's sample time, the discrete PID (and any computation delay) closed
around the position, and the eigenvalues of the closed loop. The colour is the
largest pole magnitude |z|max; |z|max < 1 is stable.

Over the map the classical boundaries are drawn for a P controller: the
continuous Hurwitz limit K0 = 2 zeta w0 and the PCT limit K0 = 2 zeta / Ts,
Ts = T/2 + 1/w0, with w0, zeta and Kv of the dominant mode pair of the tangent
model at each point.

Speed comes from doing all points of a block in one call: the equilibria by a
fixed Gauss-Newton iteration and the Jacobians in one compiled CasADi function
mapped over the block, the discretisation (batched Pade expm) and eigenvalues in
batched NumPy. Blocks run on all local cores (forked worker processes) or on a Dask
cluster (``scheduler="tcp://..."``).

Examples
--------
>>> from workbench import Plant
>>> from workbench.stability import maps
>>> plant = Plant.from_toml("designs/plants/situm_rodless.toml")        # doctest: +SKIP
>>> m = maps.stability_map(plant, maps.Axis.linspace("kp", 1, 40, 100),
...                        maps.Axis.linspace("load.mass", 0.5, 5, 100))  # doctest: +SKIP
>>> m.stable.mean()                                                      # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .. import _jit
from ..errors import InputError, WorkbenchError
from ..plant import Plant

__all__ = ["Axis", "StabilityMap", "stability_map", "parse_axis", "expm_batched",
           "AXIS_ALIASES", "CONTROLLER_AXES"]

#: Short names accepted for common plant parameters.
AXIS_ALIASES = {
    "mass": "load.mass",
    "payload": "load.mass",
    "supply_pressure": "supply.pressure",
    "supply": "supply.pressure",
    "line_length": "lines.length",
    "viscous_friction": "load.viscous_friction",
    "bore": "cylinder.bore",
    "T": "sample_time",
    "x": "position",
}

#: Axes that belong to the controller (no re-linearisation), with units.
CONTROLLER_AXES = {"kp": "V/m", "kd": "V s/m", "ki": "V/(m s)", "k0": "1/s",
                   "sample_time": "s"}

#: Gauss-Newton iterations on the pinned model, then on the real model. The pinned
#: model converges quadratically from the scaled nominal guess (residual < 1e-12
#: after 5-6 steps for the reference plants); the real-model steps are ~0 unless
#: the plant leaks.
_PINNED_ITERATIONS = 6
_REAL_ITERATIONS = 2
#: Points whose scaled equilibrium residual exceeds this are re-solved one by one
#: with the robust :func:`workbench.linearize.operating_point`.
_RESIDUAL_TOL = 1e-8
#: A closed-loop mode whose (scaled) controllability from r times observability in x
#: is below this is hidden (e.g. the pressure-sum mode of a closed-centre valve
#: without leakage, eigenvalue exactly 1): it does not take part in positioning.
_HIDDEN_TOL = 1e-10
#: Map size (points) from which the CasADi functions are compiled to C.
_COMPILE_ABOVE = 4000


# ------------------------------------------------------------------------ axes
def _units_of(plant: Plant | None, name: str) -> str:
    if name in CONTROLLER_AXES:
        return CONTROLLER_AXES[name]
    if name == "position":
        return "m"
    from ..params import SCHEMA
    for key in SCHEMA:
        if f"{key.section}.{key.name}" == name:
            return key.unit
    return ""


@dataclass(frozen=True)
class Axis:
    """One swept quantity: a plant parameter (dotted name, SI), ``position`` (m),
    or a controller quantity (``kp``, ``kd``, ``ki``, ``k0`` = kp*Kv in 1/s,
    ``sample_time``)."""

    name: str
    values: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        name = AXIS_ALIASES.get(self.name, self.name)
        object.__setattr__(self, "name", name)
        vals = np.asarray(self.values, dtype=float).ravel()
        if vals.size < 2:
            raise InputError(f"axis {name!r} needs at least 2 values")
        if not np.all(np.isfinite(vals)):
            raise InputError(f"axis {name!r} has non-finite values")
        if np.any(np.diff(vals) <= 0):
            raise InputError(f"axis {name!r} values must be strictly increasing")
        vals.setflags(write=False)
        object.__setattr__(self, "values", vals)

    @classmethod
    def linspace(cls, name: str, start: float, stop: float, num: int = 100) -> "Axis":
        return cls(name, np.linspace(start, stop, int(num)))

    @classmethod
    def logspace(cls, name: str, start: float, stop: float, num: int = 100) -> "Axis":
        if start <= 0 or stop <= 0:
            raise InputError(f"log axis {name!r} needs positive bounds")
        return cls(name, np.geomspace(start, stop, int(num)))

    @property
    def unit(self) -> str:
        return _units_of(None, self.name)

    @property
    def label(self) -> str:
        return f"{self.name} ({self.unit})" if self.unit else self.name

    @property
    def kind(self) -> str:
        if self.name in CONTROLLER_AXES:
            return "controller"
        if self.name == "position":
            return "position"
        return "plant"

    def __len__(self) -> int:
        return len(self.values)


def parse_axis(text: str) -> Axis:
    """``"name=start:stop:num"`` (``:log`` appended for a log axis) -> :class:`Axis`."""
    try:
        name, spec = text.split("=", 1)
        parts = spec.split(":")
        log = parts[-1] == "log"
        if log:
            parts = parts[:-1]
        start, stop = float(parts[0]), float(parts[1])
        num = int(parts[2]) if len(parts) > 2 else 100
    except (ValueError, IndexError):
        raise InputError(f"axis {text!r}: expected NAME=START:STOP[:NUM][:log], "
                         "e.g. kp=1:40:100 or load.mass=0.5:5:100") from None
    if num < 2 or num > 2000:
        raise InputError(f"axis {text!r}: NUM must be 2..2000")
    return (Axis.logspace if log else Axis.linspace)(name.strip(), start, stop, num)


# ------------------------------------------------------------------------ expm
_PADE13 = (64764752532480000., 32382376266240000., 7771770303897600., 1187353796428800.,
           129060195264000., 10559470521600., 670442572800., 33522128640., 1323241920.,
           40840800., 960960., 16380., 182., 1.)
_THETA13 = 5.371920351148152


def expm_batched(M: np.ndarray) -> np.ndarray:
    """Matrix exponential of a stack of matrices (..., n, n).

    Scaling and squaring with the degree-13 Pade approximant (Higham 2005), in
    batched NumPy; each matrix gets its own number of squarings. Agrees with
    ``scipy.linalg.expm`` to ~1e-13 relative (tested).
    """
    M = np.asarray(M, dtype=float)
    n = M.shape[-1]
    norms = np.abs(M).sum(axis=-2).max(axis=-1)           # 1-norm of each matrix
    s = np.maximum(0, np.ceil(np.log2(np.maximum(norms, 1e-300) / _THETA13))).astype(int)
    A = M / (2.0 ** s)[..., None, None]
    b = _PADE13
    eye = np.broadcast_to(np.eye(n), A.shape)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4
             + b[3] * A2 + b[1] * eye)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye
    E = np.linalg.solve(V - U, V + U)
    smax = int(s.max()) if s.size else 0
    for k in range(smax):
        sel = s > k
        if np.all(sel):
            E = E @ E
        else:
            E[sel] = E[sel] @ E[sel]
    return E


# ------------------------------------------------------------------------ sweeper
class _Sweeper:
    """Per-plant machinery, built once per process (picklable via its spec)."""

    def __init__(self, params_dict: dict, friction: str, position: float, controller: dict,
                 delay_samples: int, compile_c: bool) -> None:
        from ..equilibrium import PIN_UNDERLAP, RATE_PER_SCALE, operating_point
        from ..params import PlantParams
        self.spec = (params_dict, friction, position, controller, delay_samples, compile_c)
        prm = PlantParams.from_dict(params_dict)
        plant = Plant(prm, friction=friction)
        model = Plant(prm.without_effect("dry_friction")) if prm.has_effect("dry_friction") else plant
        self.plant, self.model = plant, model
        self.position, self.delay = float(position), int(delay_samples)
        self.controller = dict(controller)
        names = model.state_names
        n = len(names)
        self.n = n
        self.names = names
        ix, iv = model.states_of_kind("position") + model.states_of_kind("velocity")
        free = [i for i in range(n) if i not in (ix, iv)]
        eqs = [i for i in range(n) if i != ix]
        self.state_scale = model.state_scales()
        xs, fs = self.state_scale[free], self.state_scale[eqs] * RATE_PER_SCALE
        center = prm["valve.command_center"] + prm.get("valve.null_offset", 0.0)
        span = prm["valve.command_span"]
        self.u_scale = span
        pnames = model.param_names
        self.param_names = pnames
        self.p0 = model.p0.copy()

        z = ca.SX.sym("z", len(free) + 1)
        xp = ca.SX.sym("xpos")
        p = ca.SX.sym("p", len(pnames))
        full = [ca.SX(0)] * n
        full[names.index("x")] = xp
        for j, i in enumerate(free):
            full[i] = z[j] * xs[j]
        u = center + z[-1] * span
        # centre and span may themselves be swept: take them from p when present
        if "valve.command_center" in pnames:
            u = p[pnames.index("valve.command_center")] + (
                p[pnames.index("valve.null_offset")] if "valve.null_offset" in pnames else 0) \
                + z[-1] * (p[pnames.index("valve.command_span")])
        def lm_step(fun):
            xd = fun(ca.vertcat(*full), u, p)
            r = ca.vertcat(*[xd[i] / fs[k] for k, i in enumerate(eqs)], 1e-6 * z[-1])
            J = ca.jacobian(r, z)
            H = ca.mtimes(J.T, J)
            H = H + 1e-12 * (1 + ca.mmax(ca.diag(H))) * ca.SX.eye(H.shape[0])
            return ca.Function("lm", [z, xp, p], [ca.solve(H, ca.mtimes(J.T, r)),
                                                   ca.norm_inf(r[:-1])])
        step_pin = lm_step(model.regularised_f(PIN_UNDERLAP))
        step_real = lm_step(model.f)
        self.eq_depends = {nm: bool(ca.depends_on(
            ca.vertcat(*step_pin(z, xp, p)), p[k])) for k, nm in enumerate(pnames)}

        # initial guess: nominal equilibrium, pressures scaled with the supply pressure
        op = operating_point(model, float(np.clip(self.position, 0, model.stroke)))
        znom = np.array([op.state[i] / xs[j] for j, i in enumerate(free)]
                        + [(op.u - center) / span])
        ips, ipa = pnames.index("supply.pressure"), pnames.index("gas.atmospheric_pressure")
        ps_nom = self.p0[ips]
        guess = []
        pressures = set(model.states_of_kind("pressure"))
        for j, i in enumerate(free):
            if i in pressures:
                guess.append((p[ipa] + (znom[j] * xs[j] - p[ipa]) * p[ips] / ps_nom) / xs[j])
            else:
                guess.append(ca.SX(znom[j]))
        guess.append(ca.SX(znom[-1]))
        zz = ca.vertcat(*guess)
        for it in range(_PINNED_ITERATIONS + _REAL_ITERATIONS):
            dz, _ = (step_pin if it < _PINNED_ITERATIONS else step_real)(zz, xp, p)
            zz = zz - dz
        _, resid = step_real(zz, xp, p)
        st = [ca.SX(0)] * n
        st[names.index("x")] = xp
        for j, i in enumerate(free):
            st[i] = zz[j] * xs[j]
        st = ca.vertcat(*st)
        u_eq = ca.substitute(u, z, zz)
        self._eq = ca.Function("wb_equilibrium", [xp, p], [st, u_eq, resid])
        X, U = model.x_sym, model.u_sym
        self._jac = ca.Function("wb_tangent", [X, U, model.p_sym],
                                [ca.jacobian(model.xdot_expr, X), ca.jacobian(model.xdot_expr, U)])
        self._compile = compile_c
        self._compiled: dict[str, ca.Function] = {}
        self._free, self._xs, self._center, self._span = free, xs, center, span

    # -- compiled pieces
    def _fun(self, which: str, npts: int) -> ca.Function:
        base = self._eq if which == "eq" else self._jac
        if self._compile:
            if which not in self._compiled:
                self._compiled[which] = _jit.compiled(base)
            return self._compiled[which]
        return base

    def equilibria(self, positions: np.ndarray, P: np.ndarray):
        """(states (N, n), u (N,), residual (N,), fallbacks) for columns of P (np, N)."""
        N = positions.size
        f = self._fun("eq", N).map(N)
        st, u, res = f(positions[None, :], P)
        st, u, res = np.asarray(st).T, np.asarray(u).ravel(), np.asarray(res).ravel()
        bad = ~(np.isfinite(res) & (res < _RESIDUAL_TOL) & np.all(np.isfinite(st), axis=1))
        fallbacks = int(bad.sum())
        if fallbacks:
            from ..equilibrium import operating_point
            for k in np.flatnonzero(bad):
                try:
                    op = operating_point(self.model, float(positions[k]), p=P[:, k])
                    st[k], u[k], res[k] = op.state, op.u, op.residual
                except WorkbenchError:
                    st[k], u[k], res[k] = np.nan, np.nan, np.inf
        return st, u, res, fallbacks

    def tangents(self, st: np.ndarray, u: np.ndarray, P: np.ndarray):
        N = u.size
        f = self._fun("jac", N).map(N)
        A, B = f(st.T, u[None, :], P)
        n = self.n
        A = np.asarray(A).reshape(n, N, n).transpose(1, 0, 2)   # [A_1 ... A_N] -> (N, n, n)
        B = np.asarray(B).reshape(n, N).T[:, :, None]            # (N, n, 1)
        return A, B

    # -- one block of points
    def evaluate(self, positions, P, kp, kd, ki, T, k0=None) -> dict:
        """Everything of a block; arrays of length N (k0: kp from k0/Kv when given)."""
        # equilibria: one solve per distinct (position, equilibrium-relevant params)
        rel = [k for k, nm in enumerate(self.param_names) if self.eq_depends[nm]]
        key = np.column_stack([positions, P[rel].T]) if rel else positions[:, None]
        uniq, inv = np.unique(key, axis=0, return_inverse=True)
        inv = inv.ravel()
        first = np.zeros(len(uniq), dtype=int)
        first[inv[::-1]] = np.arange(len(inv))[::-1]
        st_u, u_u, res_u, fallbacks = self.equilibria(positions[first], P[:, first])
        st, u, res = st_u[inv], u_u[inv], res_u[inv]
        ok = np.isfinite(res)
        A, B = self.tangents(np.where(ok[:, None], st, 0.0), np.where(ok, u, 0.0), P)
        S = self.state_scale
        As = A * S[None, None, :] / S[None, :, None]        # S^-1 A S
        Bs = B / S[None, :, None] * self.u_scale            # per span of command
        kv = self._velocity_gain(As, Bs)
        if k0 is not None:
            kp = k0 / kv
        rho, hidden = self._closed_loop_radius(As, Bs, kp, kd, ki, T)
        rho = np.where(ok, rho, np.nan)
        return {"rho": rho, "kv": kv, "kp": kp, "hidden": hidden, "residual": res,
                "fallbacks": fallbacks, "u_eq": u}

    def _velocity_gain(self, As, Bs):
        """Kv = lim s->0 s G_x(s), m/(V s), at s = 1e-4 rad/s (relative error ~1e-4 / |slowest
        visible mode|, < 1e-5 for the reference plants)."""
        N, n, _ = As.shape
        s = 1e-4
        M = s * np.eye(n)[None] - As
        sol = np.linalg.solve(M, Bs)[:, :, 0]
        return s * sol[:, 0] * self.state_scale[0] / self.u_scale

    def _closed_loop_radius(self, As, Bs, kp, kd, ki, T):
        """Largest |z| of the visible closed-loop modes, and how many were hidden."""
        N, n, _ = As.shape
        T = np.broadcast_to(np.asarray(T, dtype=float), (N,))
        kp = np.broadcast_to(np.asarray(kp, dtype=float), (N,))
        kd = np.broadcast_to(np.asarray(kd, dtype=float), (N,))
        ki = np.broadcast_to(np.asarray(ki, dtype=float), (N,))
        # ZOH: expm([[A, B], [0, 0]] T)
        Maug = np.zeros((N, n + 1, n + 1))
        Maug[:, :n, :n] = As * T[:, None, None]
        Maug[:, :n, n:] = Bs * T[:, None, None]
        E = expm_batched(Maug)
        Ad, Bd = E[:, :n, :n], E[:, :n, n]
        cx = self.state_scale[0]                   # x = cx * xs_0
        use_d, use_i = bool(np.any(kd != 0)), bool(np.any(ki != 0))
        d = self.delay
        nc = int(use_d) + int(use_i)
        m = n + nc + d
        Acl = np.zeros((N, m, m))
        Br = np.zeros((N, m))
        # controller in scaled units: error e (m) -> u (V) -> scaled u (/ span)
        gain = 1.0 / self.u_scale
        Dc = (kp + kd / T + ki * T) * gain
        c_rows = []
        col = n
        if use_d:
            c_rows.append(("d", col)); col += 1
        if use_i:
            c_rows.append(("i", col)); col += 1
        u_row = np.zeros((N, m))                 # u_scaled = u_row @ state + Dc * r
        u_row[:, 0] = -Dc * cx
        for kind, c in c_rows:
            if kind == "d":                      # state e_prev (m)
                u_row[:, c] = -kd / T * gain
                Acl[:, c, 0] = -cx
                Br[:, c] = 1.0
            else:                                # state integral (m s)
                u_row[:, c] = ki * gain
                Acl[:, c, c] = 1.0
                Acl[:, c, 0] = -T * cx
                Br[:, c] = T
        Acl[:, :n, :n] = Ad
        if d == 0:
            Acl[:, :n, :] += Bd[:, :, None] * u_row[:, None, :]
            Br[:, :n] += Bd * Dc[:, None]
        else:
            w1, wd = n + nc, n + nc + d - 1
            Acl[:, :n, wd] += Bd
            Acl[:, w1, :] = u_row
            Br[:, w1] = Dc
            for j in range(1, d):
                Acl[:, w1 + j, w1 + j - 1] = 1.0
        ok = np.all(np.isfinite(Acl), axis=(1, 2))
        Acl[~ok] = 0.0
        lam, V = np.linalg.eig(Acl)
        W = np.linalg.inv(V)                      # rows: left eigenvectors
        c_out = V[:, 0, :]                        # x observability of each mode
        b_in = np.einsum("nij,nj->ni", W, Br)     # r controllability of each mode
        weight = np.abs(c_out) * np.abs(b_in) / (
            np.linalg.norm(V, axis=1) * np.linalg.norm(W, axis=2))
        visible = weight > _HIDDEN_TOL
        mag = np.where(visible, np.abs(lam), 0.0)
        rho = mag.max(axis=1)
        # no visible mode at all: the command does not reach the position (e.g. a
        # valve deadband at the centre) -- there is no loop to judge
        rho[~ok | ~np.any(visible, axis=1)] = np.nan
        return rho, (~visible).sum(axis=1)

    def dominant(self, st, u, P):
        """w0, zeta, Kv of the dominant mode pair of the open-loop tangent (for the
        classical boundaries). Modes ranked by their share |residue / lambda| of the
        position response; integrators and hidden modes skipped."""
        A, B = self.tangents(st, u, P)
        S = self.state_scale
        As = A * S[None, None, :] / S[None, :, None]
        Bs = B / S[None, :, None] * self.u_scale
        lam, V = np.linalg.eig(As)
        W = np.linalg.inv(V)
        res = V[:, 0, :] * np.einsum("nij,nj->ni", W, Bs[:, :, 0])
        scale = np.max(np.abs(lam), axis=1, keepdims=True)
        integ = np.abs(lam) < 1e-9 * scale
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            score = np.where(integ, -1.0, np.abs(res) / np.maximum(np.abs(lam), 1e-300))
        w0 = np.full(len(lam), np.nan)
        zeta = np.full(len(lam), np.nan)
        for k in range(len(lam)):
            order = np.argsort(-score[k])
            first = order[0]
            if score[k, first] <= 0:
                continue
            l1 = lam[k, first]
            if abs(l1.imag) > 1e-9 * abs(l1):
                l2 = np.conj(l1)
            else:
                reals = [j for j in order[1:] if score[k, j] > 0
                         and abs(lam[k, j].imag) <= 1e-9 * abs(lam[k, j])]
                if not reals:
                    continue
                l2 = lam[k, reals[0]]
            w2 = (l1 * l2).real
            if w2 <= 0:
                continue
            w0[k] = math.sqrt(w2)
            zeta[k] = -(l1 + l2).real / (2 * w0[k])
        return w0, zeta, self._velocity_gain(As, Bs)


_SWEEPERS: dict = {}

#: How long to wait for a Dask scheduler before giving up.
DASK_CONNECT_TIMEOUT = "10s"


def _sweeper_for(spec) -> _Sweeper:
    import pickle
    key = pickle.dumps(spec)
    sw = _SWEEPERS.get(key)
    if sw is None:
        sw = _SWEEPERS[key] = _Sweeper(*spec)
    return sw


def _evaluate_block(spec, inputs: dict) -> dict:
    """Worker entry point (module level, so Dask and forked workers can call it)."""
    return _sweeper_for(spec).evaluate(**inputs)


# ------------------------------------------------------------------------ result
@dataclass(frozen=True)
class StabilityMap:
    """Largest closed-loop pole magnitude over a plane of two parameters.

    Arrays are indexed ``[iy, ix]`` (rows follow the y axis, as in images).

    Attributes
    ----------
    x, y : the two axes. rho : |z|max of the visible closed-loop modes (-).
    kv : velocity gain of the tangent model at each point, m/(V s).
    kp : proportional gain at each point, V/m. k0 : loop gain kp*Kv, 1/s.
    hidden_modes : closed-loop modes hidden from the position loop (count).
    boundary : coarse-grid w0 (rad/s), zeta (-), k0 ratios to the continuous and PCT
        limits (None unless the controller is a P controller).
    fallbacks : equilibria solved one by one after the batched solve missed.
    """

    x: Axis
    y: Axis
    rho: np.ndarray
    kv: np.ndarray
    kp: np.ndarray
    hidden_modes: np.ndarray
    plant_name: str
    position: float
    controller: dict
    delay_samples: int
    boundary: dict | None
    fallbacks: int
    elapsed_s: float
    notes: tuple[str, ...] = ()

    @property
    def stable(self) -> np.ndarray:
        return self.rho < 1.0

    @property
    def k0(self) -> np.ndarray:
        return self.kp * self.kv

    @property
    def points_per_s(self) -> float:
        return self.rho.size / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def as_dict(self) -> dict:
        def arr(a):
            return [[None if not np.isfinite(v) else float(v) for v in row] for row in a]
        out = {"plant": self.plant_name, "position_m": self.position,
               "controller": self.controller, "delay_samples": self.delay_samples,
               "x": {"name": self.x.name, "unit": self.x.unit, "values": self.x.values.tolist()},
               "y": {"name": self.y.name, "unit": self.y.unit, "values": self.y.values.tolist()},
               "rho": arr(self.rho), "stable_fraction": float(np.mean(self.stable)),
               "fallbacks": self.fallbacks, "elapsed_s": self.elapsed_s,
               "points_per_s": self.points_per_s, "notes": list(self.notes)}
        return out

    def to_csv(self, path) -> None:
        """Long format: one row per point (x, y, rho, stable, kp, kv, k0)."""
        import pandas as pd
        from ..params import atomic_write_text
        X, Y = np.meshgrid(self.x.values, self.y.values)
        df = pd.DataFrame({self.x.name: X.ravel(), self.y.name: Y.ravel(),
                           "rho": self.rho.ravel(), "stable": self.stable.ravel(),
                           "kp_V_per_m": self.kp.ravel(), "kv_m_per_Vs": self.kv.ravel(),
                           "k0_per_s": self.k0.ravel()})
        atomic_write_text(path, df.to_csv(index=False, float_format="%.9g"))


# ------------------------------------------------------------------------ driver
def _controller_spec(plant: Plant, controller) -> dict:
    if controller is None:
        from ..controllers import from_plant
        controller = from_plant(plant)
    if isinstance(controller, dict):
        c = dict(controller)
    else:
        c = {"kp": controller.kp, "kd": getattr(controller, "kd", 0.0),
             "ki": getattr(controller, "ki", 0.0), "sample_time": controller.sample_time}
    for k in ("kp", "sample_time"):
        if k not in c:
            raise InputError(f"controller needs {k!r}")
    c.setdefault("kd", 0.0)
    c.setdefault("ki", 0.0)
    return c


def stability_map(plant: Plant, x: Axis, y: Axis, *, position: float | None = None,
                  controller=None, delay_samples: int = 0, scheduler: str | None = None,
                  workers: int | None = None, block_size: int = 2500,
                  boundary_points: int = 40, progress: bool | None = None,
                  compile_c: bool = True) -> StabilityMap:
    """Stability map of the sampled position loop over the plane ``x`` by ``y``.

    Parameters
    ----------
    plant : the plant (its effects included; dry friction is left out of the
        tangent models, as in :func:`workbench.linearize.tangent`).
    x, y : the axes (:class:`Axis`); plant parameters by dotted name, ``position``
        (m), or controller quantities ``kp`` (V/m), ``kd``, ``ki``, ``k0`` (1/s, the
        loop gain kp*Kv), ``sample_time`` (s).
    position : piston position of the equilibrium, m (default mid-stroke), unless an
        axis sweeps it.
    controller : a :class:`~workbench.controllers.PID` (or dict with kp, kd, ki,
        sample_time); default the plant file's controller.
    delay_samples : samples of computation delay between measuring and applying.
    scheduler : Dask scheduler address (``tcp://host:8786``) or a
        ``distributed.Client``; default: local worker processes on all cores.
    workers : local worker processes (default all cores; 1 = in this process).
    block_size : points per task.
    boundary_points : points per axis of the coarse grid on which the classical
        (continuous, PCT) boundaries are computed.
    progress : show a progress bar (default: when on a terminal).
    """
    t_start = time.perf_counter()
    if x.name == y.name:
        raise InputError(f"both axes sweep {x.name!r}")
    pnames = Plant(plant.params.without_effect("dry_friction")).param_names \
        if plant.params.has_effect("dry_friction") else plant.param_names
    for ax in (x, y):
        if ax.kind == "plant" and ax.name not in pnames:
            from difflib import get_close_matches
            near = get_close_matches(ax.name, list(pnames) + list(CONTROLLER_AXES) + ["position"], 1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise InputError(f"cannot sweep {ax.name!r}: not a parameter of this plant{hint}; "
                             f"plant parameters: {', '.join(pnames)}; also position, "
                             f"{', '.join(CONTROLLER_AXES)}")
        if ax.kind == "position" and (ax.values.min() < 0 or ax.values.max() > plant.stroke):
            raise InputError(f"position axis must lie within the stroke [0, {plant.stroke:g}] m")
        if ax.name in ("sample_time",) and ax.values.min() <= 0:
            raise InputError("sample_time axis must be > 0")
        if ax.kind == "plant" and ax.values.min() <= 0 and ax.name not in (
                "load.external_force", "valve.null_offset"):
            raise InputError(f"axis {ax.name!r} must stay > 0")
    if {x.name, y.name} >= {"kp", "k0"}:
        raise InputError("kp and k0 are the same gain; sweep one of them")
    ctrl = _controller_spec(plant, controller)
    if delay_samples < 0 or int(delay_samples) != delay_samples:
        raise InputError("delay_samples must be a non-negative integer")
    pos = plant.stroke / 2 if position is None else float(position)
    if not 0 <= pos <= plant.stroke:
        raise InputError(f"position {pos:g} m is outside the stroke [0, {plant.stroke:g}] m")
    ny, nx = len(y), len(x)
    compile_c = bool(compile_c) and nx * ny >= _COMPILE_ABOVE
    spec = (plant.params.to_dict(), plant.friction, pos, ctrl, int(delay_samples), compile_c)

    XX, YY = np.meshgrid(x.values, y.values)
    flat = {x.name: XX.ravel(), y.name: YY.ravel()}
    N = nx * ny
    sweeper = _sweeper_for(spec)
    P = np.tile(sweeper.p0[:, None], (1, N))
    for name, vals in flat.items():
        if name in sweeper.param_names:
            P[sweeper.param_names.index(name)] = vals
    positions = flat.get("position", np.full(N, pos))
    gains = {k: np.broadcast_to(np.asarray(flat.get(k, ctrl[k]), dtype=float), (N,))
             for k in ("kp", "kd", "ki")}
    T = np.broadcast_to(np.asarray(flat.get("sample_time", ctrl["sample_time"]), float), (N,))
    k0 = flat.get("k0")

    starts = list(range(0, N, block_size))
    tasks = []
    for s0 in starts:
        sl = slice(s0, min(N, s0 + block_size))
        tasks.append({"positions": np.ascontiguousarray(positions[sl]),
                      "P": np.ascontiguousarray(P[:, sl]),
                      "kp": np.ascontiguousarray(gains["kp"][sl]),
                      "kd": np.ascontiguousarray(gains["kd"][sl]),
                      "ki": np.ascontiguousarray(gains["ki"][sl]),
                      "T": np.ascontiguousarray(T[sl]),
                      "k0": None if k0 is None else np.ascontiguousarray(k0[sl])})
    results = _run_tasks(spec, tasks, scheduler, workers, progress, N)
    cat = {k: np.concatenate([r[k] for r in results]) for k in ("rho", "kv", "kp", "hidden")}
    fallbacks = int(sum(r["fallbacks"] for r in results))

    notes = []
    if plant.params.has_effect("dry_friction"):
        notes.append("dry friction left out of the tangent models (not differentiable at rest)")
    if np.any(cat["hidden"] > 0):
        notes.append("modes hidden from the position loop (e.g. the pressure sum of a "
                     "closed-centre valve without leakage, |z| = 1) are not counted in |z|max")
    if np.any(np.isnan(cat["rho"])):
        notes.append(f"{int(np.isnan(cat['rho']).sum())} points have no position loop to judge "
                     "(no equilibrium, or the command has no small-signal effect on the "
                     "position, e.g. inside a valve deadband): shown blank")
    if fallbacks:
        notes.append(f"{fallbacks} equilibria needed the one-by-one solver (e.g. a leaking "
                     "closed-centre valve settles at atmosphere)")

    boundary = None
    if ctrl["kd"] == 0 and ctrl["ki"] == 0 and not {x.name, y.name} & {"kd", "ki"}:
        boundary = _boundaries(sweeper, x, y, flat, P, positions, gains, T, k0, boundary_points)
    elapsed = time.perf_counter() - t_start
    return StabilityMap(x=x, y=y, rho=cat["rho"].reshape(ny, nx), kv=cat["kv"].reshape(ny, nx),
                        kp=cat["kp"].reshape(ny, nx), hidden_modes=cat["hidden"].reshape(ny, nx),
                        plant_name=str(plant.summary().get("name", "")),
                        position=pos, controller=ctrl, delay_samples=int(delay_samples),
                        boundary=boundary, fallbacks=fallbacks, elapsed_s=elapsed,
                        notes=tuple(notes))


def _boundaries(sweeper, x, y, flat, P, positions, gains, T, k0, npts):
    """Continuous and PCT limits on a coarse sub-grid (P controller only)."""
    ny, nx = len(y), len(x)
    ix = np.unique(np.linspace(0, nx - 1, min(nx, npts)).round().astype(int))
    iy = np.unique(np.linspace(0, ny - 1, min(ny, npts)).round().astype(int))
    idx = (iy[:, None] * nx + ix[None, :]).ravel()
    st, u, res, _ = sweeper.equilibria(positions[idx], P[:, idx])
    ok = np.isfinite(res)
    w0, zeta, kv = sweeper.dominant(np.where(ok[:, None], st, 0.0), np.where(ok, u, 0.0), P[:, idx])
    Ts = T[idx] / 2 + 1.0 / w0
    kk0 = k0[idx] if k0 is not None else gains["kp"][idx] * kv
    shape = (len(iy), len(ix))
    return {"x": x.values[ix], "y": y.values[iy],
            "w0": w0.reshape(shape), "zeta": zeta.reshape(shape), "kv": kv.reshape(shape),
            "continuous_ratio": (kk0 / (2 * zeta * w0)).reshape(shape),
            "pct_ratio": (kk0 / (2 * zeta / Ts)).reshape(shape)}


def _run_tasks(spec, tasks, scheduler, workers, progress, npoints):
    from tqdm.auto import tqdm
    import sys
    show = sys.stderr.isatty() if progress is None else bool(progress)
    bar = tqdm(total=npoints, desc="stability map", unit="pt", disable=not show, leave=False)
    results: list = [None] * len(tasks)
    try:
        if scheduler is not None:
            results = _run_dask(spec, tasks, scheduler, bar)
        else:
            nproc = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
            if nproc > 1 and len(tasks) > 1 and _can_fork():
                import multiprocessing as mp
                from concurrent.futures import ProcessPoolExecutor, as_completed
                ctx = mp.get_context("fork")
                _sweeper_for(spec)._fun("eq", max(len(t["kp"]) for t in tasks))   # compile before fork
                _sweeper_for(spec)._fun("jac", max(len(t["kp"]) for t in tasks))
                with ProcessPoolExecutor(max_workers=min(nproc, len(tasks)), mp_context=ctx) as ex:
                    futs = {ex.submit(_evaluate_block, spec, t): i for i, t in enumerate(tasks)}
                    for fut in as_completed(futs):
                        i = futs[fut]
                        results[i] = fut.result()
                        bar.update(len(tasks[i]["kp"]))
            else:
                for i, t in enumerate(tasks):
                    results[i] = _evaluate_block(spec, t)
                    bar.update(len(t["kp"]))
    finally:
        bar.close()
    return results


def _can_fork() -> bool:
    import multiprocessing as mp
    return "fork" in mp.get_all_start_methods()


def _run_dask(spec, tasks, scheduler, bar):
    try:
        from distributed import Client, as_completed
    except ImportError as exc:          # pragma: no cover - dependency of the project
        raise WorkbenchError("a Dask scheduler was given but 'distributed' is not installed") from exc
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=DASK_CONNECT_TIMEOUT) if own else scheduler
    except (OSError, TimeoutError) as exc:
        raise WorkbenchError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
    try:
        spec_f = client.scatter(spec, broadcast=True)
        futs = [client.submit(_evaluate_block, spec_f, t, pure=False) for t in tasks]
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
