"""Catalog (datasheet) valve data: one nominal-flow curve against the command.

A proportional valve's datasheet gives the nominal flow Q_N (l/min ANR) of a port
against the command, measured at the ISO 6358 nominal conditions (upstream 7 bar abs,
downstream 6 bar abs unless stated), and a critical pressure ratio b. With b given,
each point fixes the sonic conductance of the open restriction,
C(u) = Q_N / (p1 psi(p2 / p1)), psi the ISO 6358 subsonic factor (physics.md), and the
ISO 6358 law then gives the whole characteristic q_m(p, u) at every port pressure:
supply -> port for Q_N > 0, port -> exhaust for Q_N < 0. That table is what
approximations I and II are fitted to (``workbench identify valve CURVE.csv --catalog
--critical-ratio B``).

The curve knows nothing of leakage: where Q_N = 0 the port is closed, and the pressure
gain characteristic (which lives on the leakage) cannot be obtained from a datasheet.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ...errors import InputError
from ...physics import gas
from .table import ValveTable

__all__ = ["CatalogCurve", "load_catalog_curve", "catalog_table", "LITRE_PER_MIN_ANR"]

#: m^3/s (ANR) per l/min (ANR).
LITRE_PER_MIN_ANR = 1e-3 / 60.0
#: ISO 6358 nominal-flow conditions, Pa absolute (6 -> 5 bar gauge).
NOMINAL_UPSTREAM, NOMINAL_DOWNSTREAM = 6e5 + gas.P_ATM, 5e5 + gas.P_ATM


@dataclass(frozen=True)
class CatalogCurve:
    """Nominal flow against command (signed: > 0 supply -> port, < 0 port -> exhaust).

    Attributes
    ----------
    u : V. q_n : l/min ANR. p1, p2 : nominal upstream and downstream pressures, Pa abs.
    source : where it came from.
    """

    u: np.ndarray
    q_n: np.ndarray
    p1: float = NOMINAL_UPSTREAM
    p2: float = NOMINAL_DOWNSTREAM
    source: str = "<memory>"

    def conductance(self, b: float) -> np.ndarray:
        """|C(u)|, m^3/(s Pa), from Q_N with critical ratio ``b`` (ISO 6358 at p1 -> p2)."""
        _check_b(b)
        x = self.p2 / self.p1
        psi = 1.0 if x <= b else math.sqrt(1.0 - ((x - b) / (1.0 - b)) ** 2)
        return np.abs(self.q_n) * LITRE_PER_MIN_ANR / (self.p1 * psi)


def _check_b(b: float) -> None:
    if not (isinstance(b, (int, float)) and math.isfinite(b) and 0.0 < b < 1.0):
        raise InputError(f"expected a critical pressure ratio 0 < b < 1, got {b!r}",
                         location="--critical-ratio")


def load_catalog_curve(path: str | os.PathLike) -> CatalogCurve:
    """Read a catalog curve CSV: columns ``u`` (V) and ``q_n`` (l/min ANR, signed).

    Optional ``# nominal_upstream_pressure: 701325`` and ``# nominal_downstream_pressure:
    601325`` lines (Pa abs) override the ISO 6358 nominal conditions.

    Raises
    ------
    InputError
        Naming the file and line: missing column, a cell that is not a finite number,
        fewer than 3 points, repeated commands, nominal pressures not p1 > p2 > 0.
    """
    path, src = Path(path), str(path)
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", source=src) from None
    meta, header, rows = {}, None, []
    for no, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            key, sep, val = line[1:].partition(":")
            if sep and header is None:
                meta[key.strip()] = (val.strip(), no)
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = cells
            if "u" not in header or "q_n" not in header:
                raise InputError("a catalog curve needs the columns u (V) and q_n (l/min ANR, "
                                 f"> 0 into the port, < 0 to the exhaust); the header is {line!r}",
                                 source=src, location=f"line {no}")
            continue
        try:
            vals = [float(cells[header.index(c)]) for c in ("u", "q_n")]
        except (ValueError, IndexError):
            raise InputError(f"expected numbers in columns u and q_n, got {line!r}", source=src,
                             location=f"line {no}") from None
        if not all(math.isfinite(v) for v in vals):
            raise InputError(f"expected finite numbers, got {line!r}", source=src,
                             location=f"line {no}")
        rows.append(vals)
    if len(rows) < 3:
        raise InputError(f"a catalog curve needs at least 3 points, got {len(rows)}", source=src)
    data = np.array(rows)
    if len(np.unique(data[:, 0])) != len(data):
        raise InputError("a command appears twice: one nominal flow per command", source=src,
                         location="column 'u'")
    p = {}
    for key, default in (("nominal_upstream_pressure", NOMINAL_UPSTREAM),
                         ("nominal_downstream_pressure", NOMINAL_DOWNSTREAM)):
        text, no = meta.get(key, (repr(default), 0))
        try:
            p[key] = float(text)
        except ValueError:
            raise InputError(f"expected a pressure in Pa abs, got {text!r}", source=src,
                             location=f"line {no}, metadata '{key}'") from None
    p1, p2 = p["nominal_upstream_pressure"], p["nominal_downstream_pressure"]
    if not (math.isfinite(p1) and math.isfinite(p2) and p1 > p2 > 0):
        raise InputError(f"nominal pressures must satisfy p1 > p2 > 0 Pa abs, got {p1:g}, {p2:g}",
                         source=src)
    order = np.argsort(data[:, 0])
    return CatalogCurve(u=data[order, 0], q_n=data[order, 1], p1=p1, p2=p2, source=src)


def catalog_table(curve: CatalogCurve, b: float, supply_pressure: float,
                  atmospheric_pressure: float = gas.P_ATM, temperature: float = gas.T_REF,
                  p_values: Sequence[float] | None = None) -> ValveTable:
    """The characteristic q_m(p, u) implied by a catalog curve and ``b`` (ISO 6358).

    Parameters
    ----------
    curve : CatalogCurve. b : critical pressure ratio, -.
    supply_pressure, atmospheric_pressure : Pa abs. temperature : supply air, K.
    p_values : port pressures of the table, Pa abs (default 15 from atmosphere to supply).

    Returns
    -------
    ValveTable
        Every (u, p) of the curve's commands and ``p_values``; metadata records the
        curve, b and the pressures.
    """
    _check_b(b)
    if not (math.isfinite(supply_pressure) and supply_pressure > atmospheric_pressure > 0):
        raise InputError(f"expected a supply pressure above atmosphere (Pa abs), got "
                         f"{supply_pressure!r}", location="--supply-pressure")
    ps = (np.linspace(atmospheric_pressure, supply_pressure, 15) if p_values is None
          else np.asarray(p_values, dtype=float))
    centre = float(curve.u[np.argmin(np.abs(curve.q_n))])
    if not np.any(curve.q_n != 0):
        raise InputError("every nominal flow of the curve is 0: nothing to fit", source=curve.source)
    wrong = ((curve.u < centre) & (curve.q_n > 0)) | ((curve.u > centre) & (curve.q_n < 0))
    if np.any(wrong):
        k = int(np.flatnonzero(wrong)[0])
        raise InputError(f"the nominal flow at u = {curve.u[k]:g} V has the wrong sign for its "
                         f"side of the centre ({centre:g} V, the command of the smallest flow): "
                         "q_n must be < 0 (to the exhaust) below it and > 0 (from the supply) "
                         "above it", source=curve.source, location="column 'q_n'")
    c = curve.conductance(b)
    uu, pp = (a.ravel() for a in np.meshgrid(curve.u, ps, indexing="ij"))
    cc = np.repeat(c, len(ps))
    sgn = np.repeat(np.sign(curve.q_n), len(ps))
    q_in = np.asarray(gas.iso6358_flow(cc, b, supply_pressure, pp, temperature, temperature))
    q_out = np.asarray(gas.iso6358_flow(cc, b, pp, atmospheric_pressure, temperature, temperature))
    q = np.where(sgn > 0, q_in, np.where(sgn < 0, -q_out, 0.0))
    meta = {"generator": "workbench.identify.valve.catalog_table: ISO 6358 law from a catalog "
                         f"nominal-flow curve ({curve.source}), b = {b!r}",
            "supply_pressure": float(supply_pressure),
            "atmospheric_pressure": float(atmospheric_pressure), "temperature": float(temperature),
            "command_center": centre,
            "command_span": float(max(curve.u[-1] - centre, centre - curve.u[0])),
            "critical_pressure_ratio": float(b)}
    return ValveTable.from_arrays(uu, pp, q, meta, source=f"{curve.source} (catalog)")
