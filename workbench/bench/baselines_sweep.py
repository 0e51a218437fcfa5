"""Baseline of ``workbench bench sweep``: the stability map as a competent user writes it
point by point, with the symbolic plant built once (the parameters passed as a vector,
not a rebuilt plant), the equilibrium and the exact tangent from the workbench's API,
and the sampled-data loop in plain numpy/scipy: ZOH by one matrix exponential, the
discrete PD as one extra state, the eigenvalues of the closed-loop matrix.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

__all__ = ["pointwise_rho"]


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


def batched_rho(plant, positions, pressures, ctrl) -> np.ndarray:
    """rho at all points at once: the model built once, the equilibria by one mapped
    CasADi Newton rootfinder (the pinned valve of :func:`workbench.equilibrium.
    operating_point`, square: v', p_a', ... = 0 for the free states and the command),
    A and B by one mapped Jacobian call, ZOH and eigenvalues batched in numpy/scipy."""
    import casadi as ca

    from ..equilibrium import PIN_UNDERLAP, RATE_PER_SCALE
    n, npts = len(plant.states), len(positions)
    ix, iv = plant.state_index("x"), plant.state_index("v")
    free = [i for i in range(n) if i not in (ix, iv)]
    eqs = [i for i in range(n) if i != ix]
    sc = plant.state_scales()
    center, span = float(plant.inputs[0].rest), float(plant.inputs[0].scale)
    q, xp = ca.SX.sym("q", len(free) + 1), ca.SX.sym("x")
    p = ca.SX.sym("p", len(plant.p0))
    full = [ca.SX(0.0)] * n
    full[ix] = xp
    for j, i in enumerate(free):
        full[i] = q[j] * sc[i]
    xdot = plant.regularised_f(PIN_UNDERLAP)(ca.vertcat(*full), center + q[-1] * span, p)
    res = ca.vertcat(*[xdot[i] / (sc[i] * RATE_PER_SCALE) for i in eqs])
    rf = ca.rootfinder("eq", "newton", ca.Function("g", [q, ca.vertcat(xp, p)], [res]),
                       {"abstol": 1e-13, "max_iter": 100, "error_on_fail": False})
    P = np.tile(np.asarray(plant.p0, dtype=float)[:, None], (1, npts))
    P[plant.param_index("supply.pressure")] = pressures
    rest = plant.rest_state(u=center)
    q0 = np.tile(np.append(rest[free] / sc[free], 0.0)[:, None], (1, npts))
    Q = np.asarray(rf.map(npts)(q0, np.vstack([np.asarray(positions)[None, :], P])))
    X = np.zeros((n, npts))
    X[ix] = positions
    X[free] = Q[:-1] * sc[free][:, None]
    U = center + Q[-1] * span
    xs, us, ps = plant.x_sym, plant.u_sym, plant.p_sym
    jac = ca.Function("ab", [xs, us, ps], [ca.jacobian(plant.xdot_expr, xs),
                                           ca.jacobian(plant.xdot_expr, us)]).map(npts)
    A, B = (np.asarray(m) for m in jac(X, U[None, :], P))
    A = A.reshape(n, npts, n).transpose(1, 0, 2)            # (npts, n, n)
    B = B.T.reshape(npts, n, 1)
    T, kp, kd = ctrl.sample_time, ctrl.kp, ctrl.kd
    M = np.zeros((npts, n + 1, n + 1))
    M[:, :n, :n], M[:, :n, n:] = A * T, B * T
    E = expm(M)
    Ad, Bd = E[:, :n, :n], E[:, :n, n:]
    C = np.zeros((1, n))
    C[0, ix] = 1.0
    Acl = np.zeros((npts, n + 1, n + 1))
    Acl[:, :n, :n] = Ad - (kp + kd / T) * Bd @ C
    Acl[:, :n, n:] = -(kd / T) * Bd
    Acl[:, n, :n] = -C
    z = np.abs(np.linalg.eigvals(Acl))
    z = np.where(np.abs(z - 1.0) > 1e-6, z, 0.0)            # the hidden mode on |z| = 1
    return z.max(axis=1)
