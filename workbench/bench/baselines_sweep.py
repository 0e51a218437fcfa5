"""Baselines of ``workbench bench sweep``: the stability map as a competent user writes it.

* :class:`BatchedMap` (the strongest): all points at once, the model built once (only the swept
  supply pressure symbolic), the equilibria by Newton steps of one mapped CasADi function (compiled to C), one mapped
  tangent call, batched scipy ``expm`` on state-scaled matrices and numpy eigenvalues.
  Measured against the first version of this baseline (CasADi virtual machine,
  ``rootfinder``, unscaled ``expm``) on the 200 x 200 map, one BLAS thread, load ~19:
  0.54 s against 1.31 s CPU; the map itself, in one process, 0.48 s.
* :func:`pointwise_rho`: point by point, with the symbolic plant built once (the
  parameters passed as a vector, not a rebuilt plant), the equilibrium and the exact
  tangent from the workbench's API, and the sampled-data loop in plain numpy/scipy:
  ZOH by one matrix exponential, the discrete PD as one extra state, the eigenvalues of
  the closed-loop matrix.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ["pointwise_rho", "batched_rho", "BatchedMap", "expm_batched"]


def _closed_loop_rho(A, B, C, kp, kd, T) -> float:
    """|z|max of the loop u = kp e + kd (e - e_prev) / T, e = -y, ZOH plant; modes on the
    unit circle within 1e-6 (the pressure-sum mode that no input or output sees) left out."""
    n = A.shape[0]
    M = np.zeros((n + 1, n + 1))
    M[:n, :n], M[:n, n:] = A * T, B * T
    E = expm(M)
    Ad, Bd = E[:n, :n], E[:n, n:]
    Acl = np.block([[Ad - (kp + kd / T) * Bd @ C, -(kd / T) * Bd], [-C, np.zeros((1, 1))]])
    z = np.abs(np.linalg.eigvals(Acl))
    z = z[np.abs(z - 1.0) > 1e-6]
    return float(np.max(z))


def pointwise_rho(plant, positions, pressures, ctrl) -> np.ndarray:
    """rho at the points (positions[i], supply pressures[i]) (m, Pa), model built once."""
    import casadi as ca

    from ..equilibrium import operating_point
    xs, us, ps_ = plant.x_sym, plant.u_sym, plant.p_sym
    jac = ca.Function("ab", [xs, us, ps_], [ca.jacobian(plant.xdot_expr, xs),
                                           ca.jacobian(plant.xdot_expr, us)])
    ip, ix = plant.param_index("supply.pressure"), plant.state_index("x")
    C = np.zeros((1, len(plant.states)))
    C[0, ix] = 1.0
    out = np.empty(len(positions))
    for i, (x, ps) in enumerate(zip(positions, pressures)):
        p = np.array(plant.p0, dtype=float)
        p[ip] = ps
        op = operating_point(plant, float(x), p)
        A, B = (np.asarray(m) for m in jac(op.state, op.u, p))
        out[i] = _closed_loop_rho(A, B.reshape(-1, 1), C, ctrl.kp, ctrl.kd, ctrl.sample_time)
    return out


class BatchedMap:
    """rho at all points at once, as a competent user writes it for speed.

    Built once (outside the timed call, like the map's compiled kernels): the pinned
    equilibrium's Newton step (the square system v', p_a', ... = 0 of :func:`workbench.
    equilibrium.operating_point` in the free states and the command, scaled as there)
    and the tangent (A, B) as CasADi functions mapped over the points, compiled to C by
    CasADi's ``jit`` when a compiler is there (``compile_c``; else the virtual machine).
    Per call: Newton steps on all points at once until the largest step is below 1e-12
    (at most 30), the tangent, ZOH by scipy's batched ``expm`` of the *state-scaled*
    augmented matrix (a similarity transform: the same eigenvalues, but a 1-norm of ~2
    instead of ~1e5, so far fewer squarings) by a batched Pade expm
    (:func:`expm_batched`), the discrete PD as one extra state and
    batched numpy eigenvalues.
    """

    def __init__(self, plant, ctrl, npts: int, compile_c: bool = True) -> None:
        import casadi as ca

        from ..equilibrium import PIN_UNDERLAP, RATE_PER_SCALE
        n = len(plant.states)
        ix, iv = plant.state_index("x"), plant.state_index("v")
        self.free = [i for i in range(n) if i not in (ix, iv)]
        eqs = [i for i in range(n) if i != ix]
        self.sc = plant.state_scales()
        self.center = float(plant.inputs[0].rest)
        self.span = float(plant.inputs[0].scale)
        q, xp, ps = ca.SX.sym("q", len(self.free) + 1), ca.SX.sym("x"), ca.SX.sym("ps")
        # only the swept supply pressure is symbolic: the other parameters are numbers
        # that CasADi folds into the expressions (3x fewer operations than a p vector)
        p = ca.SX(ca.DM(plant.p0))
        p[plant.param_index("supply.pressure")] = ps
        full = [ca.SX(0.0)] * n
        full[ix] = xp
        for j, i in enumerate(self.free):
            full[i] = q[j] * self.sc[i]
        xdot = plant.regularised_f(PIN_UNDERLAP)(ca.vertcat(*full), self.center + q[-1] * self.span, p)
        res = ca.vertcat(*[xdot[i] / (self.sc[i] * RATE_PER_SCALE) for i in eqs])
        step = ca.Function("newton", [q, xp, ps], [ca.solve(ca.jacobian(res, q), res)])
        xs, us = ca.SX.sym("xs", n), ca.SX.sym("us")
        xdot = plant.f(xs, us, p)
        tangent = ca.Function("ab", [xs, us, ps], [ca.jacobian(xdot, xs),
                                                   ca.jacobian(xdot, us)])
        opts = {}
        if compile_c:
            # the flags the map's own functions get (stability.kernel._FLAGS): 4 % off
            # this baseline's time (307 vs 320 ms CPU on the 200 x 200 map, load 16)
            opts = {"jit": True, "compiler": "shell", "jit_options": {
                "flags": ["-O2", "-fno-math-errno", "-fno-semantic-interposition"]}}
        self.step = _mapped(step.map(npts), opts)
        self.tangent = _mapped(tangent.map(npts), opts)
        self.plant, self.ctrl, self.npts, self.ix = plant, ctrl, npts, ix
        self.rest = plant.rest_state(u=self.center)

    def __call__(self, positions, pressures) -> np.ndarray:
        """rho at the points (positions[i] (m), supply pressures[i] (Pa))."""
        n, npts, sc, free = len(self.sc), self.npts, self.sc, self.free
        P = np.asarray(pressures, dtype=float)[None, :]
        xrow = np.asarray(positions, dtype=float)[None, :]
        Q = np.tile(np.append(self.rest[free] / sc[free], 0.0)[:, None], (1, npts))
        for _ in range(30):
            d = self.step(Q, xrow, P).full()
            Q -= d
            if np.max(np.abs(d)) < 1e-12:
                break
        X = np.zeros((n, npts))
        X[self.ix] = xrow
        X[free] = Q[:-1] * sc[free][:, None]
        A, B = (m.full() for m in self.tangent(X, self.center + Q[-1:] * self.span, P))
        A = A.reshape(n, npts, n).transpose(1, 0, 2) * (sc[None, None, :] / sc[None, :, None])
        B = B.T.reshape(npts, n, 1) / sc[None, :, None]
        return _rho_scaled(A, B, sc[self.ix], self.ix, self.ctrl)


def _mapped(fun, opts: dict):
    """``fun`` (a mapped Function) wrapped so that CasADi's ``jit`` options apply."""
    import casadi as ca
    if not opts:
        return fun
    ins = [ca.MX.sym(fun.name_in(i), fun.sparsity_in(i)) for i in range(fun.n_in())]
    try:
        return ca.Function(fun.name() + "_c", ins, fun.call(ins), opts)
    except RuntimeError:                  # no C compiler: the virtual machine
        return fun


#: Coefficients of the diagonal (6, 6) Pade approximant of exp.
_PADE6 = (1.0, 1 / 2, 5 / 44, 1 / 66, 1 / 792, 1 / 15840, 1 / 665280)


def expm_batched(M: np.ndarray) -> np.ndarray:
    """exp of each matrix of ``M`` (k, n, n): (6, 6) Pade after scaling every matrix by
    the same 2^-s to a 1-norm <= 0.5 (truncation ~1e-17 relative), then s squarings.

    scipy's ``expm`` takes a stack too but picks the order and scaling matrix by matrix
    in Python: 12 us per 5 x 5 matrix, against well under 1 us here.
    """
    nrm = float(np.max(np.sum(np.abs(M), axis=-2))) if M.size else 0.0
    s = max(0, int(np.ceil(np.log2(nrm / 0.5)))) if nrm > 0 else 0
    A = M / 2.0 ** s
    eye = np.eye(M.shape[-1])
    c = _PADE6
    A2 = A @ A
    A4 = A2 @ A2
    U = A @ (c[1] * eye + c[3] * A2 + c[5] * A4)
    V = c[0] * eye + c[2] * A2 + c[4] * A4 + c[6] * (A4 @ A2)
    E = np.linalg.solve(V - U, V + U)
    for _ in range(s):
        E = E @ E
    return E


def _rho_scaled(A, B, cx: float, ix: int, ctrl) -> np.ndarray:
    """|z|max of the PD loop on state-scaled (A, B) (npts, n, n), (npts, n, 1); the
    position is state ``ix`` with scale ``cx`` (m per unit)."""
    npts, n = A.shape[0], A.shape[1]
    T, kp, kd = ctrl.sample_time, ctrl.kp, ctrl.kd
    M = np.zeros((npts, n + 1, n + 1))
    M[:, :n, :n], M[:, :n, n:] = A * T, B * T
    E = expm_batched(M)
    Ad, Bd = E[:, :n, :n], E[:, :n, n]
    Acl = np.zeros((npts, n + 1, n + 1))
    Acl[:, :n, :n] = Ad
    Acl[:, :n, ix] -= (kp + kd / T) * cx * Bd
    Acl[:, :n, n] = -(kd / T) * Bd
    Acl[:, n, ix] = -cx
    z = np.abs(np.linalg.eigvals(Acl))
    z = np.where(np.abs(z - 1.0) > 1e-6, z, 0.0)            # the hidden mode on |z| = 1
    return z.max(axis=1)


def batched_rho(plant, positions, pressures, ctrl, compile_c: bool = False) -> np.ndarray:
    """rho at all points at once (:class:`BatchedMap`, built and called once)."""
    return BatchedMap(plant, ctrl, len(positions), compile_c=compile_c)(positions, pressures)
