"""The designed NMPC on a rig simulated by other code (issue 14's blind check, in small).

``controllers.design(plant, "nmpc")`` from the plant file of designs/precision_positioning.py
runs in closed loop (tests/foreign_loop.py) with tests/foreign_rig.py's rig: the plant
file's friction as a LuGre model (pre-sliding, frictional lag; the workbench simulates
Karnopp stick-slip), lines as 5 pi-segments with laminar + Blasius resistance (the
workbench: its own segment layout), scipy's LSODA, a 12-bit position ADC and 300 Pa
pressure noise drawn by the loop, not by workbench.controllers.sensors. Two 60 mm steps
and their holds (3.3 s).

Measured 2026-11-24 (the first two holds of the 10.8 s profile, seed 0): steady state 0.093 / 0.021 mm (quantum
0.122 mm), no command activity over the holds' second halves. The same controller
with the hold lock it replaced (valve closed within half a quantum, released beyond
two): 0.039 / 0.057 mm on this rig, but on the lumped-line LuGre rig 0.178 mm and on
smooth-friction rigs hunting of 1.2-7.8 mm peak-to-peak (the full 10.8 s profile of
tests/test_precision_positioning.py; the table in designs/precision_positioning.py's
report).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import foreign_loop as fl
from workbench import Plant, references
from workbench.controllers.design import design

PLANT = Path(__file__).resolve().parents[1] / "designs" / "plants" / "rigs" / "precision_rig25.toml"
C = 0.25


@pytest.fixture(scope="module")
def run():
    plant = Plant.from_toml(PLANT)
    p = references.profile([(0, C), (0.3, C), (0.3, C + 0.06), (1.8, C + 0.06), (1.8, C),
                            (3.3, C)])
    ref = references.Reference(p.times, p.values)
    q = plant.stroke / 4096
    ctrl = design(plant, "nmpc", reference=ref, quantum=q, pressure_noise=300.0)
    rig = fl.rig_for(PLANT, law="lugre", line_model="pi5")
    return fl.run(ctrl, rig, ref, 3.3, seed=0), q, ctrl.inner.lead


def test_the_loop_reads_the_rigs_adc_and_applies_the_clipped_command(run):
    res, q, _ = run
    # position ADC: 12 bits over the 0.5 m stroke, no position noise given
    assert np.allclose(res.x_meas, np.round(res.x / q) * q, atol=1e-12)
    assert res.u.min() >= 0.0 and res.u.max() <= 10.0
    # it moved as commanded: within 1 mm of each step's target 0.5 s after it
    for t, target in ((0.8, C + 0.06), (2.3, C)):
        assert abs(res.x[np.searchsorted(res.t, t)] - target) < 1e-3


def test_holds_on_the_foreign_lugre_rig_are_within_one_quantum_and_at_rest(run):
    # a strict xfail after session 7's merge (hold 1: 0.197 mm peak-to-peak in its
    # second half). Now (branch h14f) hold 1 is locked at rest from 0.46 s until the
    # hold hands over to the NMPC one horizon (80 ms) before the step; the NMPC then
    # starts the step early (0.195 mm, 37 command changes before 1.8 s). That window
    # is the next move's and is left out, as in evaluation.hold_evidence
    res, q, lead = run
    holds = fl.holds(res, q, lead=lead)
    assert len(holds) == 2
    for h in holds:
        assert h["steady_state_error"] <= q, holds
        # no limit cycle: over the second half the position within a quantum and at
        # most the two command changes of the valve closing once
        assert h["peak_to_peak"] <= q and h["command_changes"] <= 2, holds
    assert math.isclose(holds[0]["target"], C + 0.06)


@pytest.fixture(scope="module")
def fl_smooth_lumped():
    """The designed FL on the foreign rig with smooth Stribeck friction and one lumped
    line section, sensor seeds 0 and 1: the hold evidence of each run."""
    plant = Plant.from_toml(PLANT)
    p = references.profile([(0, C), (0.3, C), (0.3, C + 0.06), (1.8, C + 0.06), (1.8, C),
                            (3.3, C)])
    ref = references.Reference(p.times, p.values)
    q = plant.stroke / 4096
    rig = fl.rig_for(PLANT, law="smooth", line_model="lumped")
    out = []
    for seed in (0, 1):
        ctrl = design(plant, "fl", reference=ref, quantum=q, pressure_noise=300.0)
        out.append(fl.holds(fl.run(ctrl, rig, ref, 3.3, seed=seed), q, lead=ctrl.inner.lead))
    return out, q


def test_fl_lands_near_its_targets_on_the_smooth_friction_lumped_line_rig(fl_smooth_lumped):
    # session 9 (h14h): PID and FL hunted on this rig, 0.6-1.5 mm off with 33-80
    # command changes per hold. The FL at 25 rad/s arrived short (a stuck piston
    # the position terms moved at k0 e = 15.6e3 e m/s^3) and the holds pulsed from
    # there: steady state (mm) seed 0 1.52 / 0.99, seed 1 0.64 / 2.07, mean 1.31.
    # At the bandwidth the lines' delay allows (40 rad/s, design._fl_bandwidth) and
    # with the break-away probe (design.breakaway_probe): seed 0 0.08 / 0.28, seed 1
    # 0.60 / 0.16 mm; not at rest: 29-40 command changes per hold, in the hold's
    # settle / pulse modes (the FL stops 0.2-0.8 mm short and the hold pulses it
    # in). On the LuGre 5-segment rig the same FL is within a quantum and at rest
    # (0.094 / 0.017 and 0.101 / 0.043 mm, no command change; main 0.58 / 0.17 mm
    # with 26 changes). Required: the mean over the four holds below 0.5 mm (0.28)
    runs, q = fl_smooth_lumped
    errors = [h["steady_state_error"] for holds in runs for h in holds]
    assert len(errors) == 4
    assert np.mean(errors) < 0.5e-3, errors
