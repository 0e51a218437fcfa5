"""Identification: a model from data, each with the validation that says whether to trust it.

Modules: :mod:`.arx` (least squares ARX, order selection, residual analysis),
:mod:`.excitation` (PRBS / APRBS), :mod:`.rls` (recursive least squares with
forgetting), :mod:`.valve_fit` (paper 003's valve characteristic approximations),
:mod:`.grey_box` (physical parameters of the CasADi plant from recordings).

Each module that has a command line part exposes ``add_cli(subparsers)``, which adds
its ``workbench identify NAME`` sub-command.
"""
