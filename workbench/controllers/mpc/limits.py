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

__all__ = ["interior_rows", "interior_points", "FIRST_INTERVAL", "LIMIT_SPACING"]

#: s: the largest time between two points of a plan where its limits are checked.
#: Between two such points a limited quantity can still exceed its limit by its
#: curvature over the gap; measured on the 25 mm rig (plans integrated by Radau at
#: rtol 1e-10, tests/test_mpc_interior_limits.py): points 2.5 ms apart keep a 0.5
#: m/s speed limit to 0.504 m/s and a 5.6 bar pressure limit to 5.608 bar, where
#: points 10 ms apart (the nodes alone) let them reach 0.68 m/s and 5.80 bar. The
#: excursion grows with the square of the gap: an NMPC sampled at 2.5 ms keeps them
#: at its nodes alone to 0.501 m/s and 5.609 bar, so at 2.5 ms or faster no point is
#: added between the nodes (and the setting costs nothing).
LIMIT_SPACING = 2.5e-3

#: The first shooting interval whose interior points get limit rows: 1, i.e. none
#: within the first sample. Those points lie 1 .. substeps - 1 RK4 steps after the
#: measurement; whether they keep a limit is decided by the measured state (and, on
#: a rig, by the lines' delay), and the first command moves them little. A violation
#: there that no command can avoid was still priced by the exact L1 penalty, which
#: bought each small reduction with the whole command range: in closed loop
#: (``designs/nmpc_position.py``'s limit steps, 1 m lines, speed limit 2 m/s) the
#: speed, overshot to 2.05 m/s by the lines' delay, was braked at 10 V then 0 V in
#: mid-stroke, the piston stopped, restarted, and braked at the margin with a 6.45
#: bar peak (supply 6 bar). From the second interval on: 5.51 .. 5.62 bar, as with
#: the limits at the nodes only (5.51 .. 5.64 bar).
FIRST_INTERVAL = 1


def interior_points(sample_time: float, substeps: int) -> tuple[int, ...]:
    """The RK4 substep ends (1 .. substeps - 1) limited inside each interval: every
    stride-th, the stride the largest that keeps points at most
    :data:`LIMIT_SPACING` apart (every end when the substeps are longer than that;
    none when the nodes already are that close).

    >>> interior_points(0.01, 4), interior_points(0.005, 4), interior_points(0.002, 4)
    ((1, 2, 3), (2,), ())
    """
    h = sample_time / substeps
    if sample_time <= LIMIT_SPACING * (1 + 1e-9):
        return ()
    stride = max(1, int(LIMIT_SPACING / h * (1 + 1e-9)))
    return tuple(range(stride, substeps, stride))


def interior_rows(pb, Zi, Ai, Bi, hs, Gf, lo, hi, slack_columns):
    """Condensed soft-limit rows at the points between the shooting nodes (SX or MX).

    The state at interior point j of interval k (k >= :data:`FIRST_INTERVAL`),
    linearised about the plan, is
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
    N, nx, m, k0 = pb.N, pb.nx, pb.m_int, pb.first_interior
    vals = {i: [] for i, _ in pb.soft}
    sens = {i: [] for i, _ in pb.soft}
    for k in range(k0, N):
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
    n = (N - k0) * m
    inf = ca.inf * ca.DM.ones(n, 1)
    for i, js in pb.soft:
        v, S, e = ca.vertcat(*vals[i]), ca.vertcat(*sens[i]), slack_columns(js, n)
        rows += [ca.horzcat(S, e), ca.horzcat(S, -e)]
        lb += [lo[i] - v, -inf]
        ub += [inf, hi[i] - v]
    return rows, lb, ub
