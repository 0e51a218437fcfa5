"""The batched kernel of a stability map: every point of a block in a few calls.

For a block of N points (positions, parameter columns, controller gains) the
:class:`_Sweeper` of a plant computes

1. the equilibria, by a fixed Gauss-Newton iteration compiled into one CasADi
   Function mapped over the block (:func:`_equilibrium_function`; points it misses are
   re-solved one by one with :func:`workbench.equilibrium.operating_point`);
2. the tangent models (A, B), one CasADi Jacobian mapped over the block;
3. the ZOH discretisation, by the batched Pade matrix exponential :func:`expm_batched`;
4. the discrete PID loop (with any computation delay) closed around the position
   (:func:`_closed_loop`);
5. the eigenvalues, and the largest magnitude among the modes visible from the
   reference to the position (:func:`_visible_radius`).

:func:`workbench.stability.maps.stability_map` cuts a map into blocks and hands them
to :mod:`workbench.stability.parallel`.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ..integrate import jit as _jit
from ..errors import WorkbenchError
from ..plant import Plant

__all__ = ["expm_batched"]

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
    """Per-plant machinery, built once per process (picklable via its spec).

    Parameters
    ----------
    params_dict : dict
        The plant file as a dict (:meth:`workbench.params.PlantParams.to_dict`).
    friction : {"stick", "smooth"}
        The plant's dry-friction form (dry friction is left out of the tangent models).
    position : float
        Piston position of the nominal equilibrium (the initial guess), m.
    controller : dict
        kp (V/m), kd (V s/m), ki (V/(m s)), sample_time (s).
    delay_samples : int
        Samples of computation delay.
    compile_c : bool
        Compile the CasADi functions to C (:mod:`workbench.integrate.jit`).
    """

    def __init__(self, params_dict: dict, friction: str, position: float, controller: dict,
                 delay_samples: int, compile_c: bool) -> None:
        from ..params import PlantParams
        self.spec = (params_dict, friction, position, controller, delay_samples, compile_c)
        prm = PlantParams.from_dict(params_dict)
        plant = Plant(prm, friction=friction)
        model = Plant(prm.without_effect("dry_friction")) if prm.has_effect("dry_friction") else plant
        self.plant, self.model = plant, model
        self.position, self.delay = float(position), int(delay_samples)
        self.controller = dict(controller)
        self.names = model.state_names
        self.n = len(self.names)
        self.state_scale = model.state_scales()
        self.u_scale = prm["valve.command_span"]
        self.param_names = model.param_names
        self.p0 = model.p0.copy()
        self._eq, self.eq_depends = _equilibrium_function(model, self.position)
        X, U = model.x_sym, model.u_sym
        self._jac = ca.Function("wb_tangent", [X, U, model.p_sym],
                                [ca.jacobian(model.xdot_expr, X), ca.jacobian(model.xdot_expr, U)])
        self._compile = compile_c
        self._compiled: dict[str, ca.Function] = {}

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
        Acl, Br = _closed_loop(Ad, Bd, kp, kd, ki, T, self.state_scale[0], self.u_scale,
                               self.delay)
        return _visible_radius(Acl, Br)

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


# ------------------------------------------------------------------------ equilibrium
def _equilibrium_function(model: Plant, position: float):
    """The equilibrium at a position as one CasADi Function of (position, p).

    The unknowns are the states other than x and v, and the command, each scaled
    (states by their :attr:`~workbench.plant.Signal.scale`, the command by the
    span); the equations are f = 0 for every state but x, each rate scaled by its
    state's scale times :data:`workbench.equilibrium.RATE_PER_SCALE`. Gauss-Newton
    runs :data:`_PINNED_ITERATIONS` steps on the pinned model (every valve edge leaks
    :data:`workbench.equilibrium.PIN_UNDERLAP`), then :data:`_REAL_ITERATIONS` on the
    real one, from the nominal equilibrium at ``position`` (m) with its pressures
    scaled to the supply pressure in ``p``.

    Returns
    -------
    (casadi.Function, dict)
        ``wb_equilibrium(xpos, p) -> (state, u, scaled residual)``, and for each
        parameter name whether the equilibrium depends on it.
    """
    from ..equilibrium import PIN_UNDERLAP, RATE_PER_SCALE
    prm, names = model.params, model.state_names
    n, pnames = len(names), model.param_names
    ix, iv = model.states_of_kind("position") + model.states_of_kind("velocity")
    free = [i for i in range(n) if i not in (ix, iv)]
    eqs = [i for i in range(n) if i != ix]
    scale = model.state_scales()
    xs, fs = scale[free], scale[eqs] * RATE_PER_SCALE
    center = prm["valve.command_center"] + prm.get("valve.null_offset", 0.0)
    span = prm["valve.command_span"]

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
    depends = {nm: bool(ca.depends_on(ca.vertcat(*step_pin(z, xp, p)), p[k]))
               for k, nm in enumerate(pnames)}

    zz = _initial_guess(model, position, free, xs, center, span, p)
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
    return ca.Function("wb_equilibrium", [xp, p], [st, u_eq, resid]), depends


def _initial_guess(model: Plant, position: float, free, xs, center, span, p):
    """Scaled unknowns of the nominal equilibrium at ``position`` (m), its pressures
    moved with the supply pressure in ``p`` (an SX column)."""
    from ..equilibrium import operating_point
    pnames, p0 = model.param_names, model.p0
    op = operating_point(model, float(np.clip(position, 0, model.stroke)))
    znom = np.array([op.state[i] / xs[j] for j, i in enumerate(free)]
                    + [(op.u - center) / span])
    ips, ipa = pnames.index("supply.pressure"), pnames.index("gas.atmospheric_pressure")
    ps_nom = p0[ips]
    guess = []
    pressures = set(model.states_of_kind("pressure"))
    for j, i in enumerate(free):
        if i in pressures:
            guess.append((p[ipa] + (znom[j] * xs[j] - p[ipa]) * p[ips] / ps_nom) / xs[j])
        else:
            guess.append(ca.SX(znom[j]))
    guess.append(ca.SX(znom[-1]))
    return ca.vertcat(*guess)


# ------------------------------------------------------------------------ the discrete loop
def _closed_loop(Ad, Bd, kp, kd, ki, T, cx, u_scale, d):
    """The sampled position loop of each point as x+ = Acl x + Br r (scaled states).

    Parameters
    ----------
    Ad, Bd : numpy.ndarray
        ZOH plant of each point, (N, n, n) and (N, n), scaled states and command
        per span.
    kp, kd, ki, T : numpy.ndarray
        PID gains (V/m, V s/m, V/(m s)) and sample time (s) of each point, (N,).
    cx : float
        Scale of the position state, m (x = cx * scaled x).
    u_scale : float
        Command span, V.
    d : int
        Samples of computation delay.

    Returns
    -------
    (Acl (N, m, m), Br (N, m)): the plant states, then the error memory (with kd),
    the error integral (with ki) and the delay line; r in m.
    """
    N, n, _ = Ad.shape
    use_d, use_i = bool(np.any(kd != 0)), bool(np.any(ki != 0))
    nc = int(use_d) + int(use_i)
    m = n + nc + d
    Acl = np.zeros((N, m, m))
    Br = np.zeros((N, m))
    # controller in scaled units: error e (m) -> u (V) -> scaled u (/ span)
    gain = 1.0 / u_scale
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
    return Acl, Br


def _visible_radius(Acl, Br):
    """Largest |z| of the closed-loop modes visible from r to x, and how many were hidden.

    A mode is hidden when its (normalised) observability in x times controllability
    from r is below :data:`_HIDDEN_TOL`; a point with no visible mode (or a non-finite
    loop) gets NaN.
    """
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
