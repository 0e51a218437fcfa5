"""The multiple-shooting least-squares problem: Radau IIA step and interval functions
(:mod:`workbench.integrate`), sparsity patterns, CasADi callbacks for IPOPT."""

from __future__ import annotations

import math
import os
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from ...integrate import RADAU_IIA, radau_sensitivity, radau_stages
from ...integrate import jit as _jit
from ...plant import Plant
from .data import _Data
from .parameters import _Param


#: :data:`workbench.integrate.RADAU_IIA`).
RADAU_TABLES: dict[int, tuple[np.ndarray, np.ndarray]] = {
    s: (tab.A, np.array(tab.c, dtype=float)) for s, tab in RADAU_IIA.items()}

#: Above this size of the stage equations (stages x states) the step is built from
#: matrix expressions with a sparse QR instead of scalar code (line segments).
LARGE_SYSTEM = 24



def _step_functions(model: Plant, nsel: int, out_idx: Sequence[int], stages: int,
                    newton: int, flags: Sequence[str] | None = ("-O1",)
                    ) -> tuple[ca.Function, ca.Function]:
    """One step of the fixed-step Radau IIA scheme: primal and with sensitivities.

    gb_step(X, u, h, p) -> (X+, y):  y = measured outputs at X (before the step).
    gb_step_sens(X, S, u, h, p, E) -> (X+, S+, y, dy): S = d X / d[X_node, theta] with
    theta = E' p (E selects the estimated parameters), dy = d y / d[X_node, theta].
    """
    tableau = RADAU_IIA[stages]
    nx, npf = len(model.states), len(model.p0)
    nc = nx + nsel
    xs, us, ps = model.x_sym, model.u_sym, model.p_sym
    fx = ca.Function("gb_f", [xs, us, ps], [model.xdot_expr])
    fjac = ca.Function("gb_fj", [xs, us, ps], [ca.jacobian(model.xdot_expr, xs),
                                               ca.jacobian(model.xdot_expr, ps)])
    y_expr = model.y_expr[list(out_idx)]
    hjac = ca.Function("gb_h", [xs, us, ps], [y_expr, ca.jacobian(y_expr, xs),
                                              ca.jacobian(y_expr, ps)])

    # Small plants: scalar expressions (SX) with a symbolic QR, compiled to C. Plants
    # with many states (line segments) would give huge code (3 segments, 16 states, 2
    # stages: 81 s of gcc for the dense symbolic QR): matrix expressions (MX) with a
    # sparse QR factorised at run time, also compiled (the generated C of CasADi's
    # "qr" linear solver: ~6 s of gcc once per plant structure, cached on disk, for
    # 2-3x cheaper sensitivities and 3-4x cheaper replays than the virtual machine;
    # notes/s13/h12r_scripts/micro_gb.py, session 13).
    large = stages * nx > LARGE_SYSTEM
    T = ca.MX if large else ca.SX
    X = T.sym("X", nx)
    S = T.sym("S", nx, nc)
    u = T.sym("u")
    h = T.sym("h")
    p = T.sym("p", npf)
    E = T.sym("E", npf, nsel)
    y, hy_x, hy_p = hjac(X, u, p)
    dy = ca.mtimes(hy_x, S) + ca.horzcat(T.zeros(len(out_idx), nx), ca.mtimes(hy_p, E))
    # the Radau IIA step of workbench.integrate: stages by Newton, sensitivities by the
    # implicit function theorem on the stage equations
    Z = radau_stages(tableau, fx, fjac, X, u, h, p, newton, large)
    last = slice((stages - 1) * nx, stages * nx)
    primal = ca.Function("gb_step", [X, u, h, p], [X + Z[last], y], ["X", "u", "h", "p"],
                         ["Xn", "y"])
    Xk, Sk = radau_sensitivity(tableau, fjac, X, Z, S, u, h, p, E, large)
    sens = ca.Function("gb_step_sens", [X, S, u, h, p, E], [Xk, Sk, y, dy],
                       ["X", "S", "u", "h", "p", "E"], ["Xn", "Sn", "y", "dy"])
    if flags is None:        # CasADi's virtual machine, no compiler
        return primal, sens
    # compiled once, cached by the hash of the generated source (_jit changes the
    # working directory while generating, so never two at a time)
    return _jit.compiled(primal, tuple(flags)), _jit.compiled(sens, tuple(flags))


def _interval_functions(step: ca.Function, step_sens: ca.Function, nx: int, nsel: int,
                        ny: int, npf: int, M: int, substeps: int, n_int: int):
    """All intervals at once: primal (S, U, H, p) -> (X_end, Y) and with sensitivities
    (S, U, H, p, E) -> (X_end, S_end, Y, dY); also one interval's primal function.

    Each sample is ``substeps`` steps of h / substeps with the command held; outputs are
    taken at the samples."""
    nc = nx + nsel
    L = M * substeps
    Xm = ca.MX.sym("X", nx)
    U = ca.MX.sym("U", 1, M)
    H = ca.MX.sym("H", 1, M)
    P = ca.MX.sym("P", npf)
    E = ca.MX.sym("E", npf, nsel)
    Us = ca.reshape(ca.repmat(U, substeps, 1), 1, L)
    Hs = ca.reshape(ca.repmat(H / substeps, substeps, 1), 1, L)
    at_samples = list(range(0, L, substeps))
    dcols = [k * nc + c for k in at_samples for c in range(nc)]
    acc = step.mapaccum("gb_acc", L, [0], [0])
    Xs, Y = acc(Xm, Us, Hs, ca.repmat(P, 1, L))
    one = ca.Function("gb_interval", [Xm, U, H, P], [Xs[:, -1], Y[:, at_samples]])
    acc_s = step_sens.mapaccum("gb_acc_sens", L, [0, 1], [0, 1])
    S0 = ca.DM(np.hstack([np.eye(nx), np.zeros((nx, nsel))]))
    Xs, Ss, Y, dY = acc_s(Xm, S0, Us, Hs, ca.repmat(P, 1, L), ca.repmat(E, 1, L))
    one_s = ca.Function("gb_interval_sens", [Xm, U, H, P, E],
                        [Xs[:, -1], Ss[:, (L - 1) * nc:], Y[:, at_samples], dY[:, dcols]])
    threads = max(1, min(os.cpu_count() or 1, 8))
    mode = "thread" if threads > 1 and n_int > 1 else "serial"
    all_p = one.map(n_int, mode, threads) if mode == "thread" else one.map(n_int)
    all_s = one_s.map(n_int, mode, threads) if mode == "thread" else one_s.map(n_int)
    Sm = ca.MX.sym("S", nx, n_int)
    Ua = ca.MX.sym("U", 1, M * n_int)
    Ha = ca.MX.sym("H", 1, M * n_int)
    Pa = ca.MX.sym("P", npf)
    Ea = ca.MX.sym("E", npf, nsel)
    prim = ca.Function("gb_all", [Sm, Ua, Ha, Pa], all_p(Sm, Ua, Ha, ca.repmat(Pa, 1, n_int)))
    sens = ca.Function("gb_all_sens", [Sm, Ua, Ha, Pa, Ea],
                       all_s(Sm, Ua, Ha, ca.repmat(Pa, 1, n_int), ca.repmat(Ea, 1, n_int)))
    return prim, sens, one


# ====================================================================== NLP
class _Pattern:
    """A fixed sparsity given in COO order, with the permutation to CasADi's CCS."""

    def __init__(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        order = np.lexsort((rows, cols))
        self.perm = order
        self.rows = rows[order]
        self.colind = np.searchsorted(cols[order], np.arange(shape[1] + 1)).astype(np.int64)
        self.shape = shape
        self.sparsity = ca.Sparsity(shape[0], shape[1], self.colind.tolist(), self.rows.tolist())

    def dm(self, values: np.ndarray) -> ca.DM:
        return ca.DM(self.sparsity, np.asarray(values, dtype=float)[self.perm])

    def scipy(self, values: np.ndarray):
        import scipy.sparse as sp
        return sp.csc_matrix((np.asarray(values, dtype=float)[self.perm], self.rows, self.colind),
                             shape=self.shape)


class _Callback(ca.Callback):
    """A CasADi function evaluated by Python (IPOPT callbacks)."""

    def __init__(self, name: str, sp_in: list, sp_out: list, fun: Callable,
                 jac: tuple | None = None) -> None:
        ca.Callback.__init__(self)
        self._in, self._out, self._fun, self._jac = sp_in, sp_out, fun, jac
        self._keep: list = []
        self.construct(name, {})

    def get_n_in(self):
        return len(self._in)

    def get_n_out(self):
        return len(self._out)

    def get_sparsity_in(self, i):
        return self._in[i]

    def get_sparsity_out(self, i):
        return self._out[i]

    def eval(self, arg):
        return self._fun(arg)

    def has_jacobian(self):
        return self._jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        sp_in, sp_out, fun = self._jac
        cb = _Callback(name, sp_in, sp_out, fun)
        self._keep.append(cb)
        return cb


class _IterationCallback(ca.Callback):
    """IPOPT's iteration callback: progress, and a stop when the parameters stand still.

    Kinks in the model (valve deadband, the valve edges switching at the centre, flow
    reversal, clipping) make the gradient jump, so near the solution IPOPT's optimality
    measure can stall above its tolerance while the estimates only jitter. Such a run is
    stopped when, for ``patience`` iterations in a row, every scaled parameter moved by
    less than ``fraction`` of a lower bound of its standard deviation (from the
    parameter block of the Gauss-Newton Hessian, which ignores the correlation with the
    node states and so underestimates it) and the continuity constraints hold to ``gtol``.
    """

    def __init__(self, prob: "_Problem", fraction: float, gtol: float, patience: int,
                 tick: Callable[[float], None] | None) -> None:
        ca.Callback.__init__(self)
        self.prob = prob
        self.nw, self.ng, self.nsel = prob.nw, prob.ng, prob.nsel
        self.fraction, self.gtol, self.patience, self.tick = fraction, gtol, patience, tick
        self.history: list[np.ndarray] = []
        self.gmax: list[float] = []
        self.still = 0
        self.stopped = False
        self.construct("gb_iteration", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nw)
        if name in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        if name == "f":
            return ca.Sparsity.dense(1)
        return ca.Sparsity(0, 1)

    def eval(self, arg):
        x = np.asarray(arg[0], dtype=float).ravel()
        f = float(arg[1])
        g = np.asarray(arg[2], dtype=float).ravel()
        if self.tick is not None:
            self.tick(f)
        z = x[:self.nsel].copy()
        gm = float(np.max(np.abs(g), initial=0.0))
        sigma = self.prob.sigma_lower(f)
        if self.history and sigma is not None and gm < self.gtol \
                and np.all(np.abs(z - self.history[-1]) < self.fraction * sigma):
            self.still += 1
        else:
            self.still = 0
        self.history.append(z)
        self.gmax.append(gm)
        if self.still >= self.patience:
            self.stopped = True
            return [1]
        return [0]


class _Problem:
    """The multiple-shooting least-squares problem and its derivatives (numpy)."""

    def __init__(self, model: Plant, params: list[_Param], data: list[_Data],
                 sig_names: tuple[str, ...], M: int, stages: int, substeps: int, newton: int,
                 weights: Mapping[str, float], flags: Sequence[str] | None = ("-O1",)) -> None:
        self.model, self.params, self.data, self.M = model, params, data, M
        self.sig = sig_names
        self.nx = nx = len(model.states)
        self.nsel = nsel = len(params)
        self.nc = nx + nsel
        self.ny = ny = len(sig_names)
        self.npf = len(model.p0)
        self.sc = model.state_scales()
        out_idx = [model.output_index(s) for s in sig_names]
        first = 0
        for d in data:
            d.n_int = int(math.ceil(len(d.t) / M))
            d.first = first
            first += d.n_int
        self.n_int = n_int = first
        self.ntot = ntot = M * n_int
        # command, steps, measurements and weights on the padded grid
        U = np.zeros(ntot)
        Hs = np.zeros(ntot)
        Ym = np.zeros((ny, ntot))
        W = np.zeros((ny, ntot))
        self.rec_of_int = np.zeros(n_int, dtype=np.int64)
        for k, d in enumerate(data):
            a = d.first * M
            n = len(d.t)
            U[a:a + n] = d.u
            U[a + n:a + d.n_int * M] = d.u[-1]
            Hs[a:a + n - 1] = np.diff(d.t)
            for i, s in enumerate(sig_names):
                if s in d.y:
                    Ym[i, a:a + n] = d.y[s]
                    W[i, a:a + n] = float(weights.get(s, 1.0)) / d.noise[s]
            self.rec_of_int[d.first:d.first + d.n_int] = k
        self.U, self.H, self.Ym, self.W = U, Hs, Ym, W
        self.n_res = int(np.count_nonzero(W))
        self.E = np.zeros((self.npf, nsel))
        for j, prm in enumerate(params):
            self.E[prm.index, j] = 1.0
        # continuity pairs (j -> j + 1 inside one recording)
        self.pairs = np.array([j for j in range(n_int - 1)
                               if self.rec_of_int[j] == self.rec_of_int[j + 1]], dtype=np.int64)
        self.ng = nx * len(self.pairs)
        self.nw = nsel + nx * n_int
        step, step_sens = _step_functions(model, nsel, out_idx, stages, newton, flags)
        self.f_prim, self.f_sens, self._one = _interval_functions(
            step, step_sens, nx, nsel, ny, self.npf, M, substeps, n_int)
        self._build_patterns()
        self._cache_p: tuple[bytes, Any] | None = None
        self._cache_s: tuple[bytes, Any] | None = None
        self._Hzz: np.ndarray | None = None
        self.n_eval = 0
        self.n_sens = 0
        self.on_iteration: Callable[[float], None] | None = None

    # ------------------------------------------------------------ layout helpers
    def node_slice(self, j: int) -> slice:
        a = self.nsel + j * self.nx
        return slice(a, a + self.nx)

    def split(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        z = w[:self.nsel]
        s = w[self.nsel:].reshape(self.n_int, self.nx)      # scaled nodes, row per node
        p = self.model.p0.copy()
        for prm, zi in zip(self.params, z):
            p[prm.index] = prm.value(float(zi))
        return z, s, p

    def _build_patterns(self) -> None:
        nx, nsel, M, ny, n_int = self.nx, self.nsel, self.M, self.ny, self.n_int
        # constraint Jacobian: per pair q rows q*nx + a; cols z, s_j (nx), s_{j+1} (diag)
        q = np.arange(len(self.pairs))
        rows, cols = [], []
        a = np.arange(nx)
        R = (q[:, None] * nx + a[None, :])                        # (nq, nx)
        rows.append(np.repeat(R[:, :, None], nsel, axis=2).ravel())
        cols.append(np.broadcast_to(np.arange(nsel), (len(q), nx, nsel)).ravel())
        cj = nsel + self.pairs[:, None] * nx + a[None, :]          # (nq, nx) columns of s_j
        rows.append(np.repeat(R[:, :, None], nx, axis=2).ravel())
        cols.append(np.repeat(cj[:, None, :], nx, axis=1).ravel())
        rows.append(R.ravel())
        cols.append((cj + nx).ravel())
        self.jg = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.ng, self.nw))
        # Hessian (upper triangle): z-z, z-s_j, s_j-s_j
        rows, cols = [], []
        iu, ju = np.triu_indices(nsel)
        rows.append(iu)
        cols.append(ju)
        jj = np.arange(n_int)
        base = nsel + jj[:, None] * nx                             # (n_int, 1)
        rows.append(np.broadcast_to(np.arange(nsel)[None, :, None], (n_int, nsel, nx)).ravel())
        cols.append(np.broadcast_to((base + a[None, :])[:, None, :], (n_int, nsel, nx)).ravel())
        iu2, ju2 = np.triu_indices(nx)
        rows.append((base + iu2[None, :]).ravel())
        cols.append((base + ju2[None, :]).ravel())
        self.hp = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.nw, self.nw))
        self._iu, self._ju, self._iu2, self._ju2 = iu, ju, iu2, ju2
        # residual Jacobian (for the covariance): rows k*ny + i of interval j
        nrow = ny * M
        rj = np.arange(n_int)[:, None] * nrow + np.arange(nrow)[None, :]   # (n_int, nrow)
        rows = [np.broadcast_to(rj[:, :, None], (n_int, nrow, nsel)).ravel(),
                np.broadcast_to(rj[:, :, None], (n_int, nrow, nx)).ravel()]
        cols = [np.broadcast_to(np.arange(nsel), (n_int, nrow, nsel)).ravel(),
                np.broadcast_to((base + a[None, :])[:, None, :], (n_int, nrow, nx)).ravel()]
        self.jr = _Pattern(np.concatenate(rows), np.concatenate(cols), (self.ntot * ny, self.nw))

    # ------------------------------------------------------------ evaluation
    def primal(self, w: np.ndarray):
        key = w.tobytes()
        if self._cache_p is not None and self._cache_p[0] == key:
            return self._cache_p[1]
        if self._cache_s is not None and self._cache_s[0] == key:
            out = self._cache_s[1][:3]
            self._cache_p = (key, out)
            return out
        z, s, p = self.split(w)
        Xe, Y = self.f_prim((s * self.sc).T, self.U[None, :], self.H[None, :], p)
        self.n_eval += 1
        out = self._residuals(s, np.asarray(Xe), np.asarray(Y))
        self._cache_p = (key, out)
        return out

    def _residuals(self, s: np.ndarray, Xe: np.ndarray, Y: np.ndarray):
        r = self.W * (Y - self.Ym)                                 # (ny, ntot)
        g = (Xe[:, self.pairs].T / self.sc - s[self.pairs + 1]).ravel()
        return r, g, Y

    def full(self, w: np.ndarray):
        key = w.tobytes()
        if self._cache_s is not None and self._cache_s[0] == key:
            return self._cache_s[1]
        z, s, p = self.split(w)
        Xe, Se, Y, dY = self.f_sens((s * self.sc).T, self.U[None, :], self.H[None, :], p, self.E)
        self.n_sens += 1
        r, g, Yn = self._residuals(s, np.asarray(Xe), np.asarray(Y))
        nx, nc, M, ny, n_int = self.nx, self.nc, self.M, self.ny, self.n_int
        dpdz = np.array([prm.dvalue(float(zi)) for prm, zi in zip(self.params, z)])
        dY = np.asarray(dY).reshape(ny, self.ntot, nc)                # [i, k, c]
        dY = dY * self.W[:, :, None]
        dY = dY.transpose(1, 0, 2).reshape(n_int, M * ny, nc)      # [j, k*ny + i, c]
        As = dY[:, :, :nx] * self.sc[None, None, :]
        Bz = dY[:, :, nx:] * dpdz[None, None, :]
        Se = np.asarray(Se).reshape(nx, n_int, nc).transpose(1, 0, 2)   # [j, a, c]
        Phi = Se[:, :, :nx] * (self.sc[None, None, :] / self.sc[None, :, None])
        Gam = Se[:, :, nx:] * (dpdz[None, None, :] / self.sc[None, :, None])
        out = (r, g, Yn, As, Bz, Phi, Gam)
        self._cache_s = (key, out)
        return out

    # ------------------------------------------------------------ NLP pieces
    def f_g(self, w):
        r, g, _ = self.primal(w)
        return 0.5 * float(np.sum(r * r)) / self.n_res, g

    def grad_f(self, w):
        r, g, _, As, Bz, _, _ = self.full(w)
        R = r.T.reshape(self.n_int, self.M * self.ny)
        gz = np.einsum("jr,jri->i", R, Bz)
        gs = np.einsum("jr,jri->ji", R, As)
        f = 0.5 * float(np.sum(r * r)) / self.n_res
        return f, np.concatenate([gz, gs.ravel()]) / self.n_res

    def jac_g(self, w):
        r, g, _, _, _, Phi, Gam = self.full(w)
        P = Phi[self.pairs]
        G = Gam[self.pairs]
        vals = np.concatenate([G.ravel(), P.ravel(), -np.ones(self.ng)])
        return g, vals

    def sigma_lower(self, cost: float) -> np.ndarray | None:
        """Lower bounds of the standard deviations of the scaled parameters at the last
        Hessian evaluation (parameter block of J'J only), residuals at ``cost``."""
        if self._Hzz is None:
            return None
        d = np.diag(self._Hzz)
        with np.errstate(divide="ignore"):
            return np.sqrt(max(2.0 * cost, 1.0) / np.where(d > 0, d, np.nan))

    def hess(self, w, lam_f):
        _, _, _, As, Bz, _, _ = self.full(w)
        Hzz = np.einsum("jri,jrk->ik", Bz, Bz)
        self._Hzz = Hzz
        Hzs = np.einsum("jri,jrk->jik", Bz, As)
        Hss = np.einsum("jri,jrk->jik", As, As)
        vals = np.concatenate([Hzz[self._iu, self._ju], Hzs.ravel(),
                               Hss[:, self._iu2, self._ju2].ravel()])
        return vals * (lam_f / self.n_res)

    def residual_jacobian(self, w):
        """Residual Jacobian (scipy CSC, unscaled) and residual vector (row k*ny + i)."""
        r, _, _, As, Bz, _, _ = self.full(w)
        vals = np.concatenate([Bz.ravel(), As.ravel()])
        return self.jr.scipy(vals), r.T.ravel()

    def constraint_jacobian(self, w):
        g, vals = self.jac_g(w)
        return self.jg.scipy(vals)

    # ------------------------------------------------------------ IPOPT
    def solver(self, max_iter: int, tol: float, verbose: bool) -> ca.Function:
        d = ca.Sparsity.dense
        nw, ng = self.nw, self.ng
        P0 = ca.Sparsity(0, 1)
        self._callbacks = []

        def fg(arg):
            f, g = self.f_g(np.asarray(arg[0], dtype=float).ravel())
            return [f, g]

        def jac_fg(arg):
            w = np.asarray(arg[0], dtype=float).ravel()
            f, grad = self.grad_f(w)
            _, vals = self.jac_g(w)
            return [ca.DM(grad.reshape(1, -1)), self.jg.dm(vals)]

        def grad(arg):
            f, gr = self.grad_f(np.asarray(arg[0], dtype=float).ravel())
            return [f, gr]

        def jac(arg):
            g, vals = self.jac_g(np.asarray(arg[0], dtype=float).ravel())
            return [g, self.jg.dm(vals)]

        def hess(arg):
            w = np.asarray(arg[0], dtype=float).ravel()
            return [self.hp.dm(self.hess(w, float(arg[2])))]

        cb_fg = _Callback("gb_fg", [d(nw)], [d(1), d(ng)], fg,
                          jac=([d(nw), d(1), d(ng)], [d(1, nw), self.jg.sparsity], jac_fg))
        cb_grad = _Callback("gb_grad_f", [d(nw), P0], [d(1), d(nw)], grad)
        cb_jac = _Callback("gb_jac_g", [d(nw), P0], [d(ng), self.jg.sparsity], jac)
        cb_hess = _Callback("gb_hess_l", [d(nw), P0, d(1), d(ng)], [self.hp.sparsity], hess)
        self.iteration = _IterationCallback(self, 0.1, 1e-5, 3, self.on_iteration)
        self._callbacks = [cb_fg, cb_grad, cb_jac, cb_hess, self.iteration]
        wsym = ca.MX.sym("w", nw)
        fgx = cb_fg(wsym)
        opts = {
            "grad_f": cb_grad, "jac_g": cb_jac, "hess_lag": cb_hess,
            "iteration_callback": self.iteration,
            "print_time": False, "error_on_fail": False,
            "ipopt.print_level": 5 if verbose else 0, "ipopt.sb": "yes",
            "ipopt.max_iter": int(max_iter), "ipopt.tol": float(tol),
            "ipopt.acceptable_tol": 100.0 * float(tol), "ipopt.acceptable_iter": 2,
            "ipopt.acceptable_obj_change_tol": 1e-10,
            "ipopt.constr_viol_tol": 1e-9, "ipopt.nlp_scaling_method": "none",
            "ipopt.mu_strategy": "adaptive",
        }
        return ca.nlpsol("gb_solver", "ipopt", {"x": wsym, "f": fgx[0], "g": fgx[1]}, opts)

    # ------------------------------------------------------------ start values
    def simulate_nodes(self, x0s: list[np.ndarray], p: np.ndarray) -> np.ndarray:
        """Single shooting with the fixed-step scheme: states at every node, (n_int, nx)."""
        nodes = np.zeros((self.n_int, self.nx))
        M = self.M
        for d, x0 in zip(self.data, x0s):
            x = np.asarray(x0, dtype=float)
            for j in range(d.first, d.first + d.n_int):
                nodes[j] = x
                seg = slice(j * M, (j + 1) * M)
                xe, _ = self._one(x, self.U[None, seg], self.H[None, seg], p)
                x = np.asarray(xe).ravel()
                if not np.all(np.isfinite(x)):
                    x = nodes[j].copy()
        return nodes
