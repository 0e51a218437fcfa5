"""The batched kernel of a stability map: every point of a block in a few calls.

For a block of N points (positions, parameter columns, controller gains) the
:class:`_Sweeper` of a plant computes

1. the equilibria, by a fixed Gauss-Newton iteration (:func:`_equilibrium_function`),
   and the tangent models (A, B) there, as one CasADi Function (``wb_point``)
   compiled to C and mapped over the block's distinct points, evaluated through
   CasADi's function buffer straight into NumPy arrays; points the iteration misses
   are re-solved one by one with :func:`workbench.equilibrium.operating_point`;
2. the velocity gain Kv of each tangent model;
3. the ZOH discretisation, by the batched Pade matrix exponential :func:`expm_batched`;
4. the discrete PID loop (with any computation delay) closed around the position
   (:func:`_closed_loop`);
5. the eigenvalues, and the largest magnitude among the modes visible from the
   reference to the position (:func:`_visible_radius`).

:func:`workbench.stability.maps.stability_map` cuts a map into blocks and hands them
to :mod:`workbench.stability.parallel`.
"""

from __future__ import annotations


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
#: Pade approximants of exp (Higham 2005, Table 2.3): degree -> (theta_m, coefficients
#: b_0 .. b_m); r_m(A) has backward error <= unit roundoff for ||A||_1 <= theta_m.
_PADE = {
    3: (1.495585217958292e-2, (120., 60., 12., 1.)),
    5: (2.539398330063230e-1, (30240., 15120., 3360., 420., 30., 1.)),
    7: (9.504178996162932e-1, (17297280., 8648640., 1995840., 277200., 25200., 1512., 56.,
                               1.)),
    9: (2.097847961257068e0, (17643225600., 8821612800., 2075673600., 302702400., 30270240.,
                              2162160., 110880., 3960., 90., 1.)),
    13: (5.371920351148152e0, (64764752532480000., 32382376266240000., 7771770303897600.,
                               1187353796428800., 129060195264000., 10559470521600.,
                               670442572800., 33522128640., 1323241920., 40840800., 960960.,
                               16380., 182., 1.)),
}


def expm_batched(M: np.ndarray) -> np.ndarray:
    """Matrix exponential of a stack of matrices (..., n, n).

    Scaling and squaring with Pade approximants (Higham 2005) in batched NumPy: the
    lowest degree of 3, 5, 7, 9 whose theta bounds the largest 1-norm in the stack
    (every matrix's backward error then <= unit roundoff, as in Higham's algorithm
    for each alone), else degree 13 with each matrix scaled by its own number of
    squarings. Agrees with ``scipy.linalg.expm`` to ~1e-13 relative (tested).
    """
    M = np.asarray(M, dtype=float)
    n = M.shape[-1]
    norms = np.abs(M).sum(axis=-2).max(axis=-1)           # 1-norm of each matrix
    top = float(norms.max()) if norms.size else 0.0
    m = next((d for d in (3, 5, 7, 9) if top <= _PADE[d][0]), 13)
    if m < 13:
        s = np.zeros(norms.shape, dtype=int)
        A = M
    else:
        s = np.maximum(0, np.ceil(np.log2(np.maximum(norms, 1e-300) / _PADE[13][0]))).astype(int)
        A = M / (2.0 ** s)[..., None, None]
    U, V = _pade_uv(A, m)
    E = np.linalg.solve(V - U, V + U)
    smax = int(s.max()) if s.size else 0
    for k in range(smax):
        sel = s > k
        if np.all(sel):
            E = E @ E
        else:
            E[sel] = E[sel] @ E[sel]
    return E


def _pade_uv(A: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Odd (U) and even (V) parts of the degree-``m`` Pade numerator: r_m = (V - U)^-1 (V + U)."""
    b = _PADE[m][1]
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    A2 = A @ A
    if m == 13:
        A4 = A2 @ A2
        A6 = A4 @ A2
        U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4
                 + b[3] * A2 + b[1] * eye)
        V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 \
            + b[0] * eye
        return U, V
    powers = [eye, A2]                                     # A^0, A^2, A^4, ...
    while len(powers) <= m // 2:
        powers.append(powers[-1] @ A2)
    U = A @ sum(b[2 * j + 1] * powers[j] for j in range(m // 2 + 1))
    V = sum(b[2 * j] * powers[j] for j in range(m // 2 + 1))
    return U, V


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
        A, B = (ca.densify(ca.jacobian(model.xdot_expr, v)) for v in (X, U))
        self._jac = ca.Function("wb_tangent", [X, U, model.p_sym], [A, B])
        # the equilibrium and the tangent there as one function (one call per block)
        xp, p = ca.SX.sym("xpos"), ca.SX.sym("p", len(self.param_names))
        st, u, res = self._eq(xp, p)
        self._point = ca.Function("wb_point", [xp, p], [st, u, res, *self._jac(st, u, p)])
        self._compile = compile_c
        self._compiled: dict[str, ca.Function] = {}

    # -- compiled pieces
    def _fun(self, which: str, npts: int = 0) -> ca.Function:
        base = {"eq": self._eq, "jac": self._jac, "point": self._point}[which]
        if self._compile:
            if which not in self._compiled:
                self._compiled[which] = _compiled(base)
            return self._compiled[which]
        return base

    def equilibria(self, positions: np.ndarray, P: np.ndarray):
        """(states (N, n), u (N,), residual (N,), fallbacks) for columns of P (np, N)."""
        st, u, res = _mapped_call(self._fun("eq"), [positions[:, None], P.T])
        return self._fallback(st, u[:, 0], res[:, 0], positions, P)[:4]

    def _fallback(self, st, u, res, positions, P):
        """The points the batched iteration missed, solved one by one (robust solver)."""
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
        return st, u, res, fallbacks, bad

    def tangents(self, st: np.ndarray, u: np.ndarray, P: np.ndarray):
        """(A (N, n, n), B (N, n, 1)) at states (N, n), commands (N,), columns of P."""
        A, B = _mapped_call(self._fun("jac"), [st, u[:, None], P.T])
        n = self.n
        # per point A column by column: A[k] is the transpose of the row-major block
        return A.reshape(-1, n, n).transpose(0, 2, 1), B[:, :, None]

    def points(self, positions: np.ndarray, P: np.ndarray):
        """Equilibria and tangents in one call: (st, u, res, A, B, fallbacks); the
        points the batched iteration missed are solved one by one, their tangents
        evaluated apart."""
        n = self.n
        st, u, res, A, B = _mapped_call(self._fun("point"), [positions[:, None], P.T])
        st, u, res, fallbacks, bad = self._fallback(st, u[:, 0], res[:, 0], positions, P)
        A, B = A.reshape(-1, n, n).transpose(0, 2, 1), B[:, :, None]
        if fallbacks:
            ok = bad & np.isfinite(res)
            if ok.any():                        # few points: CasADi's virtual machine
                Af, Bf = _mapped_call(self._jac, [st[ok], u[ok, None], P[:, ok].T])
                A[ok], B[ok] = Af.reshape(-1, n, n).transpose(0, 2, 1), Bf[:, :, None]
        return st, u, res, A, B, fallbacks

    # -- one block of points
    def evaluate(self, positions, P, kp, kd, ki, T, k0=None) -> dict:
        """Everything of a block; arrays of length N (k0: kp from k0/Kv when given)."""
        # one equilibrium and tangent per distinct (position, parameters)
        first, inv = _unique_rows(np.column_stack([positions, P.T]))
        _, u, res, A, B, fallbacks = self.points(positions[first], P[:, first])
        u, res, A, B = u[inv], res[inv], A[inv], B[inv]
        ok = np.isfinite(res)
        A[~ok], B[~ok] = 0.0, 0.0                            # no equilibrium: blank point
        S = self.state_scale
        As = A * S[None, None, :] / S[None, :, None]        # S^-1 A S
        Bs = B / S[None, :, None] * self.u_scale            # per span of command
        kv = np.where(ok, self._velocity_gain(As, Bs), np.nan)
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
        """w0, zeta, Kv of the dominant mode pair of the open-loop tangent at states
        ``st``, commands ``u`` and parameter columns ``P`` (:meth:`dominant_of`)."""
        return self.dominant_of(*self.tangents(st, u, P))

    def dominant_of(self, A, B):
        """w0, zeta, Kv of the dominant mode pair of the open-loop tangents (A, B) (for
        the classical boundaries). Modes ranked by their share |residue / lambda| of
        the position response; integrators and hidden modes skipped."""
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
        w0, zeta = _dominant_pair(lam, score)
        return w0, zeta, self._velocity_gain(As, Bs)


def _dominant_pair(lam: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """w0 (rad/s) and zeta of each point's dominant pair: the mode of highest score
    (> 0) with its conjugate, or, when that mode is real, with the real mode of the
    next highest score (> 0); NaN where there is no such pair or w0^2 <= 0."""
    rows = np.arange(lam.shape[0])
    first = np.argmax(score, axis=1)
    l1 = lam[rows, first]
    cplx = np.abs(l1.imag) > 1e-9 * np.abs(l1)
    real_j = np.abs(lam.imag) <= 1e-9 * np.abs(lam)
    cand = np.where((score > 0) & real_j, score, -np.inf)
    cand[rows, first] = -np.inf
    second = np.argmax(cand, axis=1)
    has_second = np.isfinite(cand[rows, second])
    l2 = np.where(cplx, np.conj(l1), lam[rows, second])
    w2 = (l1 * l2).real
    ok = (score[rows, first] > 0) & (cplx | has_second) & (w2 > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w0 = np.where(ok, np.sqrt(np.where(ok, w2, 1.0)), np.nan)
        zeta = np.where(ok, -(l1 + l2).real / (2 * w0), np.nan)
    return w0, zeta


def _unique_rows(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(index of the first occurrence of each distinct row, row -> distinct index).

    Only the columns that vary are compared (a map's points differ in at most its two
    axes), by one lexicographic sort.
    """
    N = key.shape[0]
    if N == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    var = key[:, np.any(key != key[:1], axis=0)]
    if var.shape[1] == 0:
        return np.zeros(1, dtype=int), np.zeros(N, dtype=int)
    order = np.lexsort(var.T[::-1])
    srt = var[order]
    new = np.empty(N, dtype=bool)
    new[0] = True
    new[1:] = np.any(srt[1:] != srt[:-1], axis=1)
    group = np.cumsum(new) - 1
    inv = np.empty(N, dtype=int)
    inv[order] = group
    first = np.full(int(group[-1]) + 1, N, dtype=int)
    np.minimum.at(first, inv, np.arange(N))
    return first, inv


#: C flags of the map's functions, tried in turn: -fno-math-errno makes sqrt one
#: instruction (nothing reads errno); -fno-semantic-interposition lets the compiler
#: inline CasADi's runtime helpers (casadi_sq, casadi_sign, ...) in a shared library.
#: Equilibrium and tangent of a 2500-point block: 5.7 ms at -O2, 4.1 ms with these,
#: 3.6 ms with fmax / fmin inlined too (the same numbers, bit for bit).
_FLAGS = (("-O2", "-fno-math-errno", "-fno-semantic-interposition"),
          ("-O2", "-fno-math-errno"), ("-O2",))


def _compiled(fun: ca.Function) -> ca.Function:
    """``fun`` compiled to C into the JIT cache (:func:`workbench.integrate.jit.
    shared_library`) with :data:`_FLAGS` and CasADi's ``fmax`` / ``fmin`` inlined; the
    Function itself (CasADi's virtual machine) without a C compiler."""
    import os
    import tempfile
    from pathlib import Path
    if not _jit.have_compiler():
        return fun
    with tempfile.TemporaryDirectory(prefix="wb_map_") as tmp:
        gen = ca.CodeGenerator(f"{fun.name()}.c", {"with_header": False})
        gen.add(fun)
        gen.generate(tmp + os.sep)
        src = Path(tmp, f"{fun.name()}.c").read_text()
    src = _jit.inline_minmax(src)
    try:
        path, _ = _jit.shared_library(fun.name(), src, _FLAGS)
    except _jit.CompileError:
        return fun
    return ca.external(fun.name(), str(path))


_MAPS: dict = {}


def _mapped(fun: ca.Function, N: int) -> ca.Function:
    """``fun.map(N)``, kept (a map's construction costs ~0.2 ms; a map runs in blocks
    of one size)."""
    key = (id(fun), N)
    hit = _MAPS.get(key)
    if hit is None or hit[0] is not fun:
        if len(_MAPS) > 64:
            _MAPS.clear()
        hit = _MAPS[key] = (fun, fun.map(N))
    return hit[1]


def _mapped_call(fun: ca.Function, args: list) -> list:
    """``fun`` mapped over the rows of ``args`` (each (N, size of that input)); the
    outputs as arrays (N, size of each output), dense. Zero-copy through CasADi's
    function buffer when this CasADi has it."""
    N = args[0].shape[0]
    ins = [np.ascontiguousarray(a, dtype=float) for a in args]
    outs = [np.empty((N, fun.numel_out(i))) for i in range(fun.n_out())]
    if N == 0:
        return outs
    fm = _mapped(fun, N)
    try:
        buf, trigger = fm.buffer()
    except AttributeError:                      # CasADi without FunctionBuffer
        res = fm(*[a.T for a in ins])
        res = res if isinstance(res, (list, tuple)) else [res]
        for o, r in zip(outs, res):
            o[:] = np.asarray(r).reshape(-1, N, order="F").T if o.shape[1] else 0.0
        return outs
    for i, a in enumerate(ins):
        buf.set_arg(i, memoryview(a.reshape(-1)))
    for i, o in enumerate(outs):
        buf.set_res(i, memoryview(o.reshape(-1)))
    trigger()
    return outs


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
