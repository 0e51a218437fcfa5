"""Piston friction: viscous, Coulomb, static (break-away) and Stribeck.

Two forms. :func:`stick_slip_acceleration` is the simulation form (Karnopp): a
piston inside the stick band whose driving force is below break-away is held (its
velocity decays to exactly zero and stays there), so it does not creep.
:func:`smooth_friction` is a differentiable form for optimisation.
"""

from __future__ import annotations

from . import ops

__all__ = ["stribeck_level", "smooth_friction", "stick_slip_acceleration",
           "STICK_VELOCITY", "STICK_TIME_CONSTANT"]

#: m/s: below this speed the piston may stick (Karnopp band).
STICK_VELOCITY = 1e-4
#: s: time constant with which a sticking piston's residual speed is removed.
STICK_TIME_CONSTANT = 1e-3


def stribeck_level(v, coulomb, static, stribeck_velocity):
    """Dry friction magnitude at speed v: Fc + (Fs - Fc) exp(-(v/vs)^2), N.

    Parameters
    ----------
    v : velocity, m/s (float, ndarray or casadi expression).
    coulomb, static : Coulomb and static (break-away) friction levels, N.
    stribeck_velocity : Stribeck velocity vs, m/s.
    """
    return coulomb + (static - coulomb) * ops.exp(-(v / stribeck_velocity) ** 2)


def smooth_friction(v, coulomb, static, stribeck_velocity, viscous, v_smooth=1e-3):
    """Differentiable friction force (N, opposes v): Stribeck level * tanh(v/v_smooth) + beta v.

    ``v`` in m/s, ``viscous`` in N s/m, ``v_smooth`` (m/s) the width of the tanh
    sign; the other arguments as in :func:`stribeck_level`.
    """
    return (stribeck_level(v, coulomb, static, stribeck_velocity) * ops.tanh(v / v_smooth)
            + viscous * v)


def stick_slip_acceleration(v, drive_force, mass, viscous, coulomb, static,
                            stribeck_velocity, v_stick=STICK_VELOCITY,
                            tau=STICK_TIME_CONSTANT):
    """Piston acceleration (m/s^2) with Karnopp stick-slip friction.

    Parameters
    ----------
    v : velocity, m/s.
    drive_force : every force on the piston except friction, N (positive along +x).
    mass : kg. viscous : N s/m. coulomb, static : N. stribeck_velocity : m/s.

    In the band |v| < v_stick: if |F| <= F_static the piston sticks (a = -v/tau,
    so a piston at rest stays exactly at rest); otherwise it breaks away against
    the static level. Outside the band friction is the Stribeck curve plus viscous.
    """
    sgn_v = ops.sign(v)
    slip = (drive_force - sgn_v * stribeck_level(v, coulomb, static, stribeck_velocity)
            - viscous * v) / mass
    breakaway = (drive_force - ops.sign(drive_force) * static) / mass
    # a residual speed below 1e-12 m/s is no longer decayed: decaying on through
    # 1e-150 m/s made CVODES fail (NaN) with a closed valve (issue 14)
    stick = ops.where(ops.fabs(v) < 1e-12, 0.0 * v, -v / tau)
    in_band = ops.fabs(v) < v_stick
    held = ops.fabs(drive_force) <= static
    return ops.where(in_band, ops.where(held, stick, breakaway), slip)
