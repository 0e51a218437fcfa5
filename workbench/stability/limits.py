"""Gain limits of the sampled position loop: Hurwitz, PCT and exact sampled-data (paper 000).

The position loop of paper 000 is the third-order process under unity feedback with a
P controller,

    L(s) = K0 / ( s (s^2/w0^2 + 2 zeta s/w0 + 1) ),    K0 = kp Kv   (1/s),

sampled every T seconds with a zero-order hold. Four upper limits on K0 are compared:

* continuous (Hurwitz, no sampling):      K0 < 2 zeta w0
* PCT (sampler + ZOH as a lag T/2):       K0 < 2 zeta / Ts,   Ts = T/2 + 1/w0
* exact sampled data (ZOH at T):          smallest K0 > 0 putting a pole of
                                           1 + K0 G(z) = 0 on the unit circle
* the same with one sample of computation delay, G(z)/z.

The sampled-data limits are computed from the unit-circle crossings of the root locus
(frequencies where G(e^{j theta}) is real and negative), not by bisection, so they are
exact to rounding; :func:`sampled_gain_limit` works for any discrete SISO loop, e.g. the
ZOH discretisation of the full exact tangent model of a plant.

Examples
--------
Table II of paper 000 (w0 = 32.97 rad/s, zeta = 1.1, T = 10 ms, K0 = 7 1/s):

>>> from workbench import stability
>>> lim = stability.gain_limits(w0=32.97, zeta=1.1, sample_time=0.01, k0=7.0)
>>> round(lim.continuous, 2), round(lim.pct, 2), round(lim.sampled, 2)
(72.53, 62.27, 53.84)
>>> round(lim.sampled_delay, 2), round(lim.gain_margin, 2)
(36.15, 7.69)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, optimize

from ..errors import InputError, WorkbenchError, positive

__all__ = [
    "GainLimits", "gain_limits", "limits_from_plant", "sampled_gain_limit",
    "unit_circle_crossings", "zoh_position_loop", "pct_time_constant",
    "continuous_limit", "pct_limit", "closed_loop_poles", "pct_closed_loop_poles",
]

#: Points of the uniform grid on theta in [0, pi] searched for sign changes of
#: Im(N conj D); the unit-circle roots of the corresponding polynomial are added as
#: seeds, so close pairs of crossings that the grid straddles are not lost.
_GRID = 4097


# ---------------------------------------------------------------------- input checks


def _check_model(w0: Any, zeta: Any, sample_time: Any) -> tuple[float, float, float]:
    return (positive("w0", w0, "rad/s"), positive("zeta", zeta, "(damping ratio)"),
            positive("sample_time", sample_time, "s"))


def _check_k0(k0: Any) -> float | None:
    return None if k0 is None else positive("k0 (loop gain kp Kv)", k0, "1/s")


# ---------------------------------------------------------------------- analytic limits
def pct_time_constant(w0: float, T: float) -> float:
    """Lumped time constant of the PCT system, Ts = T/2 + 1/w0, s.

    Parameters
    ----------
    w0 : float
        Natural frequency of the process, rad/s.
    T : float
        Sample time, s (the sampler + ZOH is approximated by a lag of T/2).
    """
    w0 = positive("w0", w0, "rad/s")
    T = positive("sample_time", T, "s")
    return T / 2.0 + 1.0 / w0


def continuous_limit(w0: float, zeta: float) -> float:
    """Hurwitz limit of the unsampled loop, K0 < 2 zeta w0, 1/s."""
    return 2.0 * positive("zeta", zeta, "(damping ratio)") * positive("w0", w0, "rad/s")


def pct_limit(w0: float, zeta: float, sample_time: float) -> float:
    """Hurwitz limit of the PCT system, K0 < 2 zeta / Ts with Ts = T/2 + 1/w0, 1/s."""
    return 2.0 * positive("zeta", zeta, "(damping ratio)") / pct_time_constant(w0, sample_time)


# ---------------------------------------------------------------------- discrete loop
def zoh_position_loop(w0: float, zeta: float, sample_time: float,
                      delay: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation of 1 / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) at T.

    Parameters
    ----------
    w0 : float
        Natural frequency, rad/s.
    zeta : float
        Damping ratio, -.
    sample_time : float
        T, s.
    delay : bool
        Append one sample of computation delay (multiply by 1/z).

    Returns
    -------
    num, den : ndarray
        Coefficients of G(z) in descending powers of z (unit loop gain: the loop with
        gain K0 is K0 G(z)); ``den`` is monic.
    """
    w0, zeta, T = _check_model(w0, zeta, sample_time)
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -w0 ** 2, -2.0 * zeta * w0]])
    B = np.array([[0.0], [0.0], [w0 ** 2]])
    C = np.array([[1.0, 0.0, 0.0]])
    M = np.zeros((4, 4))
    M[:3, :3], M[:3, 3:] = A, B
    E = linalg.expm(M * T)                   # [[Ad, Bd], [0, 1]]: exact ZOH
    Ad, Bd = E[:3, :3], E[:3, 3:]
    # G(z) = C (zI - Ad)^-1 Bd = (det(zI - Ad + Bd C) - det(zI - Ad)) / det(zI - Ad)
    den = np.real(np.poly(Ad))
    num = np.real(np.poly(Ad - Bd @ C)) - den
    num = num[1:]                            # leading coefficients cancel (strictly proper)
    if delay:
        den = np.append(den, 0.0)
    return num, den


def _trim_leading_zeros(c: np.ndarray) -> np.ndarray:
    nz = np.flatnonzero(c)
    return c[nz[0]:] if nz.size else c[:0]


def _as_num_den(loop: Any, den: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """(num, den) of a discrete SISO loop given as arrays or a python-control system."""
    if den is not None:
        num = np.atleast_1d(np.asarray(loop, dtype=float)).ravel()
        dd = np.atleast_1d(np.asarray(den, dtype=float)).ravel()
    else:
        try:
            import control
        except ImportError:  # pragma: no cover - python-control is a dependency
            raise InputError("give num and den arrays") from None
        if not isinstance(loop, (control.TransferFunction, control.StateSpace)):
            raise InputError("give the loop as (num, den) coefficient arrays in descending "
                             "powers of z, or as a discrete python-control TransferFunction "
                             f"or StateSpace, not {type(loop).__name__}")
        if loop.ninputs != 1 or loop.noutputs != 1:
            raise InputError(f"the loop must be SISO, got {loop.ninputs} inputs and "
                             f"{loop.noutputs} outputs (select one output, e.g. "
                             "lin.to_control(outputs=['x']))")
        if not loop.isdtime(strict=True):
            raise InputError("the loop must be discrete-time (discretise it first, e.g. "
                             "control.c2d(sys, T, 'zoh'))")
        tf = control.ss2tf(loop) if isinstance(loop, control.StateSpace) else loop
        num = np.asarray(tf.num[0][0], dtype=float).ravel()
        dd = np.asarray(tf.den[0][0], dtype=float).ravel()
    num = _trim_leading_zeros(num)
    dd = _trim_leading_zeros(dd)
    if num.size == 0 or dd.size == 0:
        raise InputError("the loop's numerator and denominator must not be zero")
    if not (np.all(np.isfinite(num)) and np.all(np.isfinite(dd))):
        raise InputError("the loop's coefficients must be finite")
    if num.size > dd.size:
        raise InputError("the loop must be proper (numerator degree <= denominator degree)")
    return num, dd


def _closed_loop_roots(num: np.ndarray, den: np.ndarray, k: float) -> np.ndarray:
    """Roots of den(z) + k num(z)."""
    char = den.astype(float).copy()
    char[den.size - num.size:] += k * num
    return np.roots(char)


def unit_circle_crossings(loop: Any, den: Any = None) -> list[tuple[float, float]]:
    """Where the root locus of 1 + K G(z) = 0 meets the unit circle, for K > 0.

    A closed-loop pole is at z = e^{j theta} exactly when G(e^{j theta}) = -1/K, i.e.
    where G is real and negative on the unit circle. Those theta in [0, pi] are the
    zeros of Im(N(z) conj(D(z))) (Im G without its poles): found by sign changes on a
    grid (uniform, plus log-spaced near theta = 0 for stiff loops) refined with
    :func:`scipy.optimize.brentq`, by the unit-circle roots
    of the equivalent polynomial (for tangential or close pairs), and at theta = 0, pi.
    Open-loop poles on the unit circle (the integrator at z = 1) give K = 0 and are
    skipped.

    Parameters
    ----------
    loop : array_like or python-control system
        Numerator coefficients (descending powers of z) with ``den``, or a discrete SISO
        ``TransferFunction`` / ``StateSpace``.
    den : array_like, optional
        Denominator coefficients, descending powers of z.

    Returns
    -------
    list of (theta, K)
        Normalised frequency theta = omega T (rad, in [0, pi]) and gain K > 0 of each
        crossing, sorted by K.
    """
    num, dd = _as_num_den(loop, den)

    def n_d(theta):
        z = np.exp(1j * np.asarray(theta, dtype=float))
        return np.polyval(num, z), np.polyval(dd, z)

    def f(theta):
        n, d = n_d(theta)
        return np.imag(n * np.conj(d))

    thetas: list[float] = [0.0, math.pi]
    # uniform in theta, plus log-spaced towards 0 for stiff loops (w0 T << 1), whose
    # crossings lie below the uniform spacing
    grid = np.union1d(np.linspace(0.0, math.pi, _GRID),
                      np.logspace(-7.0, math.log10(4.0 * math.pi / _GRID), 400))
    fg = f(grid)
    thetas.extend(float(t) for t in grid[1:-1][fg[1:-1] == 0.0])
    for i in np.nonzero(fg[:-1] * fg[1:] < 0.0)[0]:
        thetas.append(optimize.brentq(lambda t: float(f(t)), grid[i], grid[i + 1],
                                      xtol=1e-15, rtol=4 * np.finfo(float).eps))
    # polynomial whose unit-circle roots are the zeros of f: on |z| = 1,
    # conj(D(z)) = D(1/z), so N(z) D(1/z) is real  <=>  P(z) = z^(n-m) P_rev(z)
    # with P = N * reverse(D) (degrees m = deg P - n, n = deg D).
    n = dd.size - 1
    P = np.convolve(num, dd[::-1])           # formal degree m + n, leading zeros kept
    m = P.size - 1 - n
    R = _trim_leading_zeros(np.concatenate([np.zeros(n - m), P])
                            - np.concatenate([P[::-1], np.zeros(n - m)]))
    if R.size > 1:
        for r in np.roots(R):
            th = float(np.angle(r))
            # only crossings the grid missed (tangential or closer than its spacing)
            if (abs(abs(r) - 1.0) < 1e-6 and 0.0 < th < math.pi
                    and min(abs(th - t) for t in thetas) > 1e-7):
                thetas.append(th)

    # open-loop poles on the unit circle (the integrator at z = 1): G is infinite
    # there, K = 0, not a crossing
    circle_poles = np.array([r for r in (np.roots(dd) if dd.size > 1 else [])
                             if abs(abs(r) - 1.0) < 1e-6])
    out: list[tuple[float, float]] = []
    for th in sorted(thetas):
        if circle_poles.size and np.min(np.abs(circle_poles - np.exp(1j * th))) < 1e-6:
            continue
        nz, dz = n_d(th)
        if dz == 0.0:
            continue
        g = complex(nz / dz)
        if g.real >= 0.0 or abs(g.imag) > 1e-6 * abs(g):
            continue
        k = -1.0 / g.real
        if any(abs(th - t0) < 1e-9 for t0, _ in out):
            continue                         # the same crossing found twice
        out.append((float(th), float(k)))
    return sorted(out, key=lambda c: c[1])


def _moving_roots(num: np.ndarray, dd: np.ndarray, k: float) -> np.ndarray:
    """Roots of den + k num that the gain moves, and raise on an unstable fixed one.

    Roots common to num and den (modes the feedback can neither see nor move, such as
    the pressure-level mode of a tangent model at rest) are no loop poles: they are
    the roots that stay put when k is halved. A fixed root outside the unit circle
    is still an error.
    """
    r1 = _closed_loop_roots(num, dd, k)
    r2 = _closed_loop_roots(num, dd, 0.5 * k)
    fixed = np.array([np.min(np.abs(r2 - r)) <= 1e-6 * max(1.0, abs(r)) for r in r1],
                     dtype=bool)
    if np.any(np.abs(r1[fixed]) > 1.0 + 1e-6):
        raise WorkbenchError(
            "the loop has an unstable mode that feedback cannot move (a pole cancelled "
            f"by a zero at |z| = {np.max(np.abs(r1[fixed])):.6g}): no gain stabilises it")
    return r1[~fixed]


def _sampled_limit_and_theta(num: np.ndarray, dd: np.ndarray) -> tuple[float, float]:
    crossings = unit_circle_crossings(num, dd)
    if crossings:
        theta, k = crossings[0]
        k_test = 0.5 * k
    else:
        theta, k, k_test = float("nan"), float("inf"), 1.0
    # no crossing in (0, k): stable at one gain in there means stable on all of it
    moving = _moving_roots(num, dd, k_test)
    if moving.size and np.max(np.abs(moving)) >= 1.0:
        raise WorkbenchError(
            "the closed loop is unstable already at small positive gains, so it has no "
            "upper gain limit: check the sign of the loop gain and look for unstable "
            "open-loop poles")
    return k, theta


def sampled_gain_limit(loop: Any, den: Any = None) -> float:
    """Exact sampled-data gain limit: smallest K > 0 with a pole of 1 + K G(z) on |z| = 1.

    Parameters
    ----------
    loop : array_like or python-control system
        Numerator coefficients of G(z) (descending powers of z) with ``den``, or a
        discrete SISO python-control ``TransferFunction`` / ``StateSpace``. Any plant,
        e.g. ``control.c2d(lin.to_control(outputs=['x']), T, 'zoh')`` for the exact
        tangent model; the gain K is then in the units of 1/G.
    den : array_like, optional
        Denominator coefficients of G(z), descending powers of z.

    Returns
    -------
    float
        The limit (``inf`` when no closed-loop pole ever reaches the unit circle). The
        closed loop is checked to be stable for 0 < K < limit. Modes that feedback
        cannot move (roots common to numerator and denominator, e.g. the marginal
        pressure-level mode of a tangent model at rest) are not loop poles and are
        left out of that check unless they are unstable.

    Raises
    ------
    InputError
        The loop is not a discrete proper SISO system.
    WorkbenchError
        The closed loop is unstable already for small K > 0 (no upper limit exists),
        or has an unstable mode that feedback cannot move.

    Notes
    -----
    The result is exact up to the accuracy of the polynomial coefficients. When the
    sample time is short against the loop's dynamics (w0 T below ~0.01 for the position
    loop), the open-loop poles crowd around z = 1 and the coefficients fix the limit
    only to ~1e-6 relative; any method working on G(z) as a ratio of polynomials
    shares this.

    Examples
    --------
    >>> from workbench.stability import sampled_gain_limit, zoh_position_loop
    >>> round(sampled_gain_limit(*zoh_position_loop(32.97, 1.1, 0.01)), 2)
    53.84
    """
    num, dd = _as_num_den(loop, den)
    return _sampled_limit_and_theta(num, dd)[0]


# ---------------------------------------------------------------------- poles
def closed_loop_poles(w0: float, zeta: float, sample_time: float, k0: float,
                      delay: bool = False) -> np.ndarray:
    """Poles (z-plane) of the sampled P loop K0 G(z) / (1 + K0 G(z)), ZOH at T.

    Parameters
    ----------
    w0 : rad/s. zeta : -. sample_time : T, s. k0 : loop gain kp Kv, 1/s.
    delay : bool
        With one sample of computation delay (one more pole).

    Returns
    -------
    ndarray of complex
        Poles sorted by decreasing modulus.
    """
    k0 = _check_k0(k0)
    if k0 is None:
        raise InputError("k0 (loop gain kp Kv, 1/s) is needed for the closed-loop poles")
    num, dd = zoh_position_loop(w0, zeta, sample_time, delay=delay)
    p = _closed_loop_roots(num, dd, k0)
    return p[np.argsort(-np.abs(p))]


def pct_closed_loop_poles(w0: float, zeta: float, sample_time: float, k0: float) -> np.ndarray:
    """Poles of the PCT closed loop K0 / (Ts^2 s^3 + 2 zeta Ts s^2 + s + K0), mapped z = e^{sT}.

    Parameters
    ----------
    w0 : rad/s. zeta : -. sample_time : T, s. k0 : loop gain, 1/s.

    Returns
    -------
    ndarray of complex
        z-plane poles sorted by decreasing modulus (paper 000: 0.928 +- 0.076j, 0.619
        for Table II and K0 = 7).
    """
    w0, zeta, T = _check_model(w0, zeta, sample_time)
    k0 = _check_k0(k0)
    if k0 is None:
        raise InputError("k0 (loop gain kp Kv, 1/s) is needed for the closed-loop poles")
    ts = pct_time_constant(w0, T)
    s = np.roots([ts ** 2, 2.0 * zeta * ts, 1.0, k0])
    z = np.exp(s * T)
    return z[np.argsort(-np.abs(z))]


# ---------------------------------------------------------------------- result
def _margins(num: np.ndarray, dd: np.ndarray, k0: float, T: float) -> tuple[float, float]:
    import control
    sys = control.tf(k0 * num, dd, T)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")      # python-control's 'poly' -> 'frd' fallback notes
        gm, pm, *_ = control.stability_margins(sys)
    gm = float(gm) if gm is not None and np.isfinite(gm) else float("inf")
    pm = float(pm) if pm is not None and np.isfinite(pm) else float("inf")
    return gm, pm


@dataclass(frozen=True)
class GainLimits:
    """Gain limits of the sampled P position loop and the margins at the given K0.

    All limits are on the loop gain K0 = kp Kv, 1/s; divide by Kv for the controller
    gain kp (V/m).

    Attributes
    ----------
    k0 : loop gain analysed, 1/s (None: limits only, no margins).
    w0 : natural frequency, rad/s. zeta : damping ratio, -. sample_time : T, s.
    continuous : Hurwitz limit without sampling, 2 zeta w0, 1/s.
    pct : Hurwitz limit of the PCT system, 2 zeta / Ts, 1/s.
    sampled : exact sampled-data limit (ZOH at T), 1/s.
    sampled_delay : the same with one sample of computation delay, 1/s.
    gain_margin : factor by which k0 may grow on the sampled loop (no delay), -
        (inf without phase crossover; None without k0).
    phase_margin_deg : phase margin of the sampled loop at k0, degrees
        (inf without gain crossover; None without k0).
    kv : velocity gain of the process, m/(V s), when known (None otherwise).
    sampled_frequency, sampled_delay_frequency : angular frequency of the oscillation
        at the sampled limits, rad/s.
    """

    k0: float | None = field(metadata={"unit": "1/s"})
    w0: float = field(metadata={"unit": "rad/s"})
    zeta: float = field(metadata={"unit": "-"})
    sample_time: float = field(metadata={"unit": "s"})
    continuous: float = field(metadata={"unit": "1/s"})
    pct: float = field(metadata={"unit": "1/s"})
    sampled: float = field(metadata={"unit": "1/s"})
    sampled_delay: float = field(metadata={"unit": "1/s"})
    gain_margin: float | None = field(default=None, metadata={"unit": "-"})
    phase_margin_deg: float | None = field(default=None, metadata={"unit": "deg"})
    kv: float | None = field(default=None, metadata={"unit": "m/(V s)"})
    sampled_frequency: float = field(default=float("nan"), metadata={"unit": "rad/s"})
    sampled_delay_frequency: float = field(default=float("nan"), metadata={"unit": "rad/s"})

    LIMIT_NAMES = ("continuous", "pct", "sampled", "sampled_delay")

    @property
    def pct_time_constant(self) -> float:
        """Ts = T/2 + 1/w0, s."""
        return self.sample_time / 2.0 + 1.0 / self.w0

    @property
    def kp(self) -> float | None:
        """Controller gain k0 / Kv, V/m (None when k0 or Kv is unknown)."""
        return None if self.k0 is None or self.kv is None else self.k0 / self.kv

    def kp_limit(self, name: str) -> float | None:
        """A limit as a controller gain, limit / Kv, V/m (None when Kv is unknown)."""
        if name not in self.LIMIT_NAMES:
            raise KeyError(f"unknown limit '{name}'; known: {', '.join(self.LIMIT_NAMES)}")
        return None if self.kv is None else getattr(self, name) / self.kv

    def to_dict(self) -> dict:
        """JSON-ready dict: k0, the four limits (1/s), the margins, then context.

        Infinite margins stay ``inf`` here; writers pass the dict through
        :func:`workbench.params.json_safe`, which makes them JSON null.
        """
        d = {"k0": self.k0, "continuous": self.continuous, "pct": self.pct,
             "sampled": self.sampled, "sampled_delay": self.sampled_delay,
             "gain_margin": self.gain_margin, "phase_margin_deg": self.phase_margin_deg,
             "w0": self.w0, "zeta": self.zeta, "sample_time": self.sample_time,
             "pct_time_constant_s": self.pct_time_constant,
             "sampled_frequency_rad_s": self.sampled_frequency,
             "sampled_delay_frequency_rad_s": self.sampled_delay_frequency,
             "kv": self.kv, "kp": self.kp}
        if self.kv is not None:
            d["kp_limits"] = {n: self.kp_limit(n) for n in self.LIMIT_NAMES}
        return d


def gain_limits(w0: float, zeta: float, sample_time: float, k0: float | None = None,
                kv: float | None = None) -> GainLimits:
    """Continuous, PCT and exact sampled-data gain limits of the P position loop.

    Parameters
    ----------
    w0 : float
        Natural frequency of the process, rad/s.
    zeta : float
        Damping ratio, - (> 0).
    sample_time : float
        T, s.
    k0 : float, optional
        Loop gain kp Kv, 1/s, at which the gain and phase margins are evaluated
        (sampled loop without extra delay). Without it the margins are None.
    kv : float, optional
        Velocity gain of the process, m/(V s), only carried along so that the limits
        can be read as controller gains (``kp_limit``).

    Returns
    -------
    GainLimits

    Raises
    ------
    InputError
        Non-positive or non-finite w0, zeta, sample_time, k0 or kv.

    Examples
    --------
    >>> lim = gain_limits(32.97, 1.1, 0.01, k0=7.0)
    >>> round(lim.pct, 2), round(lim.sampled_delay, 2)
    (62.27, 36.15)
    """
    w0, zeta, T = _check_model(w0, zeta, sample_time)
    k0 = _check_k0(k0)
    kv = None if kv is None else positive("kv", kv, "m/(V s)")
    num, dd = zoh_position_loop(w0, zeta, T)
    s_lim, s_th = _sampled_limit_and_theta(num, dd)
    d_lim, d_th = _sampled_limit_and_theta(num, np.append(dd, 0.0))
    gm = pm = None
    if k0 is not None:
        gm, pm = _margins(num, dd, k0, T)
    return GainLimits(k0=k0, w0=w0, zeta=zeta, sample_time=T,
                      continuous=2.0 * zeta * w0, pct=2.0 * zeta / pct_time_constant(w0, T),
                      sampled=s_lim, sampled_delay=d_lim, gain_margin=gm,
                      phase_margin_deg=pm, kv=kv, sampled_frequency=s_th / T,
                      sampled_delay_frequency=d_th / T)


def limits_from_plant(plant, x: float, sample_time: float | None = None,
                      kp: float | None = None, k0: float | None = None) -> GainLimits:
    """Gain limits at position ``x`` from the exact linearisation of a plant.

    The equilibrium at ``x`` is found, the exact tangent model taken and paper 000's
    reduced model Kv / (s (s^2/w0^2 + 2 zeta s/w0 + 1)) fitted to it
    (:func:`workbench.linearize.reduced_position_model`); K0 = kp Kv.

    Parameters
    ----------
    plant : workbench.Plant
    x : float
        Piston position, m.
    sample_time : float, optional
        T, s; default the plant file's ``controller.sample_time``.
    kp : float, optional
        Controller gain, V/m; default the plant file's ``controller.kp``.
    k0 : float, optional
        Loop gain, 1/s, instead of kp (give one of them at most).

    Returns
    -------
    GainLimits
        With ``kv`` set. When neither k0, kp nor a ``[controller]`` is available the
        limits are still computed and ``k0``, ``gain_margin``, ``phase_margin_deg``
        are None.

    Raises
    ------
    InputError
        No sample time (neither given nor in the plant file), both kp and k0 given,
        or a non-positive value.
    WorkbenchError
        No equilibrium at ``x``, or the command does not move the piston there.
    """
    from .. import linearize
    prm = plant.params
    has_ctrl = prm.has_controller
    if kp is not None and k0 is not None:
        raise InputError("give the controller gain kp (V/m) or the loop gain k0 (1/s), "
                         "not both")
    if sample_time is None:
        if not has_ctrl:
            raise InputError("the plant file has no [controller] section, so the sample "
                             "time must be given", source=prm.source)
        sample_time = prm["controller.sample_time"]
    op = linearize.operating_point(plant, x)
    lin = linearize.tangent(plant, op)
    red = linearize.reduced_position_model(lin)
    if red.kv <= 0.0:
        raise WorkbenchError(f"the velocity gain Kv at x = {x:g} m is {red.kv:g} m/(V s); "
                             "a P position loop needs Kv > 0")
    if k0 is None:
        if kp is None and has_ctrl:
            kp = prm["controller.kp"]
        if kp is not None:
            k0 = positive("kp", kp, "V/m") * red.kv
    return gain_limits(red.w0, red.zeta, sample_time, k0=k0, kv=red.kv)
