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
>>> from workbench.identify import valve as vf
>>> table = vf.load_valve_table("tests/data/valve/rig25_table.csv")
>>> fit1 = vf.fit_polynomial(table, 5, 10)
>>> fit2 = vf.fit_affine(table)
>>> round(fit1.quality.r, 4), round(fit2.quality.max_error_g_s, 2)
(0.9999, 1.47)
>>> base = PlantParams.from_toml("designs/plants/rig25_mpye.toml")
>>> plant = Plant(base.replace(**fit2.plant_values()))
>>> gains = vf.pressure_gain(fit2.flow, [4.9, 5.0, 5.1], table.pressure_range)

Modules: :mod:`.table` (the table format), :mod:`.generator` (tables from a plant's
valve), :mod:`.polynomial` (approximation I), :mod:`.affine` (approximation II),
:mod:`.quality` (R and errors), :mod:`.gain` (pressure gain characteristic),
:mod:`.tank` (tank step tests), :mod:`.report` (all at once, figures),
:mod:`.flow_stage` (a 3/2 flow stage like paper 003's, the known law of ``designs/paper_003.py``),
:mod:`.catalog` (datasheet nominal-flow curves), :mod:`.blocked` (blocked-port pressure gain
points as fit constraints), :mod:`.counts` (degrees from paper 003's
coefficient counts), :mod:`.plausibility` (flow limits before a fit is written to a plant).

Command line (:mod:`workbench.cli.identify`): ``workbench identify valve TABLE.csv
--approx both --out DIR`` and ``workbench identify valve-table PLANT.toml --out
TABLE.csv`` (the generator). ``--approximation II --coefficients 15`` picks paper 003's
structure by its coefficient count (:mod:`.counts`), ``--phi-from centre`` holds phi at the
centred column, ``--pressure-gain PG.csv`` makes both fits pass through measured
blocked-port points q(p_e, u) = 0 (:mod:`.blocked`), ``--catalog --critical-ratio B --supply-pressure P`` fits a datasheet
nominal-flow curve (:mod:`.catalog`), and ``--plant-toml`` is refused when the fitted
law's flows exceed the ISO 6358 choked flow of the base plant's conductance
(:mod:`.plausibility`). Fits refuse what the data cannot determine (a polynomial degree
beyond the distinct pressures, a flow direction without data).
"""

from __future__ import annotations

from .affine import PRESSURE_SCALE, AffineTableFit, fit_affine
from .blocked import check_pressure_gain_points, load_pressure_gain
from .catalog import CatalogCurve, catalog_table, load_catalog_curve
from .counts import affine_count, affine_structure, polynomial_degrees
from .flow_stage import FlowStage, chebyshev_pressures
from .gain import (PressureGain, TableLaw, compare_pressure_gain, pressure_gain,
                   pressure_gain_from_data)
from .generator import centre_dense_commands, generate_valve_table, valve_flow_law
from .lstsq import serial_blas
from .plausibility import flow_limit_problems
from .polynomial import DegreeSelection, PolynomialValveFit, fit_polynomial, select_degrees
from .quality import FitQuality
from .report import ValveFitReport, analyse, valve_curves, write_figures
from .table import COLUMNS, G_PER_KG, MIN_POINTS, ValveTable, load_valve_table
from .tank import TankStep, TankStepTests, tank_steps

__all__ = [
    "COLUMNS", "MIN_POINTS", "G_PER_KG", "PRESSURE_SCALE",
    "ValveTable", "load_valve_table",
    "valve_flow_law", "centre_dense_commands", "generate_valve_table",
    "FlowStage", "chebyshev_pressures", "CatalogCurve", "load_catalog_curve", "catalog_table",
    "affine_count", "affine_structure", "polynomial_degrees", "flow_limit_problems",
    "FitQuality", "PolynomialValveFit", "fit_polynomial", "DegreeSelection", "select_degrees",
    "AffineTableFit", "fit_affine", "TableLaw",
    "check_pressure_gain_points", "load_pressure_gain",
    "PressureGain", "pressure_gain", "pressure_gain_from_data", "compare_pressure_gain",
    "TankStep", "TankStepTests", "tank_steps",
    "ValveFitReport", "analyse", "valve_curves", "write_figures", "serial_blas",
]
