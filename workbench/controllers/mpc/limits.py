"""Limits between the shooting nodes: the condensed QP rows of the soft limits at the
RK4 substeps inside each interval (:func:`interior_rows`).

At the nodes alone, a trajectory can satisfy every limit and still violate one in
between: a braking chamber's pressure peaks, a piston reverses, a speed maximum
falls between two samples. :func:`.model.interior_map` gives the states at the
ends of the RK4 substeps and their Jacobians; :func:`interior_rows` linearises the
limits there as :func:`.qp.condense` does at the nodes.
"""

from __future__ import annotations

import casadi as ca

__all__ = ["interior_rows"]


def interior_rows(pb, Zi, Ai, Bi, hs, Gf, lo, hi, slack_columns):
    """Condensed soft-limit rows at the points between the shooting nodes (SX or MX).

    The state at interior point j of interval k, linearised about the plan, is
    Z_kj + dZ_kj/dz (h_k + G_k dw) + dZ_kj/dw dw_k (h_k, G_k: the node correction
    at zero moves and its sensitivity to the moves, as :func:`.qp.condense` builds
    them). Each soft limit gets a lower and an upper row per point, with the same
    slack as at the nodes.

    Parameters
    ----------
    pb : Problem. Zi : (nx, N m), Ai : (nx, nx N m), Bi : (nx, N m) from ``pb.Fi``
        mapped over the intervals. hs : N + 1 node corrections (nx,). Gf : N + 1
        sensitivities (nx, N). lo, hi : scaled limits by state index.
    slack_columns : callable, slack index -> (rows, ns) SX selecting that slack.

    Returns
    -------
    rows, lb, ub : lists of SX blocks to append to the node rows.
    """
    N, nx, m = pb.N, pb.nx, pb.m_int
    vals = {i: [] for i, _ in pb.soft}
    sens = {i: [] for i, _ in pb.soft}
    for k in range(N):
        ek = ca.DM.zeros(1, N)                         # DM: works in SX and MX code
        ek[0, k] = 1.0
        for j in range(m):
            c = k * m + j
            A = Ai[:, c * nx:(c + 1) * nx]
            base = Zi[:, c] + ca.mtimes(A, hs[k])
            S = ca.mtimes(A, Gf[k])
            for i, _ in pb.soft:
                vals[i].append(base[i])
                sens[i].append(S[i, :] + Bi[i, c] * ek)
    rows, lb, ub = [], [], []
    inf = ca.inf * ca.DM.ones(N * m, 1)
    for i, js in pb.soft:
        v, S, e = ca.vertcat(*vals[i]), ca.vertcat(*sens[i]), slack_columns(js, N * m)
        rows += [ca.horzcat(S, e), ca.horzcat(S, -e)]
        lb += [lo[i] - v, -inf]
        ub += [inf, hi[i] - v]
    return rows, lb, ub
