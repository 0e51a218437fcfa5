"""Approximation II of paper 003: the input-affine law fitted with constraints by IPOPT."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, Callable

import casadi as ca
import numpy as np

from ...errors import InputError, WorkbenchError
from ...physics.valve import AffineValveFit, gamma_odd
from ._numeric import clip as _clip, is_symbolic as _is_sym, numeric as _numeric
from .blocked import check_pressure_gain_points
from .lstsq import constraint_rank, lstsq as _lstsq, lstsq_equality
from .quality import FitQuality, _normalised_command, _quality
from .table import G_PER_KG, ValveTable

__all__ = ["PRESSURE_SCALE", "AffineTableFit", "fit_affine"]

#: Pressure polynomials of approximation II are in p / this (bar), as the plant file's.
PRESSURE_SCALE = 1e5


@dataclass(frozen=True)
class AffineTableFit:
    """Approximation II fitted to a table: q_m = phi(p) + psi(p, sgn Gamma) Gamma(s).

    Attributes
    ----------
    law : AffineValveFit
        The coefficients in the plant file's convention (ascending powers of
        p / 1e5 Pa; phi in kg/s, psi in kg/s per unit Gamma, Gamma(s) = sum_k g_k
        s |s|^(k-1) of the normalised opening s); its ``rms``/``max_error`` are
        those on the table.
    center, span : V; s = (u - center) / span clipped to [-1, 1], as the plant does.
    quality : FitQuality on the table (``free`` counts independent parameters).
    normalisation : text of the scale constraint (Gamma(1) = 1).
    pin_ends : whether q(p_supply, s = 1) = 0 and q(p_atm, s = -1) = 0 were imposed.
    phi_from : ``"fit"`` (phi fitted with the rest) or ``"centre"`` (phi fitted to the
        centred command's column alone, then held: q(p, centre) = phi(p) by the form).
    pressure_gain : the blocked-port points (u in V, p_e in Pa) imposed as q = 0.
    supply_pressure, atmospheric_pressure : Pa, used by ``pin_ends``.
    solver_status : IPOPT's return status. iterations : its iteration count.

    Notes
    -----
    Counting the coefficients (degrees phi 5, psi 5, Gamma 2): phi 6, psi_in 6,
    psi_out 6, Gamma 2 odd terms (g1 s + g2 s|s|; an odd Gamma has no constant and
    no even terms) = 20 stored numbers; Gamma(1) = 1 fixes the scale shared by psi
    and Gamma (psi Gamma = (c psi)(Gamma / c)), leaving 19 free, and ``pin_ends``
    two more equalities, 17. Paper 003 counts (n+1) + (m+1) + (l+1) = 6 + 6 + 3 = 15:
    one psi polynomial and a full quadratic Gamma including the constant that
    Gamma(0) = 0 forces to zero. Its psi has an inlet and an exhaust branch (its
    Fig. 5b, and the text: "two different functions"), which that count does not
    include; with one psi for both branches (``shared_psi=True`` in
    :func:`fit_affine`) the numbers are 6 + 6 + 2 = 14 stored, 13 free, the paper's
    15 minus Gamma's forced constant and minus the scale normalisation.
    """

    law: AffineValveFit
    center: float
    span: float
    quality: FitQuality
    normalisation: str
    pin_ends: bool
    supply_pressure: float
    atmospheric_pressure: float
    solver_status: str
    iterations: int
    phi_from: str = "fit"
    pressure_gain: tuple[tuple[float, float], ...] = ()

    @property
    def phi(self) -> tuple[float, ...]:
        return self.law.phi

    @property
    def psi_in(self) -> tuple[float, ...]:
        return self.law.psi_in

    @property
    def psi_out(self) -> tuple[float, ...]:
        return self.law.psi_out

    @property
    def gamma(self) -> tuple[float, ...]:
        return self.law.gamma

    def opening(self, u):
        """Normalised opening s = (u - center)/span clipped to [-1, 1], -."""
        return _clip((u - self.center) / self.span, -1.0, 1.0)

    def gamma_of(self, u):
        """Gamma(s(u)), -: odd in s by construction, Gamma(0) = 0."""
        return gamma_odd(self.opening(u), self.law.gamma)

    def flow(self, p, u):
        """q_m (kg/s) at pressure ``p`` (Pa) and command ``u`` (V); floats, arrays or CasADi."""
        if _is_sym(p, u):
            return self.law.flow(p, self.opening(u))
        out = self._numeric_flow(p, u)
        return float(out) if out.ndim == 0 else out

    @cached_property
    def _numeric_flow(self) -> Callable[[Any, Any], np.ndarray]:
        return _numeric(self.flow)

    def plant_values(self) -> dict[str, Any]:
        """Dotted plant-file keys that make a plant's valve follow this law.

        For :meth:`workbench.PlantParams.replace`: the law and its coefficients, the
        command centre and span of the fit, and no deadband or null offset (the fitted
        Gamma already contains what the table showed of them).
        """
        vals = self.law.plant_values()
        vals.update({"valve.command_center": self.center, "valve.command_span": self.span,
                     "valve.deadband": None, "valve.null_offset": None})
        return vals

    def toml_lines(self) -> str:
        """The ``[valve]`` lines of a plant file for this law (full precision).

        They include ``command_center`` and ``command_span``, which replace the plant
        file's; a deadband or null offset must be removed (see :meth:`plant_values`).
        """
        return "\n".join([f"command_center = {self.center!r}",
                          f"command_span = {self.span!r}", self.law.toml_lines()])

    def to_dict(self) -> dict[str, Any]:
        return {"approximation": "II", "phi_kg_s": list(self.phi),
                "psi_in_kg_s": list(self.psi_in), "psi_out_kg_s": list(self.psi_out),
                "gamma": list(self.gamma), "pressure_variable": "p / 1e5 Pa",
                "command_variable": f"s = (u - {self.center!r}) / {self.span!r}, "
                                    "clipped to [-1, 1]",
                "normalisation": self.normalisation, "pin_ends": self.pin_ends,
                "phi_from": self.phi_from,
                "pressure_gain_points": [list(r) for r in self.pressure_gain],
                "solver_status": self.solver_status, "iterations": self.iterations,
                **self.quality.to_dict()}


def _to_bar_monomials(coeffs: np.ndarray, offset_bar: float, scale_bar: float) -> np.ndarray:
    """Ascending coefficients in x = (pb - offset)/scale -> ascending in pb = p/1e5."""
    P = np.polynomial.Polynomial
    out = P(coeffs)(P([-offset_bar / scale_bar, 1.0 / scale_bar])).coef
    return np.pad(out, (0, len(coeffs) - len(out)))


def fit_affine(table: ValveTable, phi_degree: int | None = 5, psi_degree: int = 5,
               gamma_degree: int = 2, *, pin_ends: bool = False, monotone: bool = True,
               shared_psi: bool = False, phi_from: str = "fit", center: float | None = None,
               span: float | None = None, pressure_gain=None,
               print_level: int = 0) -> AffineTableFit:
    """Approximation II with constraints, by CasADi + IPOPT (paper 003, eq. 5).

    Unknowns: the coefficients of phi (degree ``phi_degree``, or phi = 0 for None),
    psi_in and psi_out (degree ``psi_degree``) and the ``gamma_degree`` odd terms of
    Gamma(s) = sum_k g_k s |s|^(k-1) (so Gamma(-s) = -Gamma(s) and Gamma(0) = 0 hold
    for any coefficients, exactly). Minimised: the mean squared flow error in g/s.
    Constraints:

    * Gamma(1) = 1 (normalisation: removes the scale shared by psi and Gamma, and
      makes psi_in(p) + phi(p) the flow of the fully open inlet);
    * ``monotone``: Gamma'(s) >= 0 on 21 points of [0, 1] (exact for degree 2,
      where Gamma' is linear in |s|), so sgn Gamma = sgn s and Gamma is invertible
      (feedback linearisation needs u = Gamma^-1);
    * ``pin_ends``: q(p_supply, s = 1) = 0 and q(p_atm, s = -1) = 0, a fully open valve
      holds a tank at supply pressure (inlet) or at atmosphere (exhaust).

    Because sgn Gamma = sgn s, the branch of psi of every table point is known and
    the objective is a smooth polynomial (without ``monotone`` the branch is still
    taken from sgn s; the reported errors use the law itself, so a Gamma that
    changes sign inside a side would show there). The start is Gamma(s) = s with phi, psi by
    linear least squares. Internally the pressure polynomials use x = (p - p_mid) /
    p_half in [-1, 1] for conditioning; they are converted to powers of p / 1e5 Pa.
    ``shared_psi`` uses one psi for inlet and exhaust (paper 003's count, see
    :class:`AffineTableFit`).

    ``phi_from="centre"`` fits phi by linear least squares to the column of the centred
    command (s = 0) alone and holds it: because Gamma(0) = 0 the form says q(p, centre)
    = phi(p), so the leakage polynomial is measured directly, and the equilibrium of
    the centred valve and its slope Cp = -phi'(p_e) (the tank's time constant) are
    those of the data, not a compromise with the open-valve points. With ``"fit"``
    phi is fitted with everything else (paper 003's nonlinear regression).

    ``pressure_gain``: optional measured blocked-port points, rows (u in V, p_e in Pa),
    imposed as equality constraints q(p_e, u) = 0 (:mod:`.blocked` says why); a point at
    the centred command constrains phi alone (phi(p_e) = 0), also when phi is taken
    from the centred column. Each point removes one free parameter.

    Raises
    ------
    InputError
        Bad degrees, fewer points than unknowns, or data that cannot determine the
        unknowns: a pressure polynomial of degree n needs more than n distinct
        pressures (phi over the table, psi_in among the points with u above the
        centre, psi_out below it), a flow direction without data for its psi, Gamma
        with more odd terms than distinct openings on a side, ``phi_from="centre"``
        without a centred column of enough pressures. The message says which.
    WorkbenchError
        IPOPT fails.
    """
    if psi_degree < 0 or gamma_degree < 1 or (phi_degree is not None and phi_degree < 0):
        raise InputError(f"expected degrees phi >= 0 (or none), psi >= 0, gamma >= 1; got "
                         f"{phi_degree}, {psi_degree}, {gamma_degree}",
                         location="--affine-degrees")
    if phi_from not in ("fit", "centre"):
        raise InputError(f"expected phi_from 'fit' or 'centre', got {phi_from!r}",
                         location="--phi-from")
    center, span = _normalised_command(table, center, span)
    pb = _affine_problem(table, center, span, phi_degree, psi_degree, gamma_degree,
                         shared_psi, pin_ends)
    _check_determined(pb, table.source)
    blocked = _blocked_points(pressure_gain, table, pb, center, span)
    phi_fixed = _centre_phi(pb, table.source, blocked) if phi_from == "centre" else None
    if phi_fixed is not None:
        blocked = blocked[blocked[:, 0] != 0.0]       # met by phi_fixed already
    w, f, g = _affine_nlp(pb)
    cons, lbg, ubg = _affine_constraints(pb, g, monotone, pin_ends)
    cons += [_affine_at(pb, g, s_k, x_k) for s_k, x_k in blocked]
    lbg += [0.0] * len(blocked)
    ubg += [0.0] * len(blocked)
    solver = ca.nlpsol("valve_affine", "ipopt", {"x": w, "f": f, "g": ca.vertcat(*cons)},
                       {"ipopt.print_level": int(print_level), "print_time": False,
                        "ipopt.tol": 1e-12, "ipopt.max_iter": 500, "ipopt.sb": "yes"})
    lbx, ubx = np.full(w.numel(), -np.inf), np.full(w.numel(), np.inf)
    if phi_fixed is not None:
        lbx[:pb.n_phi] = ubx[:pb.n_phi] = phi_fixed
    sol = solver(x0=_affine_start(pb, phi_fixed), lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx)
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    if not stats.get("success", False) and status not in ("Solved_To_Acceptable_Level",):
        raise WorkbenchError(f"IPOPT did not fit approximation II: {status}")
    phi, psi_in, psi_out, gamma = _affine_coefficients(pb, np.asarray(sol["x"]).ravel())
    n_stored = len(phi) * (pb.n_phi > 0) + pb.n_branches * pb.n_psi + pb.n_gam
    lo, hi = pb.p_range
    law = AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                         pressure_scale=PRESSURE_SCALE, rms=0.0, max_error=0.0,
                         pressure_range=(lo, hi), points=len(pb.q))
    q_fit = np.asarray(_numeric(lambda p, u: law.flow(p, _clip((u - center) / span, -1.0, 1.0)))(
        table.p, table.u), dtype=float)
    n_blocked = 0 if pressure_gain is None else len(np.asarray(pressure_gain))
    quality = _quality(table, q_fit, n_stored,
                       pb.n_free - (pb.n_phi if phi_fixed is not None else 0) - n_blocked)
    law = AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                         pressure_scale=PRESSURE_SCALE, rms=quality.rms,
                         max_error=quality.max_error, pressure_range=(lo, hi), points=len(pb.q))
    return AffineTableFit(law=law, center=center, span=span, quality=quality,
                          normalisation="Gamma(1) = 1", pin_ends=bool(pin_ends),
                          supply_pressure=table.supply_pressure,
                          atmospheric_pressure=table.atmospheric_pressure,
                          solver_status=status, iterations=int(stats.get("iter_count", -1)),
                          phi_from=phi_from,
                          pressure_gain=() if pressure_gain is None else tuple(
                              (float(a), float(b)) for a, b in np.asarray(pressure_gain, float)))


def _check_determined(pb: "_AffineProblem", source: str) -> None:
    """Refuse unknowns the data cannot determine (distinct pressures and openings)."""
    def distinct(sel):
        return len(np.unique(pb.x[sel]))
    every = np.ones(len(pb.q), bool)
    if pb.n_phi and distinct(every) < pb.n_phi:
        raise InputError(f"phi of degree {pb.n_phi - 1} needs at least {pb.n_phi} distinct "
                         f"pressures; the table has {distinct(every)}: a polynomial through "
                         "fewer pressures than coefficients is free between them (lower the "
                         "degree)", source=source, location="--affine-degrees")
    sides = ([("psi (shared)", pb.s != 0)] if pb.shared_psi else
             [("psi_in (flow from the supply, u above the centre)", pb.s > 0),
              ("psi_out (flow to the exhaust, u below the centre)", pb.s < 0)])
    for name, sel in sides:
        if not np.any(sel):
            raise InputError(f"no data for {name}: the table has no command on that side of "
                             "the centre, so that flow direction cannot be fitted (measure "
                             "it, or fit one shared psi)", source=source, location="table")
        if distinct(sel) < pb.n_psi:
            raise InputError(f"{name} of degree {pb.n_psi - 1} needs at least {pb.n_psi} "
                             f"distinct pressures among its points; the table has "
                             f"{distinct(sel)} (lower the psi degree)", source=source,
                             location="--affine-degrees")
    for side, sel in (("above", pb.s > 0), ("below", pb.s < 0)):
        n_open = len(np.unique(np.abs(pb.s[sel])))
        if np.any(sel) and n_open < pb.n_gam:
            raise InputError(f"Gamma with {pb.n_gam} odd terms needs at least {pb.n_gam} "
                             f"distinct commands {side} the centre; the table has {n_open}",
                             source=source, location="--affine-degrees")


def _blocked_points(points, table: ValveTable, pb: "_AffineProblem", center: float,
                    span: float) -> np.ndarray:
    """Pressure gain points as rows (s, x) in the fit's scaled variables (s = 0 exactly at
    the centred command); refuses a centre point when phi is absent (q(p, centre) = 0)."""
    if points is None:
        return np.zeros((0, 2))
    a = check_pressure_gain_points(points, table, table.source)
    s = np.clip((a[:, 0] - center) / span, -1.0, 1.0)
    s[np.abs(s) < 1e-12] = 0.0
    if pb.n_phi == 0 and np.any(s == 0.0):
        raise InputError("a pressure gain point at the centred command needs a phi "
                         "polynomial: without phi the law gives q = 0 there at every pressure",
                         source=table.source, location="pressure_gain")
    for side, sel in (("above", s > 0), ("below", s < 0)):
        if np.sum(sel) > pb.n_psi + pb.n_gam - 1:
            raise InputError(f"{int(np.sum(sel))} pressure gain points {side} the centre, "
                             f"more than the law has free parameters there; use fewer",
                             source=table.source, location="pressure_gain")
    return np.stack([s, (a[:, 1] - pb.p_mid) / pb.p_half], axis=1)


def _affine_at(pb: "_AffineProblem", unknowns, s_k: float, x_k: float):
    """q (g/s) of the law at one scaled point (s_k, x_k), symbolic in the unknowns."""
    a, b_in, b_out, g = unknowns
    q = sum(a[k] * x_k ** k for k in range(pb.n_phi)) if pb.n_phi else 0.0
    if s_k != 0.0:
        b = b_in if s_k > 0 else b_out
        gam = sum(g[k] * s_k * abs(s_k) ** k for k in range(pb.n_gam))
        q = q + sum(b[k] * x_k ** k for k in range(pb.n_psi)) * gam
    return q


def _centre_phi(pb: "_AffineProblem", source: str,
                blocked: np.ndarray | None = None) -> np.ndarray:
    """phi (scaled, g/s) by least squares on the centred column: q(p, centre) = phi(p);
    blocked-port points at the centre (rows s = 0, x) are met exactly."""
    sel = np.abs(pb.s) < 1e-12
    if pb.n_phi == 0:
        raise InputError("phi from the centre needs a phi polynomial (its degree is -1)",
                         location="--phi-from")
    n_p = len(np.unique(pb.x[sel]))
    if n_p < pb.n_phi:
        raise InputError(f"phi from the centre needs the centred command (s = 0) measured at "
                         f"{pb.n_phi} or more distinct pressures; the table has {n_p} there",
                         source=source, location="--phi-from")
    centre = np.zeros((0, 2)) if blocked is None else blocked[blocked[:, 0] == 0.0]
    if len(centre) == 0:
        return _lstsq(pb.phi_basis[sel], pb.q[sel])
    C = np.vander(centre[:, 1], pb.n_phi, increasing=True)
    if len(C) >= pb.n_phi or constraint_rank(C) < len(C):
        raise InputError("too many pressure gain points at the centred command for phi's "
                         "degree", source=source, location="pressure_gain")
    return lstsq_equality(pb.phi_basis[sel], pb.q[sel], C)


@dataclass(frozen=True)
class _AffineProblem:
    """Data of the approximation II fit in its scaled variables (flows in g/s)."""

    q: np.ndarray              # table flows, g/s
    s: np.ndarray              # normalised commands clipped to [-1, 1]
    x: np.ndarray              # (p - p_mid) / p_half
    p_mid: float               # Pa
    p_half: float              # Pa
    p_range: tuple[float, float]
    supply_pressure: float     # Pa
    atmospheric_pressure: float  # Pa
    n_phi: int
    n_psi: int
    n_gam: int
    n_branches: int
    n_free: int
    shared_psi: bool

    @property
    def psi_basis(self) -> np.ndarray:
        return np.vander(self.x, self.n_psi, increasing=True)

    @property
    def phi_basis(self) -> np.ndarray:
        return np.vander(self.x, max(self.n_phi, 1), increasing=True)[:, :self.n_phi]

    @property
    def inlet(self) -> np.ndarray:
        return (self.s > 0).astype(float)

    @property
    def outlet(self) -> np.ndarray:
        return (self.s < 0).astype(float)


def _affine_problem(table: ValveTable, center: float, span: float, phi_degree: int | None,
                    psi_degree: int, gamma_degree: int, shared_psi: bool,
                    pin_ends: bool) -> _AffineProblem:
    """Scaled data and unknown counts; refuses more free parameters than points."""
    q = table.q_m * G_PER_KG                    # fitted in g/s: coefficients O(1)
    s = np.clip((table.u - center) / span, -1.0, 1.0)
    lo, hi = table.pressure_range
    p_mid, p_half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    x = (table.p - p_mid) / p_half
    n_phi = 0 if phi_degree is None else phi_degree + 1
    n_psi = psi_degree + 1
    n_gam = int(gamma_degree)
    n_branches = 1 if shared_psi else 2
    n_free = n_phi + n_branches * n_psi + n_gam - 1 - (2 if pin_ends else 0)
    if n_free >= len(q):
        raise InputError(f"approximation II with these degrees has {n_free} free parameters "
                         f"but the table only {len(q)} points", source=table.source)
    return _AffineProblem(q=q, s=s, x=x, p_mid=p_mid, p_half=p_half, p_range=(lo, hi),
                          supply_pressure=table.supply_pressure,
                          atmospheric_pressure=table.atmospheric_pressure, n_phi=n_phi,
                          n_psi=n_psi, n_gam=n_gam, n_branches=n_branches, n_free=n_free,
                          shared_psi=bool(shared_psi))


def _affine_nlp(pb: _AffineProblem):
    """Unknowns w = [phi, psi_in, (psi_out), gamma] (SX), the objective, and gamma's symbols."""
    Bp, Bphi = pb.psi_basis, pb.phi_basis
    S = np.stack([pb.s * np.abs(pb.s) ** k for k in range(pb.n_gam)], axis=1)   # Gamma basis
    a = ca.SX.sym("phi", pb.n_phi)
    b_in = ca.SX.sym("psi_in", pb.n_psi)
    b_out = b_in if pb.shared_psi else ca.SX.sym("psi_out", pb.n_psi)
    g = ca.SX.sym("gamma", pb.n_gam)
    w = ca.vertcat(a, b_in, *([] if pb.shared_psi else [b_out]), g)
    gam = ca.mtimes(ca.DM(S), g)
    psi = (ca.mtimes(ca.DM(Bp), b_in) * ca.DM(pb.inlet)
           + ca.mtimes(ca.DM(Bp), b_out) * ca.DM(pb.outlet))
    q_hat = psi * gam
    if pb.n_phi:
        q_hat = q_hat + ca.mtimes(ca.DM(Bphi), a)
    f = ca.sumsqr(q_hat - ca.DM(pb.q)) / len(pb.q)
    return w, f, (a, b_in, b_out, g)


def _affine_constraints(pb: _AffineProblem, unknowns, monotone: bool, pin_ends: bool):
    """Gamma(1) = 1, Gamma' >= 0 on [0, 1] (``monotone``), the pinned ends: (g, lbg, ubg)."""
    a, b_in, b_out, g = unknowns
    n_phi, n_psi, n_gam = pb.n_phi, pb.n_psi, pb.n_gam

    def poly_at(coef, xx, n):
        return sum(coef[k] * xx ** k for k in range(n)) if n else 0.0

    cons, lbg, ubg = [ca.sum1(g) - 1.0], [0.0], [0.0]      # Gamma(1) = 1
    if monotone:
        for sv in np.linspace(0.0, 1.0, 21):
            cons.append(sum((k + 1) * g[k] * sv ** k for k in range(n_gam)))
            lbg.append(0.0)
            ubg.append(ca.inf)
    if pin_ends:
        xs = (pb.supply_pressure - pb.p_mid) / pb.p_half
        xa = (pb.atmospheric_pressure - pb.p_mid) / pb.p_half
        cons.append(poly_at(a, xs, n_phi) + poly_at(b_in, xs, n_psi))
        cons.append(poly_at(a, xa, n_phi) - poly_at(b_out, xa, n_psi))
        lbg += [0.0, 0.0]
        ubg += [0.0, 0.0]
    return cons, lbg, ubg


def _affine_start(pb: _AffineProblem, phi_fixed: np.ndarray | None = None) -> np.ndarray:
    """Start: Gamma = s, phi (unless held at ``phi_fixed``) and psi by linear least squares."""
    Bp, s = pb.psi_basis, pb.s
    blocks = [pb.phi_basis] if pb.n_phi and phi_fixed is None else []
    if pb.shared_psi:
        blocks.append(Bp * s[:, None])
    else:
        blocks += [Bp * (s * pb.inlet)[:, None], Bp * (s * pb.outlet)[:, None]]
    if phi_fixed is None:
        return np.concatenate([_lstsq(np.hstack(blocks), pb.q), np.eye(pb.n_gam)[0]])
    rest = _lstsq(np.hstack(blocks), pb.q - pb.phi_basis @ phi_fixed)
    return np.concatenate([phi_fixed, rest, np.eye(pb.n_gam)[0]])


def _affine_coefficients(pb: _AffineProblem, wv: np.ndarray):
    """Solution vector -> (phi, psi_in, psi_out, gamma) in kg/s and powers of p / 1e5 Pa."""
    n_phi, n_psi, n_gam = pb.n_phi, pb.n_psi, pb.n_gam
    i = 0
    phi_x = wv[i:i + n_phi] / G_PER_KG
    i += n_phi
    psi_in_x = wv[i:i + n_psi] / G_PER_KG
    i += n_psi
    if pb.shared_psi:
        psi_out_x = psi_in_x
    else:
        psi_out_x = wv[i:i + n_psi] / G_PER_KG
        i += n_psi
    gam_v = wv[i:i + n_gam]
    ob, sb = pb.p_mid / PRESSURE_SCALE, pb.p_half / PRESSURE_SCALE
    phi = tuple(float(c) for c in _to_bar_monomials(phi_x, ob, sb)) if n_phi else (0.0,)
    psi_in = tuple(float(c) for c in _to_bar_monomials(psi_in_x, ob, sb))
    psi_out = tuple(float(c) for c in _to_bar_monomials(psi_out_x, ob, sb))
    gamma = tuple(float(c) for c in gam_v)
    return phi, psi_in, psi_out, gamma
