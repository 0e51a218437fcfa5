"""Identification: a model from data, each with the validation that says whether to trust it.

Modules: :mod:`.arx` (least squares ARX, order selection, validation),
:mod:`.residuals` (whiteness and input-independence tests of residuals),
:mod:`.excitation` (PRBS / APRBS), :mod:`.rls` (recursive least squares with
forgetting), :mod:`.valve` (paper 003's valve characteristic approximations), :mod:`.grey_box` (physical parameters of the
CasADi plant from recordings).

The ``workbench identify`` command line is :mod:`workbench.cli.identify`.
"""

from __future__ import annotations

import importlib

#: Public names, imported on first use from their sub-package (the command line's
#: ``--help`` must not load SciPy and CasADi): name -> (sub-module, attribute).
_NAMES = {
    **{n: ("arx", n) for n in ("ArxModel", "ArxValidation", "OrderSelection", "fit_arx",
                               "select_order")},
    "validate_arx": ("arx", "validate"),
    **{n: ("excitation", n) for n in ("aprbs", "as_reference", "prbs")},
    **{n: ("grey_box", n) for n in ("GreyBoxResult", "estimate")},
    **{n: ("rls", n) for n in ("ForgettingChoice", "RlsResult", "choose_forgetting", "rls")},
    **{n: ("valve", n) for n in ("AffineTableFit", "PolynomialValveFit", "ValveTable",
                                 "fit_affine", "fit_polynomial", "generate_valve_table",
                                 "load_valve_table", "select_degrees")},
}

__all__ = [
    "ArxModel", "ArxValidation", "OrderSelection", "fit_arx", "select_order", "validate_arx",
    "prbs", "aprbs", "as_reference",
    "RlsResult", "ForgettingChoice", "rls", "choose_forgetting",
    "ValveTable", "PolynomialValveFit", "AffineTableFit", "load_valve_table",
    "generate_valve_table", "fit_polynomial", "fit_affine", "select_degrees",
    "GreyBoxResult", "estimate",
]


def __getattr__(name: str):
    if name in _NAMES:
        module, attr = _NAMES[name]
        value = getattr(importlib.import_module(f".{module}", __name__), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
