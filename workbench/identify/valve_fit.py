"""Valve characteristic fits of paper 003: approximations I and II from a measured table.

A valve table is the measured mass flow q_m (kg/s) *into* a port held at pressure p
(Pa, absolute) with the valve at command u (V): a CSV file with columns ``u``, ``p``,
``q_m`` and optional ``# key: value`` metadata lines (:func:`load_valve_table`). From
it this module gives

* **approximation I** (:func:`fit_polynomial`): the full bivariate polynomial
  q_m = sum_ij c_ij x^i s^j, degrees chosen by the user or by k-fold cross validation
  (:func:`select_degrees`); the simulation model of paper 003;
* **approximation II** (:func:`fit_affine`): the input-affine law
  q_m = phi(p) + psi(p, sgn Gamma) Gamma(s) with Gamma odd, fitted with constraints
  by CasADi + IPOPT; the control model, written in the plant file's convention so a
  :class:`~workbench.Plant` can use it (:meth:`AffineTableFit.plant_values`);
* their validation as in paper 003: the multiple correlation coefficient R and the
  errors in g/s (:class:`FitQuality`), the pressure gain characteristic q_m(p_e, u) = 0
  with Cp = -dq/dp and Gu = dq/du along it (:func:`pressure_gain`,
  :func:`pressure_gain_from_data`), and the tank step tests (:func:`tank_steps`);
* a generator of such tables from a plant's four-edge valve with a symmetric
  underlap leakage and measurement noise (:func:`generate_valve_table`).

Variables: s = (u - command_center) / command_span is the normalised command
(clipped to the table's range); the pressure polynomials of approximation II are in
p / 1e5 Pa (bar), as the plant file's ``affine_*`` keys (:mod:`workbench.params`).

Examples
--------
>>> from workbench import Plant, PlantParams
>>> from workbench.identify import valve_fit as vf
>>> table = vf.load_valve_table("tests/data/valve/rig25_table.csv")      # doctest: +SKIP
>>> fit1 = vf.fit_polynomial(table, 5, 10)                               # doctest: +SKIP
>>> fit2 = vf.fit_affine(table)                                          # doctest: +SKIP
>>> round(fit1.quality.r, 4), round(fit2.quality.max_error_g_s, 2)      # doctest: +SKIP
(0.9999, 1.47)
>>> base = PlantParams.from_toml("designs/plants/rig25_mpye.toml")     # doctest: +SKIP
>>> plant = Plant(base.replace(**fit2.plant_values()))                   # doctest: +SKIP
>>> gains = vf.pressure_gain(fit2.flow, [4.9, 5.0, 5.1], table.pressure_range)  # doctest: +SKIP

Command line: ``workbench identify valve TABLE.csv --approx both --out DIR`` and
``workbench identify valve-table PLANT.toml --out TABLE.csv`` (the generator).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np
from scipy import integrate, optimize

from ..errors import InputError, WorkbenchError
from ..linearize import TankTangent, tank_tangent
from ..params import PlantParams
from ..physics import gas
from ..physics.valve import (AffineValveFit, affine_flow, effective_opening, gamma_odd,
                             polyval, rounded_edge_openings, spool_position)

__all__ = [
    "COLUMNS", "MIN_POINTS", "G_PER_KG",
    "ValveTable", "load_valve_table",
    "valve_flow_law", "centre_dense_commands", "generate_valve_table",
    "FitQuality", "PolynomialValveFit", "fit_polynomial", "DegreeSelection", "select_degrees",
    "AffineTableFit", "fit_affine", "TableLaw",
    "PressureGain", "pressure_gain", "pressure_gain_from_data", "compare_pressure_gain",
    "TankStep", "TankStepTests", "tank_steps",
    "ValveFitReport", "analyse", "valve_curves", "add_cli",
]

#: Columns of a valve table and their SI units.
COLUMNS: Mapping[str, str] = MappingProxyType({"u": "V", "p": "Pa", "q_m": "kg/s"})
#: Fewest points a table may have (and at least 2 distinct commands and pressures).
MIN_POINTS = 6
#: Grams per kilogram: paper 003 states flow errors in g/s.
G_PER_KG = 1e3
#: Metadata keys read as numbers (SI): name -> (unit, meaning).
_NUMERIC_META = {
    "supply_pressure": ("Pa", "supply pressure of the characterisation, absolute"),
    "atmospheric_pressure": ("Pa", "exhaust (atmospheric) pressure, absolute"),
    "temperature": ("K", "supply air temperature"),
    "command_center": ("V", "command that centres the spool"),
    "command_span": ("V", "|u - centre| that opens an edge fully"),
}
#: Pressure polynomials of approximation II are in p / this (bar), as the plant file's.
PRESSURE_SCALE = 1e5


def _is_sym(*args) -> bool:
    return any(isinstance(a, (ca.SX, ca.MX)) for a in args)


def _clip(x, lo, hi):
    if _is_sym(x):
        return ca.fmin(ca.fmax(x, lo), hi)
    return np.clip(x, lo, hi)


def _json_floats(values) -> list:
    """Floats for JSON: NaN and inf become None (JSON has neither)."""
    return [float(v) if np.isfinite(v) else None for v in np.asarray(values, dtype=float).ravel()]


def _numeric(flow: Callable) -> Callable[[Any, Any], np.ndarray]:
    """A numpy-broadcasting evaluator of a CasADi-traceable ``flow(p, u)``."""
    p, u = ca.SX.sym("p"), ca.SX.sym("u")
    fun = ca.Function("q", [p, u], [flow(p, u)])

    def evaluate(pp, uu):
        pp, uu = np.broadcast_arrays(np.asarray(pp, dtype=float), np.asarray(uu, dtype=float))
        if pp.size == 0:
            return np.zeros(pp.shape)
        out = np.asarray(fun(pp.reshape(1, -1), uu.reshape(1, -1)))
        return out.reshape(pp.shape)
    return evaluate


# ====================================================================== the table
@dataclass(frozen=True, eq=False)
class ValveTable:
    """Measured valve characteristic q_m(p, u), validated and immutable.

    Parameters
    ----------
    u : array_like, shape (n,)
        Commands, V.
    p : array_like, shape (n,)
        Port pressures, Pa absolute (> 0).
    q_m : array_like, shape (n,)
        Mass flows into the port through the valve, kg/s.
    metadata : mapping of str to str
        ``# key: value`` header lines. Read as numbers when present:
        ``supply_pressure``, ``atmospheric_pressure`` (Pa), ``temperature`` (K),
        ``command_center``, ``command_span`` (V).
    source : str
        Where the table came from, for messages.

    Raises
    ------
    InputError
        Arrays of different lengths, NaN or inf, a pressure <= 0, fewer than
        :data:`MIN_POINTS` points or fewer than 2 distinct commands or pressures,
        a bad numeric metadata value. (:func:`load_valve_table` reports the file line.)
    """

    u: np.ndarray
    p: np.ndarray
    q_m: np.ndarray
    metadata: Mapping[str, str] = field(default_factory=dict)
    source: str = "<memory>"

    def __post_init__(self) -> None:
        arrays = {}
        for name in COLUMNS:
            a = np.array(getattr(self, name), dtype=float).ravel()
            a.flags.writeable = False
            arrays[name] = a
        n = {len(a) for a in arrays.values()}
        if len(n) != 1:
            raise InputError("columns u, p, q_m have different lengths "
                             + ", ".join(f"{k}: {len(v)}" for k, v in arrays.items()),
                             source=self.source)
        for name, a in arrays.items():
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise InputError(f"column '{name}' has a NaN or infinite value at index "
                                 f"{bad[0]}", source=self.source)
        _check_values(arrays["u"], arrays["p"], self.source, lambda i: f"index {i}")
        meta = {str(k): str(v) for k, v in dict(self.metadata).items()}
        for key in _NUMERIC_META:
            if key in meta:
                _meta_number(key, meta[key], self.source, f"metadata '{key}'")
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        object.__setattr__(self, "metadata", MappingProxyType(meta))

    # ---------------------------------------------------------------- access
    def __len__(self) -> int:
        return int(self.u.shape[0])

    def _meta(self, key: str, default: float) -> float:
        if key in self.metadata:
            return _meta_number(key, self.metadata[key], self.source, f"metadata '{key}'")
        return float(default)

    @property
    def supply_pressure(self) -> float:
        """Supply pressure, Pa: metadata ``supply_pressure``, else the highest table pressure."""
        return self._meta("supply_pressure", float(np.max(self.p)))

    @property
    def atmospheric_pressure(self) -> float:
        """Exhaust pressure, Pa: metadata ``atmospheric_pressure``, else 101325 Pa."""
        return self._meta("atmospheric_pressure", gas.P_ATM)

    @property
    def temperature(self) -> float:
        """Supply air temperature, K: metadata ``temperature``, else 293.15 K."""
        return self._meta("temperature", gas.T_REF)

    @property
    def command_center(self) -> float:
        """Command of the centred spool, V: metadata, else the middle of the table's commands."""
        return self._meta("command_center", 0.5 * (np.min(self.u) + np.max(self.u)))

    @property
    def command_span(self) -> float:
        """Half-range of the command, V: metadata, else half the table's command range."""
        return self._meta("command_span", 0.5 * (np.max(self.u) - np.min(self.u)))

    @property
    def pressure_range(self) -> tuple[float, float]:
        """(lowest, highest) table pressure, Pa."""
        return float(np.min(self.p)), float(np.max(self.p))

    @property
    def command_range(self) -> tuple[float, float]:
        """(lowest, highest) table command, V."""
        return float(np.min(self.u)), float(np.max(self.u))

    def columns(self) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """Per distinct command: (u, pressures sorted, flows), repeated pressures averaged."""
        out = []
        for uu in np.unique(self.u):
            sel = self.u == uu
            ps, inv = np.unique(self.p[sel], return_inverse=True)
            qs = np.bincount(inv, weights=self.q_m[sel]) / np.bincount(inv)
            out.append((float(uu), ps, qs))
        return out

    @classmethod
    def from_arrays(cls, u, p, q_m, metadata: Mapping[str, Any] | None = None,
                    source: str = "<memory>") -> "ValveTable":
        """Build a table from arrays (SI); metadata values are stored as text."""
        meta = {k: (repr(float(v)) if isinstance(v, (float, np.floating)) else str(v))
                for k, v in (metadata or {}).items()}
        return cls(u=u, p=p, q_m=q_m, metadata=meta, source=source)

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write the table (metadata lines, header ``u,p,q_m``, rows), atomically.

        Numbers are written with the shortest text that reads back to the same float.
        """
        from ..params import atomic_write_text
        lines = []
        for key, value in self.metadata.items():
            for part in str(value).split("\n"):
                lines.append(f"# {key}: {part}".rstrip())
        lines.append(",".join(COLUMNS))
        lines += [f"{a!r},{b!r},{c!r}" for a, b, c in
                  zip(self.u.tolist(), self.p.tolist(), self.q_m.tolist())]
        atomic_write_text(path, "\n".join(lines) + "\n")
        return Path(path)

    def __repr__(self) -> str:
        lo, hi = self.pressure_range
        return (f"ValveTable(source={self.source!r}, points={len(self)}, "
                f"u {self.command_range[0]:g}..{self.command_range[1]:g} V, "
                f"p {lo:g}..{hi:g} Pa)")


def _meta_number(key: str, text: str, source: str, where: str) -> float:
    unit, doc = _NUMERIC_META[key]
    try:
        val = float(text)
    except ValueError:
        raise InputError(f"expected a number in {unit} ({doc}), got {text!r}",
                         source=source, location=where) from None
    if not (math.isfinite(val) and (val > 0 or key == "command_center")):
        raise InputError(f"expected a {'finite' if key == 'command_center' else 'positive'} "
                         f"number in {unit} ({doc}), got {text!r}", source=source,
                         location=where)
    return val


def _check_values(u: np.ndarray, p: np.ndarray, source: str, where: Callable[[int], str]):
    bad = np.flatnonzero(p <= 0)
    if bad.size:
        i = int(bad[0])
        raise InputError(f"pressure {p[i]:g} Pa is not positive: pressures are absolute, in "
                         "Pa (a gauge value needs + 101325 Pa)", source=source,
                         location=f"{where(i)}, column 'p'")
    if len(u) < MIN_POINTS:
        raise InputError(f"too few points: {len(u)}; a valve table needs at least "
                         f"{MIN_POINTS} (paper 003 used 201)", source=source)
    if len(np.unique(u)) < 2 or len(np.unique(p)) < 2:
        raise InputError(f"too few distinct values: {len(np.unique(u))} commands and "
                         f"{len(np.unique(p))} pressures; a characteristic needs at least "
                         "2 of each", source=source)
    if np.max(p) < 100.0:
        raise InputError(f"largest pressure is {np.max(p):g} Pa: pressures must be in Pa "
                         "absolute (a value in bar needs * 1e5)", source=source,
                         location="column 'p'")


def load_valve_table(path: str | os.PathLike) -> ValveTable:
    """Read and validate a valve table CSV.

    The file has optional ``# key: value`` metadata lines, a header naming the columns
    (``u``, ``p``, ``q_m`` in any order; extra columns are ignored), then one row per
    point. Blank lines and other ``#`` comments are skipped; rows need not be sorted.

    Raises
    ------
    InputError
        Naming the file and the 1-based line (and column): file not found, missing
        column, a cell that is not a number, NaN or inf, a pressure <= 0, a row with
        the wrong number of cells, too few points.
    """
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", source=src) from None
    meta: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    header: list[str] | None = None
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            key, sep, value = body.partition(":")
            if header is None and sep and key.strip() and " " not in key.strip():
                meta[key.strip()] = value.strip()
                meta_line[key.strip()] = lineno
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = cells
            missing = [c for c in COLUMNS if c not in header]
            if missing:
                raise InputError(
                    f"missing column{'s' if len(missing) > 1 else ''} "
                    + ", ".join(f"'{c}'" for c in missing)
                    + f"; the header is {line!r}, a valve table needs u (V), p (Pa "
                    "absolute) and q_m (kg/s, into the port)",
                    source=src, location=f"line {lineno} (header)")
            idx = [header.index(c) for c in COLUMNS]
            header_line = lineno
            continue
        if len(cells) != len(header):
            raise InputError(f"expected {len(header)} cells (as the header on line "
                             f"{header_line}), got {len(cells)}", source=src,
                             location=f"line {lineno}")
        vals = []
        for name, i in zip(COLUMNS, idx):
            try:
                v = float(cells[i])
            except ValueError:
                raise InputError(f"expected a number, got {cells[i]!r}", source=src,
                                 location=f"line {lineno}, column '{name}'") from None
            if not math.isfinite(v):
                raise InputError(f"expected a finite number, got {cells[i]!r}", source=src,
                                 location=f"line {lineno}, column '{name}'")
            vals.append(v)
        rows.append(vals)
        row_lines.append(lineno)
    if header is None:
        raise InputError("no header line: expected a line naming the columns u,p,q_m",
                         source=src)
    data = np.array(rows, dtype=float).reshape(-1, 3)
    _check_values(data[:, 0], data[:, 1], src, lambda i: f"line {row_lines[i]}")
    for key in _NUMERIC_META:
        if key in meta:
            _meta_number(key, meta[key], src, f"line {meta_line[key]}, metadata '{key}'")
    return ValveTable(u=data[:, 0], p=data[:, 1], q_m=data[:, 2], metadata=meta, source=src)


# ====================================================================== generator
def _params_of(plant_or_params) -> PlantParams:
    if isinstance(plant_or_params, PlantParams):
        return plant_or_params
    if isinstance(plant_or_params, (str, os.PathLike)):
        return PlantParams.from_toml(plant_or_params)
    prm = getattr(plant_or_params, "params", None)
    if isinstance(prm, PlantParams):
        return prm
    raise TypeError(f"expected a Plant, PlantParams or a plant file, got {plant_or_params!r}")


def valve_flow_law(plant_or_params, leakage: float = 0.0) -> Callable:
    """The port flow q_m(p, u) (kg/s) of a plant's valve, as a CasADi-traceable function.

    The port-A flow of the plant's 5/3 valve with the port at pressure p (Pa) and
    command u (V): the plant's command centre, span, null offset and deadband, its
    supply and atmospheric pressures and temperature. Under ``law = "iso6358"`` the
    four ISO 6358 edges; ``leakage`` = d gives every edge a symmetric, rounded
    underlap: for the signed opening o the inlet (supply -> port) edge opens
    (sqrt(o^2 + d^2) + o) / 2 and the exhaust (port -> atmosphere) edge
    (sqrt(o^2 + d^2) - o) / 2 instead of max(o, 0) and max(-o, 0). At the centre both
    are open d/2: the port is fed from the supply and leaks to the exhaust, and the
    flow is zero at a pressure between atmosphere and supply that moves with u (the
    pressure gain characteristic). An overlapped edge still passes d^2 / (4 |o|), the
    clearance leakage that falls with the overlap length; an open edge tends to o.
    The flow is smooth in u. With d = 0 this is exactly
    :func:`workbench.physics.valve.four_edge_flows`. Under ``law = "input_affine"``
    the plant's affine law (``leakage`` must then be 0).

    Parameters
    ----------
    plant_or_params : Plant, PlantParams or plant file path
    leakage : float
        Underlap d of every edge, fraction of full opening (of the command span), in [0, 1).
    """
    prm = _params_of(plant_or_params)
    if not 0.0 <= leakage < 1.0:
        raise InputError(f"expected a leakage (underlap) in [0, 1) of the span, got {leakage!r}",
                         location="leakage")
    center = prm["valve.command_center"]
    span = prm["valve.command_span"]
    offset = prm.get("valve.null_offset", 0.0)
    deadband = prm.get("valve.deadband", 0.0)
    p_s, p_atm, T = prm["supply.pressure"], prm["gas.atmospheric_pressure"], prm["gas.temperature"]

    def opening(u):
        s = spool_position(u, center, span, offset)
        # effective_opening(s, 0) equals s but its CasADi derivative at s = 0 is 0.75
        # (fmax/fmin ties in its clip); without a deadband s is used directly.
        return effective_opening(s, deadband) if deadband else s

    if prm["valve.law"] == "input_affine":
        if leakage:
            raise InputError("leakage can only be added to a four-edge (iso6358) valve; "
                             "this plant's valve law is 'input_affine'", location="leakage")
        phi, psi_in, psi_out, gam = (prm[f"valve.affine_{k}"] for k in
                                     ("phi", "psi_in", "psi_out", "gamma"))

        def flow(p, u):
            return affine_flow(p, gamma_odd(opening(u), gam), phi, psi_in, psi_out)
        return flow
    C, b = prm["valve.sonic_conductance"], prm["valve.critical_pressure_ratio"]
    d = float(leakage)

    def flow(p, u):
        # physics.valve's rounded underlap law (with d = 0 exactly the plant's four edges)
        o_in, o_out = rounded_edge_openings(opening(u), d)
        return (o_in * gas.iso6358_flow(C, b, p_s, p, T, T)
                - o_out * gas.iso6358_flow(C, b, p, p_atm, T, T))
    return flow


def centre_dense_commands(center: float, span: float, n: int = 21,
                          power: float = 2.0) -> np.ndarray:
    """``n`` commands (V) over [center - span, center + span], denser near the centre.

    u = center + span sign(x) |x|^power for x evenly spaced in [-1, 1]: paper 003
    measured more densely where the characteristic is nonlinear (around the centre,
    where the pressure gain characteristic lives).
    """
    x = np.linspace(-1.0, 1.0, int(n))
    return center + span * np.sign(x) * np.abs(x) ** power


def generate_valve_table(plant_or_params, u_values: Sequence[float] | None = None,
                         p_values: Sequence[float] | None = None, leakage: float = 0.0,
                         noise: float = 0.0, seed: int = 0,
                         made_with: str | None = None) -> ValveTable:
    """A valve table q_m(p, u) from a plant's physical valve (:func:`valve_flow_law`).

    Parameters
    ----------
    plant_or_params : Plant, PlantParams or plant file path
    u_values : commands, V (default :func:`centre_dense_commands` over the span, 21).
    p_values : port pressures, Pa absolute (default 15 from atmosphere to supply).
    leakage : symmetric geometric underlap of every edge, fraction of the span.
    noise : standard deviation of Gaussian noise added to every flow, kg/s.
    seed : seed of the noise generator.
    made_with : text stored as the ``made_with`` metadata (the command that made it).

    Returns
    -------
    ValveTable
        The full grid, u varying slowest; metadata records the plant, supply and
        atmospheric pressures, temperature, command centre and span, leakage,
        noise and seed.
    """
    prm = _params_of(plant_or_params)
    if noise < 0 or not math.isfinite(noise):
        raise InputError(f"expected a noise standard deviation >= 0 (kg/s), got {noise!r}",
                         location="noise")
    p_s, p_atm = prm["supply.pressure"], prm["gas.atmospheric_pressure"]
    center, span = prm["valve.command_center"], prm["valve.command_span"]
    u_values = (centre_dense_commands(center, span) if u_values is None
                else np.asarray(u_values, dtype=float))
    p_values = (np.linspace(p_atm, p_s, 15) if p_values is None
                else np.asarray(p_values, dtype=float))
    uu, pp = (a.ravel() for a in np.meshgrid(u_values, p_values, indexing="ij"))
    q = _numeric(valve_flow_law(prm, leakage))(pp, uu)
    if noise > 0:
        q = q + np.random.default_rng(seed).normal(0.0, noise, q.shape)
    meta: dict[str, Any] = {}
    if made_with:
        meta["made_with"] = made_with
    meta.update({
        "plant": f"{prm.name} ({prm.source})",
        "generator": "workbench.identify.valve_fit.generate_valve_table: port A flow of the "
                     "four-edge valve, every edge with a rounded underlap 'leakage'",
        "supply_pressure": float(p_s), "atmospheric_pressure": float(p_atm),
        "temperature": float(prm["gas.temperature"]),
        "command_center": float(center), "command_span": float(span),
        "leakage": float(leakage), "noise_kg_s": float(noise), "seed": int(seed),
    })
    return ValveTable.from_arrays(uu, pp, q, meta, source="<generated>")


# ====================================================================== fit quality
@dataclass(frozen=True)
class FitQuality:
    """How well a law reproduces a table (paper 003's criteria).

    Attributes
    ----------
    r : multiple correlation coefficient R = sqrt(1 - SS_res / SS_tot), -. This is
        what paper 003 reports (R = 0.99); for a linear least-squares fit with a
        constant term it equals the correlation of measured and fitted flows.
    r2 : coefficient of determination R^2 = 1 - SS_res / SS_tot, -.
    rms, max_error : RMS and largest |q_fit - q_table|, kg/s (``*_g_s`` in g/s).
    points : number of table points. coefficients : number of stored coefficients.
    free : number of independent (fitted) parameters.
    worst_u, worst_p : command (V) and pressure (Pa) of the largest error.
    """

    r: float
    r2: float
    rms: float
    max_error: float
    points: int
    coefficients: int
    free: int
    worst_u: float = float("nan")
    worst_p: float = float("nan")

    @property
    def rms_g_s(self) -> float:
        return self.rms * G_PER_KG

    @property
    def max_error_g_s(self) -> float:
        return self.max_error * G_PER_KG

    def as_dict(self) -> dict[str, Any]:
        return {"R": self.r, "R2": self.r2, "rms_g_s": self.rms_g_s,
                "max_error_g_s": self.max_error_g_s, "worst_at": {"u_V": self.worst_u,
                                                                   "p_Pa": self.worst_p},
                "points": self.points, "coefficients": self.coefficients,
                "free_parameters": self.free}


def _quality(table: ValveTable, q_fit: np.ndarray, coefficients: int, free: int) -> FitQuality:
    q = table.q_m
    err = q_fit - q
    ss_res = float(np.sum(err ** 2))
    ss_tot = float(np.sum((q - np.mean(q)) ** 2))
    r2 = 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")
    i = int(np.argmax(np.abs(err)))
    return FitQuality(r=math.sqrt(max(r2, 0.0)), r2=r2, rms=float(np.sqrt(np.mean(err ** 2))),
                      max_error=float(abs(err[i])), points=int(len(q)),
                      coefficients=int(coefficients), free=int(free),
                      worst_u=float(table.u[i]), worst_p=float(table.p[i]))


def _normalised_command(table: ValveTable, center: float | None, span: float | None):
    c = table.command_center if center is None else float(center)
    s = table.command_span if span is None else float(span)
    if not s > 0:
        raise InputError(f"expected a positive command span (V), got {s!r}", source=table.source)
    return c, s


# ====================================================================== approximation I
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
    """

    coefficients: np.ndarray
    center: float
    span: float
    pressure_offset: float
    pressure_scale: float
    s_range: tuple[float, float]
    quality: FitQuality

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

    def as_dict(self) -> dict[str, Any]:
        n, m = self.degrees
        return {"approximation": "I", "degrees": {"n_pressure": n, "m_command": m},
                "variables": {"x": f"(p - {self.pressure_offset!r}) / {self.pressure_scale!r}",
                              "s": f"(u - {self.center!r}) / {self.span!r}, clipped to "
                                   f"[{self.s_range[0]!r}, {self.s_range[1]!r}]"},
                "coefficients_kg_s": self.coefficients.tolist(),
                **self.quality.as_dict()}


def _poly_design(x: np.ndarray, s: np.ndarray, n: int, m: int) -> np.ndarray:
    vx = np.vander(x, n + 1, increasing=True)
    vs = np.vander(s, m + 1, increasing=True)
    return (vx[:, :, None] * vs[:, None, :]).reshape(len(x), -1)


def _openblas_local_setters() -> list:
    """``openblas_set_num_threads_local`` of the OpenBLAS copies numpy and scipy load."""
    import ctypes
    import glob
    found = []
    for pkg in (np, __import__("scipy")):
        base = os.path.dirname(os.path.dirname(pkg.__file__))
        name = pkg.__name__
        for lib in glob.glob(os.path.join(base, f"{name}.libs", "*openblas*.so*")):
            try:
                fn = ctypes.CDLL(lib).openblas_set_num_threads_local
            except (OSError, AttributeError):
                continue
            fn.argtypes, fn.restype = [ctypes.c_int], ctypes.c_int
            found.append(fn)
    return found


_BLAS_SETTERS: list | None = None


@contextmanager
def serial_blas():
    """Run OpenBLAS single-threaded in this thread for the block (restored afterwards).

    The least-squares problems here are a few hundred by a few dozen: OpenBLAS's
    worker threads only add synchronisation, and on a loaded machine (more runnable
    processes than cores) they make one such solve 10 to 100 times slower. A no-op
    where the thread-local setter is not available.
    """
    global _BLAS_SETTERS
    if _BLAS_SETTERS is None:
        _BLAS_SETTERS = _openblas_local_setters()
    previous = [fn(1) for fn in _BLAS_SETTERS]
    try:
        yield
    finally:
        for fn, n in zip(_BLAS_SETTERS, previous):
            fn(n)


def _lstsq(A: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0.0] = 1.0
    with serial_blas():
        sol, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
    return sol / scale


def _poly_vars(table: ValveTable, center: float, span: float):
    lo, hi = table.pressure_range
    offset, scale = 0.5 * (lo + hi), 0.5 * (hi - lo)
    x = (table.p - offset) / scale
    s = (table.u - center) / span
    return x, s, offset, scale


def fit_polynomial(table: ValveTable, n: int = 5, m: int = 10, *, center: float | None = None,
                   span: float | None = None) -> PolynomialValveFit:
    """Approximation I by linear least squares: degrees ``n`` in p and ``m`` in u.

    Paper 003 settles on n = 5, m = 10 (66 coefficients). Fitting is done in the
    scaled variables of :class:`PolynomialValveFit` (columns also normalised).

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
    sol = _lstsq(A, table.q_m)
    coeffs = sol.reshape(n + 1, m + 1)
    coeffs.flags.writeable = False
    q_fit = A @ sol
    return PolynomialValveFit(coefficients=coeffs, center=center, span=span,
                              pressure_offset=offset, pressure_scale=scale,
                              s_range=(float(np.min(s)), float(np.max(s))),
                              quality=_quality(table, q_fit, k, k))


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

    def as_dict(self) -> dict[str, Any]:
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


# ====================================================================== approximation II
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

    def as_dict(self) -> dict[str, Any]:
        return {"approximation": "II", "phi_kg_s": list(self.phi),
                "psi_in_kg_s": list(self.psi_in), "psi_out_kg_s": list(self.psi_out),
                "gamma": list(self.gamma), "pressure_variable": "p / 1e5 Pa",
                "command_variable": f"s = (u - {self.center!r}) / {self.span!r}, "
                                    "clipped to [-1, 1]",
                "normalisation": self.normalisation, "pin_ends": self.pin_ends,
                "solver_status": self.solver_status, "iterations": self.iterations,
                **self.quality.as_dict()}


def _to_bar_monomials(coeffs: np.ndarray, offset_bar: float, scale_bar: float) -> np.ndarray:
    """Ascending coefficients in x = (pb - offset)/scale -> ascending in pb = p/1e5."""
    P = np.polynomial.Polynomial
    out = P(coeffs)(P([-offset_bar / scale_bar, 1.0 / scale_bar])).coef
    return np.pad(out, (0, len(coeffs) - len(out)))


def fit_affine(table: ValveTable, phi_degree: int | None = 5, psi_degree: int = 5,
               gamma_degree: int = 2, *, pin_ends: bool = False, monotone: bool = True,
               shared_psi: bool = False, center: float | None = None,
               span: float | None = None, print_level: int = 0) -> AffineTableFit:
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

    Raises
    ------
    InputError
        Bad degrees, or fewer points than unknowns.
    WorkbenchError
        IPOPT fails.
    """
    if psi_degree < 0 or gamma_degree < 1 or (phi_degree is not None and phi_degree < 0):
        raise InputError(f"expected degrees phi >= 0 (or none), psi >= 0, gamma >= 1; got "
                         f"{phi_degree}, {psi_degree}, {gamma_degree}",
                         location="--affine-degrees")
    center, span = _normalised_command(table, center, span)
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

    Bp = np.vander(x, n_psi, increasing=True)
    Bphi = np.vander(x, max(n_phi, 1), increasing=True)[:, :n_phi]
    S = np.stack([s * np.abs(s) ** k for k in range(n_gam)], axis=1)   # Gamma basis
    inlet = (s > 0).astype(float)
    outlet = (s < 0).astype(float)

    a = ca.SX.sym("phi", n_phi)
    b_in = ca.SX.sym("psi_in", n_psi)
    b_out = b_in if shared_psi else ca.SX.sym("psi_out", n_psi)
    g = ca.SX.sym("gamma", n_gam)
    w = ca.vertcat(a, b_in, *([] if shared_psi else [b_out]), g)
    gam = ca.mtimes(ca.DM(S), g)
    psi = (ca.mtimes(ca.DM(Bp), b_in) * ca.DM(inlet)
           + ca.mtimes(ca.DM(Bp), b_out) * ca.DM(outlet))
    q_hat = psi * gam
    if n_phi:
        q_hat = q_hat + ca.mtimes(ca.DM(Bphi), a)
    f = ca.sumsqr(q_hat - ca.DM(q)) / len(q)

    def poly_at(coef, xx, n):
        return sum(coef[k] * xx ** k for k in range(n)) if n else 0.0

    cons, lbg, ubg = [ca.sum1(g) - 1.0], [0.0], [0.0]      # Gamma(1) = 1
    if monotone:
        for sv in np.linspace(0.0, 1.0, 21):
            cons.append(sum((k + 1) * g[k] * sv ** k for k in range(n_gam)))
            lbg.append(0.0)
            ubg.append(ca.inf)
    p_s, p_atm = table.supply_pressure, table.atmospheric_pressure
    if pin_ends:
        xs, xa = (p_s - p_mid) / p_half, (p_atm - p_mid) / p_half
        cons.append(poly_at(a, xs, n_phi) + poly_at(b_in, xs, n_psi))
        cons.append(poly_at(a, xa, n_phi) - poly_at(b_out, xa, n_psi))
        lbg += [0.0, 0.0]
        ubg += [0.0, 0.0]

    # start: Gamma = s, linear least squares for phi and psi
    blocks = [Bphi] if n_phi else []
    if shared_psi:
        blocks.append(Bp * s[:, None])
    else:
        blocks += [Bp * (s * inlet)[:, None], Bp * (s * outlet)[:, None]]
    w0 = np.concatenate([_lstsq(np.hstack(blocks), q), np.eye(n_gam)[0]])

    solver = ca.nlpsol("valve_affine", "ipopt", {"x": w, "f": f, "g": ca.vertcat(*cons)},
                       {"ipopt.print_level": int(print_level), "print_time": False,
                        "ipopt.tol": 1e-12, "ipopt.max_iter": 500, "ipopt.sb": "yes"})
    sol = solver(x0=w0, lbg=lbg, ubg=ubg)
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    if not stats.get("success", False) and status not in ("Solved_To_Acceptable_Level",):
        raise WorkbenchError(f"IPOPT did not fit approximation II: {status}")
    wv = np.asarray(sol["x"]).ravel()
    i = 0
    phi_x = wv[i:i + n_phi] / G_PER_KG
    i += n_phi
    psi_in_x = wv[i:i + n_psi] / G_PER_KG
    i += n_psi
    if shared_psi:
        psi_out_x = psi_in_x
    else:
        psi_out_x = wv[i:i + n_psi] / G_PER_KG
        i += n_psi
    gam_v = wv[i:i + n_gam]
    ob, sb = p_mid / PRESSURE_SCALE, p_half / PRESSURE_SCALE
    phi = tuple(float(c) for c in _to_bar_monomials(phi_x, ob, sb)) if n_phi else (0.0,)
    psi_in = tuple(float(c) for c in _to_bar_monomials(psi_in_x, ob, sb))
    psi_out = tuple(float(c) for c in _to_bar_monomials(psi_out_x, ob, sb))
    gamma = tuple(float(c) for c in gam_v)
    n_stored = len(phi) * (n_phi > 0) + n_branches * n_psi + n_gam
    law = AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                         pressure_scale=PRESSURE_SCALE, rms=0.0, max_error=0.0,
                         pressure_range=(lo, hi), points=len(q))
    q_fit = np.asarray(_numeric(lambda p, u: law.flow(p, _clip((u - center) / span, -1.0, 1.0)))(
        table.p, table.u), dtype=float)
    quality = _quality(table, q_fit, n_stored, n_free)
    law = AffineValveFit(phi=phi, psi_in=psi_in, psi_out=psi_out, gamma=gamma,
                         pressure_scale=PRESSURE_SCALE, rms=quality.rms,
                         max_error=quality.max_error, pressure_range=(lo, hi), points=len(q))
    return AffineTableFit(law=law, center=center, span=span, quality=quality,
                          normalisation="Gamma(1) = 1", pin_ends=bool(pin_ends),
                          supply_pressure=p_s, atmospheric_pressure=p_atm,
                          solver_status=status, iterations=int(stats.get("iter_count", -1)))


# ====================================================================== data as a law
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


# ====================================================================== pressure gain
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

    def as_dict(self) -> dict[str, Any]:
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


# ====================================================================== tank steps
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

    def as_dict(self) -> dict[str, Any]:
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


# ====================================================================== everything at once
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

    def as_dict(self) -> dict[str, Any]:
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
            out["approximation_I"] = self.approx_1.as_dict()
        if self.selection is not None:
            out["degree_selection"] = self.selection.as_dict()
        if self.approx_2 is not None:
            out["approximation_II"] = self.approx_2.as_dict()
        data = self.gains.get("data")
        ref = self.gains.get(self.reference) if self.reference else None
        out["pressure_gain"] = {}
        for lab, g in self.gains.items():
            entry = g.as_dict()
            if data is not None and lab != "data":
                entry["vs_data"] = compare_pressure_gain(data, g, t.pressure_range)
            if ref is not None and lab != self.reference:
                entry["vs_reference"] = compare_pressure_gain(ref, g, t.pressure_range)
            out["pressure_gain"][lab] = entry
        if self.tank is not None:
            out["tank_steps"] = self.tank.as_dict()
        out["notes"] = list(self.notes)
        return out


def analyse(table: ValveTable, approx: str = "both", degrees: tuple[int, int] | None = None,
            select: bool = False, affine_degrees: tuple[int | None, int, int] = (5, 5, 2),
            pin_ends: bool = False, tank_volume: float = 1e-3, tank: bool = True,
            k: float = 1.2, seed: int = 0, reference: Callable | None = None,
            reference_label: str = "generating valve") -> ValveFitReport:
    """Fit approximation I and/or II, then the pressure gain and tank step validation.

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
            a1 = sel.fit
        else:
            n, m = degrees if degrees is not None else (5, 10)
            a1 = fit_polynomial(table, n, m)
    if approx in ("II", "both"):
        a2 = fit_affine(table, *affine_degrees, pin_ends=pin_ends)
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
        gains[lab] = pressure_gain(fl, fine, (lo, hi), label=lab)
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


# ====================================================================== command line
def _figures(report: ValveFitReport, out: Path) -> list[str]:
    """Write the four figures of a report into ``out``; returns their file names."""
    from . import plots
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


def _cmd_valve(args: argparse.Namespace) -> int:
    table = load_valve_table(args.table)
    if args.plant_toml and not args.base:
        raise InputError("--plant-toml needs --base PLANT.toml (the plant whose valve is "
                         "replaced by the fitted law)", location="--plant-toml")
    if args.plant_toml and args.approx == "I":
        raise InputError("--plant-toml writes the input-affine law: use --approx II or both",
                         location="--plant-toml")
    base = PlantParams.from_toml(args.base) if args.base else None
    reference = None
    if args.reference_plant:
        leak = args.leakage
        if leak is None:
            leak = float(table.metadata.get("leakage", 0.0)) if _is_number(
                table.metadata.get("leakage", "0")) else 0.0
        reference = valve_flow_law(args.reference_plant, leak)
    phi_deg = None if args.affine_degrees[0] < 0 else args.affine_degrees[0]
    report = analyse(table, approx=args.approx,
                     degrees=tuple(args.degrees) if args.degrees else None, select=args.select,
                     affine_degrees=(phi_deg, args.affine_degrees[1], args.affine_degrees[2]),
                     pin_ends=args.pin_ends, tank_volume=args.tank_volume, tank=not args.no_tank,
                     reference=reference)
    result = report.as_dict()
    if args.plant_toml:
        new = base.replace(**report.approx_2.plant_values())
        new.to_toml(args.plant_toml)
        result["plant_toml"] = str(args.plant_toml)
        p_base, p_tab = base["supply.pressure"], table.supply_pressure
        if abs(p_base - p_tab) > 0.01 * p_tab:
            note = (f"the base plant's supply pressure ({p_base:g} Pa) differs from the "
                    f"table's ({p_tab:g} Pa): the input-affine law does not see the supply "
                    "pressure, it holds only at the table's")
            result["notes"].append(note)
            report = ValveFitReport(**{**report.__dict__, "notes": report.notes + (note,)})
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        from ..params import atomic_write_text
        atomic_write_text(out / "valve_fit.json", json.dumps(result, indent=2) + "\n")
        result["files"] = ["valve_fit.json"] + ([] if args.no_plot else _figures(report, out))
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"valve table {table.source}: {len(table)} points, u {table.command_range[0]:g}.."
          f"{table.command_range[1]:g} V, p {table.pressure_range[0] / 1e5:.3f}.."
          f"{table.pressure_range[1] / 1e5:.3f} bar")
    for lab, fit in (("approximation I", report.approx_1), ("approximation II", report.approx_2)):
        if fit is None:
            continue
        qd = fit.quality
        what = (f"n = {fit.degrees[0]}, m = {fit.degrees[1]}" if lab.endswith(" I")
                else f"phi {len(fit.phi) - 1 if any(fit.phi) else '-'}, psi {len(fit.psi_in) - 1}, "
                     f"Gamma {len(fit.gamma)} odd terms")
        print(f"  {lab:<17} {what}: {qd.coefficients} coefficients ({qd.free} free), "
              f"R = {qd.r:.5f}, errors max {qd.max_error_g_s:.3f} g/s, RMS {qd.rms_g_s:.3f} g/s")
    refs = [r for r in ("data", report.reference) if r in report.gains]
    for lab, g in report.gains.items():
        for r in refs:
            if lab in refs[:refs.index(r) + 1]:
                continue
            cmp_ = compare_pressure_gain(report.gains[r], g, table.pressure_range)
            if cmp_["commands"]:
                gu = cmp_["median_rel_gu"]
                print(f"  pressure gain {lab} vs {r}: max |dp_e| "
                      f"{cmp_['max_abs_dp_e_Pa'] / 1e5:.4f} bar over {cmp_['commands']} "
                      f"commands; median relative difference Cp {100 * cmp_['median_rel_cp']:.1f} %"
                      f", Gu " + (f"{100 * gu:.1f} %" if gu is not None else "n/a"))
    if report.tank is not None:
        tk = report.tank
        for lab in tk.labels():
            if lab == tk.reference:
                continue
            errs = ", ".join(f"{du:+g} V: {100 * tk.max_error(lab, du):.2f} %"
                             for du in tk.step_sizes())
            print(f"  tank steps {lab} vs {tk.reference} (max pressure error): {errs}")
    for n_ in report.notes:
        print(f"  note: {n_}")
    if args.plant_toml:
        print(f"  wrote {args.plant_toml}")
    if args.out:
        print(f"  wrote {', '.join(result['files'])} in {args.out}")
    return 0


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except (TypeError, ValueError):
        return False


def _float_list(text: str, option: str) -> np.ndarray:
    """``a,b,c`` or ``START:STOP:NUM`` -> array."""
    try:
        if ":" in text:
            a, b, n = text.split(":")
            return np.linspace(float(a), float(b), int(n))
        return np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise InputError(f"expected a,b,c or START:STOP:NUM, got {text!r}",
                         location=option) from None


def _cmd_valve_table(args: argparse.Namespace) -> int:
    prm = PlantParams.from_toml(args.plant)
    cmd = ["workbench", "identify", "valve-table", str(args.plant), "--out", str(args.out),
           "--leakage", repr(args.leakage), "--noise", repr(args.noise), "--seed", str(args.seed)]
    cmd += ["--u", args.u] if args.u is not None else ["--n-u", str(args.n_u)]
    cmd += ["--p", args.p] if args.p is not None else ["--n-p", str(args.n_p)]
    made_with = " ".join(shlex.quote(c) for c in cmd)
    center, span = prm["valve.command_center"], prm["valve.command_span"]
    u = (centre_dense_commands(center, span, args.n_u) if args.u is None
         else _float_list(args.u, "--u"))
    p = (np.linspace(prm["gas.atmospheric_pressure"], prm["supply.pressure"], args.n_p)
         if args.p is None else _float_list(args.p, "--p"))
    table = generate_valve_table(prm, u, p, leakage=args.leakage, noise=args.noise,
                                 seed=args.seed, made_with=made_with)
    table.to_csv(args.out)
    print(f"wrote {args.out}: {len(table)} points")
    return 0


def add_cli(subparsers) -> None:
    """Add ``workbench identify valve`` and ``workbench identify valve-table``."""
    v = subparsers.add_parser(
        "valve", help="fit paper 003's valve characteristic approximations I and II",
        description="Fit a measured valve table (CSV: u [V], p [Pa abs], q_m [kg/s into the "
                    "port]) with approximation I (full polynomial, degrees n in p, m in u) "
                    "and/or II (input-affine q = phi(p) + psi(p, sgn Gamma) Gamma(u), Gamma odd, "
                    "fitted by IPOPT with Gamma(1) = 1 and Gamma monotone). Reports R "
                    "(multiple correlation coefficient) and errors in g/s, the pressure gain "
                    "characteristic (q_m = 0 curve) with Cp, Gu against the data, and tank "
                    "step tests (+-1 V and +-0.1 V at the command centre) against the table "
                    "(or against --reference-plant's valve when the table was generated).",
        epilog="Example: workbench identify valve tests/data/valve/rig25_table.csv --approx both "
               "--out fit/ --plant-toml fitted.toml --base designs/plants/rig25_mpye.toml")
    v.add_argument("table", metavar="TABLE.csv", help="valve table")
    v.add_argument("--approx", choices=("I", "II", "both"), default="both",
                   help="which approximation (default both)")
    v.add_argument("--degrees", nargs=2, type=int, metavar=("N", "M"),
                   help="approximation I degrees in p and u (default 5 10, paper 003)")
    v.add_argument("--select", action="store_true",
                   help="choose approximation I degrees by 5-fold cross validation "
                        "(n 1..7, m 1..12)")
    v.add_argument("--affine-degrees", nargs=3, type=int, default=[5, 5, 2],
                   metavar=("PHI", "PSI", "GAMMA"),
                   help="approximation II: degree of phi (-1: phi = 0), of psi_in/psi_out, "
                        "and number of odd Gamma terms (default 5 5 2, paper 003)")
    v.add_argument("--pin-ends", action="store_true",
                   help="approximation II: impose q(p_supply, full inlet) = 0 and "
                        "q(p_atm, full exhaust) = 0")
    v.add_argument("--tank-volume", type=float, default=1e-3, metavar="V",
                   help="tank volume of the step tests, m^3 (default 1e-3)")
    v.add_argument("--no-tank", action="store_true", help="skip the tank step tests")
    v.add_argument("--reference-plant", metavar="PLANT.toml",
                   help="the plant whose valve made the table (see valve-table): its true law "
                        "is the reference of the tank steps and adds its pressure gain curve")
    v.add_argument("--leakage", type=float, metavar="D",
                   help="underlap leakage of --reference-plant's valve (default: the table's "
                        "'leakage' metadata, else 0)")
    v.add_argument("--out", metavar="DIR", help="write DIR/valve_fit.json and figures")
    v.add_argument("--no-plot", action="store_true", help="no figures in DIR")
    v.add_argument("--json", action="store_true", help="print the results as JSON (SI; errors g/s)")
    v.add_argument("--plant-toml", metavar="OUT.toml",
                   help="write a copy of --base with its valve replaced by the fitted "
                        "approximation II")
    v.add_argument("--base", metavar="PLANT.toml", help="plant file for --plant-toml")
    v.set_defaults(func=_cmd_valve)

    g = subparsers.add_parser(
        "valve-table", help="generate a valve table from a plant's four-edge valve",
        description="Write a valve table CSV (u, p, q_m) from the plant file's valve (four "
                    "ISO 6358 edges, its centre, span, offset, deadband) with a symmetric "
                    "geometric underlap --leakage (fraction of the span) and Gaussian noise "
                    "(kg/s). The header records the command and the settings.")
    g.add_argument("plant", metavar="PLANT.toml", help="plant file")
    g.add_argument("--out", required=True, metavar="TABLE.csv", help="output CSV")
    g.add_argument("--leakage", type=float, default=0.0, help="underlap, fraction of the span")
    g.add_argument("--noise", type=float, default=0.0, help="noise standard deviation, kg/s")
    g.add_argument("--seed", type=int, default=0, help="noise seed")
    g.add_argument("--u", metavar="LIST",
                   help="commands, V: a,b,c or START:STOP:NUM (default: 21, denser at the centre)")
    g.add_argument("--p", metavar="LIST",
                   help="pressures, Pa abs: a,b,c or START:STOP:NUM (default: 15 from "
                        "atmosphere to supply)")
    g.add_argument("--n-u", type=int, default=21, help="number of default commands")
    g.add_argument("--n-p", type=int, default=15, help="number of default pressures")
    g.set_defaults(func=_cmd_valve_table)
