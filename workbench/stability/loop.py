"""The controller of a stability map: the plant file's ``[controller]``, overridden by the caller.

:func:`map_controller` gives the ``controller`` dict that
:func:`workbench.stability.maps.stability_map` takes (``workbench map`` uses it).
"""

from __future__ import annotations

from typing import Collection

from ..errors import InputError

__all__ = ["map_controller", "DEFAULT_SWEPT_KP", "DEFAULT_SWEPT_SAMPLE_TIME"]

#: V/m: placeholder gain when an axis sweeps kp or k0 (the axis sets the gain at every point).
DEFAULT_SWEPT_KP = 1.0
#: s: placeholder sample time when an axis sweeps it.
DEFAULT_SWEPT_SAMPLE_TIME = 0.01


def map_controller(plant, swept: Collection[str] = (), *, kp: float | None = None,
                   kd: float | None = None, ki: float | None = None,
                   sample_time: float | None = None) -> dict:
    """Controller gains and period for a stability map.

    Starts from the plant file's ``[controller]`` (or kp and the sample time unset,
    kd = ki = 0 without one); every gain given here replaces the file's.

    Parameters
    ----------
    plant : workbench.Plant
        The plant (its ``[controller]``, when it has one).
    swept : collection of str
        Names of the swept axes (``kp``, ``k0``, ``sample_time``, plant parameters...):
        a swept gain or sample time needs no value, a placeholder is used.
    kp : float, optional
        Proportional gain, V/m.
    kd : float, optional
        Derivative gain, V s/m.
    ki : float, optional
        Integral gain, V/(m s).
    sample_time : float, optional
        Sample time, s.

    Returns
    -------
    dict
        ``kp`` (V/m), ``kd`` (V s/m), ``ki`` (V/(m s)), ``sample_time`` (s).

    Raises
    ------
    InputError
        No sample time or no gain, neither in the plant file, given nor swept.
    """
    if plant.params.has_controller:
        from ..controllers import from_plant
        ctrl = from_plant(plant)
        out = {"kp": ctrl.kp, "kd": ctrl.kd, "ki": ctrl.ki, "sample_time": ctrl.sample_time}
    else:
        out = {"kp": None, "kd": 0.0, "ki": 0.0, "sample_time": None}
    for key, val in (("kp", kp), ("kd", kd), ("ki", ki), ("sample_time", sample_time)):
        if val is not None:
            out[key] = val
    swept = set(swept)
    if out["sample_time"] is None and "sample_time" not in swept:
        raise InputError("no sample time: the plant file has no [controller]; give --sample-time")
    if out["kp"] is None and not swept & {"kp", "k0"}:
        raise InputError("no gain: the plant file has no [controller]; give --kp or sweep kp/k0")
    out["kp"] = out["kp"] or DEFAULT_SWEPT_KP
    out["sample_time"] = out["sample_time"] or DEFAULT_SWEPT_SAMPLE_TIME
    return out
