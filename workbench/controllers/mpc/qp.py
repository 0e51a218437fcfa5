"""The Gauss-Newton SQP step of the NMPC: linearise, condense onto the command moves,
solve the QP, update the plan, all in one CasADi function.

The multiple-shooting problem linearised at the current plan (X, U) has the
variables dz_k (state corrections at the N + 1 nodes), dw_k (command moves) and the
slacks. Eliminating the dz_k by the linearised dynamics dz_{k+1} = A_k dz_k +
B_k dw_k + c_k (c_k: the shooting defects) leaves a dense, strictly convex QP in
the N moves and the slacks (*condensing*): H (N + ns)^2, and two rows per soft
constraint and node. :func:`sqp_step` builds

    prep (C): shift the previous plan, update the force estimate, interval
              Jacobians, condensed QP data
    QP:       the conic solver (DAQP by default)
    post (C): the new plan from the QP step, the first command, the predicted
              limit violations, a sanity flag

as a single function ``wb_nmpc_step``, so a sample costs one call from Python.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .limits import interior_rows


__all__ = ["sqp_step", "intervals", "condense", "prepare", "apply_step", "qp_solver", "INSIDE",
           "DAQP_PRIMAL_TOL", "daqp_primal_tol", "SQP_CONTRACTION", "SQP_DAMPING"]

#: scaled command: the plan is kept this far inside the command range (1e-8 V on a 10 V
#: span; see :func:`apply_step`)
INSIDE = 1e-9

#: DAQP's primal tolerance (its ``primal_tol``: the violation it accepts of a row, the
#: row normalised by the factor of H) with limits between the nodes, for the CasADi
#: plugin and the compiled sample (:mod:`.fast_c`) alike (:func:`daqp_primal_tol`).
#: There DAQP's default 1e-6 let a solve stop with a row violated by 3e-7 that another
#: solve of the same QP (from another starting working set) held active: plans 3e-7
#: apart where both should give the one optimum (rig25; a point's row between two
#: nodes is nearly parallel to theirs). At 1e-9 the two agree to rounding.
DAQP_PRIMAL_TOL = 1e-9

#: Mode sqp: a Gauss-Newton step at least this fraction of the one before does not
#: contract; if it also turns the commands back (its moves against the previous
#: step's), the fraction of the step taken is multiplied by :data:`SQP_DAMPING`.
SQP_CONTRACTION = 0.9
#: Mode sqp: factor on the fraction of the Gauss-Newton step taken at each step that
#: does not contract (RTI takes one full step a sample and is not changed). On a stuck
#: piston (nodes at 3-10 mm/s, about the smooth friction's width, where its slope is
#: steepest) the full steps fell into a 2-cycle: the plan alternated between two
#: (first command 0.1189 / 0.1238 scaled, the step 0.0063 for ever; with exact
#: sensitivities too): the iteration map's eigenvalue is near -1, and a step of a
#: times the full one maps an eigenvalue lambda to 1 - a (1 - lambda), -1 to 0 at
#: a = 1/2, with the same fixed point (the plan). Measured (tests/test_mpc_friction.py's
#: rig without lines, 0.2 mm steps, 30 iterations; /tmp/h14j/sqp2.py): samples not
#: converged 7 -> 1 of 201 (it converges in 40 iterations), mean iterations 4.4 -> 4.0.
#: Tried: damping every step that does not contract (without the turn back): 2 of 201,
#: but a cold start slowed (a 0.19 m step from rest did not converge in 50 iterations,
#: tests/test_mpc_interior_limits.py); doubling the fraction back after a contracting
#: step: 3 of 201.
SQP_DAMPING = 0.5


def daqp_primal_tol(pb) -> float | None:
    """DAQP's ``primal_tol`` for the problem: :data:`DAQP_PRIMAL_TOL` with limits
    between the nodes, else None (DAQP's default, 1e-6).

    Without those rows both solves agree to 1e-8 at the default (the tests of
    :mod:`.fast`), and the default is kept: near a stuck piston the closed loop
    amplifies the last bits of a plan, and the precision profile's figures move with
    the tolerance (``precision_positioning.py --quick``, at 1e-9 against 1e-6: sine
    worst 1.34 -> 0.98 mm on the nominal rig, but the perturbed rig's worst hold
    21 -> 217 um): a change of outcome by rounding, neither better nor worse.
    """
    return DAQP_PRIMAL_TOL if getattr(pb, "m_int", 0) else None


def sqp_step(pb, jit: bool | None = None) -> "ca.Function | _LazyStep":
    """One Gauss-Newton SQP step as a single call: prep (C), QP, post (C).

    Parameters
    ----------
    pb : workbench.controllers.mpc.problem.Problem
        Dimensions, scaling, limits and interval maps; ``pb.c.qp_solver`` names the
        conic plugin.
    jit : bool, optional
        Compile prep and post to C (:func:`workbench.integrate.jit.compiled`);
        default ``pb.c.jit``. False keeps the whole step generatable as C source
        (:mod:`.fast` generates it with the QP solver).

    Returns
    -------
    casadi.Function or _LazyStep
        (compiled: built at its first call, so that an NMPC whose updates run as one
        compiled C call, :mod:`.fast`, never compiles it)
        ``wb_nmpc_step(Xp, Up, shift, x0, R, VR, up, zprev, dprev, est, P) -> (X, U,
        u0, viol, ok, step, d)``: the previous plan (shifted by one sample if
        ``shift``), the measured state, the reference position and velocity at the
        N + 1 nodes (scaled), the last command,
        the measured state and force estimate one sample ago (``est``: 1 to update
        it), the settings vector; the new plan, its first command, the predicted
        violations (scaled, per state), success, the largest command step, the force
        estimate used.
    """
    if pb.c.jit if jit is None else jit:
        return _LazyStep(pb)
    return _step(pb, prepare(pb), apply_step(pb))


class _LazyStep:
    """:func:`sqp_step` with prep and post compiled to C at the first call."""

    def __init__(self, pb) -> None:
        self._pb, self._f = pb, None

    def __call__(self, *args):
        if self._f is None:
            from ...integrate.jit import compiled
            self._f = _step(self._pb, compiled(prepare(self._pb)),
                            compiled(apply_step(self._pb)))
        return self._f(*args)


def _step(pb, prep: ca.Function, post: ca.Function) -> ca.Function:
    """prep, the QP, post as one function (see :func:`sqp_step`)."""
    qp = qp_solver(pb.c.qp_solver, pb.N + pb.ns, pb.n_rows, daqp_primal_tol(pb))
    ins = [ca.MX.sym(prep.name_in(i), prep.sparsity_in(i)) for i in range(prep.n_in())]
    o = prep(*ins)
    sol = qp(h=o[0], g=o[1], a=o[2], lba=o[3], uba=o[4], lbx=o[5], ubx=o[6])
    res = post(o[9], o[10], o[7], o[8], sol["x"], ins[-1])
    return ca.Function("wb_nmpc_step", ins, [*res, o[11]],
                       ["Xp", "Up", "shift", "x0", "R", "VR", "up", "zprev", "dprev",
                        "est", "P"],
                       ["X", "U", "u0", "viol", "ok", "step", "d"])


def intervals(pb) -> ca.Function:
    """(previous plan, shift?, measured state, settings) -> the plan linearised.

    Returns ``wb_nmpc_lin(Xp, Up, shift, x0, up, zprev, dprev, est, P) -> (X, U, d, A,
    B, c, dz0[, Zi, Ai, Bi])``: the plan (shifted if ``shift``), the force estimate,
    the interval Jacobians A (nx, nx N) and B (nx, N), the shooting defects c (nx, N),
    the measured minus the planned initial state dz0, and with limits between the
    nodes the interior points and their Jacobians (``pb.Fi`` mapped): the inputs of
    :func:`condense` besides the reference, ``up`` and P.
    """
    N, nx = pb.N, pb.nx
    Xp = ca.MX.sym("Xp", nx, N + 1)
    Up = ca.MX.sym("Up", 1, N)
    shift = ca.MX.sym("shift")
    x0 = ca.MX.sym("x0", nx)
    up = ca.MX.sym("up")
    zprev = ca.MX.sym("zprev", nx)                     # measured state one sample ago
    dprev = ca.MX.sym("dprev")                         # disturbance estimate then, N
    est = ca.MX.sym("est")                             # 1: update the estimate
    P = ca.MX.sym("P", pb.P.size)
    ins = [Xp, Up, shift, x0, up, zprev, dprev, est, P]
    return ca.Function("wb_nmpc_lin", ins, _intervals(pb, *ins),
                       ["Xp", "Up", "shift", "x0", "up", "zprev", "dprev", "est", "P"],
                       ["X", "U", "d", "A", "B", "c", "dz0"]
                       + ([] if pb.Fi is None else ["Zi", "Ai", "Bi"]))


def _intervals(pb, Xp, Up, shift, x0, up, zprev, dprev, est, P) -> list:
    """The expressions of :func:`intervals`."""
    N = pb.N
    # the estimate's one-interval prediction only where it is used (est, gain != 0:
    # the first step of a sample with the observer on); else d_{k-1}, bounded as
    # estimate() bounds it (the same value: estimate() adds 0 to it then)
    d = ca.if_else(est * P[-1] != 0, pb.estimate(zprev, up, dprev, x0, est, P[-1]),
                   ca.fmin(ca.fmax(dprev, -pb.d_max), pb.d_max), True)
    X = ca.if_else(shift, ca.horzcat(Xp[:, 1:], Xp[:, N]), Xp)
    U = ca.if_else(shift, ca.horzcat(Up[:, 1:], Up[:, N - 1]), Up)
    Xn, A, B, *inner = _interval_and_points(pb).map(N)(X[:, :N], U, ca.repmat(d, 1, N))
    return [X, U, d, A, B, Xn - X[:, 1:], x0 - X[:, 0], *inner]


def _interval_and_points(pb) -> ca.Function:
    """``pb.Fj``, and with limits between the nodes ``pb.Fi`` too, as one function
    (z, w, d) -> (z+, A, B[, Z, dZ/dz, dZ/dw]): the two integrate the same RK4 substeps,
    computed once here (common subexpressions eliminated: with three points per
    interval the linearisation took 61 us a sample as two maps, against 26 us without
    the points; loaded machine)."""
    if pb.Fi is None:
        return pb.Fj
    z, w, d = (ca.SX.sym(n, pb.Fj.sparsity_in(i)) for i, n in enumerate("zwd"))
    return ca.Function("wb_nmpc_Fji", [z, w, d], [*pb.Fj(z, w, d), *pb.Fi(z, w, d)],
                       {"cse": True})


def prepare(pb) -> ca.Function:
    """(previous plan, shift?, measured state, reference, settings) -> QP data:
    :func:`intervals` then :func:`condense`."""
    N, nx = pb.N, pb.nx
    Xp = ca.MX.sym("Xp", nx, N + 1)
    Up = ca.MX.sym("Up", 1, N)
    shift = ca.MX.sym("shift")
    x0 = ca.MX.sym("x0", nx)
    R = ca.MX.sym("R", 1, N + 1)                       # reference at the nodes, scaled
    VR = ca.MX.sym("VR", 1, N + 1)                     # its velocity, scaled
    up = ca.MX.sym("up")
    zprev = ca.MX.sym("zprev", nx)
    dprev = ca.MX.sym("dprev")
    est = ca.MX.sym("est")
    P = ca.MX.sym("P", pb.P.size)
    X, U, d, A, B, c, dz0, *inner = _intervals(pb, Xp, Up, shift, x0, up, zprev, dprev, est, P)
    out = condense(pb)(A, B, c, dz0, X, U, R, VR, up, P, *inner)
    return ca.Function("wb_nmpc_prep", [Xp, Up, shift, x0, R, VR, up, zprev, dprev, est, P],
                       [*out, X, U, d])


def condense(pb, Sym=ca.MX) -> ca.Function:
    """Condensed Gauss-Newton QP from interval sensitivities.

    ``Sym`` MX (default): a compact loop of block products in the generated C (120 kB
    at N = 20, compiled in 2-3 s; 15 us per call); SX: straight-line scalar code
    (0.7 MB, 30 s to compile, 6 us per call, but slower from cold caches).

    Returns ``wb_nmpc_condense(A, B, c, dz0, X, U, R, VR, up, P) -> (H, g, A, lba, uba,
    lbx, ubx, h, G)``: the QP in the moves and slacks, and the node corrections at
    zero moves h (nx, N + 1) with their sensitivity G (nx (N + 1), N) to the moves.
    """
    N, nx, ns = pb.N, pb.nx, pb.ns
    A_ = Sym.sym("A", nx, nx * N)
    B_ = Sym.sym("B", nx, N)
    c = Sym.sym("c", nx, N)                          # shooting defects
    dz0 = Sym.sym("dz0", nx)                         # measured - guessed x_0
    X = Sym.sym("X", nx, N + 1)
    U = Sym.sym("U", 1, N)
    R = Sym.sym("R", 1, N + 1)
    VR = Sym.sym("VR", 1, N + 1)
    up = Sym.sym("up")
    P = Sym.sym("P", pb.P.size)
    inner = [] if pb.Fi is None else [Sym.sym(n, pb.Fi.sparsity_out(i).shape[0],
                                              pb.Fi.sparsity_out(i).shape[1] * N)
                                      for i, n in enumerate(("Zi", "Ai", "Bi"))]
    wx, wv, wdu, rho1, rho2, lo, hi = pb.unpack(P)
    # dz_k = h_k + G_k dw, G_k with k non-zero columns
    hs, Gs = [dz0], [Sym(nx, 0)]
    for k in range(N):
        A = A_[:, k * nx:(k + 1) * nx]
        Gs.append(ca.horzcat(ca.mtimes(A, Gs[-1]), B_[:, k]))
        hs.append(ca.mtimes(A, hs[-1]) + c[:, k])
    Gf = [ca.horzcat(G, Sym(nx, N - G.shape[1])) for G in Gs]
    Hh = ca.horzcat(*hs)
    Xp = X + Hh                                        # states at dw = 0
    S = [ca.vertcat(*[Gf[k][i, :] for k in range(1, N + 1)]) for i in range(nx)]
    ex = (Xp[0, 1:] - R[0, 1:]).T
    ev = (Xp[1, 1:] - VR[0, 1:]).T
    D = np.eye(N) - np.eye(N, k=-1)
    e0 = np.zeros(N)
    e0[0] = 1.0
    Wx = ca.repmat(wx, 1, N)
    Wv = ca.repmat(wv, 1, N)
    Hc = (ca.mtimes(S[0].T, S[0] * Wx) + ca.mtimes(S[1].T, S[1] * Wv)
          + wdu * ca.DM(D.T @ D))
    gc = (ca.mtimes(S[0].T, wx * ex) + ca.mtimes(S[1].T, wv * ev)
          + wdu * ca.mtimes(ca.DM(D.T), ca.mtimes(ca.DM(D), U.T) - ca.DM(e0) * up))
    H = ca.diagcat(Hc, rho2 * Sym.eye(ns))
    g = ca.vertcat(gc, rho1 * Sym.ones(ns))
    one = ca.DM.ones(N, 1)
    rows, lb, ub = [], [], []
    for i, j in pb.soft:
        v = Xp[i, 1:].T
        e = ca.DM.zeros(N, ns)
        e[:, j] = 1.0
        rows += [ca.horzcat(S[i], e), ca.horzcat(S[i], -e)]
        lb += [lo[i] - v, -ca.inf * one]
        ub += [ca.inf * one, hi[i] - v]
    if inner:                                          # limits between the nodes
        more = interior_rows(pb, *inner, hs, Gf, lo, hi, _slack_columns(ns))
        rows, lb, ub = rows + more[0], lb + more[1], ub + more[2]
    lbx = ca.vertcat(pb.w_lo - U.T, ca.DM.zeros(ns))
    ubx = ca.vertcat(pb.w_hi - U.T, ca.inf * ca.DM.ones(ns))
    return ca.Function("wb_nmpc_condense", [A_, B_, c, dz0, X, U, R, VR, up, P, *inner],
                       [ca.densify(H), ca.densify(g), ca.densify(ca.vertcat(*rows)),
                        ca.vertcat(*lb), ca.vertcat(*ub), lbx, ubx, Hh,
                        ca.densify(ca.vertcat(*Gf))])


def _slack_columns(ns: int):
    """slack index j, rows n -> (n, ns) DM with ones in column j."""
    def cols(j: int, n: int):
        e = ca.DM.zeros(n, ns)
        e[:, j] = 1.0
        return e
    return cols


def apply_step(pb) -> ca.Function:
    """Apply the QP step: new plan, first command, predicted violations, sanity."""
    N, nx, ns = pb.N, pb.nx, pb.ns
    X = ca.SX.sym("X", nx, N + 1)
    U = ca.SX.sym("U", 1, N)
    h = ca.SX.sym("h", nx, N + 1)
    G = ca.SX.sym("G", nx * (N + 1), N)
    dw = ca.SX.sym("dw", N + ns)
    P = ca.SX.sym("P", pb.P.size)
    _, _, _, _, _, lo, hi = pb.unpack(P)
    du = dw[:N]
    Un = U + du.T
    Xn = X + h + ca.reshape(ca.mtimes(G, du), nx, N + 1)
    viol = ca.vertcat(*[ca.fmax(0.0, ca.fmax(ca.mmax(lo[i] - Xn[i, 1:]),
                                               ca.mmax(Xn[i, 1:] - hi[i])))
                        for i in range(nx)])
    tot = ca.sum1(dw) + ca.sum1(ca.sum2(Xn))
    ok = ca.logic_and(tot == tot,                      # no NaN
                      ca.logic_and(ca.mmax(ca.fabs(ca.vec(Xn))) < 1e2,
                                   ca.logic_and(ca.mmin(Un) >= pb.w_lo - 1e-6,
                                                ca.mmax(Un) <= pb.w_hi + 1e-6)))
    # the QP's tolerance, not a clip; and INSIDE the range: the model clips the spool
    # at the command limits, so its sensitivity to the command is 1 inside, 0 outside
    # and 0.5 exactly at the limit (the fmin/fmax tie): a plan left at the limit was
    # linearised with 1 or 0.5 by the rounding of the QP's step (an exact QP solved
    # another way flipped it: H 4x off at the next sample)
    Un = ca.fmin(ca.fmax(Un, pb.w_lo + INSIDE), pb.w_hi - INSIDE)
    return ca.Function("wb_nmpc_post", [X, U, h, G, dw, P],
                       [Xn, Un, Un[0], viol, ok, ca.mmax(ca.fabs(du))])


def qp_solver(name: str, nz: int, nc: int, primal_tol: float | None = None) -> ca.Function:
    """The CasADi conic plugin ``name`` for a dense QP of nz variables and nc rows
    (``primal_tol``: DAQP's, None its default)."""
    hs, As = ca.Sparsity.dense(nz, nz), ca.Sparsity.dense(nc, nz)
    opts: dict[str, Any] = {"error_on_fail": False}
    if name == "daqp":
        if primal_tol is not None:
            opts.update(daqp={"primal_tol": float(primal_tol)})
    elif name == "qpoases":
        opts.update(printLevel="none", sparse=False)
    elif name == "osqp":
        opts.update(warm_start_primal=True,
                    osqp={"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8,
                          "polish": True, "max_iter": 20000})
    elif name == "qrqp":
        opts.update(print_iter=False, print_header=False, print_info=False)
    return ca.conic("wb_nmpc_qp", name, {"h": hs, "a": As}, opts)
