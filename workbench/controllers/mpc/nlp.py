"""The NMPC's full multiple-shooting NLP solved by IPOPT (mode ``"ipopt"``).

Same discretisation (the RK4 interval map), cost and soft limits as the condensed
QP of :mod:`.qp`, with exact Hessians: the accurate reference the real-time
iteration is measured against. Warm started with the previous primal and dual
solution shifted by one sample.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


__all__ = ["IpoptSolver"]


class IpoptSolver:
    """IPOPT on the multiple-shooting NLP of one :class:`~.problem.Problem`.

    Decision vector w = (vec(X) (4 (N + 1)), U (N), slacks (ns)); parameters
    (x0, R, VR, u_prev, d, P). Constraints: the initial state and the N defects
    (equalities, first), then per soft limit the lower and upper rows at nodes 1..N.

    Parameters
    ----------
    pb : workbench.controllers.mpc.problem.Problem
    """

    def __init__(self, pb) -> None:
        self.pb = pb
        nlp = self._nlp()
        ip = {"print_level": 0, "sb": "yes", "max_iter": 10 * pb.c.max_iterations, "tol": 1e-8}
        opts = {"print_time": False, "ipopt": ip}
        self._cold = ca.nlpsol("wb_nmpc_nlp", "ipopt", nlp, opts)
        # warm start: primal and dual guesses from the previous solution, shifted;
        # small bound pushes and barrier so IPOPT does not move away from them first
        warm = dict(ip, warm_start_init_point="yes", warm_start_bound_push=1e-8,
                    warm_start_mult_bound_push=1e-8, warm_start_slack_bound_push=1e-8,
                    mu_init=1e-6)
        self._warm_args = ("wb_nmpc_nlp_warm", "ipopt", nlp, dict(opts, ipopt=warm))
        self._warm = None
        self._bounds()

    def _nlp(self) -> dict:
        """The NLP (same discretisation, cost and limits as the QP) as CasADi MX."""
        pb = self.pb
        N, nx, ns = pb.N, pb.nx, pb.ns
        X = ca.MX.sym("X", nx, N + 1)
        U = ca.MX.sym("U", 1, N)
        s = ca.MX.sym("s", ns)
        x0 = ca.MX.sym("x0", nx)
        R = ca.MX.sym("R", 1, N + 1)
        VR = ca.MX.sym("VR", 1, N + 1)
        up = ca.MX.sym("up")
        d = ca.MX.sym("d")
        P = ca.MX.sym("P", pb.P.size)
        wx, wv, wdu, rho1, rho2, lo, hi = pb.unpack(P)
        Xn = pb.F.map(N)(X[:, :N], U, ca.repmat(d, 1, N))
        ex = (X[0, 1:] - R[0, 1:]).T
        ev = (X[1, 1:] - VR[0, 1:]).T
        du = ca.vertcat(U[0, 0] - up, (U[0, 1:] - U[0, :-1]).T)
        J = 0.5 * (ca.dot(wx * ex, ex) + ca.dot(wv * ev, ev) + wdu * ca.dot(du, du)) \
            + rho1 * ca.sum1(s) + 0.5 * rho2 * ca.dot(s, s)
        g = [X[:, 0] - x0, ca.vec(Xn - X[:, 1:])]
        for i, k_s in pb.soft:
            g += [X[i, 1:].T + s[k_s] - lo[i], X[i, 1:].T - s[k_s] - hi[i]]
        return {"x": ca.vertcat(ca.vec(X), U.T, s), "p": ca.vertcat(x0, R.T, VR.T, up, d, P),
                "f": J, "g": ca.vertcat(*g)}

    def _bounds(self) -> None:
        """Bounds of the constraints (defects 0, soft rows one-sided) and of w."""
        pb = self.pb
        N, nx, ns, n_soft = pb.N, pb.nx, pb.ns, len(pb.soft)
        n_eq = nx * (N + 1)
        self._lbg = np.concatenate([np.zeros(n_eq)] + [np.zeros(N), -np.inf * np.ones(N)] * n_soft)
        self._ubg = np.concatenate([np.zeros(n_eq)] + [np.inf * np.ones(N), np.zeros(N)] * n_soft)
        nw = nx * (N + 1) + N + ns
        lbw, ubw = -np.inf * np.ones(nw), np.inf * np.ones(nw)
        lbw[nx * (N + 1):nx * (N + 1) + N] = pb.w_lo
        ubw[nx * (N + 1):nx * (N + 1) + N] = pb.w_hi
        lbw[-ns:] = 0.0
        self._lbw, self._ubw = lbw, ubw

    def shift_duals(self, lam):
        """Multipliers of the previous NLP moved one sample on (last one repeated)."""
        N, nx = self.pb.N, self.pb.nx
        lam_x, lam_g = (np.asarray(v, dtype=float).ravel().copy() for v in lam)
        n_eq = nx * (N + 1)
        eq = lam_g[:n_eq].reshape(N + 1, nx)
        lam_g[:n_eq] = np.vstack([eq[1:], eq[-1:]]).ravel()
        rows = lam_g[n_eq:].reshape(-1, N)
        lam_g[n_eq:] = np.hstack([rows[:, 1:], rows[:, -1:]]).ravel()
        lu = lam_x[n_eq:n_eq + N]
        lam_x[n_eq:n_eq + N] = np.append(lu[1:], lu[-1])
        return lam_x, lam_g

    def __call__(self, X, U, shift: bool, zm, R, VR, u_prev, d, lam=None):
        """Solve from the plan (X, U), shifted by one sample if ``shift``.

        Parameters
        ----------
        X, U : plan (scaled), the initial guess. zm : (4,) measured state, scaled.
        R, VR : (N + 1,) reference position and velocity at the nodes, scaled.
        u_prev : last command, scaled.
        d : N, disturbance force. lam : (lam_x, lam_g) of the previous solve, shifted
            as the dual guess when ``shift`` (then with IPOPT's warm-start options).

        Returns
        -------
        (X, U, iterations, success, (lam_x, lam_g))
        """
        pb = self.pb
        N, nx = pb.N, pb.nx
        X, U = np.asarray(X), np.asarray(U).ravel()
        if shift:
            X = np.hstack([X[:, 1:], X[:, -1:]])
            U = np.append(U[1:], U[-1])
        w0 = np.concatenate([X.ravel(order="F"), U, np.zeros(pb.ns)])
        p = np.concatenate([zm, np.ravel(R), np.ravel(VR), [u_prev, d], pb.P])
        args = dict(x0=w0, p=p, lbx=self._lbw, ubx=self._ubw, lbg=self._lbg, ubg=self._ubg)
        solver = self._cold
        if shift and lam is not None:
            args["lam_x0"], args["lam_g0"] = self.shift_duals(lam)
            if self._warm is None:
                self._warm = ca.nlpsol(*self._warm_args)
            solver = self._warm
        sol = solver(**args)
        st = solver.stats()
        w = np.asarray(sol["x"]).ravel()
        X = ca.DM(w[:nx * (N + 1)].reshape(N + 1, nx).T)
        U = ca.DM(w[nx * (N + 1):nx * (N + 1) + N][None, :])
        return (X, U, int(st.get("iter_count", 0)), bool(st.get("success", False)),
                (np.asarray(sol["lam_x"]), np.asarray(sol["lam_g"])))
