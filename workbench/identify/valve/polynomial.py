"""Approximation I of paper 003: the full bivariate polynomial q_m(p, u), degree selection."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ...errors import InputError
from ...physics.valve import polyval
from ._numeric import clip as _clip, json_floats as _json_floats
from .blocked import check_pressure_gain_points
from .lstsq import constraint_rank, lstsq as _lstsq, lstsq_equality
from .quality import FitQuality, _normalised_command, _quality
from .table import G_PER_KG, ValveTable

__all__ = ["PolynomialValveFit", "fit_polynomial", "DegreeSelection", "select_degrees"]


@dataclass(frozen=True)
class PolynomialValveFit:
    """Approximation I: q_m = sum_ij c_ij x^i s^j (paper 003, eq. 4).

    Attributes
    ----------
    coefficients : ndarray, shape (n + 1, m + 1)
        c_ij in kg/s multiplying x^i s^j.
    center, span : V. s = (u - center) / span, clipped to the table's command range
        (the valve saturates; the polynomial is not extrapolated in u).
    pressure_offset, pressure_scale : Pa. x = (p - pressure_offset) / pressure_scale;
        the middle and half-width of the table's pressures, so x is in [-1, 1] and
        the least-squares problem is well conditioned (not p / 1e5: with degree 5 in
        [1, 6] bar the monomials would span four decades).
    s_range : (low, high) normalised commands of the table.
    quality : FitQuality on the table.
    pressure_gain : the blocked-port points (u in V, p_e in Pa) the fit passes through
        (q = 0 there), empty when none were given.
    """

    coefficients: np.ndarray
    center: float
    span: float
    pressure_offset: float
    pressure_scale: float
    s_range: tuple[float, float]
    quality: FitQuality
    pressure_gain: tuple[tuple[float, float], ...] = ()

    @property
    def degrees(self) -> tuple[int, int]:
        """(n, m): degrees in pressure and in command."""
        return self.coefficients.shape[0] - 1, self.coefficients.shape[1] - 1

    def flow(self, p, u):
        """q_m (kg/s) at pressure ``p`` (Pa) and command ``u`` (V); floats, arrays or CasADi."""
        x = (p - self.pressure_offset) / self.pressure_scale
        s = _clip((u - self.center) / self.span, *self.s_range)
        rows = [polyval(list(row), s) for row in self.coefficients]
        return polyval(rows, x)

    def to_dict(self) -> dict[str, Any]:
        n, m = self.degrees
        return {"approximation": "I", "degrees": {"n_pressure": n, "m_command": m},
                "variables": {"x": f"(p - {self.pressure_offset!r}) / {self.pressure_scale!r}",
                              "s": f"(u - {self.center!r}) / {self.span!r}, clipped to "
                                   f"[{self.s_range[0]!r}, {self.s_range[1]!r}]"},
                "coefficients_kg_s": self.coefficients.tolist(),
                "pressure_gain_points": [list(r) for r in self.pressure_gain],
                **self.quality.to_dict()}


def _poly_design(x: np.ndarray, s: np.ndarray, n: int, m: int) -> np.ndarray:
    vx = np.vander(x, n + 1, increasing=True)
    vs = np.vander(s, m + 1, increasing=True)
    return (vx[:, :, None] * vs[:, None, :]).reshape(len(x), -1)


def _poly_vars(table: ValveTable, center: float, span: float):
    lo, hi = table.pressure_range
    offset, scale = 0.5 * (lo + hi), 0.5 * (hi - lo)
    x = (table.p - offset) / scale
    s = (table.u - center) / span
    return x, s, offset, scale


def fit_polynomial(table: ValveTable, n: int = 5, m: int = 10, *, center: float | None = None,
                   span: float | None = None, pressure_gain=None) -> PolynomialValveFit:
    """Approximation I by linear least squares: degrees ``n`` in p and ``m`` in u.

    Paper 003 settles on n = 5, m = 10 (66 coefficients). Fitting is done in the
    scaled variables of :class:`PolynomialValveFit` (columns also normalised).

    ``pressure_gain``: optional measured blocked-port points, rows (u in V, p_e in Pa),
    imposed exactly as q(p_e, u) = 0 (least squares in the null space of the
    constraints; :mod:`.blocked` says why). Each point removes one free coefficient.

    Raises
    ------
    InputError
        Degrees < 0, or as many coefficients as points (or more): the fit would
        interpolate the noise; or too few distinct commands/pressures for the degree.
    """
    n, m = int(n), int(m)
    if n < 0 or m < 0:
        raise InputError(f"expected degrees >= 0, got n = {n}, m = {m}", location="--degrees")
    k = (n + 1) * (m + 1)
    if k >= len(table):
        raise InputError(f"degrees n = {n}, m = {m} need {k} coefficients but the table has "
                         f"only {len(table)} points; lower the degrees", source=table.source,
                         location="--degrees")
    nu, npr = len(np.unique(table.u)), len(np.unique(table.p))
    if m >= nu or n >= npr:
        raise InputError(f"degree m = {m} in u needs more than {m} distinct commands and "
                         f"n = {n} in p more than {n} distinct pressures; the table has "
                         f"{nu} and {npr}", source=table.source, location="--degrees")
    center, span = _normalised_command(table, center, span)
    x, s, offset, scale = _poly_vars(table, center, span)
    A = _poly_design(x, s, n, m)
    free = k
    if pressure_gain is None:
        sol = _lstsq(A, table.q_m)
    else:
        pts = check_pressure_gain_points(pressure_gain, table, table.source)
        C = _poly_design((pts[:, 1] - offset) / scale, (pts[:, 0] - center) / span, n, m)
        _check_constraints(C, k, table.source)
        sol = lstsq_equality(A, table.q_m, C)
        free = k - len(pts)
    coeffs = sol.reshape(n + 1, m + 1)
    coeffs.flags.writeable = False
    q_fit = A @ sol
    return PolynomialValveFit(coefficients=coeffs, center=center, span=span,
                              pressure_offset=offset, pressure_scale=scale,
                              s_range=(float(np.min(s)), float(np.max(s))),
                              quality=_quality(table, q_fit, k, free),
                              pressure_gain=() if pressure_gain is None else
                              tuple((float(a), float(b)) for a, b in pts))


def _check_constraints(C: np.ndarray, k: int, source: str) -> None:
    """Refuse pressure gain points the polynomial cannot meet all at once."""
    if len(C) >= k:
        raise InputError(f"{len(C)} pressure gain points for {k} coefficients: the fit would be "
                         "fixed by them alone (use fewer points or higher degrees)",
                         source=source, location="pressure_gain")
    if constraint_rank(C) < len(C):
        raise InputError("the pressure gain points are not independent for this polynomial "
                         "(more points at one command than its degree in p can pass through); "
                         "use fewer points", source=source, location="pressure_gain")


@dataclass(frozen=True)
class DegreeSelection:
    """Degrees of approximation I chosen by k-fold cross validation.

    Attributes
    ----------
    n, m : chosen degrees in p and u.
    n_values, m_values : the grid searched.
    cv_rms : ndarray (len(n_values), len(m_values)), cross-validated RMS error, kg/s
        (NaN where the degrees need too many coefficients).
    folds : number of folds. tolerance : relative slack of the parsimony rule.
    fit : the approximation I refitted on all points with (n, m).
    """

    n: int
    m: int
    n_values: tuple[int, ...]
    m_values: tuple[int, ...]
    cv_rms: np.ndarray
    folds: int
    tolerance: float
    fit: PolynomialValveFit

    def to_dict(self) -> dict[str, Any]:
        return {"n": self.n, "m": self.m, "folds": self.folds, "tolerance": self.tolerance,
                "n_values": list(self.n_values), "m_values": list(self.m_values),
                "cv_rms_g_s": [_json_floats(row * G_PER_KG) for row in self.cv_rms]}


def select_degrees(table: ValveTable, n_values: Sequence[int] = range(1, 8),
                   m_values: Sequence[int] = range(1, 13), folds: int = 5, seed: int = 0,
                   tolerance: float = 0.02, *, center: float | None = None,
                   span: float | None = None) -> DegreeSelection:
    """Choose approximation I's degrees by ``folds``-fold cross validation over a grid.

    Points are shuffled (``seed``) into folds; for every (n, m) each fold is predicted
    by the fit on the others, and the RMS over all held-out predictions is recorded.
    The chosen degrees are those with the fewest coefficients whose CV RMS is within
    ``tolerance`` (relative) of the best: more coefficients that do not predict
    unseen points better only follow the noise.
    """
    if folds < 2:
        raise InputError(f"expected at least 2 folds, got {folds}", location="--folds")
    center, span = _normalised_command(table, center, span)
    x, s, _, _ = _poly_vars(table, center, span)
    q = table.q_m
    idx = np.random.default_rng(seed).permutation(len(q))
    parts = np.array_split(idx, folds)
    nv, mv = tuple(int(v) for v in n_values), tuple(int(v) for v in m_values)
    cv = np.full((len(nv), len(mv)), np.nan)
    n_train = len(q) - max(len(pt) for pt in parts)
    for a, n in enumerate(nv):
        for b, m in enumerate(mv):
            if (n + 1) * (m + 1) >= n_train:
                continue
            A = _poly_design(x, s, n, m)
            sq = 0.0
            for pt in parts:
                train = np.setdiff1d(idx, pt)
                sol = _lstsq(A[train], q[train])
                sq += float(np.sum((A[pt] @ sol - q[pt]) ** 2))
            cv[a, b] = math.sqrt(sq / len(q))
    if not np.any(np.isfinite(cv)):
        raise InputError(f"the table ({len(q)} points) is too small for any degrees of the "
                         "grid with cross validation", source=table.source)
    best = np.nanmin(cv)
    cands = [((nv[a] + 1) * (mv[b] + 1), cv[a, b], a, b) for a in range(len(nv))
             for b in range(len(mv))
             if np.isfinite(cv[a, b]) and cv[a, b] <= best * (1 + tolerance)]
    _, _, a, b = min(cands)
    return DegreeSelection(n=nv[a], m=mv[b], n_values=nv, m_values=mv, cv_rms=cv, folds=folds,
                           tolerance=tolerance,
                           fit=fit_polynomial(table, nv[a], mv[b], center=center, span=span))
