"""Identification: a model from data, each with the validation that says whether to trust it.

Modules: :mod:`.arx` (least squares ARX, order selection, validation),
:mod:`.residuals` (whiteness and input-independence tests of residuals),
:mod:`.excitation` (PRBS / APRBS), :mod:`.rls` (recursive least squares with
forgetting), :mod:`.valve` (paper 003's valve characteristic approximations), :mod:`.grey_box` (physical parameters of the
CasADi plant from recordings).

The ``workbench identify`` command line is :mod:`workbench.cli.identify`.
"""

from .arx import ArxModel, ArxValidation, OrderSelection, fit_arx, select_order
from .arx import validate as validate_arx
from .excitation import aprbs, as_reference, prbs
from .grey_box import GreyBoxResult, estimate
from .rls import ForgettingChoice, RlsResult, choose_forgetting, rls
from .valve import (AffineTableFit, PolynomialValveFit, ValveTable, fit_affine,
                    fit_polynomial, generate_valve_table, load_valve_table, select_degrees)

__all__ = [
    "ArxModel", "ArxValidation", "OrderSelection", "fit_arx", "select_order", "validate_arx",
    "prbs", "aprbs", "as_reference",
    "RlsResult", "ForgettingChoice", "rls", "choose_forgetting",
    "ValveTable", "PolynomialValveFit", "AffineTableFit", "load_valve_table",
    "generate_valve_table", "fit_polynomial", "fit_affine", "select_degrees",
    "GreyBoxResult", "estimate",
]
