"""Nonlinear model predictive position control (NMPC) on the symbolic plant.

:class:`NMPC` predicts with the plant's own CasADi model ``f(x, u, p)`` (states x, v,
p_a, p_b) by **multiple shooting**: N intervals of one sample time each, the command
held (ZOH) on every interval, each interval integrated by classical Runge-Kutta (RK4)
with ``substeps`` fixed steps. In scaled variables it minimises

    1/2 sum_k [ ((x_k - r_k)/x_tol)^2 + ((v_k - r'_k)/v_tol)^2 ]   k = 1..N (node N
    + 1/2 sum_k ((u_k - u_{k-1})/du_tol)^2                          x terminal_factor)
    + slack penalties

subject to the command range ``valve.command_min .. command_max`` (hard bounds) and,
as soft constraints at the shooting nodes and between them (``interior_limits``:
at RK4 substep ends at most 2.5 ms apart, from the second interval on), the stroke
``stroke_margin .. L - stroke_margin``, the chamber pressures atmosphere .. supply
(tightened by ``pressure_margin``) and the speed ``max_speed``: one slack per kind
over the horizon with an exact L1 penalty plus a small quadratic term, so a limit
gives way only where no admissible command can keep it and the problem is always
feasible.

Three solution modes share that problem:

``"rti"`` (real-time iteration, the default)
    One Gauss-Newton SQP step per sample from the previous solution shifted by one
    sample (warm start). The QP is condensed onto the N command moves (plus the
    slacks): a dense, strictly convex QP of about 20 variables and 160 rows (616
    with the rows between the nodes at 10 ms), solved
    by DAQP, a dual active-set solver made for embedded MPC. Linearisation and
    condensing, and the update of the plan from the QP step, are CasADi functions
    compiled to C through :func:`workbench.integrate.jit.compiled`; with the QP between them
    they form one CasADi function, so a sample costs one call from Python.
``"sqp"``
    The same Gauss-Newton steps repeated until the command step is below
    ``tolerance`` (at most ``max_iterations``).
``"ipopt"``
    The full multiple-shooting NLP solved by IPOPT with exact Hessians (the accurate
    reference), warm started with the previous primal and dual solution shifted.

Integrator and sensitivities: the chamber modes of the 25 mm rig reach 1e3 1/s at
mid-stroke and 1e4 .. 2.5e4 1/s within 10 mm of an end (small chamber, pressure
ratio near 1) and the end stops are a 300 Hz contact. A fixed number of simplified
Newton iterations of an implicit Runge-Kutta step (Radau IIA) diverged in such
states; RK4's error stays bounded there (the fast modes exist only near a pressure
ratio of 1, in the valve law's laminar patch, which limits their growth) and is
typically 1e-4 mm in position per sample on the trajectories the loop runs. The interval map is therefore RK4 (defects exact); its
Jacobians are by default the (1, 2) Pade approximant (L-stable, 3rd order) of the
exponential of the continuous Jacobian at the interval's midpoint, 5x cheaper than
differentiating the RK4 steps (``sensitivities="exact"``) with the same closed-loop
tracking. With inexact Jacobians the SQP fixed point satisfies the dynamics exactly
but is only close to optimal (on the tests, 1e-3 V from IPOPT's commands);
``"exact"`` converges to the NLP's optimum.

The controller reads the full state (x, v, p_a, p_b) from the measurements the
simulator passes; its prediction model is therefore a 4-state plant
(:meth:`NMPC.for_plant` reduces any plant file to one: lines, spool dynamics, heat
transfer and supply droop are left to the feedback), or with ``lines="lumped"`` that
and one segment per line (node pressure and flow into the chamber, the plant's own
line law), whose states the NMPC estimates from the measured chamber pressures and
the commands it sent (:mod:`.lines`): the lag from command to chamber is then in the
prediction (what :func:`workbench.controllers.design` uses on a lined plant). Dry friction is predicted in
its smooth form, F_str(v) tanh(v / v_e), with v_e half the Stribeck velocity and
as many RK4 substeps as that needs for one step to resolve the decay at rest
(:func:`.model.friction_velocity`): with too few, RK4 is unstable there, and the
prediction of a stuck piston, and with it the plan, turned on rounding. A valve deadband
or null offset in the model is planned through: the NMPC plans in the compensated
command (its model has no dead zone, where a linearisation at the centre would have
no authority) and applies the plan through the deadband inverse
(:func:`.model.planning_model`). A force observer
(``disturbance_gain``) estimates what the model lacks (dry friction, a load) from
the velocity it mispredicted, which gives the loop integral action. Without a
``preview`` the reference is known only at the current sample: over the horizon it
is extrapolated along the current reference rate when that rate is below
``reference_rate_limit`` (a ramp), else held (a step). With ``preview`` (the whole
reference known in advance, e.g. a smoothed :class:`~workbench.references.Trajectory`)
the nodes follow it, position and velocity (the chord over one sample).

Examples
--------
>>> from workbench import Plant, simulate
>>> from workbench.controllers.mpc import NMPC
>>> plant = Plant.from_toml("designs/plants/rig25_mpye.toml")
>>> nmpc = NMPC.for_plant(plant, horizon=20, jit=False)   # jit=True: compiled C, faster
>>> sol = nmpc.solve({"x": 0.25, "v": 0.0, "p_a": 4.5e5, "p_b": 4.5e5}, r=0.3)
>>> round(float(sol.commands[0]), 1), round(float(sol.states[-1][0]), 3)  # V; m at the end
(7.8, 0.3)
>>> run = simulate.closed_loop(plant, nmpc, simulate.steps([0.3, 0.2], hold=1.0), x0=0.25)
>>> round(float(run["x"][-1]), 4)               # m: on the last step after 1 s
0.2

``validate.validate(plant, nmpc)`` runs the 23 s validation profile the same way.

Layout
------
:mod:`.model`
    The prediction model (:func:`prediction_model`), the scaled RK4 interval map and
    its Jacobians, the reference over the horizon (:func:`horizon_reference`).
:mod:`.lines`
    The estimate of the lumped lines' states (a Kalman filter on the NMPC's model).
:mod:`.limits`
    The soft-limit rows between the shooting nodes (``interior_limits``).
:mod:`.problem`
    The discretised problem: scaling, limits, weights, the force observer.
:mod:`.qp`
    The Gauss-Newton SQP step: condensing, the QP, the plan update (modes rti, sqp).
:mod:`.nlp`
    The full NLP for IPOPT (mode ipopt).
:mod:`.update`
    One update per sample: the solvers per mode, fallback, the report.
:mod:`.controller`
    :class:`NMPC`: settings, their checks, the controller protocol.
:mod:`.results`
    :class:`StepInfo`, :class:`NMPCState`, :class:`Solution`.
:mod:`.fast`
    :class:`CompiledNMPC`: the whole sample (modes rti, sqp) as one compiled C call.
:mod:`.baselines`
    :class:`Recorder` (solve times) and :class:`DoMPC` (the same problem in do-mpc).
"""

from .baselines import DoMPC, Recorder
from .controller import NMPC
from .fast import CompiledNMPC
from .model import NMPC_STATES, STATE_EFFECTS, horizon_reference, prediction_model
from .results import NMPCState, Solution, StepInfo

__all__ = ["NMPC", "CompiledNMPC", "NMPCState", "StepInfo", "Solution", "Recorder", "DoMPC", "prediction_model",
           "horizon_reference", "STATE_EFFECTS", "NMPC_STATES"]
