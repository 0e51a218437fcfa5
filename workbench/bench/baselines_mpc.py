"""Baselines of ``workbench bench mpc``: the NMPC's own problem solved as a competent
CasADi user would, without the workbench's condensing and compiled step.

All take the same multiple-shooting NLP as the NMPC's IPOPT mode (its RK4 interval
map, scaled variables, cost and soft limits: ``nmpc._problem.ipopt._nlp()``), built
from an NMPC with ``jit=False`` so that it can be generated as C:

* :class:`PlainRTI`: one Gauss-Newton step per sample on the sparse (uncondensed)
  QP, Jacobians compiled to C, OSQP (warm started, updated in place), primal
  shifted by one sample;
* :func:`ipopt_gauss_newton`: IPOPT to convergence with the Gauss-Newton Hessian
  (the cost's: constraint curvature left out, via ``hess_lag``), the NLP expanded to
  SX, warm start from the shifted primal and dual solution;
* :func:`do_mpc_recommended`: the workbench's do-mpc set-up with the IPOPT options
  do-mpc's documentation recommends for speed (``expand``, warm start, no output).

Every controller has ``sample_time``, ``reset()`` and ``update(state, r, y) -> (state,
u)`` like :class:`~workbench.controllers.mpc.NMPC`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..controllers.mpc import horizon_reference
from ..controllers.mpc.model import V_SCALE
from ..controllers.mpc.update import admissible
from ..integrate.jit import compiled

__all__ = ["PlainRTI", "ipopt_gauss_newton", "do_mpc_recommended", "osqp_unavailable",
           "cost_hessian"]


def osqp_unavailable() -> str | None:
    """None when osqp (the ``bench`` extra) imports, else why not."""
    try:
        import osqp  # noqa: F401
    except ImportError as exc:
        return f"osqp is not installed (pip install workbench[bench]): {exc}"
    return None


class _Shifted:
    """Common part: the NLP, its bounds, parameters of one sample, the shifted guess."""

    def __init__(self, nmpc) -> None:
        self.nmpc, self.sample_time = nmpc, nmpc.sample_time
        self.pb = pb = nmpc._problem
        ip = pb.ipopt
        self.nlp = ip._nlp()
        self.lbw, self.ubw, self.lbg, self.ubg = ip._lbw, ip._ubw, ip._lbg, ip._ubg
        self.nxs, self.N = pb.nx * (pb.N + 1), pb.N

    def params(self, r: float, r_prev, y: dict) -> np.ndarray:
        pb = self.pb
        z = np.array([y["x"], y["v"], y["p_a"], y["p_b"]]) / pb.sx
        # the NLP's parameters: (x0, R at the N + 1 nodes, their velocity, u_prev, d, P),
        # the node reference made as the NMPC makes it (same extrapolation, same stroke)
        R, rate = horizon_reference(r, r_prev, pb.T, self.N, self.nmpc.reference_rate_limit)
        R, VR = admissible(pb, np.asarray(R, dtype=float).ravel(), np.full(self.N + 1, rate))
        return np.concatenate([z, R / pb.L, VR / V_SCALE, [self.u_prev, 0.0], pb.P]), z

    def guess(self, w, z):
        if w is None:                     # at rest at the measured state, command centred
            X = np.tile(z, self.N + 1)
            return np.concatenate([X, np.zeros(self.N), np.zeros(self.pb.ns)])
        X = w[:self.nxs].reshape(self.N + 1, -1)
        U = w[self.nxs:self.nxs + self.N]
        return np.concatenate([np.vstack([X[1:], X[-1:]]).ravel(), np.append(U[1:], U[-1]),
                               np.zeros(self.pb.ns)])

    def command(self, w) -> float:
        return self.pb.u_c + self.pb.u_s * float(w[self.nxs])

    def reset(self):
        self.u_prev = 0.0
        return None


def cost_hessian(nlp: dict, P: np.ndarray, regularisation: float) -> ca.DM:
    """The Hessian of the NLP's cost (constant: the cost is quadratic) + regularisation I.

    It holds the weights, which are parameters (the settings P at the end of p): it is
    evaluated at the settings. (Evaluated at p = 0 it lacked the weights: the QP was an
    LP, which OSQP did not solve in 4000 iterations at 250 of 300 samples.)
    """
    w, p, f = nlp["x"], nlp["p"], nlp["f"]
    nw = w.shape[0]
    p0 = np.concatenate([np.zeros(p.shape[0] - P.size), P])
    H = ca.Function("h", [w, p], [ca.hessian(f, w)[0]])(np.zeros(nw), p0)
    return H + regularisation * ca.DM.eye(nw)            # strictly convex


class PlainRTI(_Shifted):
    """Gauss-Newton real-time iteration: one sparse QP per sample, the model's interval
    sensitivities (``pb.Fj``) in the constraint Jacobian.

    ``qp="osqp"``: the osqp package (set up once, updated in place; ``eps`` its
    tolerances, default OSQP's 1e-3: polishing, on, makes the solution exact on the
    active set it finds; with eps 1e-6 the benchmark's closed-loop cost agreed to
    1e-7 and each sample took 20 % longer; OSQP's default ``rho`` and scaling; warm
    started as an
    RTI is: the primal step at 0 (the linearisation point is the shifted plan) and the
    previous multipliers shifted by one node). A QP stopped at ``max_iter`` is applied
    all the same (an RTI applies what it has in time; counted in ``inaccurate``); only
    a QP without a finite step counts as a failure. Otherwise a CasADi ``conic``
    plugin on the same sparse QP (``"qpoases"``: its sparse Schur-complement variant;
    it prints a banner on stdout, so the benchmark does not use it). The Hessian
    is the cost's (constant: the cost is quadratic) plus ``regularisation`` I.
    """

    def __init__(self, nmpc, qp: str = "osqp", eps: float = 1e-3,
                 regularisation: float = 1e-8, rho: float = 0.1) -> None:
        import scipy.sparse as sp
        super().__init__(nmpc)
        w, p, f, g = (self.nlp[k] for k in ("x", "p", "f", "g"))
        nw = w.shape[0]
        lin = ca.Function("wb_rti_lin", [w, p], [ca.gradient(f, w), *self._linearization(w, p)])
        self.lin = compiled(lin)            # MX: the interval map's derivatives mapped, not unrolled
        self.H = cost_hessian(self.nlp, self.pb.P, regularisation)
        self.kind, self.failures, self.inaccurate, self.nw = qp, 0, 0, nw
        self._y: np.ndarray | None = None
        sa = self.lin.sparsity_out(2)
        if qp == "osqp":
            import osqp
            # [G; I] in CSC with G's structural nonzeros kept (labels, not values: an
            # explicit zero must not drop out of the pattern OSQP was set up with)
            lab = sp.vstack([sp.csc_matrix((np.arange(1.0, sa.nnz() + 1), sa.row(),
                                            sa.colind()), shape=sa.shape),
                             sp.diags(np.arange(sa.nnz() + 1.0, sa.nnz() + nw + 1))],
                            format="csc")
            lab.sort_indices()
            self._perm = lab.data.astype(int) - 1
            A0 = sp.csc_matrix((np.ones(lab.nnz), lab.indices, lab.indptr), shape=lab.shape)
            P = sp.triu(sp.csc_matrix(self.H.sparse()), format="csc")
            self.qp = osqp.OSQP()
            self.qp.setup(P=P, q=np.zeros(nw), A=A0, l=-np.ones(A0.shape[0]),
                          u=np.ones(A0.shape[0]), eps_abs=eps, eps_rel=eps, rho=rho,
                          warm_starting=True,
                          polishing=True, verbose=False, max_iter=4000)
        else:
            opts = {"error_on_fail": False, "printLevel": "none", "sparse": True} \
                if qp == "qpoases" else {"error_on_fail": False}
            self.qp = ca.conic("wb_rti_qp", qp, {"h": self.H.sparsity(), "a": sa}, opts)
        self.u_prev = 0.0

    def _linearization(self, w, p):
        """The constraints g(w) and their Jacobian from one evaluation of the model's
        interval map with its sensitivities (``pb.Fj``: what the NMPC's own QP uses;
        the exact derivative of RK4 through the stiff chamber modes is not a usable
        linearisation). The rows as the NLP's (``IpoptSolver._nlp``): initial state,
        defects F(X_k, U_k) - X_{k+1} (F from Fj: the same RK4 map as the NLP's), then
        per soft limit the lower and upper rows; the Jacobian is that of their
        linearisation at w (linear in the point v where it is taken: A_k, B_k, I, the
        soft rows' constants), so g and its Jacobian share the one mapped call."""
        pb = self.pb
        N, nx, ns = pb.N, pb.nx, pb.ns
        n0 = nx * (N + 1)
        v = ca.MX.sym("v", w.shape[0])                    # where the Jacobian is taken
        X, U = ca.reshape(w[:n0], nx, N + 1), w[n0:n0 + N].T
        Fn, A, B = pb.Fj.map(N)(X[:, :N], U, ca.MX.zeros(1, N))
        _, _, _, _, _, lo, hi = pb.unpack(p[-pb.P.size:])

        def rows(z):
            Xz, Uz, sz = ca.reshape(z[:n0], nx, N + 1), z[n0:n0 + N].T, z[n0 + N:]
            lin = [Fn[:, k] + ca.mtimes(A[:, k * nx:(k + 1) * nx], Xz[:, k] - X[:, k])
                   + B[:, k] * (Uz[0, k] - U[0, k]) for k in range(N)]
            g = [Xz[:, 0] - p[:nx], ca.vec(ca.horzcat(*lin) - Xz[:, 1:])]
            for i, k_s in pb.soft:
                g += [Xz[i, 1:].T + sz[k_s] - lo[i], Xz[i, 1:].T - sz[k_s] - hi[i]]
            return ca.vertcat(*g)
        return rows(w), ca.jacobian(rows(v), v)

    def _solve(self, grad, g, G, w) -> np.ndarray | None:
        lba, uba = self.lbg - g, self.ubg - g
        if self.kind != "osqp":
            sol = self.qp(h=self.H, g=grad, a=G, lba=lba, uba=uba, lbx=self.lbw - w,
                          ubx=self.ubw - w)
            ok = self.qp.stats().get("success", False)
            return np.asarray(sol["x"]).ravel() if ok else None
        Ax = np.concatenate([np.asarray(G.nonzeros()), np.ones(self.nw)])[self._perm]
        self.qp.update(q=grad, Ax=Ax, l=np.concatenate([lba, self.lbw - w]),
                       u=np.concatenate([uba, self.ubw - w]))
        if self._y is not None:
            self.qp.warm_start(x=np.zeros(self.nw), y=self._shift_y(self._y))
        res = self.qp.solve()
        if res.info.status_val != 1:
            self.inaccurate += 1
        # solved, solved inaccurate, or stopped at max_iter with a finite iterate
        if res.info.status_val in (1, 2, 7) and np.all(np.isfinite(res.x)):
            self._y = res.y
            return res.x
        self._y = None
        return None

    def reset(self):
        self._y = None
        return super().reset()

    def _shift_y(self, y: np.ndarray) -> np.ndarray:
        """OSQP's multipliers (rows: initial state and defects, soft rows, then the
        bounds of w) moved one node on, the last repeated (as IPOPT's are shifted)."""
        N, nx, m = self.N, self.pb.nx, self.lbg.size
        n_eq = nx * (N + 1)
        y = y.copy()
        eq = y[:n_eq].reshape(N + 1, nx)
        y[:n_eq] = np.vstack([eq[1:], eq[-1:]]).ravel()
        rows = y[n_eq:m].reshape(-1, N)
        y[n_eq:m] = np.hstack([rows[:, 1:], rows[:, -1:]]).ravel()
        bx = y[m:m + n_eq].reshape(N + 1, nx)
        y[m:m + n_eq] = np.vstack([bx[1:], bx[-1:]]).ravel()
        y[m + n_eq:m + n_eq + N] = np.append(y[m + n_eq + 1:m + n_eq + N], y[m + n_eq + N - 1])
        return y

    def update(self, state, r: float, y: dict):
        w_prev, r_prev = (None, None) if state is None else state
        p, z = self.params(r, r_prev, y)
        w = self.guess(w_prev, z)
        ok = True
        for _ in range(10 if w_prev is None else 1):       # converge at a (re)start
            grad, g, G = self.lin(w, p)
            dw = self._solve(np.asarray(grad).ravel(), np.asarray(g).ravel(), G, w)
            if dw is None or not np.all(np.isfinite(dw)):
                self.failures += 1
                ok = False
                break
            w = w + dw
        self.u_prev = float(np.clip(w[self.nxs], self.pb.w_lo, self.pb.w_hi))
        # a failed QP: apply the shifted plan, restart from rest at the next sample
        return (w if ok else None, r), self.pb.u_c + self.pb.u_s * self.u_prev


class _Ipopt(_Shifted):
    def __init__(self, nmpc, gauss_newton: bool = True) -> None:
        super().__init__(nmpc)
        w, p, f = self.nlp["x"], self.nlp["p"], self.nlp["f"]
        ip = {"print_level": 0, "sb": "yes", "tol": 1e-8, "max_iter": 200,
              "warm_start_init_point": "yes", "warm_start_bound_push": 1e-8,
              "warm_start_mult_bound_push": 1e-8, "warm_start_slack_bound_push": 1e-8,
              "mu_init": 1e-6}
        opts = {"print_time": False, "ipopt": ip, "expand": True}
        if gauss_newton:
            lf, lg = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", self.nlp["g"].shape[0])
            opts["hess_lag"] = ca.Function("nlp_hess_l", [w, p, lf, lg],
                                           [ca.triu(lf * ca.hessian(f, w)[0])],
                                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        self.solver = ca.nlpsol("wb_gn_ipopt", "ipopt", self.nlp, opts)
        self.u_prev = 0.0

    def update(self, state, r: float, y: dict):
        w_prev, lam, r_prev = (None, None, None) if state is None else state
        p, z = self.params(r, r_prev, y)
        args = dict(x0=self.guess(w_prev, z), p=p, lbx=self.lbw, ubx=self.ubw, lbg=self.lbg,
                    ubg=self.ubg)
        if lam is not None:
            args["lam_x0"], args["lam_g0"] = self.pb.ipopt.shift_duals(lam)
        sol = self.solver(**args)
        w = np.asarray(sol["x"]).ravel()
        self.u_prev = float(w[self.nxs])
        return (w, (np.asarray(sol["lam_x"]), np.asarray(sol["lam_g"])), r), self.command(w)


def ipopt_gauss_newton(nmpc) -> _Ipopt:
    """IPOPT, Gauss-Newton Hessian, expanded NLP, warm started (primal and dual)."""
    return _Ipopt(nmpc, gauss_newton=True)


def do_mpc_recommended(nmpc):
    """The workbench's do-mpc set-up (:class:`~workbench.controllers.mpc.DoMPC`) with the
    IPOPT options do-mpc's documentation recommends for speed: ``expand`` the NLP to SX,
    IPOPT warm started from the previous solution do-mpc already passes, no output."""
    from ..controllers.mpc import DoMPC

    class _Recommended(DoMPC):
        def _reference(self, mpc) -> None:
            mpc.settings.nlpsol_opts.update({
                "expand": True, "ipopt.warm_start_init_point": "yes",
                "ipopt.warm_start_bound_push": 1e-8, "ipopt.warm_start_mult_bound_push": 1e-8,
                "ipopt.mu_init": 1e-6})
            super()._reference(mpc)
    return _Recommended(nmpc)
