"""Excitation signals for identification experiments: PRBS and APRBS.

Both generators return a plain array of ``n`` samples (one per sample instant) between
``low`` and ``high`` (the admissible range, in the unit of the signal: V for a valve
command, m for a position reference) that changes level at most every ``hold_min``
samples. They are deterministic: the same ``seed`` gives the same signal.

* :func:`prbs`: pseudo-random binary sequence, a maximum-length shift-register
  sequence (m-sequence) clocked every ``hold_min`` samples. Two levels only: good for
  linear models around one operating point, blind to nonlinearity.
* :func:`aprbs`: amplitude-modulated PRBS, random levels over the whole range held
  for random durations of ``hold_min`` to ``hold_max`` samples. Covers the range, so
  it also shows nonlinearity; paper 000 identified its rig with an APRBS 0-10 V.

:func:`as_reference` turns either into a :class:`workbench.simulate.Reference`
(held between samples) for a closed-loop experiment on the plant model.

Examples
--------
>>> from workbench.identify.excitation import prbs, aprbs
>>> u = aprbs(400, hold_min=5, low=0.0, high=10.0, seed=1)
>>> u.shape, bool(u.min() >= 0.0), bool(u.max() <= 10.0)
((400,), True, True)
>>> sorted(set(prbs(12, hold_min=3, low=-1.0, high=1.0, seed=0).tolist()))
[-1.0, 1.0]
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["prbs", "aprbs", "as_reference", "PRBS_TAPS"]

#: Feedback taps (1-based register stages) of a maximum-length Fibonacci shift
#: register of each length m = 2..32 (Xilinx XAPP052 table); period 2**m - 1.
PRBS_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4),
    9: (9, 5), 10: (10, 7), 11: (11, 9), 12: (12, 6, 4, 1), 13: (13, 4, 3, 1),
    14: (14, 5, 3, 1), 15: (15, 14), 16: (16, 15, 13, 4), 17: (17, 14), 18: (18, 11),
    19: (19, 6, 2, 1), 20: (20, 17), 21: (21, 19), 22: (22, 21), 23: (23, 18),
    24: (24, 23, 22, 17), 25: (25, 22), 26: (26, 6, 2, 1), 27: (27, 5, 2, 1),
    28: (28, 25), 29: (29, 27), 30: (30, 6, 4, 1), 31: (31, 28), 32: (32, 22, 2, 1),
}


def prbs(n: int, hold_min: int, low: float, high: float, seed: int | None = 0,
         register_length: int | None = None) -> np.ndarray:
    """Pseudo-random binary sequence between two levels with a minimum hold time.

    A maximum-length shift-register sequence (period ``2**m - 1`` bits) whose bits are
    each held for ``hold_min`` samples, so the signal stays at one level for
    ``hold_min`` to ``m * hold_min`` samples. Over a whole period its spectrum is
    flat up to about ``1 / (2.3 hold_min)`` of the sample rate.

    Parameters
    ----------
    n : int
        Number of samples, >= 1.
    hold_min : int
        Samples each bit is held (the clock period of the register), >= 1. Choose it
        near the fastest time constant of interest divided by the sample time.
    low, high : float
        The two levels, ``low < high``, in the unit of the signal (V, m, ...).
    seed : int or None, optional
        Chooses the register's (nonzero) initial state, i.e. where in the period the
        sequence starts. Same seed, same signal. ``None`` gives the all-ones state.
    register_length : int, optional
        Register length ``m`` (2..32). By default the smallest ``m`` whose period
        ``2**m - 1`` covers the ``ceil(n / hold_min)`` bits needed (at least 2), so
        the signal holds at most one period.

    Returns
    -------
    numpy.ndarray, shape (n,)
        Values ``low`` or ``high``.

    Raises
    ------
    InputError
        For a non-integer or too small ``n`` or ``hold_min``, levels that are not
        finite or not ``low < high``, or a ``register_length`` outside 2..32.

    Examples
    --------
    >>> prbs(10, hold_min=2, low=0.0, high=10.0, seed=3)
    array([ 0.,  0., 10., 10., 10., 10., 10., 10.,  0.,  0.])
    """
    n = _count("n", n, 1)
    hold_min = _count("hold_min", hold_min, 1)
    low, high = _levels(low, high)
    bits_needed = -(-n // hold_min)
    if register_length is None:
        m = max(2, math.ceil(math.log2(bits_needed + 1)))
        if m > 32:
            raise InputError(f"prbs: {bits_needed} bits need a register longer than 32 "
                             "stages; use a larger hold_min")
    else:
        m = _count("register_length", register_length, 2)
        if m > 32:
            raise InputError(f"prbs: register_length must be 2..32, got {m}")
    taps = PRBS_TAPS[m]
    if seed is None:
        state = (1 << m) - 1
    else:
        state = int(np.random.default_rng(seed).integers(1, 1 << m))
    bits = np.empty(bits_needed, dtype=bool)
    shifts = [t - 1 for t in taps]
    for i in range(bits_needed):
        bits[i] = state & 1
        fb = 0
        for s in shifts:
            fb ^= (state >> (m - 1 - s)) & 1
        state = (state >> 1) | (fb << (m - 1))
    levels = np.where(bits, high, low).astype(float)
    return np.repeat(levels, hold_min)[:n]


def aprbs(n: int, hold_min: int, low: float, high: float, seed: int | None = 0,
          hold_max: int | None = None) -> np.ndarray:
    """Amplitude-modulated PRBS: random levels over a range, held for random times.

    Each level is drawn uniformly from ``[low, high]`` and held for a whole number of
    samples drawn uniformly from ``hold_min .. hold_max``; the last level is cut at
    ``n`` samples (so only it may be held for less than ``hold_min``).

    Parameters
    ----------
    n : int
        Number of samples, >= 1.
    hold_min : int
        Shortest hold, samples, >= 1: about the fastest time constant of interest
        divided by the sample time.
    low, high : float
        Admissible range, ``low < high``, in the unit of the signal (V, m, ...).
    seed : int or None, optional
        Seed of :func:`numpy.random.default_rng`; same seed, same signal.
    hold_max : int, optional
        Longest hold, samples, >= ``hold_min``. Default ``4 * hold_min``: long enough
        for the slow dynamics to show, short enough for many levels in few samples.
        Set it near the settling time divided by the sample time.

    Returns
    -------
    numpy.ndarray, shape (n,)
        Values in ``[low, high]``, in the unit of ``low`` and ``high``.

    Raises
    ------
    InputError
        For a non-integer or too small ``n``, ``hold_min`` or ``hold_max``, or levels
        that are not finite or not ``low < high``.

    Examples
    --------
    >>> u = aprbs(1000, hold_min=10, low=0.0, high=10.0, seed=7, hold_max=30)
    >>> runs = np.diff(np.flatnonzero(np.diff(u)))
    >>> bool(runs.min() >= 10 and runs.max() <= 30)
    True
    """
    n = _count("n", n, 1)
    hold_min = _count("hold_min", hold_min, 1)
    hold_max = 4 * hold_min if hold_max is None else _count("hold_max", hold_max, 1)
    if hold_max < hold_min:
        raise InputError(f"aprbs: hold_max ({hold_max} samples) must be >= hold_min "
                         f"({hold_min} samples)")
    low, high = _levels(low, high)
    rng = np.random.default_rng(seed)
    n_levels = n // hold_min + 1           # enough even if every hold is the shortest
    holds = rng.integers(hold_min, hold_max + 1, size=n_levels)
    levels = rng.uniform(low, high, size=n_levels)
    return np.repeat(levels, holds)[:n].astype(float)


def as_reference(signal: Any, sample_time: float, t0: float = 0.0):
    """A sampled signal as a held :class:`workbench.simulate.Reference` r(t).

    Parameters
    ----------
    signal : array_like, shape (n,)
        One value per sample (e.g. from :func:`aprbs`), m for a position reference.
    sample_time : float
        Time between samples, s, > 0.
    t0 : float, optional
        Time of the first sample, s.

    Returns
    -------
    workbench.simulate.Reference
        Holds ``signal[k]`` on ``[t0 + k T, t0 + (k+1) T)`` and the last value after.

    Raises
    ------
    InputError
        For an empty or non-finite signal or a sample time that is not positive.

    Examples
    --------
    >>> ref = as_reference(aprbs(200, 10, 0.1, 0.4, seed=2), sample_time=0.01)
    >>> ref.duration
    2.0
    """
    from ..simulate import Reference

    values = np.asarray(signal, dtype=float).ravel()
    if values.size == 0:
        raise InputError("as_reference: the signal is empty")
    bad = ~np.isfinite(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"as_reference: the signal has {values[i]} at index {i}")
    if not (isinstance(sample_time, numbers.Real) and math.isfinite(sample_time)
            and sample_time > 0):
        raise InputError(f"as_reference: sample_time must be a positive number of "
                         f"seconds, got {sample_time!r}")
    if not (isinstance(t0, numbers.Real) and math.isfinite(t0)):
        raise InputError(f"as_reference: t0 must be a finite time in s, got {t0!r}")
    times = float(t0) + float(sample_time) * np.arange(values.size + 1)
    return Reference(times=times, values=np.append(values, values[-1]), hold=True)


# --------------------------------------------------------------------------------------
def _count(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, numbers.Real) and float(value).is_integer():
            value = int(value)
        else:
            raise InputError(f"{name} must be a whole number of samples, got {value!r}")
    value = int(value)
    if value < minimum:
        raise InputError(f"{name} must be >= {minimum}, got {value}")
    return value


def _levels(low: Any, high: Any) -> tuple[float, float]:
    try:
        lo, hi = float(low), float(high)
    except (TypeError, ValueError):
        raise InputError(f"low and high must be numbers, got {low!r} and {high!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise InputError(f"low and high must be finite, got {lo} and {hi}")
    if not lo < hi:
        raise InputError(f"the range must have low < high, got low = {lo}, high = {hi}")
    return lo, hi
