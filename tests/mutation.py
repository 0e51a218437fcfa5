"""Mutation testing by hand: plant plausible bugs one at a time, see which the tests catch.

Each :class:`Mutation` names a file, an exact piece of its text (which must occur
exactly once), its replacement, a one-line description and the test files (or
pytest node ids) that ought to catch it. For every mutation the script copies the
repository's ``workbench/``, ``tests/``, ``designs/`` and ``pyproject.toml`` into a
temporary directory (never the working tree), plants the bug there, runs the
targeted tests with ``PYTHONPATH`` set to the copy (``pytest -x``, with a time
limit), restores the file and records the outcome:

* ``killed``: a test failed (or could not even be collected);
* ``survived``: the targeted tests all passed with the bug in place;
* ``timeout``: the tests ran past ``--timeout`` seconds;
* ``error``: pytest could not run (no tests, usage error, internal error).

It prints a table and the score (killed / total) per module group: ``physics``
(workbench/physics, plant.py wiring), ``diagnose`` (the ranking and its evidence),
``identify`` (ARX, RLS, grey-box covariance, valve fits) and ``control`` (the valve
inversion and the gain limits of the issue's list) and ``core`` (a second, blind
round: equilibrium, linearisation, simulation loop, PID, metrics, references,
signals, replay, validation, integrators, stability kernel).

Usage (from the repository root)::

    python tests/mutation.py                      # every mutation, one at a time
    python tests/mutation.py --modules physics,diagnose --jobs 2
    python tests/mutation.py --list               # the mutations, nothing run
    python tests/mutation.py --only supply-leak-reversed,arx-variance-n
    python tests/mutation.py --json mutation.json # outcomes as JSON too

A test file named by a mutation that does not exist (yet) is skipped, and the
output says so; a mutation whose every test file is missing is reported as
``error``. The name has no ``test_`` prefix, so pytest does not collect it;
``tests/test_mutation_script.py`` checks that the list is not stale.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Sequence

REPO = Path(__file__).resolve().parents[1]
#: What a temporary copy holds (everything the targeted tests read).
COPIED = ("workbench", "tests", "designs", "pyproject.toml")
GROUPS = ("physics", "diagnose", "identify", "control", "core")
#: Seconds one mutant's tests may run before it counts as a timeout.
DEFAULT_TIMEOUT = 300.0


@dataclasses.dataclass(frozen=True)
class Mutation:
    """One planted bug: ``original`` (exactly once in ``file``) becomes ``replacement``."""

    name: str
    group: str
    file: str
    original: str
    replacement: str
    description: str
    tests: tuple[str, ...]


# ------------------------------------------------------------------ test subsets
# Each subset is small enough that one mutant runs in seconds. The files of the
# issue-17 helpers that may not exist yet are named too (skipped while missing).
PHYS = ("tests/test_effect_laws.py", "tests/test_physics.py", "tests/test_physics_backends.py",
        "tests/test_plant.py")
PHYS_PLANT = PHYS + ("tests/test_linearize.py",)
PHYS_GREY = PHYS + ("tests/test_grey_box.py",)
#: The whole of test_diagnose.py takes minutes (a full diagnosis per case): a few cases.
DIAG = ("tests/test_diagnose_rank.py", "tests/test_diagnose_blind.py",
        "tests/test_diagnose.py::test_concealed_effect_is_diagnosed[none]",
        "tests/test_diagnose.py::test_concealed_effect_is_diagnosed[leakage]",
        "tests/test_diagnose.py::test_concealed_effect_is_diagnosed[mass_error]",
        "tests/test_diagnose.py::test_json_contract_and_files")
ARX = ("tests/test_arx.py", "tests/test_serialisation.py", "tests/test_signals.py")
RLS = ("tests/test_rls.py",)
GREY = ("tests/test_grey_box.py",)
VALVE = ("tests/test_valve_fit.py",)
INV = ("tests/test_inversion.py", "tests/test_feedback_linearizing.py")
LIM = ("tests/test_limits.py", "tests/test_serialisation.py")
#: The "core" group (blind round 2): each module's own test file plus the values file.
_NEW = ("tests/test_core_values.py",)
CORE_PD = ("tests/test_simulate.py", "tests/test_limits.py") + _NEW
CORE_MET = ("tests/test_validate.py",) + _NEW
CORE_REF = ("tests/test_validate.py", "tests/test_limits.py") + _NEW
CORE_LIN = ("tests/test_linearize.py",) + _NEW
CORE_EQ = ("tests/test_linearize.py", "tests/test_plant.py", "tests/test_replay.py") + _NEW
CORE_SIM = ("tests/test_simulate.py",) + _NEW
CORE_SIG = ("tests/test_signals.py",) + _NEW
CORE_REP = ("tests/test_replay.py",) + _NEW
CORE_VAL = ("tests/test_validate.py",) + _NEW
CORE_INT = ("tests/test_integrate.py",) + _NEW
CORE_KER = ("tests/test_maps.py", "tests/test_limits.py") + _NEW
#: Issue-17 remainder (p17): the values written to JSON and the design summaries.
GREY_VAL = ("tests/test_grey_box.py::test_integration_error_recomputed_with_scipy_radau",
            "tests/test_grey_box.py::test_correlation_and_std_from_a_finite_difference_jacobian",
            "tests/test_grey_box.py::test_json_values_recomputed_from_their_definitions")
LIN_VAL = ("tests/test_json_values.py::test_linearize_residual_recomputed_from_f",
           "tests/test_linearize.py")
#: one quick design (the NMPC one: PD saturates there, so every figure is non-trivial)
DESIGN_VAL = ("tests/test_designs.py::test_nmpc_design_every_key",)
JIT = ("tests/test_integrate.py", "tests/test_simulate.py::test_compiled_loop_native_matches_vm",
       "tests/test_simulate.py::test_compiled_loop_without_compiler_runs_the_vm")
OUTPUT = ("tests/test_output.py",
          "tests/test_simulate.py::test_result_set_refuses_an_input_however_its_path_is_spelled")


def _m(name, group, file, original, replacement, description, tests):
    """A :class:`Mutation` (positional, to keep the list below compact)."""
    return Mutation(name, group, file, original, replacement, description, tuple(tests))


MUTATIONS: tuple[Mutation, ...] = (
    # ------------------------------------------------------------------ physics
    _m("supply-leak-reversed", "physics", "workbench/physics/supply.py",
       "return iso6358_flow(conductance, b, p, p_atm, temperature, temperature)",
       "return iso6358_flow(conductance, b, p_atm, p, temperature, temperature)",
       "issue 17: leak to atmosphere reversed (air pumped in from outside)", PHYS_GREY),
    _m("cross-leak-sign", "physics", "workbench/physics/supply.py",
       "return conductance * (p_a - p_b)", "return conductance * (p_b - p_a)",
       "cross-piston leak flows from low to high pressure", PHYS),
    _m("reservoir-outflow-sign", "physics", "workbench/physics/supply.py",
       "(q_in - q_out)", "(q_in + q_out)",
       "reservoir fills with the valve's draw instead of emptying", PHYS),
    _m("reservoir-regulator-swapped", "physics", "workbench/physics/supply.py",
       "iso6358_flow(regulator_conductance, b, p_set, p_s,",
       "iso6358_flow(regulator_conductance, b, p_s, p_set,",
       "regulator flow with its pressures swapped (flows out of the reservoir)", PHYS),
    _m("four-edge-exhaust-b-temperature", "physics", "workbench/physics/valve.py",
       "iso6358_flow(conductance, b, p_b, p_atm, t_b, T_REF)",
       "iso6358_flow(conductance, b, p_b, p_atm, t_a, T_REF)",
       "issue 17: exhaust edge of B uses chamber A's temperature", PHYS_GREY),
    _m("four-edge-a-exhaust-opening", "physics", "workbench/physics/valve.py",
       "a_to_e = o_minus * iso6358_flow", "a_to_e = o_plus * iso6358_flow",
       "A->exhaust edge scaled by the S->A opening", PHYS),
    _m("four-edge-supply-draw", "physics", "workbench/physics/valve.py",
       "s_to_b - b_to_e, s_to_a + s_to_b", "s_to_b - b_to_e, s_to_a - s_to_b",
       "supply draw is the difference of the two supply edges", PHYS),
    _m("spool-damping-factor", "physics", "workbench/physics/valve.py",
       "w * w * (u - y) - 2.0 * damping * w * y_dot", "w * w * (u - y) - damping * w * y_dot",
       "spool lag damping term without its factor 2", PHYS),
    _m("gamma-odd-power", "physics", "workbench/physics/valve.py",
       "power = power * mag", "power = power * du",
       "Gamma(du) uses du^k instead of du |du|^(k-1) (not odd)", PHYS + INV),
    _m("deadband-scale", "physics", "workbench/physics/valve.py",
       "/ (1.0 - deadband)", "/ (1.0 + deadband)",
       "opening after the overlap rescaled by 1 + d", PHYS),
    _m("null-offset-sign", "physics", "workbench/physics/valve.py",
       "(u - center - offset) / span", "(u - center + offset) / span",
       "valve null offset applied with the wrong sign", PHYS),
    _m("affine-psi-swapped", "physics", "workbench/physics/valve.py",
       "ops.where(gamma >= 0, polyval(psi_in, pn), polyval(psi_out, pn))",
       "ops.where(gamma >= 0, polyval(psi_out, pn), polyval(psi_in, pn))",
       "input-affine law: inlet and exhaust psi swapped", PHYS + INV),
    _m("chamber-b-volume-rate", "physics", "workbench/physics/chamber.py",
       "area_a * v, -area_b * v)", "area_a * v, area_b * v)",
       "chamber B volume grows as the piston moves towards it", PHYS),
    _m("pressure-rate-work-sign", "physics", "workbench/physics/chamber.py",
       "(r * temperature * q - p * volume_rate)", "(r * temperature * q + p * volume_rate)",
       "polytropic chamber: compression work with the wrong sign", PHYS),
    _m("heat-wall-sign", "physics", "workbench/physics/chamber.py",
       "h * (t_wall - temp))", "h * (temp - t_wall))",
       "heat flows from the cold wall into the hot gas", PHYS_GREY),
    _m("energy-outflow-temperature", "physics", "workbench/physics/chamber.py",
       "(tq_in - temp * q_out)", "(tq_in - t_wall * q_out)",
       "leaving gas carries the wall temperature instead of the chamber's", PHYS),
    _m("stribeck-levels-swapped", "physics", "workbench/physics/friction.py",
       "return coulomb + (static - coulomb) * ops.exp(",
       "return static + (coulomb - static) * ops.exp(",
       "Stribeck curve: Coulomb and static levels swapped", PHYS),
    _m("stick-held-by-coulomb", "physics", "workbench/physics/friction.py",
       "held = ops.fabs(drive_force) <= static", "held = ops.fabs(drive_force) <= coulomb",
       "piston breaks away at the Coulomb instead of the static level", PHYS),
    _m("smooth-viscous-sign", "physics", "workbench/physics/friction.py",
       "+ viscous * v)", "- viscous * v)",
       "smooth friction: viscous term pushes along the motion", PHYS),
    _m("pneumatic-force-atm-sign", "physics", "workbench/physics/piston.py",
       "- p_atm * (area_a - area_b)", "+ p_atm * (area_a - area_b)",
       "atmospheric force on the rod side with the wrong sign", PHYS),
    _m("end-stop-damping-factor", "physics", "workbench/physics/piston.py",
       "c = 2.0 * damping * mass * w", "c = damping * mass * w",
       "end-stop damping without its factor 2", PHYS),
    _m("iso-psi-denominator", "physics", "workbench/physics/gas.py",
       "smooth_sqrt(1.0 - x, margin) / (1.0 - b)", "smooth_sqrt(1.0 - x, margin) / (1.0 + b)",
       "ISO 6358 subsonic branch divided by 1 + b", PHYS),
    _m("iso-temperature-ratio", "physics", "workbench/physics/gas.py",
       "* ops.sqrt(T_REF / t1)", "* ops.sqrt(t1 / T_REF)",
       "ISO 6358 forward flow: temperature correction inverted", PHYS),
    _m("nozzle-k-factor", "physics", "workbench/physics/gas.py",
       "k = gamma / r * 2.0 / (gamma - 1.0)", "k = gamma / r * 2.0 / (gamma + 1.0)",
       "nozzle law subsonic factor with gamma + 1", PHYS),
    _m("speed-of-sound-gamma", "physics", "workbench/physics/gas.py",
       "return ops.sqrt(gamma * r * temperature)", "return ops.sqrt(r * temperature)",
       "isothermal instead of adiabatic speed of sound", PHYS),
    _m("line-laminar-factor", "physics", "workbench/physics/line.py",
       "lam = 32.0 * mu", "lam = 16.0 * mu",
       "Hagen-Poiseuille drop with 16 instead of 32", PHYS),
    _m("line-segment-off-by-one", "physics", "workbench/physics/line.py",
       "seg = length / n\n", "seg = length / (n + 1)\n",
       "line segment length off by one segment", PHYS),
    _m("line-drop-sign", "physics", "workbench/physics/line.py",
       "(p_nodes[j] - p_next - drop)", "(p_nodes[j] - p_next + drop)",
       "line friction accelerates the flow", PHYS),
    _m("plant-leak-b-pressure", "physics", "workbench/plant.py",
       "leak_b = supply.leak_to_atmosphere(s.p_b,", "leak_b = supply.leak_to_atmosphere(s.p_a,",
       "plant wiring: chamber B leaks at chamber A's pressure", PHYS_GREY),
    _m("plant-cross-b-sign", "physics", "workbench/plant.py",
       "q_b - leak_b + cross, k, T)", "q_b - leak_b - cross, k, T)",
       "plant wiring: cross leak removed from both chambers", PHYS),
    _m("plant-heat-leak-b", "physics", "workbench/plant.py",
       "qb_out + xb_out + leak_b, h, T)", "qb_out + xb_out + leak_a, h, T)",
       "plant wiring (heat transfer): chamber B loses chamber A's leak", PHYS_GREY),
    _m("plant-cross-temperature", "physics", "workbench/plant.py",
       "tq_a = T * qa_in + s.t_b * xa_in", "tq_a = T * qa_in + s.t_a * xa_in",
       "plant wiring (heat transfer): cross leak into A at A's temperature", PHYS),
    _m("plant-viscous-sign", "physics", "workbench/plant.py",
       "return (drive - beta * s.v) / m", "return (drive + beta * s.v) / m",
       "plant wiring: viscous friction pushes along the motion", PHYS_PLANT),
    _m("plant-external-force-sign", "physics", "workbench/plant.py",
       'drive = force - pv["load.external_force"]', 'drive = force + pv["load.external_force"]',
       "plant wiring: external load force with the wrong sign", PHYS_PLANT),
    _m("plant-valve-port-temperature", "physics", "workbench/plant.py",
       'pv["valve.critical_pressure_ratio"], T, port_ta,',
       'pv["valve.critical_pressure_ratio"], T, port_tb,',
       "plant wiring: valve sees chamber B's temperature at port A", PHYS_GREY),
    # blind round 2 (p17mut2): further plausible physics bugs
    _m("chamber-b-volume-x", "physics", "workbench/physics/chamber.py",
       "dead_b + area_b * (stroke - x)", "dead_b + area_b * x",
       "chamber B grows with x instead of shrinking", PHYS),
    _m("inflow-for-rate-k", "physics", "workbench/physics/chamber.py",
       "(volume * dp / k + p * volume_rate)", "(volume * dp * k + p * volume_rate)",
       "inverse pressure law: V dp k instead of V dp / k", PHYS + INV),
    _m("end-stop-high-damping-sign", "physics", "workbench/physics/piston.py",
       "-k * (x - stroke) - c * v, 0.0)", "-k * (x - stroke) + c * v, 0.0)",
       "upper end stop pushes with the velocity (negative damping)", PHYS),
    _m("temperature-rate-volume-sign", "physics", "workbench/physics/chamber.py",
       "dp / p + volume_rate / volume", "dp / p - volume_rate / volume",
       "chamber temperature: expansion term with the wrong sign", PHYS),
    _m("gas-mass-ideal-gas", "physics", "workbench/physics/chamber.py",
       "return p * volume / (r * temperature)", "return p * volume * r / temperature",
       "gas mass m = p V r / T instead of p V / (r T)", PHYS),
    # ------------------------------------------------------------------ diagnosis
    _m("dbic-penalty-sign", "diagnose", "workbench/diagnose/explain.py",
       "- r.k * math.log(n_eff)", "+ r.k * math.log(n_eff)",
       "issue 17: dBIC rewards instead of penalising fitted values", DIAG),
    _m("gain-over-j", "diagnose", "workbench/diagnose/explain.py",
       "gain = (cost0 - r.cost) / cost0 if", "gain = (cost0 - r.cost) / r.cost if",
       "issue 17: gain computed as (J0 - J) / J", DIAG),
    _m("dbic-ratio-inverted", "diagnose", "workbench/diagnose/explain.py",
       "math.log(max(cost0, 1e-300) / max(r.cost, 1e-300))",
       "math.log(max(r.cost, 1e-300) / max(cost0, 1e-300))",
       "dBIC log ratio inverted (J / J0)", DIAG),
    _m("dbic-threshold-inverted", "diagnose", "workbench/diagnose/explain.py",
       "if dbic < DBIC_MIN:", "if dbic > DBIC_MIN:",
       "significance: dBIC comparison inverted", DIAG),
    _m("gain-min-factor", "diagnose", "workbench/diagnose/explain.py",
       "GAIN_MIN = 0.25", "GAIN_MIN = 0.025",
       "significance: minimum gain ten times too small", DIAG),
    _m("gain-per-value", "diagnose", "workbench/diagnose/explain.py",
       "gain / max(r.k, 1)", "gain * max(r.k, 1)",
       "gain per fitted value multiplied instead of divided", DIAG),
    _m("seg-gain-sign", "diagnose", "workbench/diagnose/explain.py",
       "seg_gain = (seg0 - r.seg_cost) / seg0", "seg_gain = (r.seg_cost - seg0) / seg0",
       "closed-loop gain with the wrong sign", DIAG),
    _m("closed-loop-veto-off", "diagnose", "workbench/diagnose/explain.py",
       "            sig = False\n            reasons.append(f\"closed loop worse",
       "            reasons.append(f\"closed loop worse",
       "closed-loop veto reported but not applied", DIAG),
    _m("bic-weight-sign", "diagnose", "workbench/diagnose/explain.py",
       "o.weight = math.exp(0.5 * (o.dbic - ref)) / z",
       "o.weight = math.exp(-0.5 * (o.dbic - ref)) / z",
       "BIC weight favours the worst candidate", DIAG),
    _m("rank-order-reversed", "diagnose", "workbench/diagnose/explain.py",
       "-o.dbic if np.isfinite(o.dbic) else math.inf",
       "o.dbic if np.isfinite(o.dbic) else math.inf",
       "ranking: smallest dBIC first among equals in significance", DIAG),
    _m("others-ignore-significance", "diagnose", "workbench/diagnose/explain.py",
       "if r.significant and r.name not in used_names", "if r.name not in used_names",
       "further findings drawn from non-significant candidates too", DIAG),
    _m("confidence-runner-up-sign", "diagnose", "workbench/diagnose/evidence.py",
       "d = r.dbic - runner_up.dbic", "d = runner_up.dbic - r.dbic",
       "confidence against the runner-up inverted", DIAG),
    _m("confidence-gain-weights", "diagnose", "workbench/diagnose/evidence.py",
       "w *= 0.6 + 0.4 * min(", "w *= 0.4 + 0.6 * min(",
       "confidence tempered by the gain with swapped weights", DIAG),
    _m("evidence-percent", "diagnose", "workbench/diagnose/evidence.py",
       "removes {100 * r.gain:.0f} %", "removes {r.gain:.0f} %",
       "evidence sentence gives the gain as a fraction labelled %", DIAG),
    _m("where-text-order", "diagnose", "workbench/diagnose/evidence.py",
       'key=lambda kv: -kv[1]["ratio"]', 'key=lambda kv: kv[1]["ratio"]',
       "evidence names the regimes where the mismatch is smallest", DIAG),
    _m("refit-dof", "diagnose", "workbench/diagnose/refit.py",
       "/ max(m - k, 1) *", "/ max(m, 1) *",
       "refit residual variance without the degrees-of-freedom correction", DIAG),
    _m("refit-inflation-inverted", "diagnose", "workbench/diagnose/refit.py",
       "* max(m / n_eff, 1.0)", "* max(n_eff / m, 1.0)",
       "refit covariance inflation inverted (never inflates)", DIAG),
    _m("refit-log-std", "diagnose", "workbench/diagnose/refit.py",
       "std[f.key] = v * sz", "std[f.key] = sz",
       "log-scaled value's std not mapped back to its unit", DIAG),
    _m("fd-jacobian-step", "diagnose", "workbench/diagnose/refit.py",
       "J[:, i] = (fun(zi) - r0) / h", "J[:, i] = (fun(zi) - r0) / steps[i]",
       "finite-difference Jacobian ignores the flipped step at an upper bound", DIAG),
    # ------------------------------------------------------------------ identification
    _m("arx-variance-n", "identify", "workbench/identify/arx/model.py",
       "sigma2 = sse / dof", "sigma2 = sse / n_eq",
       "issue 17: ARX noise variance sse / N instead of sse / (N - d)", ARX),
    _m("arx-fpe-inverted", "identify", "workbench/identify/arx/model.py",
       "fpe = loss * (1 + d / n_eq) / (1 - d / n_eq)",
       "fpe = loss * (1 - d / n_eq) / (1 + d / n_eq)",
       "issue 17: FPE formula inverted", ARX),
    _m("arx-aic-penalty", "identify", "workbench/identify/arx/model.py",
       "aic = n_eq * log_v + 2 * d", "aic = n_eq * log_v + d",
       "AIC penalty d instead of 2 d", ARX),
    _m("arx-bic-penalty", "identify", "workbench/identify/arx/model.py",
       "bic = n_eq * log_v + d * math.log(n_eq)", "bic = n_eq * log_v + math.log(n_eq)",
       "BIC penalty without the parameter count", ARX),
    _m("arx-covariance-loss", "identify", "workbench/identify/arx/model.py",
       "cov = sigma2 * (vs @ vs.T)", "cov = loss * (vs @ vs.T)",
       "parameter covariance from the uncorrected loss", ARX),
    _m("arx-offset-sign", "identify", "workbench/identify/arx/model.py",
       "u_off = (a1 * y_off - c) / b1", "u_off = (a1 * y_off + c) / b1",
       "ARX operating-point input offset with the constant's sign flipped", ARX),
    _m("arx-max-lag-off-by-one", "identify", "workbench/identify/arx/checks.py",
       "return max(na, nk + nb - 1)", "return max(na, nk + nb)",
       "ARX maximum lag one too large (one equation lost)", ARX),
    _m("arx-fit-percent-mean", "identify", "workbench/identify/arx/checks.py",
       "den = float(np.linalg.norm(y - y.mean()))", "den = float(np.linalg.norm(y))",
       "fit percentage against |y| instead of |y - mean|", ARX),
    _m("arx-order-fit-sign", "identify", "workbench/identify/arx/order.py",
       "value = -c.validation_fit", "value = c.validation_fit",
       "order selection by fit picks the worst fit", ARX),
    _m("arx-band-sqrt", "identify", "workbench/identify/arx/validation.py",
       "band = CONFIDENCE_Z99 / math.sqrt(n)", "band = CONFIDENCE_Z99 / n",
       "correlation band 1/N instead of 1/sqrt(N)", ARX),
    _m("arx-autocorr-lag0", "identify", "workbench/identify/arx/validation.py",
       "np.abs(r_e[1:]) > band", "np.abs(r_e[0:]) > band",
       "autocorrelation count includes lag 0 (always outside)", ARX),
    _m("rls-variance-den", "identify", "workbench/identify/rls/kernels.py",
       "Vn = lk * V + eps * eps / den", "Vn = lk * V + eps * eps",
       "RLS (casadi kernel): prior residual not scaled to the posterior one", RLS),
    _m("rls-dof", "identify", "workbench/identify/rls/kernels.py",
       "dof = ne_n - ca.trace(B)", "dof = ne_n",
       "RLS (casadi kernel): variance without the degrees-of-freedom correction", RLS),
    _m("rls-information-forgetting", "identify", "workbench/identify/rls/kernels.py",
       "Mn = (lk * lk) * M + ca.mtimes(f, f.T)", "Mn = lk * M + ca.mtimes(f, f.T)",
       "RLS (casadi kernel): information matrix forgotten with lambda, not lambda^2", RLS),
    _m("rls-numpy-variance-den", "identify", "workbench/identify/rls/kernels.py",
       "V = lk * V + eps * eps / den", "V = lk * V + eps * eps",
       "RLS (numpy kernel): prior residual not scaled", RLS),
    _m("rls-c-information-forgetting", "identify", "workbench/identify/rls/ckernel.py",
       "v = lk * lk * M[i][j] + f[i] * f[j];", "v = lk * M[i][j] + f[i] * f[j];",
       "RLS (C loop): information matrix forgotten with lambda, not lambda^2", RLS),
    _m("rls-c-regressor-delay", "identify", "workbench/identify/rls/ckernel.py",
       "f[i] = u[k - nk - (i - na)];", "f[i] = u[k - nk + 1 - (i - na)];",
       "RLS (C loop): input regressor one sample late", RLS),
    _m("greybox-cov-dof", "identify", "workbench/identify/grey_box/covariance.py",
       "dof = max(1e-3, 1.0 - n_free_dims / max(prob.n_res, 1))", "dof = 1.0",
       "grey-box residual variance without the degrees-of-freedom correction", GREY),
    _m("greybox-cov-transform", "identify", "workbench/identify/grey_box/covariance.py",
       "cov = cov_z * np.outer(D, D)", "cov = cov_z",
       "grey-box covariance not mapped from optimiser to parameter units", GREY),
    _m("valve-r2-total", "identify", "workbench/identify/valve/quality.py",
       "ss_tot = float(np.sum((q - np.mean(q)) ** 2))", "ss_tot = float(np.sum(q ** 2))",
       "valve fit R^2 against the raw instead of the centred sum of squares", VALVE),
    _m("valve-zero-crossing-sign", "identify", "workbench/identify/valve/gain.py",
       "pe = ps[j] - qs[j] / slope", "pe = ps[j] + qs[j] / slope",
       "equilibrium pressure of the table: linear interpolation sign", VALVE),
    _m("valve-gu-span", "identify", "workbench/identify/valve/gain.py",
       "/ (ub - ua))", "/ (2.0 * (ub - ua)))",
       "flow gain Gu from the table halved", VALVE),
    _m("valve-lstsq-scale", "identify", "workbench/identify/valve/lstsq.py",
       "return sol / scale", "return sol * scale",
       "column scaling of the valve least squares undone the wrong way", VALVE),
    # ------------------------------------------------------------------ control
    _m("inversion-symbolic-factor", "control", "workbench/controllers/inversion.py",
       "return ca.sign(G) * 2.0 * mag / (g1 + ca.sqrt(",
       "return ca.sign(G) * mag / (g1 + ca.sqrt(",
       "issue 17: symbolic Gamma^-1 closed form off by a factor 2", INV),
    _m("inversion-numeric-factor", "control", "workbench/controllers/inversion.py",
       "return np.sign(g) * 2.0 * mag / (g1 + root), 0",
       "return np.sign(g) * mag / (g1 + root), 0",
       "numeric Gamma^-1 closed form off by a factor 2", INV),
    _m("inversion-symbolic-newton-sign", "control", "workbench/controllers/inversion.py",
       "s = ca.fmin(ca.fmax(s - (val - mag) / slope, 0.0), 1.0)",
       "s = ca.fmin(ca.fmax(s + (val - mag) / slope, 0.0), 1.0)",
       "symbolic Newton step for Gamma of degree 3+ with the wrong sign", INV),
    _m("command-for-gamma-saturation", "control", "workbench/controllers/inversion.py",
       "sat = (g < g_lo) | (g > g_hi)", "sat = (g < g_lo) & (g > g_hi)",
       "issue 17: command_for_gamma saturation flag never set", INV),
    _m("limits-sampled-frequency", "control", "workbench/stability/limits.py",
       "sampled_frequency=s_th / T,", "sampled_frequency=s_th * T,",
       "issue 17: sampled_frequency = theta * T instead of theta / T", LIM),
    _m("limits-delay-frequency", "control", "workbench/stability/limits.py",
       "sampled_delay_frequency=d_th / T)", "sampled_delay_frequency=d_th * T)",
       "sampled_delay_frequency = theta * T instead of theta / T", LIM),
    # blind round 2 (p17mut2): further plausible gain-limit bugs
    _m("limits-pct-half-sample", "control", "workbench/stability/limits.py",
       "return T / 2.0 + 1.0 / w0", "return T + 1.0 / w0",
       "PCT time constant with a full sample instead of T/2", LIM),
    _m("limits-continuous-factor", "control", "workbench/stability/limits.py",
       'return 2.0 * positive("zeta", zeta, "(damping ratio)") * positive',
       'return positive("zeta", zeta, "(damping ratio)") * positive',
       "continuous limit zeta w0 instead of 2 zeta w0", LIM),
    _m("limits-zoh-plant-gain", "control", "workbench/stability/limits.py",
       "B = np.array([[0.0], [0.0], [w0 ** 2]])", "B = np.array([[0.0], [0.0], [w0]])",
       "exact ZOH model: input gain w0 instead of w0^2", LIM),
    _m("limits-zoh-plant-damping", "control", "workbench/stability/limits.py",
       "-2.0 * zeta * w0]])", "-zeta * w0]])",
       "exact ZOH model: damping zeta w0 instead of 2 zeta w0", LIM),
    # ------------------------------------------------------------------ core (blind round 2)
    # Written from the library code alone (the tests were not read first); the test
    # files were found afterwards by grepping for the module's imports.
    _m("pid-derivative-sign", "core", "workbench/controllers/pd.py",
       "u_free = u_center + kp * e + kd * (e - e_prev) / T",
       "u_free = u_center + kp * e + kd * (e_prev - e) / T",
       "PID derivative term with the difference reversed (damps the wrong way)", CORE_PD),
    _m("pid-derivative-times-t", "core", "workbench/controllers/pd.py",
       "u_free = u_center + kp * e + kd * (e - e_prev) / T",
       "u_free = u_center + kp * e + kd * (e - e_prev) * T",
       "PID derivative multiplied by the sample time instead of divided", CORE_PD),
    _m("pid-integral-no-t", "core", "workbench/controllers/pd.py",
       "integ = integral + e * T", "integ = integral + e",
       "PID integral sums errors without the sample time", CORE_PD),
    _m("pid-antiwindup-symbolic-swapped", "core", "workbench/controllers/pd.py",
       "u_try >= u_max), integral, integ)", "u_try >= u_max), integ, integral)",
       "symbolic anti-windup holds the integral when NOT saturated", CORE_PD),
    _m("pid-antiwindup-float-off", "core", "workbench/controllers/pd.py",
       "integ = integral            # hold", "integ = integ            # hold",
       "numeric anti-windup never holds the integral", CORE_PD),
    _m("pid-to-control-num", "core", "workbench/controllers/pd.py",
       "num = [a + self.ki * T, b - a, -b]", "num = [a + self.ki * T, b + a, -b]",
       "PID transfer function numerator: middle coefficient sign", CORE_PD),
    _m("pd-slow-pole-fast", "core", "workbench/controllers/pd.py",
       "return (z + math.sqrt(z * z - 1.0)) / w0", "return (z - math.sqrt(z * z - 1.0)) / w0",
       "slow time constant replaced by the fast one (zero on the fast pole)", CORE_PD),
    _m("pd-kd-over-tau", "core", "workbench/controllers/pd.py",
       "kd=kp * tau,", "kd=kp / tau,",
       "PD zero placement kd = kp / tau instead of kp tau", CORE_PD),
    _m("dac-quantise-floor", "core", "workbench/controllers/pd.py",
       "ca.floor(u / resolution + 0.5) * resolution", "ca.floor(u / resolution) * resolution",
       "DAC quantisation truncates instead of rounding", CORE_PD),
    _m("metrics-overshoot-relative-to-level", "core", "workbench/metrics.py",
       "overshoot=100.0 * over / abs(size)", "overshoot=100.0 * over / abs(seg.r_end)",
       "overshoot in % of the final level instead of the step size", CORE_MET),
    _m("metrics-peak-from-start", "core", "workbench/metrics.py",
       "peak = float(np.max(sgn * (xx - seg.r_end)))",
       "peak = float(np.max(sgn * (xx - seg.r_start)))",
       "overshoot measured from the step's start level", CORE_MET),
    _m("metrics-rise-20", "core", "workbench/metrics.py",
       "t10 = _first_crossing(tt, progress, 0.1)", "t10 = _first_crossing(tt, progress, 0.2)",
       "rise time from 20 % instead of 10 %", CORE_MET),
    _m("metrics-crossing-interp", "core", "workbench/metrics.py",
       "(level - y0) / (y1 - y0)", "(level - y1) / (y1 - y0)",
       "first crossing interpolated from the wrong end point", CORE_MET),
    _m("metrics-settling-frac", "core", "workbench/metrics.py",
       "frac = (a - band) / (a - b)", "frac = (a - band) / (a + b)",
       "settling-time interpolation denominator sign", CORE_MET),
    _m("metrics-settling-absolute", "core", "workbench/metrics.py",
       "return float(t[k] + frac * (t[k + 1] - t[k]) - t_step)",
       "return float(t[k] + frac * (t[k + 1] - t[k]))",
       "settling time absolute instead of from the step", CORE_MET),
    _m("metrics-sse-integral", "core", "workbench/metrics.py",
       "return trapezoid(y, t) / float(t[-1] - t[0])", "return trapezoid(y, t)",
       "steady-state error the integral, not the mean, over the window", CORE_MET),
    _m("metrics-trapezoid", "core", "workbench/metrics.py",
       "0.5 * (y[1:] + y[:-1])", "0.5 * (y[1:] + y[1:])",
       "trapezoid rule uses the right end twice (IAE)", CORE_MET),
    _m("ref-steps-last-level", "core", "workbench/references.py",
       "values=np.append(levels, levels[-1])", "values=np.append(levels, levels[0])",
       "steps: the final sample repeats the first level", CORE_REF),
    _m("ref-hold-left", "core", "workbench/references.py",
       'side="right") - 1', 'side="left") - 1',
       "held reference switches one instant late (value at the jump is the old one)", CORE_REF),
    _m("ref-profile-small-step", "core", "workbench/references.py",
       "(c + a, c - a, c - a + s, c - a)", "(c + a, c - a, c + a - s, c - a)",
       "validation profile: the small step from the wrong side", CORE_REF),
    _m("ref-ramp-duration", "core", "workbench/references.py",
       "t += abs(target - pts[-1][1]) / v", "t += abs(target - pts[-1][1]) * v",
       "ramp duration distance * speed", CORE_REF),
    _m("lin-freq-response-sign", "core", "workbench/linearize.py",
       "np.linalg.solve(1j * w * np.eye(n) - self.A, self.B)",
       "np.linalg.solve(1j * w * np.eye(n) + self.A, self.B)",
       "tangent frequency response with (jwI + A)", CORE_LIN),
    _m("lin-reduced-fit-damping", "core", "workbench/linearize.py",
       "hm = kv / (s * (s * s / w0 ** 2 + 2 * z * s / w0 + 1.0))",
       "hm = kv / (s * (s * s / w0 ** 2 + z * s / w0 + 1.0))",
       "reduced-model fit: damping term without the factor 2 (zeta doubled)", CORE_LIN),
    _m("lin-position-response", "core", "workbench/linearize.py",
       "2 * self.zeta * s / self.w0", "self.zeta * s / self.w0",
       "PositionModel.response without the factor 2", CORE_LIN),
    _m("lin-position-tf", "core", "workbench/linearize.py",
       "[1.0 / w ** 2, 2.0 * self.zeta / w, 1.0, 0.0]", "[1.0 / w, 2.0 * self.zeta / w, 1.0, 0.0]",
       "PositionModel.transfer_function: 1/w0 instead of 1/w0^2", CORE_LIN),
    _m("lin-paper000-w0", "core", "workbench/linearize.py",
       "4.0 * kappa * pressure * area ** 2 / (mass * vc)",
       "4.0 * kappa * pressure * area / (mass * vc)",
       "paper 000 w0 with A instead of A^2", CORE_LIN),
    _m("lin-paper000-zeta", "core", "workbench/linearize.py",
       "viscous / 2.0 * math.sqrt", "viscous * 2.0 * math.sqrt",
       "paper 000 zeta: k_f * 2 instead of k_f / 2", CORE_LIN),
    _m("lin-kv-from-flow", "core", "workbench/linearize.py",
       "q_per_volt / (pressure * area)", "q_per_volt / (pressure * area ** 2)",
       "Kv from flow: divided by A^2", CORE_LIN),
    _m("lin-tank-tau-k", "core", "workbench/linearize.py",
       "tau = volume / (k * gas.R_AIR * temperature * cp)",
       "tau = volume / (gas.R_AIR * temperature * cp)",
       "tank time constant without the polytropic exponent", CORE_LIN),
    _m("lin-tank-cp-sign", "core", "workbench/linearize.py",
       "cp, gu = -dqdp, dqdu", "cp, gu = dqdp, dqdu",
       "tank Cp = +dq/dp (negative time constant)", CORE_LIN),
    _m("eq-u-span", "core", "workbench/equilibrium.py",
       "u = center + zz[-1] * span", "u = center + zz[-1]",
       "equilibrium command not unscaled by the command span", CORE_EQ),
    _m("eq-centre-balance-swapped", "core", "workbench/equilibrium.py",
       "gas.iso6358_flow(1.0, b, p, p_atm, t, t))", "gas.iso6358_flow(1.0, b, p_atm, p, t, t))",
       "centre balance: exhaust flow with its pressures swapped", CORE_EQ),
    _m("eq-initial-pb", "core", "workbench/equilibrium.py",
       'base[plant.state_index("p_b")] = p_b', 'base[plant.state_index("p_b")] = p_a',
       "initial state: chamber B starts at chamber A's pressure", CORE_EQ),
    _m("eq-initial-v0", "core", "workbench/equilibrium.py",
       'base[plant.state_index("v")] = v0', 'base[plant.state_index("v")] = 0.0',
       "initial state ignores the initial velocity", CORE_EQ),
    _m("sim-quantise-floor", "core", "workbench/simulate.py",
       "return float(np.round(value / step) * step)", "return float(np.floor(value / step) * step)",
       "ADC quantisation truncates instead of rounding", CORE_SIM),
    _m("sim-delay-off-by-one", "core", "workbench/simulate.py",
       "self.pending = [None] * delay_samples", "self.pending = [None] * (delay_samples + 1)",
       "command delay one sample too long (and a delay with delay_samples = 0)", CORE_SIM),
    _m("sim-position-unquantised", "core", "workbench/simulate.py",
       'y = {"x": _quantise(float(state[self.ix]), self.position_resolution),',
       'y = {"x": float(state[self.ix]),',
       "closed loop measures the position without the ADC quantisation", CORE_SIM),
    _m("sim-open-loop-zoh", "core", "workbench/simulate.py",
       "state = sim.step(state, u[k], dts[k])[-1]", "state = sim.step(state, u[k + 1], dts[k])[-1]",
       "open loop applies the next sample's command over the interval", CORE_SIM),
    _m("sim-hold-block-state", "core", "workbench/simulate.py",
       "state = out[done + b - 1]", "state = out[done]",
       "hold(): the next block starts from the first state of the previous block", CORE_SIM),
    _m("sim-grid-last-sample", "core", "workbench/simulate.py",
       "out_t = T * np.arange(int(np.floor(t_end / T + 1e-9)) + 1)",
       "out_t = T * np.arange(int(np.floor(t_end / T + 1e-9)))",
       "closed-loop output grid misses the sample at t_end", CORE_SIM),
    _m("signals-noise-leverage", "core", "workbench/signals.py",
       "robust = _MAD_TO_STD * mad / math.sqrt(1.0 - h0)", "robust = _MAD_TO_STD * mad",
       "noise floor without the smoother's leverage correction", CORE_SIG),
    _m("signals-noise-quant-sqrt12", "core", "workbench/signals.py",
       "quantisation_step(y) / math.sqrt(12.0)", "quantisation_step(y) / 12.0",
       "quantisation noise q/12 instead of q/sqrt(12)", CORE_SIG),
    _m("signals-fit-no-mean", "core", "workbench/signals.py",
       "den = float(np.linalg.norm(y - y.mean()))", "den = float(np.linalg.norm(y))",
       "fit % normalised by ||y|| instead of ||y - mean(y)||", CORE_SIG),
    _m("signals-ljung-box-n2", "core", "workbench/signals.py",
       "q = n * (n + 2) * float(np.sum(r[1:] ** 2 / (n - tau)))",
       "q = n * n * float(np.sum(r[1:] ** 2 / (n - tau)))",
       "Ljung-Box Q with n^2 instead of n (n + 2)", CORE_SIG),
    _m("signals-ljung-box-dof", "core", "workbench/signals.py",
       "return q, float(stats.chi2.sf(q, lags))", "return q, float(stats.chi2.sf(q, lags - 1))",
       "Ljung-Box p-value with one degree of freedom too few", CORE_SIG),
    _m("signals-derivative-dt", "core", "workbench/signals.py",
       "return savgol(y, window, order, deriv=deriv, dt=dt)",
       "return savgol(y, window, order, deriv=deriv)",
       "derivative per sample instead of per second", CORE_SIG),
    _m("replay-closed-time-origin", "core", "workbench/replay.py",
       "t = np.asarray(recording.t, dtype=float) - float(recording.t[0])",
       "t = np.asarray(recording.t, dtype=float)",
       "closed-loop replay keeps the recording's time origin", CORE_REP),
    _m("replay-initial-pb", "core", "workbench/replay.py",
       'p_b = float(recording["p_b"][0])', 'p_b = float(recording["p_a"][0])',
       "replay starts chamber B at chamber A's recorded pressure", CORE_REP),
    _m("replay-hold-next-command", "core", "workbench/replay.py",
       "sim.hold(state, float(u[k]), dt[k:j])", "sim.hold(state, float(u[j]), dt[k:j])",
       "hold runs apply the command after the run", CORE_REP),
    _m("validate-band-min", "core", "workbench/specification.py",
       "return max(self.settling_band * abs(step_size), self.band_floor)",
       "return min(self.settling_band * abs(step_size), self.band_floor)",
       "settling band the smaller of relative band and floor", CORE_VAL),
    _m("validate-saturation-zoh", "core", "workbench/validate.py",
       "np.sum(dt * sat[:-1])", "np.sum(dt * sat[1:])",
       "saturation share weights each sample by the interval before it", CORE_VAL),
    _m("validate-pressure-low-bound", "core", "workbench/validate.py",
       "lo, hi = p_atm - spec.pressure_tolerance,", "lo, hi = p_atm + spec.pressure_tolerance,",
       "low pressure bound atmosphere + tolerance", CORE_VAL),
    _m("tableau-rk4-a", "core", "workbench/integrate/tableaux.py",
       "(0.0, 0.0, 1.0, 0.0)),", "(0.0, 0.0, 0.5, 0.0)),",
       "RK4 fourth stage from x + h/2 k3", CORE_INT),
    _m("tableau-radau2-a", "core", "workbench/integrate/tableaux.py",
       "a=((5.0 / 12.0, -1.0 / 12.0),", "a=((5.0 / 12.0, 1.0 / 12.0),",
       "Radau IIA(2) a12 sign", CORE_INT),
    _m("tableau-radau3-c-swapped", "core", "workbench/integrate/tableaux.py",
       "c=((4 - _S6) / 10, (4 + _S6) / 10, 1.0)", "c=((4 + _S6) / 10, (4 - _S6) / 10, 1.0)",
       "Radau IIA(3) nodes swapped", CORE_INT),
    _m("tableau-ros2-c", "core", "workbench/integrate/tableaux.py",
       "c=((), (-2.0,)), m=(1.5, 0.5)", "c=((), (-1.0,)), m=(1.5, 0.5)",
       "ROS2 c21 = -1 instead of -2", CORE_INT),
    _m("tableau-ros4-gamma", "core", "workbench/integrate/tableaux.py",
       "gamma=0.57282,", "gamma=0.5,",
       "ROS4 gamma rounded to 0.5", CORE_INT),
    _m("tableau-rodas4-c21", "core", "workbench/integrate/tableaux.py",
       "c=((), (-5.6688,),", "c=((), (5.6688,),",
       "RODAS4 c21 sign", CORE_INT),
    _m("rosenbrock-hw-c-over-h", "core", "workbench/integrate/steppers.py",
       "(cj if w_form else cj / h)", "(cj if w_form else cj * h)",
       "Rosenbrock (HW form): c_ij k_j times h instead of over h", CORE_INT),
    _m("rosenbrock-w-a-h", "core", "workbench/integrate/steppers.py",
       "(h * aj if w_form else aj)", "(aj if w_form else aj)",
       "Rosenbrock (W form): stage argument without the step h", CORE_INT),
    _m("explicit-rk-stage-h", "core", "workbench/integrate/steppers.py",
       "arg = arg + (h * tableau.a[i][j]) * k[j]", "arg = arg + tableau.a[i][j] * k[j]",
       "explicit RK stage argument without the step h", CORE_INT),
    _m("radau-newton-r2-sign", "core", "workbench/integrate/steppers.py",
       "r2 = G[1] - (alp * W[1] - bet * W[2]) / h", "r2 = G[1] - (alp * W[1] + bet * W[2]) / h",
       "Radau simplified Newton: rotated block residual sign", CORE_INT),
    _m("kernel-pade-b0", "core", "workbench/stability/kernel.py",
       "V = sum(b[2 * j] * powers[j] for j in range(m // 2 + 1))",
       "V = sum(b[2 * j] * powers[j] for j in range(m // 2 + 1)) + (b[1] - b[0]) * eye",
       "batched expm (degrees below 13): Pade V with b1 instead of b0", CORE_KER),
    _m("kernel-zoh-b-no-t", "core", "workbench/stability/kernel.py",
       "Maug[:, :n, n:] = Bs * T[:, None, None]", "Maug[:, :n, n:] = Bs",
       "ZOH discretisation: B block not multiplied by T", CORE_KER),
    _m("kernel-kv-span", "core", "workbench/stability/kernel.py",
       "return s * sol[:, 0] * self.state_scale[0] / self.u_scale",
       "return s * sol[:, 0] * self.state_scale[0] * self.u_scale",
       "velocity gain Kv per V^-1 scaled the wrong way", CORE_KER),
    _m("kernel-dominant-zeta", "core", "workbench/stability/kernel.py",
       "zeta = np.where(ok, -(l1 + l2).real / (2 * w0), np.nan)",
       "zeta = np.where(ok, -(l1 + l2).real / w0, np.nan)",
       "dominant mode zeta without the factor 2", CORE_KER),
    _m("kernel-dc-kd-t", "core", "workbench/stability/kernel.py",
       "Dc = (kp + kd / T + ki * T) * gain", "Dc = (kp + kd * T + ki * T) * gain",
       "closed-loop kernel: derivative gain kd T instead of kd / T", CORE_KER),
    _m("kernel-integral-t", "core", "workbench/stability/kernel.py",
       "Acl[:, c, 0] = -T * cx", "Acl[:, c, 0] = -cx",
       "closed-loop kernel: integral state without the sample time", CORE_KER),
    # ------------------------------------------- issue 17 remainder: JSON values (p17)
    _m("greybox-interr-nominal-params", "identify", "workbench/identify/grey_box/estimate.py",
       "anchors[0], params=p_hat, anchors=anchors, every=M)",
       "anchors[0], params=None, anchors=anchors, every=M)",
       "grey-box integration error: CVODES with the nominal, not the estimated, parameters",
       GREY_VAL),
    _m("greybox-interr-anchor-shift", "identify", "workbench/identify/grey_box/estimate.py",
       "anchors = s_nodes[d.first:d.first + d.n_int] * prob.sc",
       "anchors = np.roll(s_nodes[d.first:d.first + d.n_int], -1, axis=0) * prob.sc",
       "grey-box integration error: each interval started from the next node", GREY_VAL),
    _m("greybox-corr-optimiser-units", "identify", "workbench/identify/grey_box/covariance.py",
       "corr = cov / np.outer(std, std)", "corr = cov_z / np.outer(std, std)",
       "grey-box correlation from the optimiser-unit covariance over parameter-unit stds",
       GREY_VAL),
    _m("greybox-cov-unit-variance", "identify", "workbench/identify/grey_box/covariance.py",
       "var[rows] = np.mean(r[rows] ** 2) / dof", "var[rows] = 1.0 / dof",
       "grey-box covariance assumes the normalised residuals have unit variance", GREY_VAL),
    _m("equilibrium-residual-norm", "core", "workbench/equilibrium.py",
       "return sol.x, float(np.max(np.abs(np.asarray(resfun(sol.x)[0]).ravel()[:n_eq])))",
       "return sol.x, float(np.linalg.norm(np.asarray(resfun(sol.x)[0]).ravel()[:n_eq]))",
       "equilibrium residual: 2-norm of the rows instead of the largest row", LIN_VAL),
    _m("compare-air-anr-density", "core", "workbench/compare.py",
       '"air_l_anr": air_kg / RHO_ANR * 1e3,', '"air_l_anr": air_kg * RHO_ANR * 1e3,',
       "figures: litres ANR multiplied by the density instead of divided", DESIGN_VAL),
    _m("compare-activity-per-sample", "core", "workbench/compare.py",
       "float(np.sum(np.abs(np.diff(u_s))) / duration)",
       "float(np.sum(np.abs(np.diff(u_s))) / len(u_s))",
       "figures: command activity per sample instead of per second", DESIGN_VAL),
    _m("compare-settled-unmasked", "core", "workbench/compare.py",
       '"max_error_settled": float(np.max(e[settled])) if settled.any() else math.nan,',
       '"max_error_settled": float(np.max(e)) if settled.any() else math.nan,',
       "figures: the settled error taken over the whole run", DESIGN_VAL),
    _m("validate-saturation-count", "core", "workbench/validate.py",
       "sat_frac = float(np.sum(dt * sat[:-1]) / (t[-1] - t[0]))",
       "sat_frac = float(np.mean(sat))",
       "saturation share counted over samples instead of held time", DESIGN_VAL),
    _m("jit-cache-hit-flag", "core", "workbench/integrate/jit.py",
       "        return target, True", "        return target, False",
       "JIT cache: a hit reported as a fresh build", JIT),
    _m("jit-no-compiler-raises", "core", "workbench/integrate/jit.py",
       "    if not have_compiler():\n        return fun",
       "    if not have_compiler():\n        raise CompileError('no C compiler found')",
       "JIT: no compiler is an error instead of the virtual machine", JIT),
    _m("compiled-loop-error-lost", "core", "workbench/bench/compiled_loop.py",
       "self._native, self.native_error = False, str(exc)",
       "self._native, self.native_error = False, None",
       "compiled loop: the reason the C loop is not used is lost", JIT),
    _m("output-not-input-unresolved", "core", "workbench/output.py",
       "ins[Path(p).resolve()] = p", "ins[Path(p)] = p",
       "check_not_input compares input paths unresolved (./x, symlinks, relative)", OUTPUT),
    _m("output-not-input-staged-paths", "core", "workbench/output.py",
       "check_not_input([out_abs / p.relative_to(stage) for p in files], inputs)",
       "check_not_input(files, inputs)",
       "result_set checks the staged paths, not their destinations, against the inputs", OUTPUT),
    _m("output-stage-over-existing", "core", "workbench/output.py",
       "        if not out_abs.exists():", "        if True:",
       "result_set renames the stage over an existing folder", OUTPUT),
    _m("output-stage-left-behind", "core", "workbench/output.py",
       "        if stage.exists():", "        if stage.exists() and False:",
       "result_set leaves the hidden staging folder behind on failure", OUTPUT),
)


# ------------------------------------------------------------------ checking the list
def stale(mutations: Sequence[Mutation], root: Path = REPO) -> list[str]:
    """Problems with the list: a missing file, or an original text that does not
    occur exactly once in its file (the code moved: update the mutation)."""
    problems = []
    names = [m.name for m in mutations]
    for n in sorted({n for n in names if names.count(n) > 1}):
        problems.append(f"{n}: name used more than once")
    for m in mutations:
        path = root / m.file
        if m.group not in GROUPS:
            problems.append(f"{m.name}: unknown group {m.group!r}")
        if not path.is_file():
            problems.append(f"{m.name}: {m.file} does not exist")
            continue
        count = path.read_text().count(m.original)
        if count != 1:
            problems.append(f"{m.name}: original text occurs {count} times in {m.file} "
                            f"(expected exactly once): {m.original!r}")
        if m.original == m.replacement:
            problems.append(f"{m.name}: replacement equals the original")
    return problems


def present_tests(m: Mutation, root: Path = REPO, collected: set[str] | None = None
                  ) -> tuple[list[str], list[str]]:
    """(the test ids of ``m`` to run, those skipped because they do not exist (yet)).

    A file that does not exist is skipped. With ``collected`` (the node ids pytest
    collects, see :func:`collect_nodes`), a node id ``file::test[...]`` it does not
    know is skipped too; when none of a file's node ids is left (renamed), the whole
    file runs instead.
    """
    have, missing = [], []
    for t in m.tests:
        f = t.split("::", 1)[0]
        ok = (root / f).is_file() and ("::" not in t or collected is None or t in collected)
        (have if ok else missing).append(t)
    for f in dict.fromkeys(t.split("::", 1)[0] for t in missing if "::" in t):
        if (root / f).is_file() and not any(h.split("::", 1)[0] == f for h in have):
            have.append(f)
    return have, missing


def collect_nodes(mutations: Sequence[Mutation], workdir: Path, python: str) -> set[str]:
    """Node ids pytest collects (unmutated) in the files that mutations name by node id."""
    files = sorted({t.split("::", 1)[0] for m in mutations for t in m.tests
                    if "::" in t and (workdir / t.split("::", 1)[0]).is_file()})
    if not files:
        return set()
    env = dict(os.environ, PYTHONPATH=str(workdir))
    proc = subprocess.run([python, "-m", "pytest", "--collect-only", "-q", "-p",
                           "no:cacheprovider", "-o", "addopts=", *files], cwd=workdir,
                          env=env, capture_output=True, text=True, timeout=600)
    return {ln.strip() for ln in proc.stdout.splitlines() if "::" in ln}


# ------------------------------------------------------------------ running
@dataclasses.dataclass
class Outcome:
    """What happened to one mutant."""

    name: str
    group: str
    status: str            # killed / survived / timeout / error
    seconds: float
    detail: str = ""
    tests: tuple[str, ...] = ()
    missing: tuple[str, ...] = ()


def _copy_tree(dest: Path) -> None:
    """Copy :data:`COPIED` of the repository into ``dest`` (no bytecode, no caches)."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache")
    for item in COPIED:
        src = REPO / item
        if src.is_dir():
            shutil.copytree(src, dest / item, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, dest / item)


def _drop_bytecode(path: Path) -> None:
    """Remove the cached bytecode of ``path`` (a same-size edit in the same second
    would otherwise be served from a stale .pyc)."""
    for pyc in (path.parent / "__pycache__").glob(path.stem + ".*.pyc"):
        pyc.unlink(missing_ok=True)


def _summary_line(output: str) -> str:
    """The first failing test (if any) and pytest's last line."""
    lines = [ln for ln in output.strip().splitlines() if ln.strip()]
    failed = [ln for ln in lines if ln.startswith(("FAILED", "ERROR"))]
    tail = lines[-1] if lines else ""
    return (failed[0] + " | " if failed else "") + tail


def run_one(m: Mutation, workdir: Path, timeout: float, python: str,
            collected: set[str] | None = None) -> Outcome:
    """Plant ``m`` in the copy at ``workdir``, run its tests there, restore the file."""
    have, missing = present_tests(m, workdir, collected)
    if not have:
        return Outcome(m.name, m.group, "error", 0.0,
                       "none of its test files exists", (), tuple(missing))
    path = workdir / m.file
    text = path.read_text()
    if text.count(m.original) != 1:
        return Outcome(m.name, m.group, "error", 0.0,
                       f"stale: original text occurs {text.count(m.original)} times",
                       tuple(have), tuple(missing))
    env = dict(os.environ, PYTHONPATH=str(workdir), PYTHONHASHSEED="0")
    env.setdefault("WORKBENCH_CACHE", str(Path(tempfile.gettempdir()) / "workbench-mutation-jit"))
    cmd = [python, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--no-header",
           "-o", "addopts=", *have]
    t0 = time.monotonic()
    try:
        path.write_text(text.replace(m.original, m.replacement))
        _drop_bytecode(path)
        proc = subprocess.Popen(cmd, cwd=workdir, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, start_new_session=True)
        try:
            out, _ = proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)          # only the group this script started
            proc.communicate()
            return Outcome(m.name, m.group, "timeout", time.monotonic() - t0,
                           f"over {timeout:g} s", tuple(have), tuple(missing))
    finally:
        path.write_text(text)
        _drop_bytecode(path)
    rc = proc.returncode
    status = {0: "survived", 1: "killed", 2: "killed"}.get(rc, "error")
    detail = _summary_line(out)
    if rc == 2:
        detail = "collection/import error: " + detail
    elif status == "error":
        detail = f"pytest exit {rc}: " + detail
    return Outcome(m.name, m.group, status, time.monotonic() - t0, detail[:200],
                   tuple(have), tuple(missing))


def run_baseline(tests: Sequence[str], workdir: Path, timeout: float, python: str,
                 collected: set[str] | None = None) -> Outcome:
    """The targeted tests on the unmutated copy: they must pass, or a kill means nothing."""
    m = Mutation("(baseline: no mutation)", "-", "pyproject.toml", "[tool.pytest",
                 "[tool.pytest", "unmutated", tuple(tests))
    return run_one(m, workdir, timeout, python, collected)


def run_all(mutations: Sequence[Mutation], jobs: int, timeout: float, python: str,
            baseline: bool = True, progress=print) -> tuple[list[Outcome], Outcome | None]:
    """Run every mutant in ``jobs`` temporary copies of the repository."""
    tmp = Path(tempfile.mkdtemp(prefix="workbench-mutation-"))
    outcomes: dict[str, Outcome] = {}
    base: Outcome | None = None
    try:
        slots = []
        for i in range(max(1, jobs)):
            d = tmp / f"copy{i}"
            d.mkdir()
            _copy_tree(d)
            slots.append(d)
        collected = collect_nodes(mutations, slots[0], python)
        gone = sorted({t for m in mutations for t in present_tests(m, slots[0], collected)[1]
                       if "::" in t})
        if gone:
            progress("skipping test node ids pytest does not collect: " + ", ".join(gone))
        if baseline:
            union = sorted({t for m in mutations
                            for t in present_tests(m, slots[0], collected)[0]})
            progress(f"baseline: {len(union)} test files, unmutated ...")
            base = run_baseline(union, slots[0], 4 * timeout, python, collected)
            verdict = "passed" if base.status == "survived" else f"FAILED ({base.status})"
            progress(f"baseline: {verdict} ({base.seconds:.0f} s) {base.detail}")
        free = list(slots)
        lock = threading.Lock()
        done = [0]

        def work(m: Mutation) -> Outcome:
            with lock:
                d = free.pop()
            try:
                o = run_one(m, d, timeout, python, collected)
            finally:
                with lock:
                    free.append(d)
                    done[0] += 1
                    progress(f"[{done[0]:>3}/{len(mutations)}] {o.status:<8} {o.seconds:6.1f} s "
                             f"{m.group:<8} {m.name}")
            return o

        with ThreadPoolExecutor(max_workers=len(slots)) as ex:
            for o in ex.map(work, mutations):
                outcomes[o.name] = o
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [outcomes[m.name] for m in mutations], base


# ------------------------------------------------------------------ reporting
def scores(outcomes: Sequence[Outcome]) -> dict[str, dict[str, int]]:
    """Per group (and ``all``): killed, total and each status's count."""
    out: dict[str, dict[str, int]] = {}
    for o in outcomes:
        for g in (o.group, "all"):
            s = out.setdefault(g, {"killed": 0, "survived": 0, "timeout": 0, "error": 0,
                                   "total": 0})
            s[o.status] += 1
            s["total"] += 1
    return out


def table(outcomes: Sequence[Outcome]) -> str:
    """The outcome table, the skipped (missing) test files and the score per group."""
    lines = [f"{'status':<9}{'secs':>6}  {'group':<9}{'mutation':<34}detail"]
    for o in outcomes:
        lines.append(f"{o.status:<9}{o.seconds:6.1f}  {o.group:<9}{o.name:<34}{o.detail}")
    missing = sorted({t for o in outcomes for t in o.missing})
    if missing:
        lines.append("")
        lines.append("tests named by mutations but missing (skipped): " + ", ".join(missing))
    lines.append("")
    sc = scores(outcomes)
    for g in [*GROUPS, "all"]:
        if g in sc:
            s = sc[g]
            extra = ", ".join(f"{s[k]} {k}" for k in ("survived", "timeout", "error") if s[k])
            lines.append(f"score {g:<9} {s['killed']:>3} / {s['total']:<3} killed"
                         + (f"  ({extra})" if extra else ""))
    surv = [o.name for o in outcomes if o.status != "killed"]
    if surv:
        lines.append("not killed: " + ", ".join(surv))
    return "\n".join(lines)


def list_text(mutations: Sequence[Mutation]) -> str:
    """The mutations, their files, descriptions and test files (``--list``)."""
    rows = []
    for m in mutations:
        have, missing = present_tests(m)
        tests = " ".join(Path(t).name for t in have)
        miss = f"  [missing: {' '.join(Path(t).name for t in missing)}]" if missing else ""
        rows.append(f"{m.group:<9}{m.name:<34}{m.file}\n{'':9}{m.description}\n{'':9}"
                    f"tests: {tests}{miss}")
    return "\n".join(rows) + f"\n{len(mutations)} mutations"


def select(modules: str | None, only: str | None) -> list[Mutation]:
    """The mutations of the ``--modules`` groups and ``--only`` names (all by default)."""
    ms = list(MUTATIONS)
    if modules:
        want = [g.strip() for g in modules.split(",") if g.strip()]
        bad = [g for g in want if g not in GROUPS]
        if bad:
            raise SystemExit(f"unknown module group(s) {bad}; expected some of {GROUPS}")
        ms = [m for m in ms if m.group in want]
    if only:
        names = [n.strip() for n in only.split(",") if n.strip()]
        known = {m.name for m in MUTATIONS}
        bad = [n for n in names if n not in known]
        if bad:
            raise SystemExit(f"unknown mutation(s) {bad}; see --list")
        ms = [m for m in ms if m.name in names]
    return ms


def main(argv: Sequence[str] | None = None) -> int:
    """Command line; returns 0, or 1/2 when the list is stale."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--modules", help="comma-separated groups: " + ",".join(GROUPS))
    ap.add_argument("--only", help="comma-separated mutation names")
    ap.add_argument("--list", action="store_true", help="list the mutations, run nothing")
    ap.add_argument("--jobs", type=int, default=1, help="mutants run at once (default 1)")
    ap.add_argument("--timeout", type=float, default=DEFAULT_TIMEOUT,
                    help=f"seconds per mutant (default {DEFAULT_TIMEOUT:g})")
    ap.add_argument("--no-baseline", action="store_true",
                    help="skip the run of the targeted tests on the unmutated copy")
    ap.add_argument("--json", metavar="OUT", help="write the outcomes and scores as JSON")
    ap.add_argument("--python", default=sys.executable, help="interpreter that runs pytest")
    args = ap.parse_args(argv)
    ms = select(args.modules, args.only)
    problems = stale(ms)
    if args.list:
        print(list_text(ms))
        for p in problems:
            print("STALE: " + p)
        return 1 if problems else 0
    if problems:
        print("stale mutations (fix tests/mutation.py before running):", *problems, sep="\n  ")
        return 2
    missing = sorted({t for m in ms for t in present_tests(m)[1]})
    if missing:
        print("skipping test files that do not exist yet: " + ", ".join(missing))
    t0 = time.monotonic()
    outcomes, base = run_all(ms, args.jobs, args.timeout, args.python,
                             baseline=not args.no_baseline)
    print()
    print(table(outcomes))
    print(f"wall time {time.monotonic() - t0:.0f} s with --jobs {args.jobs}")
    if base is not None and base.status != "survived":
        print(f"WARNING: the targeted tests do not pass unmutated ({base.status}: "
              f"{base.detail}); kills are not evidence")
    if args.json:
        Path(args.json).write_text(json.dumps({
            "outcomes": [dataclasses.asdict(o) for o in outcomes],
            "scores": scores(outcomes),
            "baseline": None if base is None else dataclasses.asdict(base),
            "missing_test_files": missing,
        }, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
