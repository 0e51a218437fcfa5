"""Fit quality of a valve law on a table (paper 003's R and errors in g/s)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import InputError
from .table import G_PER_KG, ValveTable

__all__ = ["FitQuality"]


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

    def to_dict(self) -> dict[str, Any]:
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
    if not np.ptp(table.q_m) > 0:
        raise InputError(f"every flow of the table is {table.q_m[0]:g} kg/s: there is no "
                         "characteristic to fit (check the q_m column and its unit, kg/s)",
                         source=table.source, location="column 'q_m'")
    c = table.command_center if center is None else float(center)
    s = table.command_span if span is None else float(span)
    if not s > 0:
        raise InputError(f"expected a positive command span (V), got {s!r}", source=table.source)
    return c, s
