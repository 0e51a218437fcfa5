"""Piston: pneumatic force and hard end stops."""

from __future__ import annotations

from . import ops

__all__ = ["pneumatic_force", "end_stop_force", "STOP_FREQUENCY", "STOP_DAMPING"]

#: Hz: natural frequency of the payload on the end-stop contact stiffness.
STOP_FREQUENCY = 300.0
#: -: damping ratio of the end-stop contact.
STOP_DAMPING = 0.7


def pneumatic_force(p_a, p_b, area_a, area_b, p_atm):
    """Net pneumatic force along +x: p_a A_a - p_b A_b - p_atm (A_a - A_b), N."""
    return p_a * area_a - p_b * area_b - p_atm * (area_a - area_b)


def end_stop_force(x, v, stroke, mass, frequency=STOP_FREQUENCY, damping=STOP_DAMPING):
    """Contact force (N) of the hard stops at x = 0 and x = stroke.

    A stiff spring-damper acting only while the piston is past a stop, stiffness
    m (2 pi f)^2 so that the contact is as fast as ``frequency`` whatever the
    payload; the force only pushes the piston back, never pulls it in.

    Parameters
    ----------
    x, v : piston position (m) and velocity (m/s).
    stroke : m. mass : kg (piston + payload).
    frequency : contact natural frequency, Hz. damping : contact damping ratio, -.
    """
    w = 2.0 * ops.PI * frequency
    k = mass * w * w
    c = 2.0 * damping * mass * w
    low = ops.where(x < 0, ops.fmax(-k * x - c * v, 0.0), 0.0)
    high = ops.where(x > stroke, ops.fmin(-k * (x - stroke) - c * v, 0.0), 0.0)
    return low + high
