"""Everything at once: fits of a table, their validation, its figures (``identify valve``)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ...errors import InputError, WorkbenchError
from ._numeric import numeric as _numeric
from .affine import AffineTableFit, fit_affine
from .gain import (PressureGain, TableLaw, compare_pressure_gain,
                   pressure_gain_from_data)
from .gain import pressure_gain as _gain_curve
from .polynomial import DegreeSelection, PolynomialValveFit, fit_polynomial, select_degrees
from .table import ValveTable
from .tank import TankStepTests, tank_steps

__all__ = ["ValveFitReport", "analyse", "write_figures", "valve_curves"]


@dataclass(frozen=True)
class ValveFitReport:
    """Fits of a table with their validation (what ``workbench identify valve`` computes).

    Attributes
    ----------
    table : ValveTable. approx_1 : PolynomialValveFit or None. selection :
    DegreeSelection or None. approx_2 : AffineTableFit or None. gains : label ->
    PressureGain (``"data"`` first). tank : TankStepTests or None. reference :
    label of the true law in ``gains`` (None when unknown). notes : remarks.
    """

    table: ValveTable
    approx_1: PolynomialValveFit | None
    selection: DegreeSelection | None
    approx_2: AffineTableFit | None
    gains: Mapping[str, PressureGain]
    tank: TankStepTests | None
    notes: tuple[str, ...] = ()
    reference: str | None = None

    def laws(self) -> dict[str, Callable]:
        out: dict[str, Callable] = {}
        if self.approx_1 is not None:
            out["approximation I"] = self.approx_1.flow
        if self.approx_2 is not None:
            out["approximation II"] = self.approx_2.flow
        return out

    def to_dict(self) -> dict[str, Any]:
        t = self.table
        out: dict[str, Any] = {
            "table": {"source": t.source, "points": len(t),
                      "commands_V": list(t.command_range), "pressures_Pa": list(t.pressure_range),
                      "supply_pressure_Pa": t.supply_pressure,
                      "atmospheric_pressure_Pa": t.atmospheric_pressure,
                      "command_center_V": t.command_center, "command_span_V": t.command_span},
            "R_definition": "multiple correlation coefficient R = sqrt(1 - SS_res/SS_tot) "
                            "(paper 003); R2 = R^2",
        }
        if self.approx_1 is not None:
            out["approximation_I"] = self.approx_1.to_dict()
        if self.selection is not None:
            out["degree_selection"] = self.selection.to_dict()
        if self.approx_2 is not None:
            out["approximation_II"] = self.approx_2.to_dict()
        data = self.gains.get("data")
        ref = self.gains.get(self.reference) if self.reference else None
        out["pressure_gain"] = {}
        for lab, g in self.gains.items():
            entry = g.to_dict()
            if data is not None and lab != "data":
                entry["vs_data"] = compare_pressure_gain(data, g, t.pressure_range)
            if ref is not None and lab != self.reference:
                entry["vs_reference"] = compare_pressure_gain(ref, g, t.pressure_range)
            out["pressure_gain"][lab] = entry
        if self.tank is not None:
            out["tank_steps"] = self.tank.to_dict()
        out["notes"] = list(self.notes)
        return out


def analyse(table: ValveTable, approx: str = "both", degrees: tuple[int, int] | None = None,
            select: bool = False, affine_degrees: tuple[int | None, int, int] = (5, 5, 2),
            pin_ends: bool = False, shared_psi: bool = False, phi_from: str = "fit",
            tank_volume: float = 1e-3, tank: bool = True,
            k: float = 1.2, seed: int = 0, reference: Callable | None = None,
            reference_label: str = "generating valve", pressure_gain=None) -> ValveFitReport:
    """Fit approximation I and/or II, then the pressure gain and tank step validation.

    ``pressure_gain``: measured blocked-port points (u in V, p_e in Pa) imposed on both
    fits as q(p_e, u) = 0 (:mod:`.blocked`); with ``select`` the degrees are chosen on
    the flow points, then the chosen polynomial is refitted with the constraints.

    The tank steps are at u_e = the table's command centre. Their reference is the
    true law when known (``reference``: a CasADi-traceable flow(p, u) such as
    :func:`valve_flow_law` of the plant that generated the table; its pressure gain
    characteristic is added as ``reference_label``), else the table itself
    (:class:`TableLaw`).
    """
    if approx not in ("I", "II", "both"):
        raise InputError(f"expected --approx I, II or both, got {approx!r}", location="--approx")
    a1 = sel = a2 = None
    notes = []
    if approx in ("I", "both"):
        if select:
            sel = select_degrees(table, seed=seed)
            a1 = (sel.fit if pressure_gain is None else
                  fit_polynomial(table, sel.n, sel.m, pressure_gain=pressure_gain))
        else:
            n, m = degrees if degrees is not None else (5, 10)
            a1 = fit_polynomial(table, n, m, pressure_gain=pressure_gain)
    if approx in ("II", "both"):
        a2 = fit_affine(table, *affine_degrees, pin_ends=pin_ends, shared_psi=shared_psi,
                        phi_from=phi_from, pressure_gain=pressure_gain)
    if pressure_gain is not None:
        notes.append(f"{len(pressure_gain)} blocked-port points imposed as q(p_e, u) = 0")
    lo, hi = table.pressure_range
    gains: dict[str, PressureGain] = {"data": pressure_gain_from_data(table)}
    cu = np.unique(table.u)
    fine = np.unique(np.concatenate([np.linspace(cu[0], cu[-1], 401), cu]))
    report_laws = {}
    if a1 is not None:
        report_laws["approximation I"] = a1.flow
    if a2 is not None:
        report_laws["approximation II"] = a2.flow
    ref_laws = {} if reference is None else {reference_label: reference}
    for lab, fl in {**ref_laws, **report_laws}.items():
        gains[lab] = _gain_curve(fl, fine, (lo, hi), label=lab)
    tests = None
    if tank:
        laws = {"data": TableLaw(table), **ref_laws, **report_laws}
        try:
            tests = tank_steps(laws, reference_label if ref_laws else "data",
                               volume=tank_volume, u_e=table.command_center,
                               k=k, temperature=table.temperature, p_range=(lo, hi))
        except WorkbenchError as exc:
            notes.append(f"tank step tests skipped: {exc}")
    return ValveFitReport(table=table, approx_1=a1, selection=sel, approx_2=a2, gains=gains,
                          tank=tests, notes=tuple(notes),
                          reference=reference_label if ref_laws else None)


def write_figures(report: ValveFitReport, out: Path) -> list[str]:
    """Write the four figures of a report into ``out``; returns their file names."""
    from .. import plots
    t = report.table
    laws = report.laws()
    plots.valve_curves_figure(valve_curves(t, laws), out / "valve_curves.png",
                              title=f"Valve characteristic: {t.source}")
    errors = {lab: _numeric(f)(t.p, t.u) - t.q_m for lab, f in laws.items()}
    plots.valve_error_figure(t.u, t.p, errors, out / "valve_errors.png")
    plots.pressure_gain_figure(list(report.gains.values()), out / "pressure_gain.png")
    names = ["valve_curves.png", "valve_errors.png", "pressure_gain.png"]
    if report.tank is not None:
        plots.tank_steps_figure(report.tank, out / "tank_steps.png")
        names.append("tank_steps.png")
    return names


def valve_curves(table: ValveTable, laws: Mapping[str, Callable],
                 pressures: Sequence[float] | None = None,
                 n: int = 201) -> dict[str, Any]:
    """Data points and fitted lines q_m(u) at several table pressures, for plotting.

    Returns ``{"pressures": [...Pa], "data": [(u, q) per pressure], "fits": {label:
    [(u_fine, q_fine) per pressure]}}``, SI.
    """
    ps = np.unique(table.p)
    if pressures is None:
        pressures = ps[np.unique(np.linspace(0, len(ps) - 1, min(6, len(ps))).round().astype(int))]
    u_fine = np.linspace(*table.command_range, n)
    data, fits = [], {lab: [] for lab in laws}
    for pv in pressures:
        sel = np.isclose(table.p, pv, rtol=1e-9, atol=0.0)
        order = np.argsort(table.u[sel])
        data.append((table.u[sel][order], table.q_m[sel][order]))
        for lab, f in laws.items():
            fits[lab].append((u_fine, _numeric(f)(np.full_like(u_fine, pv), u_fine)))
    return {"pressures": [float(v) for v in pressures], "data": data, "fits": fits}
