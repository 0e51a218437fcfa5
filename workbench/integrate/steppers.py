"""Stepping functions: a tableau, a right-hand side and a step size -> CasADi steps.

Expression level (the caller keeps its own loop and symbols):

* :func:`explicit_rk`: x+ of an explicit Runge-Kutta step (e.g. :data:`.RK4`);
* :func:`rosenbrock`: x+ of a Rosenbrock step (:data:`.ROS2`, :data:`.ROS4`,
  :data:`.RODAS4`), optionally with an approximate Jacobian W and a caller's linear
  solver (default: the unpivoted LU of :mod:`.linalg`, written out in SX);
* :func:`radau_simplified_newton`: x+ and the stages of a 3-stage Radau IIA step by
  simplified Newton in the eigenbasis of the Butcher matrix;
* :func:`radau_stages` and :func:`radau_sensitivity`: a Radau IIA step (1-3 stages)
  with full Newton on the stage equations and its sensitivities by the implicit
  function theorem (for the grey-box estimator's exact gradients).

Function level:

* :func:`step_function`: ``wb_step(x, u, z) -> (x+, z+)`` for a named method, with
  the parameters folded into ``f`` (z: the Radau stages carried between steps);
* :func:`radau_step_functions`: ``(x, u, h, p) -> x+`` and
  ``(x, S, u, h, p, E) -> (x+, S+)`` with S = dx/d[x0, E' p].
"""

from __future__ import annotations

import functools
from typing import Callable

import casadi as ca
import numpy as np

from . import linalg
from .tableaux import RADAU_IIA_3, ROS2, ROS4, RODAS4, ButcherTableau, RosenbrockTableau

__all__ = ["explicit_rk", "rosenbrock", "radau_simplified_newton", "radau_stages",
           "radau_sensitivity", "step_function", "radau_step_functions", "METHODS"]


def explicit_rk(tableau: ButcherTableau, f: Callable, x, h):
    """One explicit Runge-Kutta step: x + h sum_i b_i k_i, k_i = f(x + h sum_j a_ij k_j).

    Parameters
    ----------
    tableau : an explicit :class:`ButcherTableau`.
    f : right-hand side, x -> dx/dt (SX or MX expressions).
    x : state expression. h : step, s (float or expression).
    """
    if not tableau.explicit:
        raise ValueError(f"{tableau.name} is implicit: use a Radau stepper")
    k: list = []
    for i in range(tableau.stages):
        arg = x
        for j in range(i):
            if tableau.a[i][j]:
                arg = arg + (h * tableau.a[i][j]) * k[j]
        k.append(f(arg))
    den = _common_denominator(tableau.b)
    if den:        # x + h/D sum_i n_i k_i with integers n_i (RK4: h/6 (k1 + 2 k2 + 2 k3 + k4))
        terms = [ki if n == 1 else n * ki
                 for n, ki in zip((round(bi * den) for bi in tableau.b), k) if n]
        return x + h / den * functools.reduce(lambda a, b: a + b, terms)
    return x + h * sum(bi * ki for bi, ki in zip(tableau.b, k) if bi)


def _common_denominator(b, largest: int = 24) -> int | None:
    """The least D <= ``largest`` making every D b_i an integer (1e-12), else None."""
    for den in range(1, largest + 1):
        if all(abs(bi * den - round(bi * den)) < 1e-12 for bi in b):
            return den
    return None


def rosenbrock(tableau: RosenbrockTableau, f: Callable, x, h: float, fx=None, jacobian=None,
               solve: Callable | None = None, error: bool = False):
    """One Rosenbrock step x -> x+ (see :class:`RosenbrockTableau` for both forms).

    Parameters
    ----------
    f : right-hand side, x -> dx/dt.
    x : state expression (SX for the default solver). h : step, s.
    fx : f(x) when the caller has it already (avoids a second copy).
    jacobian : the matrix J (or an approximation W of it) of the step; default df/dx at x.
    solve : ``solve(M, rhs)`` with M = I/(h gamma) - J (form "hw") or I - gamma h J
        (form "w"); default the unpivoted LU of :mod:`.linalg` of I/(h gamma) - J,
        written out in SX and factorised once per step.

    error : also return the embedded error estimate sum_i e_i k_i (a vector like x, in
        the units of x; the tableau must have error weights ``e``): ``(x+, err)``.

    A stage whose argument equals the previous one reuses its f (ROS4's stages 3, 4).
    The step ``h`` may be an expression (a step size chosen at run time).
    """
    if error and not tableau.e:
        raise ValueError(f"{tableau.name} has no embedded error estimate")
    fx = f(x) if fx is None else fx
    J = ca.jacobian(fx, x) if jacobian is None else jacobian
    gh = tableau.gamma * h
    w_form = tableau.form == "w"
    if solve is None:
        lu = linalg.lu_factor(linalg.shifted(J, 1.0 / gh))

        def lin(b):
            return linalg.lu_solve(lu, b / gh if w_form else b)
    else:
        eye = type(J).eye(J.shape[0])
        M = eye - gh * J if w_form else eye * (1.0 / gh) - J

        def lin(b):
            return solve(M, b)
    k: list = []
    fi, prev = fx, ()
    for i, (a, c) in enumerate(zip(tableau.a, tableau.c)):
        a = tuple(a)
        while a and not a[-1]:
            a = a[:-1]
        if i and a != prev:
            fi = f(x + sum((h * aj if w_form else aj) * kj for aj, kj in zip(a, k) if aj))
        prev = a
        rhs = fi + sum((cj if w_form else cj / h) * kj for cj, kj in zip(c, k) if cj)
        k.append(lin(rhs))
    if w_form:
        x_next = x
        for mi, ki in zip(tableau.m, k):
            if mi:
                x_next = x_next + mi * h * ki
    else:
        x_next = x + sum(mi * ki for mi, ki in zip(tableau.m, k) if mi)
    if not error:
        return x_next
    err = sum((ei * h if w_form else ei) * ki for ei, ki in zip(tableau.e, k) if ei)
    return x_next, err


def _radau_constants():
    """Eigenbasis of A^-1 (T, T^-1, gamma, alpha, beta) and the stage extrapolation E."""
    A = RADAU_IIA_3.A
    Ai = np.linalg.inv(A)
    w, V = np.linalg.eig(Ai)
    ir, ic = int(np.argmin(np.abs(w.imag))), int(np.argmax(w.imag))
    T = np.column_stack([V[:, ir].real, V[:, ic].real, V[:, ic].imag])
    Ti = np.linalg.inv(T)
    L = Ti @ Ai @ T      # [[gamma, 0, 0], [0, alpha, -beta], [0, beta, alpha]]
    c = A.sum(axis=1)
    nodes = np.concatenate(([0.0], c))

    def lag(j, t):
        return np.prod([(t - nodes[q]) / (nodes[j] - nodes[q]) for q in range(4) if q != j])
    # the collocation polynomial q (q(0) = 0, q(c_j) = Z_j) continued one step:
    # next stage guesses Z_i = q(1 + c_i) - q(1)
    E = np.array([[lag(j + 1, 1.0 + c[i]) - lag(j + 1, 1.0) for j in range(3)] for i in range(3)])
    return T, Ti, L[0, 0], L[1, 1], L[2, 1], E


def radau_simplified_newton(f: Callable, x: ca.SX, h: float, z_prev: ca.SX,
                            newton_iterations: int = 3) -> tuple[ca.SX, ca.SX]:
    """One 3-stage Radau IIA step (order 5) by simplified Newton; (x+, stages).

    The stage increments Z solve Z = h (A x I) F(x + Z). With A^-1 = T L T^-1 the
    Newton matrix (A^-1/h x I - I x J) splits into (gamma/h - J) and the complex
    ((alpha + i beta)/h - J), each factorised once per step at J(x). ``z_prev`` are
    the previous step's stages (3 nx), extrapolated as the starting guess (zeros:
    start from Z = 0).
    """
    T, Ti, gam, alp, bet, E = _radau_constants()
    nx = x.shape[0]
    J = ca.jacobian(f(x), x)
    lu1 = linalg.lu_factor(linalg.shifted(J, gam / h))
    lu2 = linalg.complex_lu_factor(
        [[(v, ca.SX(bet / h) if i == j else ca.SX(0)) for j, v in enumerate(row)]
         for i, row in enumerate(linalg.shifted(J, alp / h))])
    Zo = [z_prev[i * nx:(i + 1) * nx] for i in range(3)]
    Z = [sum(E[i, j] * Zo[j] for j in range(3)) for i in range(3)]
    W = [sum(Ti[i, j] * Z[j] for j in range(3)) for i in range(3)]
    for _ in range(newton_iterations):
        F = [f(x + Z[i]) for i in range(3)]
        G = [Ti[i, 0] * F[0] + Ti[i, 1] * F[1] + Ti[i, 2] * F[2] for i in range(3)]
        r1 = G[0] - (gam / h) * W[0]
        r2 = G[1] - (alp * W[1] - bet * W[2]) / h
        r3 = G[2] - (bet * W[1] + alp * W[2]) / h
        d1 = linalg.lu_solve(lu1, r1)
        d23 = linalg.complex_lu_solve(lu2, [(r2[i], r3[i]) for i in range(nx)])
        W = [W[0] + d1, W[1] + ca.vertcat(*[d[0] for d in d23]),
             W[2] + ca.vertcat(*[d[1] for d in d23])]
        Z = [T[i, 0] * W[0] + T[i, 1] * W[1] + T[i, 2] * W[2] for i in range(3)]
    return x + Z[2], ca.vertcat(*Z)


def _solver(large: bool):
    # Large systems: CasADi's own sparse QR ("qr"), which code generation writes out
    # as C (the grey-box step of a line plant is compiled: 2-4x faster per evaluation
    # than the virtual machine); "csparse" is generated as a call back into its runtime,
    # no faster than the VM. Householder QR needs no pivoting tolerance.
    def solve(Mat, rhs):
        return ca.solve(Mat, rhs, "qr") if large else ca.solve(Mat, rhs)
    return solve


def radau_stages(tableau: ButcherTableau, f: ca.Function, fjac: ca.Function, X, u, h, p,
                 newton: int, large: bool = False):
    """Stage increments Z (s nx) of a Radau IIA step by ``newton`` full Newton iterations.

    Parameters
    ----------
    tableau : a Radau IIA :class:`ButcherTableau` (1, 2 or 3 stages).
    f : Function (x, u, p) -> dx/dt. fjac : Function (x, u, p) -> (df/dx, df/dp).
    X, u, h, p : state, command, step (s) and parameter expressions (SX or MX).
    newton : iterations, from Z_i = c_i h f(X), with the Newton matrix at X.
    large : MX with a sparse QR (CasADi's "qr", code-generated) instead of a dense
        symbolic QR (SX).

    The step is X + Z[last stage] (Radau IIA is stiffly accurate).
    """
    nx, s = X.shape[0], tableau.stages
    T = type(X)
    K = ca.kron(ca.DM(tableau.A), ca.DM.eye(nx))
    f0 = f(X, u, p)
    J0, _ = fjac(X, u, p)
    Mm = T.eye(s * nx) - h * ca.kron(ca.DM(tableau.A), J0)
    Z = ca.vertcat(*[float(tableau.c[i]) * h * f0 for i in range(s)])
    if not large:
        Q, R = ca.qr(Mm)
    for _ in range(newton):
        F = ca.vertcat(*[f(X + Z[i * nx:(i + 1) * nx], u, p) for i in range(s)])
        res = Z - h * ca.mtimes(K, F)
        Z = Z - (_solver(large)(Mm, res) if large else ca.solve(R, ca.mtimes(Q.T, res)))
    return Z


def radau_sensitivity(tableau: ButcherTableau, fjac: ca.Function, X, Z, S, u, h, p, E,
                      large: bool = False):
    """(x+, S+) of a Radau IIA step with stages Z, by the implicit function theorem.

    S = dX/d[X0, theta] (nx x (nx + nsel)) with theta = E' p; S+ is the same after
    the step, from the stage equations Z - h (A x I) F(X + Z) = 0.
    """
    nx, s = X.shape[0], tableau.stages
    T = type(X)
    K = ca.kron(ca.DM(tableau.A), ca.DM.eye(nx))
    Js, Ps = [], []
    for i in range(s):
        Ji, Pi = fjac(X + Z[i * nx:(i + 1) * nx], u, p)
        Js.append(Ji)
        Ps.append(ca.mtimes(Pi, E))
    Gz = T.eye(s * nx) - h * ca.mtimes(K, ca.diagcat(*Js))
    rhs = h * ca.mtimes(K, ca.vertcat(*[ca.horzcat(Js[i], Ps[i]) for i in range(s)]))
    D = _solver(large)(Gz, rhs)
    last = slice((s - 1) * nx, s * nx)
    Phi = T.eye(nx) + D[last, :nx]
    Sk = ca.mtimes(Phi, S) + ca.horzcat(T.zeros(nx, nx), D[last, nx:])
    return X + Z[last], Sk


def radau_step_functions(tableau: ButcherTableau, f: ca.Function, nsel: int, newton: int,
                         large: bool = False) -> tuple[ca.Function, ca.Function]:
    """Radau IIA step Functions with parameters and step size as inputs.

    Parameters
    ----------
    tableau : Radau IIA tableau. f : Function (x, u, p) -> dx/dt (SX).
    nsel : number of parameters the sensitivities are taken for (columns of E).
    newton : Newton iterations. large : MX and a sparse LU (many states).

    Returns
    -------
    step : (x, u, h, p) -> x+
    step_sens : (x, S, u, h, p, E) -> (x+, S+), S = dx/d[x0, E' p] (nx x (nx + nsel)).
    """
    nx, npar = f.size1_in(0), f.size1_in(2)
    xs, us, ps = ca.SX.sym("x", nx), ca.SX.sym("u"), ca.SX.sym("p", npar)
    fe = f(xs, us, ps)
    fx = ca.Function("rd_f", [xs, us, ps], [fe])
    fjac = ca.Function("rd_fj", [xs, us, ps], [ca.jacobian(fe, xs), ca.jacobian(fe, ps)])
    Sym = ca.MX if large else ca.SX
    X, S = Sym.sym("x", nx), Sym.sym("S", nx, nx + nsel)
    u, h, p, E = Sym.sym("u"), Sym.sym("h"), Sym.sym("p", npar), Sym.sym("E", npar, nsel)
    Z = radau_stages(tableau, fx, fjac, X, u, h, p, newton, large)
    xn, sn = radau_sensitivity(tableau, fjac, X, Z, S, u, h, p, E, large)
    step = ca.Function("radau_step", [X, u, h, p], [xn], ["x", "u", "h", "p"], ["xn"])
    sens = ca.Function("radau_step_sens", [X, S, u, h, p, E], [xn, sn],
                       ["x", "S", "u", "h", "p", "E"], ["xn", "Sn"])
    return step, sens


#: the methods of :func:`step_function`
METHODS = ("ros4", "rodas4", "radau", "ros2")
_ROSENBROCK = {"ros4": ROS4, "rodas4": RODAS4, "ros2": ROS2}


def step_function(method: str, f: Callable, nx: int, h: float, newton_iterations: int = 3,
                  name: str = "wb_step") -> ca.Function:
    """``wb_step(x, u, z) -> (x+, z+)``: one step of ``method`` for f(x, u) (SX).

    Parameters
    ----------
    method : one of :data:`METHODS`. f : (x, u) -> dx/dt, parameters folded in.
    nx : number of states. h : step, s.
    newton_iterations : simplified Newton iterations of ``"radau"`` (ignored otherwise).

    The auxiliary z is empty for the Rosenbrock methods and the Radau stages
    (3 nx: the starting guess of the next step; zeros at a restart) for ``"radau"``.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(map(repr, METHODS))}, "
                         f"got {method!r}")
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u")
    if method == "radau":
        z = ca.SX.sym("z", 3 * nx)
        x_next, z_next = radau_simplified_newton(lambda xx: f(xx, u), x, h, z,
                                                 newton_iterations)
    else:
        z, z_next = ca.SX.sym("z", 0), ca.SX(0, 1)
        x_next = rosenbrock(_ROSENBROCK[method], lambda xx: f(xx, u), x, h)
    return ca.Function(name, [x, u, z], [ca.densify(ca.cse(x_next)), ca.densify(ca.cse(z_next))])
