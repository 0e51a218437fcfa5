"""Feedback-linearising position controller on the third-order (x, v, F) model.

Control model (:class:`~workbench.controllers.force.DriveModel`): the piston
m x'' = F - beta x' - F_ext and the force rate, affine in the valve's command
characteristic G (input-affine law, paper 003)::

    dF/dt = f0(x, v, p_a, p_b) + g(x, p_a, p_b, sgn G) G

so the jerk m x''' = dF/dt - beta x'' is affine in G too. Choosing

    w = j_r + k2 (a_r - a) + k1 (v_r - v) + k0 (x_r - x) [+ ki integral(x_r - x)]
    G = (m w + beta a - f0) / g(sgn(m w + beta a - f0))

cancels the nonlinearity (a = (F - beta v - F_ext)/m from the measured pressures)
and leaves linear error dynamics with the poles placed from a bandwidth lambda:
(s + lambda)^(n-2) (s^2 + 2 zeta lambda s + lambda^2), n = 3 (or 4 with the integral),
all at -lambda for zeta = 1. The command follows from G through the valve
inversion (:mod:`.inversion`).

(x_r, v_r, a_r, j_r) come from a linear **reference model** driven by the
reference r: x_r/r = lambda_r^3 / ((s + lambda_r)(s^2 + 2 zeta_r lambda_r s + lambda_r^2)),
discretised exactly for a reference held over each sample. On the nominal plant
the loop follows it: the response to r *is* the reference model's, up to the
sampling (command held over T) and the model's mismatch. The integral term (on by
default) removes the steady-state error that unmodelled dry friction or a valve
deadband leave; with zero initial error it stays zero on the nominal plant, so the
response is the same.

Feasibility (:func:`feedback_linearizing` refuses, with the reason):

1. **Sampling**: every error pole must be slow against the sample rate,
   lambda <= pi / (10 T) -- a tenth of the Nyquist frequency, the pole moving at
   most 0.31 rad per sample. The command is held over T (a delay of about T/2,
   a phase lag of lambda T / 2 = 9 degrees at the bound); beyond it the
   continuous-time cancellation no longer describes the sampled loop. (On the
   25 mm rig at T = 10 ms the error against the reference model grows from 0.4 %
   of a step at 20 rad/s to about 1.5 % at 30 rad/s.)
2. **Valve flow**: along the reference model's response to the reference (the
   validation profile by default) the force rate m j_r + beta a_r, with the
   compression term f0 of the reference motion at the design pressures, must need
   at most ``margin`` (0.8) of the valve's full characteristic G at those
   pressures, leaving the rest for the feedback; and the force m a_r + beta v_r
   + F_ext at most ``margin`` of the pneumatic force range.

Examples
--------
>>> from workbench import Plant, simulate
>>> from workbench.controllers.feedback_linearizing import feedback_linearizing
>>> plant = Plant.from_toml("tests/data/plants/input_affine.toml")
>>> fl = feedback_linearizing(plant, bandwidth=20.0)
>>> run = simulate.closed_loop(plant, fl, simulate.steps([0.25, 0.35], 1.0))
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, is_dataclass, replace
from typing import Any

import numpy as np
from scipy.linalg import expm

from ..errors import InputError
from .force import DriveModel, _positive
from .inversion import ValveInversion

__all__ = ["breakaway", "fed_friction", "FeedbackLinearizing", "Feasibility", "feedback_linearizing", "feasibility",
           "error_gains", "reference_model", "SAMPLING_LIMIT", "FLOW_MARGIN"]

#: Largest bandwidth x sample time: pi/10, a tenth of the Nyquist frequency.
SAMPLING_LIMIT = math.pi / 10.0
#: Share of the valve's full characteristic (and of the force range) the reference may use.
FLOW_MARGIN = 0.8


def _poly_poles(bandwidth: float, damping: float, order: int) -> np.ndarray:
    """Coefficients (highest first) of (s + l)^(order - 2) (s^2 + 2 zeta l s + l^2)."""
    quad = np.array([1.0, 2.0 * damping * bandwidth, bandwidth ** 2])
    return np.polymul(np.poly(np.full(order - 2, -bandwidth)), quad)


def error_gains(bandwidth: float, damping: float = 1.0, integral: bool = True) -> dict[str, float]:
    """Gains of the linear error dynamics for a bandwidth (rad/s) and damping (-).

    Without integral: e''' + k2 e'' + k1 e' + k0 e = 0; with it, the same plus ki
    times the integral of e (a fourth pole). Returns {"k2": 1/s, "k1": 1/s^2,
    "k0": 1/s^3, "ki": 1/s^4}.
    """
    c = _poly_poles(bandwidth, damping, 4 if integral else 3)
    return {"k2": float(c[1]), "k1": float(c[2]), "k0": float(c[3]),
            "ki": float(c[4]) if integral else 0.0}


@dataclass(frozen=True)
class ReferenceModel:
    """Linear third-order reference model, exactly discretised for a held input.

    State (x_r, v_r, a_r): x_r''' = c0 (r - x_r) - c1 v_r - c2 a_r with
    s^3 + c2 s^2 + c1 s + c0 = (s + l)(s^2 + 2 zeta l s + l^2), unit DC gain.
    """

    bandwidth: float
    damping: float
    sample_time: float
    c: tuple[float, float, float] = field(init=False)
    ad: np.ndarray = field(init=False, repr=False)
    bd: np.ndarray = field(init=False, repr=False)
    ad_half: np.ndarray = field(init=False, repr=False)
    bd_half: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        coeffs = _poly_poles(self.bandwidth, self.damping, 3)
        c2, c1, c0 = float(coeffs[1]), float(coeffs[2]), float(coeffs[3])
        A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-c0, -c1, -c2]])
        B = np.array([0.0, 0.0, c0])
        M = np.zeros((4, 4))
        M[:3, :3] = A
        M[:3, 3] = B
        E = expm(M * self.sample_time)
        H = expm(M * 0.5 * self.sample_time)
        object.__setattr__(self, "c", (c0, c1, c2))
        object.__setattr__(self, "ad", E[:3, :3])
        object.__setattr__(self, "bd", E[:3, 3])
        object.__setattr__(self, "ad_half", H[:3, :3])
        object.__setattr__(self, "bd_half", H[:3, 3])

    def jerk(self, state: np.ndarray, r) -> Any:
        c0, c1, c2 = self.c
        return c0 * (r - state[0]) - c1 * state[1] - c2 * state[2]

    def step(self, state: np.ndarray, r: float) -> np.ndarray:
        """State one sample later, r held."""
        return self.ad @ state + self.bd * r

    def half_step(self, state: np.ndarray, r: float) -> np.ndarray:
        """State half a sample later, r held."""
        return self.ad_half @ state + self.bd_half * r

    def response(self, r_samples: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
        """States (N, 4) = (x_r, v_r, a_r, j_r) at the samples, input r_samples held.

        ``start`` is the state at the first sample (default at rest at r_samples[0]).
        """
        from scipy.signal import lfilter, ss2tf
        r = np.asarray(r_samples, dtype=float)
        s0 = np.array([r[0], 0.0, 0.0]) if start is None else np.asarray(start, dtype=float)
        # the free response from s0 plus the forced response, by filtering (fast):
        # rest at level s0[0] is an equilibrium, so only the deviation needs the filter
        u = r - s0[0]
        num, den = ss2tf(self.ad, self.bd.reshape(3, 1), np.eye(3), np.zeros((3, 1)))
        out = np.empty((len(r), 4))
        for i in range(3):
            out[:, i] = lfilter(num[i], den, u)
        out[:, 0] += s0[0]
        extra = s0 - np.array([s0[0], 0.0, 0.0])
        if np.any(extra != 0.0):
            s = extra.copy()
            for k in range(len(r)):
                out[k, :3] += s
                s = self.ad @ s
        c0, c1, c2 = self.c
        out[:, 3] = c0 * (r - out[:, 0]) - c1 * out[:, 1] - c2 * out[:, 2]
        return out


def reference_model(bandwidth: float, damping: float, sample_time: float) -> ReferenceModel:
    """The :class:`ReferenceModel` with poles -bandwidth (1 and a pair of damping ``damping``)."""
    return ReferenceModel(_positive("reference bandwidth", bandwidth, "rad/s"),
                          _positive("reference damping", damping, "-"),
                          _positive("sample_time", sample_time, "s"))


# ---------------------------------------------------------------------- feasibility
@dataclass(frozen=True)
class Feasibility:
    """Outcome of the bandwidth checks of :func:`feasibility` (SI).

    Attributes
    ----------
    bandwidth : rad/s checked. sample_time : s.
    sampling_limit : rad/s, SAMPLING_LIMIT / T.
    gamma_needed : largest |G| the reference needs (fraction of full opening's G).
    gamma_available : G of the fully open valve on that side within the command range.
    flow_needed, flow_available : kg/s into the filling chamber at that instant:
        needed, and what the fully open valve passes at the design pressures.
    force_needed : N, largest |m a_r + beta v_r + F_ext|. force_available : N.
    when : s, time of the largest flow demand. pressures : (p_a, p_b) Pa used.
    margin : share of G and force the reference may use.
    reasons : why the bandwidth is refused (empty: feasible).
    max_bandwidth : rad/s, largest feasible bandwidth found (by bisection), or None.
    """

    bandwidth: float
    sample_time: float
    sampling_limit: float
    gamma_needed: float
    gamma_available: float
    flow_needed: float
    flow_available: float
    force_needed: float
    force_available: float
    when: float
    pressures: tuple[float, float]
    margin: float
    reasons: tuple[str, ...] = ()
    max_bandwidth: float | None = None

    @property
    def feasible(self) -> bool:
        return not self.reasons

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field (SI; tuples as lists)."""
        return {k: list(v) if isinstance(v, tuple) else v
                for k, v in ((k, getattr(self, k)) for k in self.__dataclass_fields__)}


def _design_pressures(model: DriveModel, plant, x: float) -> tuple[float, float]:
    try:
        from ..linearize import operating_point
        op = operating_point(plant, x)
        return float(op.p_a), float(op.p_b)
    except Exception as exc:   # noqa: BLE001 - fall back to the valve's balance pressure
        from ..output import reraise_interrupt
        reraise_interrupt(exc)             # a Ctrl-C polled by CasADi is a stop
        p = model.balance_pressure()
        return p, p


def _demand(model: DriveModel, ref: ReferenceModel, r: np.ndarray, pressures):
    """Largest G and force a reference needs (vectorised over the samples)."""
    st = ref.response(r)
    x_r = np.clip(st[:, 0], 0.0, model.stroke)
    v_r, a_r, j_r = st[:, 1], st[:, 2], st[:, 3]
    rate = model.mass * j_r + model.viscous * a_r
    p_a, p_b = pressures
    G = model.gamma_for_force_rate(rate, x_r, v_r, p_a, p_b)
    force = model.mass * a_r + model.viscous * v_r + model.external_force
    return G, force, st


def _largest_feasible(ok, upper: float, reference_bandwidth: float | None) -> float | None:
    """Largest bandwidth (rad/s) in (0, upper] that ``ok(error_bw, reference_bw)`` accepts.

    Bisection to 0.1 % (plenty for a message); the reference model follows the error
    bandwidth unless ``reference_bandwidth`` is fixed. None when nothing above 0 passes.
    """
    def ref(bw: float) -> float:
        return bw if reference_bandwidth is None else reference_bandwidth

    lo, hi = 0.0, upper
    if ok(hi, ref(hi)):
        return hi
    while hi - lo > 1e-3 * hi:
        mid = 0.5 * (lo + hi)
        if ok(mid, ref(mid)):
            lo = mid
        else:
            hi = mid
    return lo if lo > 0 else None


def feasibility(model: DriveModel, bandwidth: float, sample_time: float, reference,
                pressures: tuple[float, float], damping: float = 1.0,
                reference_bandwidth: float | None = None, margin: float = FLOW_MARGIN,
                search: bool = True) -> Feasibility:
    """Check whether the valve and the sample rate can supply a bandwidth (module docstring).

    Parameters
    ----------
    model : DriveModel
    bandwidth : rad/s. sample_time : s.
    reference : a reference r(t) (m) with a ``duration`` (e.g. the validation profile),
        sampled at T for the check.
    pressures : (p_a, p_b), Pa, at which the valve's authority is judged.
    damping : of the error poles and the reference model, -.
    reference_bandwidth : rad/s (default ``bandwidth``).
    margin : share of the full valve characteristic and force range the reference may use.
    search : also find the largest feasible bandwidth (bisection) for the message.
    """
    lam = _positive("bandwidth", bandwidth, "rad/s")
    T = _positive("sample_time", sample_time, "s")
    lam_r = lam if reference_bandwidth is None else _positive("reference_bandwidth",
                                                             reference_bandwidth, "rad/s")
    duration = getattr(reference, "duration", None)
    if duration is None:
        raise InputError("the feasibility check needs a reference with a duration "
                         "(simulate.steps / simulate.profile / validate.validation_profile)")
    tk = T * np.arange(int(np.floor(duration / T + 1e-9)) + 1)
    r = np.asarray(reference(tk), dtype=float)
    limit = SAMPLING_LIMIT / T
    g_lo, g_hi = model.valve.gamma_range("a")
    f_lo, f_hi = model.force_range

    def demand(l_r):
        ref = ReferenceModel(l_r, damping, T)
        return _demand(model, ref, r, pressures)

    def ok(l_e, l_r) -> bool:
        if l_e > limit:
            return False
        G, force, _ = demand(l_r)
        return bool(np.all(np.isfinite(G)) and np.all(G <= margin * g_hi)
                    and np.all(G >= margin * g_lo) and np.all(force <= margin * f_hi)
                    and np.all(force >= margin * f_lo))

    G, force, st = demand(lam_r)
    ratio = np.where(G >= 0, G / g_hi, G / g_lo)
    ratio = np.where(np.isfinite(ratio), ratio, np.inf)
    k = int(np.argmax(ratio))
    p_a, p_b = pressures
    phi_a, in_a, out_a = model.valve.terms(p_a)
    if G[k] >= 0:
        q_need = float(phi_a + in_a * G[k]) if np.isfinite(G[k]) else math.inf
        q_avail = float(phi_a + in_a * g_hi)
    else:
        q_need = float(phi_a + out_a * G[k]) if np.isfinite(G[k]) else -math.inf
        q_avail = float(phi_a + out_a * g_lo)
    f_need = float(np.max(np.abs(force)))
    f_avail = min(abs(f_lo), abs(f_hi))
    reasons = []
    if lam > limit:
        reasons.append(f"bandwidth {lam:g} rad/s is beyond the sampling limit pi/(10 T) = "
                       f"{limit:.1f} rad/s at T = {T * 1e3:g} ms: the command is held over a "
                       f"period, and a pole moving more than {SAMPLING_LIMIT:.2f} rad per sample "
                       "is no longer what the continuous-time cancellation places")
    rate_k = float(model.mass * st[k, 3] + model.viscous * st[k, 2])
    if ratio[k] > margin:
        reasons.append(
            f"the valve cannot supply it at the current pressures (p_a = {p_a / 1e5:.2f} bar, "
            f"p_b = {p_b / 1e5:.2f} bar): at t = {tk[k]:.2f} s the reference model (bandwidth "
            f"{lam_r:g} rad/s) needs a force rate of {rate_k:.0f} N/s, "
            f"i.e. {abs(q_need) * 1e3:.1f} g/s {'into' if G[k] >= 0 else 'out of'} chamber a "
            f"({ratio[k]:.0%} of the fully open valve's {abs(q_avail) * 1e3:.1f} g/s; at most "
            f"{margin:.0%} is allowed, the rest is for the feedback)")
    if np.any(force > margin * f_hi) or np.any(force < margin * f_lo):
        reasons.append(f"the reference needs {float(force.min()):.0f} .. {float(force.max()):.0f} N "
                       f"of pneumatic force, beyond {margin:.0%} of the {f_lo:.0f} .. {f_hi:.0f} N "
                       "the chambers can give")
    best = None
    if reasons and search:
        best = _largest_feasible(ok, min(lam, limit),
                                 None if reference_bandwidth is None else lam_r)
    return Feasibility(bandwidth=lam, sample_time=T, sampling_limit=limit,
                       gamma_needed=float(abs(G[k])) if np.isfinite(G[k]) else math.inf,
                       gamma_available=float(g_hi if G[k] >= 0 else -g_lo),
                       flow_needed=abs(q_need), flow_available=abs(q_avail),
                       force_needed=f_need, force_available=f_avail, when=float(tk[k]),
                       pressures=(float(p_a), float(p_b)), margin=margin,
                       reasons=tuple(reasons), max_bandwidth=best)


def breakaway(brk, want: float, v: float, x_m: float, stribeck_velocity: float):
    """Break-away state of a stuck piston that must move: (direction +-1, measured
    position m at its start), else None (``brk``: the state at the last sample).

    Entered when the estimated speed ``v`` (m/s) is below the Stribeck velocity v_s
    (below it the friction is static-like: whatever holds the piston, up to F_s)
    and the wanted velocity ``want`` (m/s: the reference's velocity with the
    position error's correction at the loop's bandwidth) is beyond v_s. Left when
    the measured position ``x_m`` (m) has moved in that direction (the piston broke
    away: on a quantised sensor, at least a quantum) or the wanted direction
    changes. The speed is not the exit: the observer's velocity of a stuck piston is
    noisy (+-5 mm/s with 300 Pa pressure noise on the precision rig), and a speed
    threshold toggled the state from sample to sample.

    Why: while stuck, an observer's force estimate is the holding force (the piston
    does not accelerate), so a law built on it raises the force only at its error
    bandwidth (FL: lambda^3 e of jerk; 190 ms stuck at each reversal of the
    precision rig's sine, 10.6 mm behind, and a 10 mm step stalled half-way for
    170 ms, then broke away 1.8 mm past its target). The laws use the static
    friction in the wanted direction instead while this state is set (FL: or the
    force that has not moved the piston plus the Stribeck excess F_s - F_c, so a rig
    with more friction than its file is still broken away).
    """
    vs = float(stribeck_velocity)
    s = math.copysign(1.0, want) if abs(want) >= vs else 0.0
    if brk is not None:
        if s != brk[0] or brk[0] * (x_m - brk[1]) > 0:
            return None
        return brk
    if vs > 0 and s and abs(v) < vs:
        return (s, x_m)
    return None


def fed_friction(friction, v_r: float, a_r: float):
    """The friction law to feed forward at a reference slowing down (``v_r`` m/s,
    ``a_r`` m/s^2, v_r a_r < 0): its sliding part, the static level set to the
    Coulomb one (a :class:`~.compensation.FrictionModel`; other laws as given);
    else ``friction`` itself. Why: :meth:`FeedbackLinearizing._fed_law`."""
    if v_r * a_r < 0.0 and is_dataclass(friction) and hasattr(friction, "coulomb"):
        return replace(friction, static=friction.coulomb)
    return friction


# ---------------------------------------------------------------------- the controller
@dataclass(frozen=True)
class FeedbackLinearizing:
    """Feedback-linearising position controller (a DiscreteController).

    Build it with :func:`feedback_linearizing`, which checks the bandwidth.

    Sampled-data details:

    * **midpoint**: the command is held over the period while the state moves on
      (the air spring alone turns the force by f0 = -k p A^2/V v within the period),
      so the law is evaluated a second time at the middle of the period, at the state
      the model predicts under the first G (one Euler half step) and the reference
      model's state there; the held G then gives the wanted force rate on average.
      Without it the loop lags its reference model by several % of a step.
    * **disturbance observer** (``observer_bandwidth`` > 0): the model's acceleration
      (F - beta v - F_ext)/m is wrong by d/m when a force the model lacks acts (dry
      friction, a fitted valve law's error): a stuck piston looks like one accelerating
      at F/m. The observer estimates d from the measured velocity,
      d_meas = (F_k + F_k-1)/2 - beta (v_k + v_k-1)/2 - F_ext - m (v_k - v_k-1)/T,
      filtered with the pole -observer_bandwidth, and the law uses a = (F - beta v
      - F_ext - d)/m. On the nominal plant d is zero up to the sampling. Off by
      default: against stick-slip friction its estimate lags every break-away and,
      on the 25 mm rig with 10 N Coulomb friction, made the hunting worse
      (designs/fl_position.py keeps it off).

    Attributes
    ----------
    model : DriveModel (control model and valve inversion).
    sample_time : s. bandwidth : rad/s. damping : -. integral : bool.
    midpoint : bool. observer_bandwidth : rad/s (0: no observer).
    reference : ReferenceModel.
    gains : {"k2", "k1", "k0", "ki"} of the error dynamics (1/s .. 1/s^4).
    design : Feasibility or None.
    preview : the whole reference known in advance with its derivatives (a
        :class:`~workbench.references.Trajectory`, time from the first sample), or
        None. With it the law tracks r and its first three derivatives directly
        (feedforward) instead of the lagging reference model.
    friction : the plant file's friction law v (m/s) -> N along -x
        (:class:`~workbench.controllers.compensation.FrictionModel`), or None.
        Used with an outside force estimate ``d`` (:class:`~.observer.Observed`).
        At a start or reversal of the reference the friction changes by up to
        F_s + F_c within milliseconds, while the law builds force only at its error
        bandwidth (its jerk law asks lambda^3 e of force rate per metre of error):
        the piston stuck for 150-200 ms at each reversal of the precision rig's
        sine. The law therefore adds (1) the model friction's rate at the
        reference, F'(v_r) a_r / m, to the reference jerk (the force rate the known
        friction change needs), and (2) to the force estimate the part of the model
        friction at the *reference's* velocity that the estimate has not yet taken
        over, F(v_r) - F_lag, F_lag being F(v_r) through a first-order lag of
        ``friction_lag`` s. Taken at the reference's velocity, not the estimated
        one, it adds no sensor noise at a hold (v_r = 0: nothing). While the
        reference slows towards rest only the law's sliding part is fed
        (:meth:`_fed_law`).
    probe : share of the Stribeck excess F_s - F_c by which a stuck piston's force
        target leads the force once it is beyond the file's F_s (the rig holds more
        than the file says): the force then rises at k2 probe (F_s - F_c) N/s
        (:func:`~workbench.controllers.design.breakaway_probe`; default 1).
    friction_lag : s, time in which the outside estimate takes the friction over
        from the feedforward (:func:`~workbench.controllers.design.design`: the
        observer's time constant, so the friction is never counted twice); 0: the
        feedforward is the rate term only.
    release : samples of the break-away release (:meth:`_release`; 0: none).
    """

    model: DriveModel
    sample_time: float
    bandwidth: float
    damping: float = 1.0
    integral: bool = True
    midpoint: bool = True
    observer_bandwidth: float = 0.0
    reference: ReferenceModel | None = None
    design: Feasibility | None = None
    preview: Any = None
    friction: Any = None
    friction_lag: float = 0.0
    probe: float = 1.0
    release: int = 0
    gains: dict = field(init=False)

    kind = "feedback linearising"
    #: Measurements read (wrap in :class:`~workbench.controllers.observer.Observed` to
    #: run on x, p_a, p_b only).
    needs = ("x", "v", "p_a", "p_b")

    def __post_init__(self) -> None:
        object.__setattr__(self, "sample_time", _positive("sample_time", self.sample_time, "s"))
        object.__setattr__(self, "bandwidth", _positive("bandwidth", self.bandwidth, "rad/s"))
        object.__setattr__(self, "damping", _positive("damping", self.damping, "-"))
        lo = float(self.observer_bandwidth)
        if not (math.isfinite(lo) and lo >= 0):
            raise InputError(f"observer_bandwidth must be >= 0 rad/s, got {self.observer_bandwidth!r}")
        object.__setattr__(self, "observer_bandwidth", lo)
        lag = self.friction_lag
        if isinstance(lag, bool) or not isinstance(lag, (int, float)) or not (math.isfinite(lag) and lag >= 0):
            raise InputError(f"friction_lag must be >= 0 s, got {lag!r}")
        pr = self.probe
        if isinstance(pr, bool) or not isinstance(pr, (int, float)) or not (math.isfinite(pr) and pr > 0):
            raise InputError(f"probe must be a share > 0, got {pr!r}")
        rl = self.release
        if isinstance(rl, bool) or not isinstance(rl, int) or rl < 0:
            raise InputError(f"release must be a number of samples >= 0, got {rl!r}")
        if self.friction is not None and not (callable(self.friction) and all(
                hasattr(self.friction, k) for k in ("slope", "static", "coulomb"))):
            raise InputError("friction must be a law v (m/s) -> force (N) with its slope and "
                             "static / Coulomb levels: a FrictionModel")
        if self.reference is None:
            object.__setattr__(self, "reference",
                               ReferenceModel(self.bandwidth, self.damping, self.sample_time))
        elif abs(self.reference.sample_time - self.sample_time) > 1e-12:
            raise InputError("the reference model must be discretised at the controller's sample time")
        object.__setattr__(self, "gains", error_gains(self.bandwidth, self.damping, self.integral))

    def reset(self):
        """Controller state: (reference model state, integral, disturbance estimate,
        last (v, F), time since the first sample, (lagged, fed) model friction or
        None); the reference model starts at the first sample."""
        return (None, 0.0, 0.0, None, 0.0, None)

    def _fed_law(self, v_r: float, a_r: float):
        """The friction law fed forward at the reference's velocity ``v_r`` (m/s) and
        acceleration ``a_r`` (m/s^2): the plant file's, but its sliding part only
        (:func:`fed_friction`: no Stribeck excess) while the reference slows
        towards rest (v_r a_r < 0).

        Fed at the reference's velocity, the Stribeck rise F_s - F_c below v_s
        pushes a piston that still slides a few ms behind or ahead of the
        reference with up to that excess, at the end of every move (precision
        rig, FL at 40 rad/s: a 10 mm step arrived at 35-40 mm/s under 20 N, 5 N
        above its sliding friction, and stopped 0.58 mm past its target); a
        piston that must stop needs no static friction, the friction stops it.
        The excess is needed to start a stuck piston, which the break-away
        (:func:`breakaway`) gives.
        """
        return fed_friction(self.friction, v_r, a_r)

    def _friction_rate(self, tgt) -> float:
        """Jerk (m/s^3) that the model friction's rate at the reference adds:
        dF(v_r)/dt / m = F'(v_r) a_r / m (:meth:`~.compensation.FrictionModel.slope`)."""
        law = self._fed_law(float(tgt[1]), float(tgt[2]))
        return float(law.slope(tgt[1])) * float(tgt[2]) / self.model.mass

    def _friction_feedforward(self, f_lag, v_r: float, fr_prev=None,
                              a_r: float = 0.0) -> tuple[float, float, float]:
        """(feedforward force N, new lagged friction N, friction fed N) for the
        reference velocity ``v_r`` (m/s).

        Below the Stribeck velocity the fed friction only grows or changes sign: a
        reference coming to rest keeps the last direction's friction (a piston
        still sliding is braked by it until it stops; dropping it to the law's zero
        at v = 0 stopped the FL short of its target and then stuck it there).
        """
        fr = float(self._fed_law(v_r, a_r)(v_r))
        vs = float(getattr(self.friction, "stribeck_velocity", 0.0))
        if (fr_prev is not None and abs(v_r) < vs and abs(fr) <= abs(fr_prev)
                and fr * fr_prev >= 0):
            fr = fr_prev
        f_lag = fr if f_lag is None else f_lag
        ff = fr - f_lag
        if self.friction_lag > 0:
            f_lag += (1.0 - math.exp(-self.sample_time / self.friction_lag)) * (fr - f_lag)
        else:
            f_lag = fr
        return ff, f_lag, fr

    def _release(self, direction: float, tgt, slide: float, x: float, v: float, F: float,
                 t: float):
        """Release state (direction, None, end time s, force rate N/s) at a break-away.

        After a break-away the Stribeck excess F - F_need drives the piston until
        the law, at its error bandwidth (k2 = 3 lambda, 8 ms per e-fold at 40
        rad/s), has taken the force down (precision sine: 5-10 N too much for 20
        ms, the piston 1.4 mm ahead). For ``release`` samples from the one that
        sees the break-away, the rate (F_need - F) / (release T) is added to the
        law's: F_need the sliding friction, viscous force and mass times the
        acceleration the error dynamics ask for now, a_r + (k1 e1 + k0 e0) / k2.
        Fixed at the break-away (the observer's estimates of a piston that has
        just jumped are noisy, +-10 N from sample to sample); an excess only (a
        force short of the need is the law's), and only at a start or reversal (the
        reference speeding up: at a move's end on the foreign smooth-friction rig
        it stopped FL 0.8 mm short). Test profile of tests/test_precision_
        positioning.py, seeds 0-4 (3 samples): sine worst 1.36/1.55/1.59/1.47/1.46
        -> 1.04/1.16/1.43/1.05/1.08 mm, holds at rest. Tried: twice the drop stuck
        the piston again (1.7-2.4 mm); replacing the law's command instead of
        adding to it cut a fast step's start (holds limit-cycled on 4/5 seeds).
        """
        m, g = self.model, self.gains
        acc = float(tgt[2]) + (g["k1"] * (float(tgt[1]) - v)
                               + g["k0"] * (float(tgt[0]) - x)) / g["k2"]
        need = slide + m.mass * acc + m.viscous * v + m.external_force
        T = self.sample_time
        # an excess only: a force short of the need (a fast start) is the law's
        rate = min(direction * (need - F), 0.0) * direction / (self.release * T)
        return (direction, None, t + (self.release - 0.5) * T, rate)

    def _characteristic(self, xr, jr, z, d, x, v, p_a, p_b) -> tuple[float, float, float]:
        """(G, position error, model acceleration) of the linearising law at one state,
        for the reference state ``xr`` = (x_r, v_r, a_r) and jerk ``jr``."""
        m = self.model
        g = self.gains
        a = float(m.acceleration(v, p_a, p_b)) - d / m.mass
        e0, e1, e2 = xr[0] - x, xr[1] - v, xr[2] - a
        w = jr + g["k2"] * e2 + g["k1"] * e1 + g["k0"] * e0 + g["ki"] * z
        G = float(m.gamma_for_force_rate(m.mass * w + m.viscous * a, x, v, p_a, p_b))
        if not math.isfinite(G):
            G = math.copysign(1e9, G)
        return G, e0, a

    def _target(self, xr, r: float, t: float, half: bool):
        """Reference state (x_r, v_r, a_r) and jerk now (``half``: half a sample on):
        from the preview trajectory, else the reference model."""
        if self.preview is not None:
            tt = t + (0.5 * self.sample_time if half else 0.0)
            rr, vr, ar, jr = (float(q) for q in self.preview.derivatives(tt))
            return np.array([rr, vr, ar]), jr
        st = self.reference.half_step(xr, r) if half else xr
        return st, float(self.reference.jerk(st, r))

    def update(self, state, r: float, y: dict) -> tuple[tuple, float]:
        xr, z, d, last, t, fric = ((*state, 0.0, None)[:6] if len(state) == 4
                                   else (*state, None)[:6])
        f_lag, f_fed, brk = (None, None, None) if fric is None else (*fric, None)[:3]
        rel, pulse = None, 0.0
        m = self.model
        T = self.sample_time
        x, v, p_a, p_b = float(y["x"]), float(y["v"]), float(y["p_a"]), float(y["p_b"])
        F = float(m.force(p_a, p_b))
        if "d" in y:                        # an observer outside estimates the force (Observed)
            d = float(y["d"])
        elif self.observer_bandwidth > 0 and last is not None:
            v_prev, f_prev = last
            d_meas = (0.5 * (F + f_prev) - m.viscous * 0.5 * (v + v_prev) - m.external_force
                      - m.mass * (v - v_prev) / T)
            d = d + (1.0 - math.exp(-self.observer_bandwidth * T)) * (d_meas - d)
        if xr is None:                      # start the reference model where the piston is
            xr = np.array([x, v, float(m.acceleration(v, p_a, p_b)) - d / m.mass])
        tgt, jr = self._target(xr, r, t, False)
        if self.friction is not None and "d" in y:
            ff, f_lag, f_fed = self._friction_feedforward(f_lag, float(tgt[1]), f_fed,
                                                           float(tgt[2]))
            d = d + ff
            jr = jr + self._friction_rate(tgt)
            if brk is not None and brk[1] is None:      # a release under way
                rel, brk = brk, None
            was = brk
            vs = float(getattr(self.friction, "stribeck_velocity", 0.0))
            brk = breakaway(brk, float(tgt[1]), v,
                            float(y.get("x_measured", x)), vs)
            if brk is not None:
                # stuck, the reference moving on: the force to beat is the static
                # friction in that direction, not the holding force the estimate has;
                # a force beyond the model's F_s that has not moved the piston says the
                # rig's is larger: it is then taken as that force plus ``probe`` times
                # the Stribeck excess F_s - F_c, so the law keeps raising the force at
                # k2 probe (F_s - F_c) / m of jerk until the piston moves (on a rig
                # with 1.5 x the friction the force approached the model's F_s and
                # stopped there)
                fs, fc = float(self.friction.static), float(self.friction.coulomb)
                d = brk[0] * max(fs, brk[0] * (F - m.external_force)
                                  + self.probe * (fs - fc))
                f_lag = f_fed
            elif was is not None:
                # broke away: the friction drops to its sliding level now, the
                # estimate (the holding force) learns it only in friction_lag;
                # the difference is handed over as the feedforward is
                slide = was[0] * float(self.friction.coulomb)
                f_lag = f_fed - (slide - (d - ff))
                d = slide
                if self.release > 0 and was[0] * float(tgt[2]) > 0:
                    # a start or a reversal (the reference speeding up), not a move's end
                    rel = self._release(was[0], tgt, slide, x, v, F, t)
            if rel is not None and t < rel[2] and float(tgt[1]) * rel[0] > 0:
                brk = rel
                pulse = (float(m.gamma_for_force_rate(rel[3], x, v, p_a, p_b))
                         - float(m.gamma_for_force_rate(0.0, x, v, p_a, p_b)))
        G, e0, a = self._characteristic(tgt, jr, z, d, x, v, p_a, p_b)
        if self.midpoint:
            # evaluate the law again half a period on, at the state the model predicts
            G0 = min(max(G, -1e3), 1e3)
            h = 0.5 * T
            dpa, dpb = m.pressure_rates(x, v, p_a, p_b, G0)
            tgt, jr = self._target(xr, r, t, True)
            if self.friction is not None and "d" in y:
                jr = jr + self._friction_rate(tgt)
            G, _, _ = self._characteristic(tgt, jr, z + h * e0, d,
                                           x + h * v + 0.5 * h * h * a, v + h * a,
                                           p_a + h * float(dpa), p_b + h * float(dpb))
        u, sat = m.valve.command_for_gamma(G + pulse, "a")
        z_new = z + T * e0
        if sat and np.sign(e0) == np.sign(G):      # conditional integration (anti-windup)
            z_new = z
        fric = None if f_lag is None else (f_lag, f_fed, brk)
        return (self.reference.step(xr, r), z_new, d, (v, F), t + T, fric), float(u)

    def reference_response(self, reference, t_end: float,
                           x0: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(times, x_r) of the reference model at the samples for a reference r(t), m.

        Starts at rest at ``x0`` (default r(0)), as the controller does on a plant at rest.
        """
        T = self.sample_time
        tk = T * np.arange(int(np.floor(t_end / T + 1e-9)) + 1)
        r = np.asarray(reference(tk), dtype=float)
        start = np.array([r[0] if x0 is None else x0, 0.0, 0.0])
        return tk, self.reference.response(r, start)[:, 0]

    def describe(self) -> str:
        g = self.gains
        return (f"FL, bandwidth {self.bandwidth:g} rad/s, damping {self.damping:g}"
                + (", integral" if self.integral else "")
                + f" (k2 = {g['k2']:.4g} 1/s, k1 = {g['k1']:.4g} 1/s^2, k0 = {g['k0']:.4g} 1/s^3"
                + (f", ki = {g['ki']:.4g} 1/s^4" if self.integral else "") + ")")


def feedback_linearizing(plant, bandwidth: float, *, damping: float = 1.0, integral: bool = True,
                         sample_time: float | None = None, reference=None,
                         pressures: tuple[float, float] | None = None,
                         law: str | None = "input_affine", model: DriveModel | None = None,
                         valve: ValveInversion | None = None,
                         reference_bandwidth: float | None = None,
                         margin: float = FLOW_MARGIN, check: bool = True,
                         midpoint: bool = True,
                         observer_bandwidth: float = 0.0) -> FeedbackLinearizing:
    """Design a feedback-linearising position controller for a plant, from a bandwidth.

    Parameters
    ----------
    plant : workbench.Plant
        Its geometry, load and valve give the control model (effects such as dry
        friction, lines or a deadband are *not* in it).
    bandwidth : rad/s
        Magnitude of the error poles (all at -bandwidth for damping 1).
    damping : -
        Damping of one pole pair (the others are real at -bandwidth).
    integral : bool
        Add integral action (fourth error pole) against unmodelled friction/deadband.
    sample_time : s; default the plant file's ``controller.sample_time``.
    reference : reference r(t) with a duration, for the flow check; default the
        validation profile of the plant (:func:`workbench.validate.validation_profile`).
    pressures : (p_a, p_b) Pa at which the valve's authority is judged; default the
        plant's rest pressures at mid-stroke (:func:`workbench.linearize.operating_point`).
    law : valve law of the control model (default the input-affine law, fitted by
        least squares when the plant has the four-edge valve).
    model, valve : a ready DriveModel or ValveInversion instead.
    reference_bandwidth : rad/s of the reference model (default ``bandwidth``).
    margin : share of the valve and force the reference may use (default 0.8).
    check : run the feasibility check (refuse infeasible bandwidths).
    midpoint : evaluate the law at the predicted middle of each period (default; see
        :class:`FeedbackLinearizing`), else at the sample only.
    observer_bandwidth : rad/s of the disturbance observer (:class:`FeedbackLinearizing`);
        default 0 (off).

    Returns
    -------
    FeedbackLinearizing

    Raises
    ------
    InputError
        The bandwidth is beyond what the sample rate or the valve can supply; the
        message gives the reason and the largest bandwidth that passes.
    """
    if sample_time is None:
        if not plant.params.has_controller:
            raise InputError("give sample_time: the plant file has no [controller] section")
        sample_time = plant.params["controller.sample_time"]
    T = _positive("sample_time", sample_time, "s")
    lam = _positive("bandwidth", bandwidth, "rad/s")
    zeta = _positive("damping", damping, "-")
    if model is None:
        model = DriveModel.from_plant(plant, valve=valve, law=law)
    lam_r = lam if reference_bandwidth is None else _positive("reference_bandwidth",
                                                             reference_bandwidth, "rad/s")
    ref_model = ReferenceModel(lam_r, zeta, T)
    obs = float(observer_bandwidth)
    design = None
    if check:
        if reference is None:
            from ..references import validation_profile
            reference = validation_profile(plant)
        if pressures is None:
            pressures = _design_pressures(model, plant, 0.5 * plant.stroke)
        design = feasibility(model, lam, T, reference, pressures, damping=zeta,
                             reference_bandwidth=reference_bandwidth, margin=margin)
        if not design.feasible:
            hint = (f" The largest bandwidth that passes is about {design.max_bandwidth:.1f} rad/s."
                    if design.max_bandwidth else "")
            raise InputError("feedback linearisation refused: " + "; ".join(design.reasons)
                             + "." + hint)
    return FeedbackLinearizing(model=model, sample_time=T, bandwidth=lam, damping=zeta,
                               integral=integral, midpoint=midpoint,
                               observer_bandwidth=obs, reference=ref_model,
                               design=design)
