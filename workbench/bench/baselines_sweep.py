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
