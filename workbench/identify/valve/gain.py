"""The pressure gain characteristic q_m(p_e, u) = 0 with Cp and Gu, and the table as a law."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np
from scipy import optimize

from ...errors import InputError
from ._numeric import json_floats as _json_floats
from .table import ValveTable

__all__ = ["TableLaw", "PressureGain", "pressure_gain", "pressure_gain_from_data",
           "compare_pressure_gain"]


class TableLaw:
    """The table itself as a flow law: linear interpolation in p within each command's
    column, then linear in u between columns (values at the ends held).

    Numeric only (not CasADi-traceable): it stands for the measured valve in the tank
    step tests when the true law is unknown.
    """

    #: Not CasADi-traceable: no exact derivatives, no tangent model.
    traceable = False

    def __init__(self, table: ValveTable) -> None:
        cols = [c for c in table.columns() if len(c[1]) >= 2]
        if len(cols) < 2:
            raise InputError("the table needs at least 2 commands with 2 or more pressures "
                             "each to be interpolated", source=table.source)
        self.u_values = np.array([c[0] for c in cols])
        self._cols = [(c[1], c[2]) for c in cols]

    def __call__(self, p, u):
        p = np.asarray(p, dtype=float)
        u = np.asarray(u, dtype=float)
        pb, ub = np.broadcast_arrays(p, u)
        out = np.empty(pb.shape)
        for k, (pp, uu) in enumerate(zip(pb.ravel(), ub.ravel())):
            uv = self.u_values
            j = int(np.clip(np.searchsorted(uv, uu) - 1, 0, len(uv) - 2))
            t = float(np.clip((uu - uv[j]) / (uv[j + 1] - uv[j]), 0.0, 1.0))
            q0 = np.interp(pp, *self._cols[j])
            q1 = np.interp(pp, *self._cols[j + 1])
            out.ravel()[k] = (1 - t) * q0 + t * q1
        return out if out.ndim else float(out)


@dataclass(frozen=True)
class PressureGain:
    """Pressure gain characteristic q_m(p_e, u) = 0 with Cp and Gu along it.

    Attributes
    ----------
    label : which law ("data", "approximation I", ...).
    u : commands with an equilibrium inside the pressure range, V.
    p_e : equilibrium pressures, Pa.
    cp : Cp = -dq/dp at (p_e, u), kg/(s Pa).
    gu : Gu = dq/du at (p_e, u), kg/(s V) (NaN where not available).
    method : how derivatives were obtained ("CasADi AD" or "finite differences").
    """

    label: str
    u: np.ndarray
    p_e: np.ndarray
    cp: np.ndarray
    gu: np.ndarray
    method: str

    def at(self, u) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p_e, Cp, Gu) linearly interpolated at commands ``u`` (NaN outside)."""
        u = np.asarray(u, dtype=float)
        if len(self.u) == 0:
            return (np.full(u.shape, np.nan),) * 3
        f = (lambda y: np.interp(u, self.u, y, left=np.nan, right=np.nan))
        return f(self.p_e), f(self.cp), f(self.gu)

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "method": self.method, "u_V": _json_floats(self.u),
                "p_e_Pa": _json_floats(self.p_e), "cp_kg_s_Pa": _json_floats(self.cp),
                "gu_kg_s_V": _json_floats(self.gu)}


def pressure_gain(flow: Callable, u_values: Sequence[float], p_range: tuple[float, float],
                  label: str = "") -> PressureGain:
    """The q_m = 0 curve of a CasADi-traceable ``flow(p, u)`` and its exact Cp, Gu.

    For every command with a sign change of q over ``p_range`` (Pa) the equilibrium
    pressure is found by Brent's method; Cp = -dq/dp and Gu = dq/du come from CasADi's
    automatic differentiation of ``flow`` there.
    """
    p, u = ca.SX.sym("p"), ca.SX.sym("u")
    q = flow(p, u)
    fun = ca.Function("qd", [p, u], [q, ca.jacobian(q, p), ca.jacobian(q, u)])
    lo, hi = p_range
    out_u, out_p, out_cp, out_gu = [], [], [], []
    for uu in np.asarray(u_values, dtype=float):
        g = lambda pp: float(fun(pp, uu)[0])  # noqa: E731
        q_lo, q_hi = g(lo), g(hi)
        if not (q_lo > 0 > q_hi):
            continue
        pe = optimize.brentq(g, lo, hi, xtol=1e-6, rtol=1e-14)
        _, dqdp, dqdu = (float(v) for v in fun(pe, uu))
        out_u.append(uu)
        out_p.append(pe)
        out_cp.append(-dqdp)
        out_gu.append(dqdu)
    return PressureGain(label=label, u=np.array(out_u), p_e=np.array(out_p),
                        cp=np.array(out_cp), gu=np.array(out_gu), method="CasADi AD")


def pressure_gain_from_data(table: ValveTable, label: str = "data") -> PressureGain:
    """The measured q_m = 0 curve: per command, the zero of q over p by linear interpolation.

    A command counts when its flows go from positive to negative exactly once with
    rising pressure (a decreasing characteristic; a column that only touches zero
    through noise is left out). Cp is minus the slope of the crossing segment; Gu the
    central difference of the neighbouring commands' flows, each interpolated at p_e
    (finite differences are the right tool here: they are the measurement).
    """
    cols = [c for c in table.columns() if len(c[1]) >= 2]
    us, pes, cps, gus = [], [], [], []
    for k, (uu, ps, qs) in enumerate(cols):
        sgn = np.sign(qs)
        changes = np.flatnonzero((sgn[:-1] > 0) & (sgn[1:] <= 0))
        ups = np.flatnonzero((sgn[:-1] <= 0) & (sgn[1:] > 0))
        if len(changes) != 1 or len(ups):
            continue
        j = int(changes[0])
        slope = (qs[j + 1] - qs[j]) / (ps[j + 1] - ps[j])
        pe = ps[j] - qs[j] / slope
        gu = float("nan")
        if 0 < k < len(cols) - 1:
            (ua, pa, qa), (ub, pb, qb) = cols[k - 1], cols[k + 1]
            gu = float((np.interp(pe, pb, qb) - np.interp(pe, pa, qa)) / (ub - ua))
        us.append(uu)
        pes.append(pe)
        cps.append(-slope)
        gus.append(gu)
    return PressureGain(label=label, u=np.array(us), p_e=np.array(pes), cp=np.array(cps),
                        gu=np.array(gus), method="finite differences on the table")


def compare_pressure_gain(reference: PressureGain, other: PressureGain,
                          p_range: tuple[float, float] | None = None,
                          margin: float = 0.02) -> dict[str, Any]:
    """Differences of ``other`` from ``reference`` at the reference's commands.

    Only commands whose reference equilibrium lies inside ``p_range`` (Pa) by more
    than ``margin`` of its width count: where the valve is open enough to fill the
    tank to supply or empty it to atmosphere, "p_e" is just the range's end (the
    paper zooms on the characteristic proper for the same reason). Without
    ``p_range`` every command counts.

    Returns the number of commands, the largest |delta p_e| (Pa), and the median
    relative differences of Cp and Gu (fractions) over them.
    """
    pe, cp, gu = other.at(reference.u)
    ok = np.isfinite(pe)
    if p_range is not None:
        lo, hi = p_range
        w = margin * (hi - lo)
        ok &= (reference.p_e > lo + w) & (reference.p_e < hi - w)
    if not np.any(ok):
        return {"commands": 0, "max_abs_dp_e_Pa": None, "median_rel_cp": None,
                "median_rel_gu": None}
    dpe = np.abs(pe[ok] - reference.p_e[ok])
    rel = lambda a, b: float(np.nanmedian(np.abs(a - b) / np.abs(b)))  # noqa: E731
    okg = ok & np.isfinite(reference.gu) & np.isfinite(gu)
    return {"commands": int(np.sum(ok)), "max_abs_dp_e_Pa": float(np.max(dpe)),
            "median_rel_cp": rel(cp[ok], reference.cp[ok]),
            "median_rel_gu": rel(gu[okg], reference.gu[okg]) if np.any(okg) else None}
