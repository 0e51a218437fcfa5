"""Paper 003's tank step tests: a closed tank fed by each law after a command step."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy import integrate, optimize

from ...errors import InputError, WorkbenchError
from ...linearize import TankTangent, tank_tangent
from ...physics import gas
from ._numeric import numeric as _numeric

__all__ = ["TankStep", "TankStepTests", "tank_steps"]


@dataclass(frozen=True)
class TankStep:
    """Pressure of a closed tank fed by one law after a command step (paper 003, eq. 6).

    Attributes
    ----------
    label : the law. du : step, V (from u_e to u_e + du at t = 0).
    t : s. p : tank pressure, Pa. p0 : the starting pressure, Pa.
    p_e : the law's own equilibrium at u_e, Pa (NaN when it has none in the range).
    tangent : the law's first-order tangent model at (p_e, u_e), or None when the
        law is not CasADi-traceable (the table itself) or has no equilibrium.
    """

    label: str
    du: float
    t: np.ndarray
    p: np.ndarray
    p0: float
    p_e: float
    tangent: TankTangent | None

    def tangent_response(self) -> np.ndarray | None:
        """p_e + G du (1 - exp(-t / tau)) of the tangent model, Pa (None without one)."""
        if self.tangent is None:
            return None
        return self.p_e + self.tangent.gain * self.du * (1.0 - np.exp(-self.t / self.tangent.tau))


@dataclass(frozen=True)
class TankStepTests:
    """Tank step tests of paper 003 for several laws against a reference.

    Attributes
    ----------
    volume : tank volume, m^3. k : polytropic index. temperature : K. u_e : V.
    reference : label of the reference law. steps : the runs, by (label, du).
    """

    volume: float
    k: float
    temperature: float
    u_e: float
    reference: str
    steps: Mapping[tuple[str, float], TankStep]

    def labels(self) -> list[str]:
        return list(dict.fromkeys(lab for lab, _ in self.steps))

    def step_sizes(self) -> list[float]:
        return list(dict.fromkeys(du for _, du in self.steps))

    def max_error(self, label: str, du: float) -> float:
        """Largest |p_label - p_reference| / p_reference over the run, fraction."""
        a, r = self.steps[(label, du)], self.steps[(self.reference, du)]
        return float(np.max(np.abs(a.p - r.p) / r.p))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"volume_m3": self.volume, "k": self.k,
                               "temperature_K": self.temperature, "u_e_V": self.u_e,
                               "reference": self.reference, "runs": []}
        for (lab, du), st in self.steps.items():
            row = {"law": lab, "du_V": du, "p0_Pa": st.p0,
                   "p_e_Pa": st.p_e if np.isfinite(st.p_e) else None,
                   "p_end_Pa": float(st.p[-1]), "duration_s": float(st.t[-1])}
            if lab != self.reference:
                row["max_error_percent"] = 100.0 * self.max_error(lab, du)
            if st.tangent is not None:
                row.update(cp_kg_s_Pa=st.tangent.cp, gu_kg_s_V=st.tangent.gu,
                           tau_s=st.tangent.tau, G_Pa_V=st.tangent.gain,
                           tangent_p_end_Pa=st.p_e + st.tangent.gain * du)
            out["runs"].append(row)
        return out


def tank_steps(laws: Mapping[str, Callable], reference: str, volume: float = 1e-3,
               u_e: float | None = None, steps: Sequence[float] = (1.0, -1.0, 0.1, -0.1),
               k: float = 1.2, temperature: float = gas.T_REF,
               p_range: tuple[float, float] = (gas.P_ATM, 6e5), duration: float | None = None,
               samples: int = 400, start: str = "reference") -> TankStepTests:
    """Paper 003's tank test: dp/dt = k r T / V q(p, u), steps of ``steps`` V at u_e.

    Every law sees the same command step u_e -> u_e + du at t = 0, starting from the
    reference law's equilibrium pressure at u_e (``start="reference"``, the measured
    tank at rest, as in paper 003's figures 9 and 10) or from its own
    (``start="own"``: the difference at t = 0 is then the pressure gain error). A law
    without an equilibrium at u_e (e.g. approximation II with phi = 0: a closed
    centre) is still simulated from the reference's, without a tangent model. The
    reference law sets the
    duration (default 6 tangent time constants of the reference, or of the first law
    with a tangent model, at least 0.05 s; else 6 s * V / 1e-3 m^3). Laws that are
    CasADi-traceable
    also get their tangent model (tau, G) from
    :func:`workbench.linearize.tank_tangent`.

    The one-state tank is integrated with scipy's LSODA (rtol 1e-8), not with a
    stepper of :mod:`workbench.integrate`: the laws compared include the measured
    table itself (:class:`TableLaw`, interpolated in numpy), which CasADi cannot trace.

    Parameters
    ----------
    laws : label -> flow(p, u) in kg/s: CasADi-traceable, or numeric with an attribute
        ``traceable = False`` like :class:`TableLaw`.
    reference : label of the law the others are compared with.
    volume : m^3. u_e : equilibrium command, V (required).
    k : polytropic index (paper 003: 1.2). temperature : K.
    p_range : bracket of the equilibrium pressures, Pa.
    """
    if reference not in laws:
        raise InputError(f"reference law {reference!r} is not among {list(laws)}")
    if u_e is None:
        raise InputError("give the equilibrium command u_e (V)")
    if start not in ("reference", "own"):
        raise InputError(f"expected start 'reference' or 'own', got {start!r}")
    if not volume > 0:
        raise InputError(f"expected a tank volume > 0 (m^3), got {volume!r}",
                         location="--tank-volume")
    c = k * gas.R_AIR * temperature / volume
    lo, hi = p_range
    eq: dict[str, tuple[float, TankTangent | None, Callable]] = {}
    for lab, flow in laws.items():
        traceable = getattr(flow, "traceable", True)
        num = _numeric(flow) if traceable else flow
        g = lambda pp, num=num: float(num(pp, u_e))  # noqa: E731
        if not g(lo) > 0 > g(hi):
            if lab == reference or start == "own":
                raise WorkbenchError(f"law {lab!r} has no equilibrium pressure in "
                                     f"[{lo:g}, {hi:g}] Pa at u_e = {u_e:g} V")
            eq[lab] = (float("nan"), None, num)   # still simulated from the reference's p_e
            continue
        p0 = optimize.brentq(g, lo, hi, xtol=1e-6, rtol=1e-14)
        tan = (tank_tangent(flow, volume, u_e, p_e=p0, k=k, temperature=temperature)
               if traceable else None)
        eq[lab] = (p0, tan, num)
    tans = [eq[reference][1]] + [v[1] for v in eq.values()]
    tans = [tn for tn in tans if tn is not None and tn.tau > 0]
    if duration is None:
        duration = max(6.0 * tans[0].tau, 0.05) if tans else 6.0 * volume / 1e-3
    t_eval = np.linspace(0.0, duration, samples)
    runs: dict[tuple[str, float], TankStep] = {}
    for du in steps:
        for lab, (p_e, tan, num) in eq.items():
            uu = u_e + du
            p0 = eq[reference][0] if start == "reference" else p_e
            sol = integrate.solve_ivp(lambda t, y, num=num: [c * float(num(y[0], uu))],
                                      (0.0, duration), [p0], t_eval=t_eval, method="LSODA",
                                      rtol=1e-8, atol=1.0)
            if not sol.success:
                raise WorkbenchError(f"tank simulation of {lab!r}, step {du:g} V failed: "
                                     f"{sol.message}")
            runs[(lab, float(du))] = TankStep(label=lab, du=float(du), t=sol.t, p=sol.y[0],
                                              p0=p0, p_e=p_e, tangent=tan)
    return TankStepTests(volume=volume, k=k, temperature=temperature, u_e=float(u_e),
                         reference=reference, steps=runs)
