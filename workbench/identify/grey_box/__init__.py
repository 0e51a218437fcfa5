"""Grey-box estimation: physical parameters of the CasADi plant from recordings.

Any subset of the plant's parameter vector (:attr:`workbench.Plant.param_names`,
effect parameters included) is fitted to one or more recordings by replaying the
recorded command ``u`` open loop (zero-order hold at the recording's instants) and
comparing the simulated outputs with the measured ones (``x``, ``p_a``, ``p_b`` as
recorded; ``v`` and ``p_s`` when asked for). Recordings made in closed loop are
fitted the same way (the command that was applied is what the plant saw).

Method
------
*Multiple shooting.* Each recording is cut into shooting intervals of ``M`` samples
(:func:`estimate`'s ``shooting_interval``, 50 ms by default). The plant state at the
start of every interval is a decision variable, next to the (scaled) parameters, and
continuity between intervals is an equality constraint, so a long open-loop replay
never has to be stable or even close to the data at the start: the nodes start on
the measured states (velocity from differenced position, unmeasured states from a
replay with the start values) and the optimiser closes the gaps.

*Integration.* Inside an interval the plant is integrated with a fixed step per
sample (``substeps`` steps per sample when the sample time exceeds the largest step)
of the Radau IIA collocation method (2 stages, order 3, by default; 3 stages, order 5,
on request; L-stable and stiffly accurate, so the stiff chamber dynamics near a
pressure ratio of 1 or at an end stop do not limit the step). The stage equations are
solved by a fixed number of simplified Newton iterations with the exact CasADi
Jacobian; the sensitivities of each step with respect to its start state and to the
parameters are exact for the stage equations (implicit function theorem) and are
propagated through the interval in the same compiled function. The step is generated
as C and compiled once per plant structure and number of parameters
(:mod:`workbench.integrate.jit`, cached on disk); plants with many states (line segments) are
built from matrix expressions with a sparse QR factorised at run time, compiled likewise. On the 25 mm reference rig at 1 kHz the 2-stage scheme
at 1 ms stays within about 1e-6 of full scale of CVODES at a tight tolerance (the
default tolerances of :func:`workbench.simulate.open_loop` give about 1e-5); every
result reports the RMS difference to CVODES interval by interval
(``integration_error_``).

*Dry friction.* The Karnopp stick-slip form of a plant with ``friction="stick"`` is
not differentiable, so the estimation always uses the smooth form
(``plant.with_friction("smooth")``: Stribeck level times tanh(v / 1 mm/s)). That form
is stiff and kinked around v = 0 (the friction force turns over within 1 mm/s), which
costs the fixed-step scheme its order at every velocity reversal: with dry friction
the default step is 0.125 ms instead of 1 ms (at 0.25 ms the position error against
CVODES was still about 20 um on the reference rig, enough to bias estimates on a good
sensor). The before/after fits are simulated with the plant as given (a stick-slip
plant is checked in its stick-slip form).

*Optimiser.* IPOPT on the least-squares cost 0.5 sum(r^2) / n of residuals r
normalised by the measurement noise of each signal (estimated from the data unless
given), with the constrained Gauss-Newton Hessian J'J (J the residual Jacobian; the
curvature of the continuity constraints is left out, as in Bock's method). Parameters
are optimised as log(value / start) when their bounds are positive, else as
(value - start) / typical size; node states are scaled by their typical size. Default
bounds are a factor of 10 either side of the start value, within the plant file's
admissible range and rules. Kinks in the model (valve deadband, the valve edges
switching at the centre, flow reversal) make the gradient jump, so IPOPT's optimality
measure can stall while the estimates only jitter; the run then stops when the
parameters have moved by less than a tenth of their standard deviation for three
iterations (status ``Parameters_Converged``).

*Confidence.* The covariance of the estimates is that of the linearised
equality-constrained least-squares problem at the solution: the parameter rows of
the inverse KKT matrix [[J'J, G'], [G, 0]] (G the continuity Jacobian) take the node
states into account as nuisance variables, and the residual variance of each signal
is re-estimated from the residuals (a sandwich estimate, so the intervals stay honest
when the assumed noise level was off). 95 % intervals are value +- 1.96 std (delta
method from the optimised scale). A parameter whose standard deviation exceeds half
its size is reported as not identifiable. Over 16 noisy 1.5 s recordings of the
reference rig the spread of (estimate - truth) / std was 0.8 to 1.04 for the four
parameters of the benchmark.

*Honest check and verdict.* The fits before and after (NRMSE %,
:func:`workbench.recording.fit`) come from fresh CVODES simulations
(:class:`workbench.simulate.Simulator`, the integrator of
:func:`workbench.simulate.open_loop`; closed loop on the recorded ``r`` with the
plant's controller when both exist) of the nominal and of the estimated plant,
started from the recording's first sample and from the estimated initial state. The
result is a ``poor_fit`` when the estimated model cannot follow a recording: a fit
below ``fit_threshold`` (90 %) both in that replay and along the model's own
trajectory in the fit, or residuals that are strongly correlated and more than three
times the noise. An open-loop replay that drifts while the model's own trajectory
follows the data is reported in the message, not counted as a poor fit.

Layout
------
One concept per module: :mod:`.result` (:class:`GreyBoxResult`), :mod:`.parameters`
(names resolved against the plant, bounds, scaling), :mod:`.data` (recordings prepared
for the fit, noise levels, start values), :mod:`.problem` (the multiple-shooting problem:
Radau steps from :mod:`workbench.integrate`, sparsity, CasADi callbacks),
:mod:`.covariance`, :mod:`.verdict`, :mod:`.estimate` (:func:`estimate` in steps) and
:mod:`.synth` (:func:`synthetic_recording`). The before/after replays are those of
:mod:`workbench.replay`.

Examples
--------
A recording simulated by the workbench with a heavier payload, fitted from the plant
file's values (run from the repository root):

>>> from workbench import Plant
>>> from workbench.identify.grey_box import estimate, synthetic_recording
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> rig = plant.with_params(**{"load.mass": 1.5})
>>> rec = synthetic_recording(rig, 2.0, noise={"x": 1e-5, "p_a": 200.0,
...                                            "p_b": 200.0})
>>> res = estimate(plant, [rec], ["load.mass", "load.viscous_friction"])
>>> round(res.value("load.mass"), 3), res.poor_fit
(1.5, False)
>>> print(res.table())                          # doctest: +ELLIPSIS
parameter              nominal  estimate  std      95 % interval     unit
-------------------------------------------------------------------------
load.mass              1.2      1.50004   ...
The estimated model explains the recordings to the noise level.

From the command line: ``workbench identify greybox PLANT.toml RUN1.csv RUN2.csv
--params load.mass load.viscous_friction --out DIR``.
"""

from __future__ import annotations

from .covariance import _covariance, _stationary
from .data import (SIGNALS, _Data, _as_recording, _first_value, _initial_state, _prepare,
                   _smooth_derivative, _state_bounds, _typical_signal, noise_std)
from .estimate import (MAX_STEP, MAX_STEP_FRICTION, _closed_replay, _replay, _use_closed_loop,
                       estimate)
from .parameters import _TYPICAL, _Param, _make_param, _resolve_parameters, _rule_bounds
from .problem import (LARGE_SYSTEM, RADAU_TABLES, _IterationCallback, _Problem,
                      _interval_functions, _step_functions)
from .result import GreyBoxResult
from .synth import _aprbs_doublets, synthetic_recording
from .verdict import _fits, _verdict, _whiteness

__all__ = ["estimate", "GreyBoxResult", "SIGNALS", "RADAU_TABLES", "noise_std",
           "synthetic_recording"]
