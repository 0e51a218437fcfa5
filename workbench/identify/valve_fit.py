"""Former home of paper 003's valve fits, now :mod:`workbench.identify.valve` (a re-export).

Kept so that ``from workbench.identify import valve_fit`` and ``valve_fit.NAME`` keep
working; new code imports from :mod:`workbench.identify.valve`.
"""

from .valve import (COLUMNS, G_PER_KG, MIN_POINTS, PRESSURE_SCALE, AffineTableFit,
                    DegreeSelection, FitQuality, PolynomialValveFit, PressureGain, TableLaw,
                    TankStep, TankStepTests, ValveFitReport, ValveTable, analyse,
                    centre_dense_commands, compare_pressure_gain, fit_affine, fit_polynomial,
                    generate_valve_table, load_valve_table, pressure_gain,
                    pressure_gain_from_data, select_degrees, serial_blas, tank_steps,
                    valve_curves, valve_flow_law, write_figures)

__all__ = [
    "COLUMNS", "MIN_POINTS", "G_PER_KG", "PRESSURE_SCALE",
    "ValveTable", "load_valve_table",
    "valve_flow_law", "centre_dense_commands", "generate_valve_table",
    "FitQuality", "PolynomialValveFit", "fit_polynomial", "DegreeSelection", "select_degrees",
    "AffineTableFit", "fit_affine", "TableLaw",
    "PressureGain", "pressure_gain", "pressure_gain_from_data", "compare_pressure_gain",
    "TankStep", "TankStepTests", "tank_steps",
    "ValveFitReport", "analyse", "valve_curves", "write_figures", "serial_blas",
]
