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


# ------------------------------------------------------------ rigs unlike our plant files
# Each designed controller (design(plant, kind), the plant file only) on the rigs of
# foreign_loop.FOREIGN_RIGS: a 32 mm bore, 200 mm stroke, 2 kg rig whose file is 5-10 %
# off (mass, supply, valve conductance) with smooth Stribeck friction and 5-segment
# lines; the precision rig with a 5 % spool overlap, a 10-bit position sensor, LuGre
# friction 20 % above its file and one lumped line section. Two steps of 12 % of the
# stroke, each held 1.5 s; sensor seed 0; the NMPC in CasADi's VM (jit=False: the
# same law as compiled).
FOREIGN_KINDS = ("pid", "fl", "nmpc")


@pytest.fixture(scope="module")
def foreign_runs(tmp_path_factory):
    directory = tmp_path_factory.mktemp("foreign_rigs")
    out = {}
    for name in fl.FOREIGN_RIGS:
        path, rig, bits = fl.foreign_rig(name, directory)
        plant = Plant.from_toml(path)
        ref, duration = fl.step_profile(plant.stroke)
        q = plant.stroke / 2 ** bits
        for kind in FOREIGN_KINDS:
            ctrl = design(plant, kind, reference=ref, quantum=q, pressure_noise=300.0, jit=False)
            res = fl.run(ctrl, rig, ref, duration, seed=0, position_bits=bits)
            out[name, kind] = (res, fl.holds(res, q, lead=ctrl.inner.lead), q, plant,
                               ctrl.inner.hold.range, rig)
    return out


def test_the_foreign_plant_files_are_off_the_rigs_as_stated(foreign_runs):
    # the user's file: 2.0 kg, 6 bar, C = 6.25e-8; the rig: +8 %, -6 %, -8 %
    _, _, q, plant, _, rig = foreign_runs["bore32", "pid"]
    assert plant.stroke == 0.2 and float(plant.area_a) == pytest.approx(math.pi / 4 * 0.032 ** 2)
    assert float(plant.params["load.mass"]) == 2.0 and rig.m == pytest.approx(2.16)
    assert rig.P["supply.pressure"] == pytest.approx(0.94 * float(plant.params["supply.pressure"]))
    assert rig.P["valve.sonic_conductance"] == pytest.approx(
        0.92 * float(plant.params["valve.sonic_conductance"]))
    assert q == pytest.approx(0.2 / 4096)
    _, _, q, plant, _, rig = foreign_runs["overlap5_10bit", "fl"]
    assert float(plant.params["valve.deadband"]) == 0.05 and q == pytest.approx(0.5 / 1024)
    assert rig.lugre and (rig.fc, rig.fs) == (18.0, 30.0)      # file: 15 / 25 N
    assert rig.nodes == 1


@pytest.mark.parametrize("kind", FOREIGN_KINDS)
@pytest.mark.parametrize("name", sorted(fl.FOREIGN_RIGS))
def test_designed_controllers_stay_within_the_holds_reach_on_foreign_rigs(foreign_runs, name, kind):
    # no divergence or runaway: the piston inside the stroke, the command inside the
    # valve's range, each step reached, and from 0.5 s into each hold on the piston
    # within the range in which the hold takes a stuck piston over (hold_range: 2 mm
    # or the law's dead zone or the break-away jump): beyond it nothing in the design
    # would bring it back, within it the hold's pulses do
    res, holds, q, plant, reach, _ = foreign_runs[name, kind]
    assert np.all(np.isfinite(res.x)) and res.x.min() > 0 and res.x.max() < plant.stroke
    assert res.u.min() >= 0.0 and res.u.max() <= 10.0
    assert len(holds) == 2
    for h in holds:
        window = (res.t >= h["start"] + 0.5) & (res.t <= h["end"])
        worst = np.abs(res.r[window] - res.x[window]).max()
        assert worst < reach, (name, kind, h, worst, reach)


#: Failures of the precision specification on these rigs, for their owners: every one
#: is in a hold's second half. PID and FL re-measured on main d69980b, 2026-11-25
#: (h14r, /tmp/h14r/foreign.py: this module's runs, sensor seeds 0 / 1; per hold: steady
#: state, command changes and peak-to-peak over its second half). On the smooth-Stribeck
#: bore32 rig (no stiction plateau: a piston under any net force creeps) the hold leaves the valve closed with 1.2-1.3 N of
#: net force, inside its force band (F_c / 10 = 2.2 N), and the piston creeps at
#: 0.07 mm/s, a quantum in 0.7 s; the force loop's smallest step (MIN_OPENING for one
#: sample) is 1.55 N there. On the 10-bit LuGre rig the PID arrives 2.2-2.4 mm short (its
#: rate feedforward drops the model friction's collapse, -3.7 V for one sample, as the
#: reference stops while the piston still slides 2.6 mm behind at 50-90 mm/s) and the
#: hold walks it in one 0.49 mm quantum per pulse, 100-250 ms apart.
#: bore32 NMPC passes since branch h14q (hold.HoldPositioner._balance: a held piston
#: seen to creep has its net force balanced and is not pulsed one level out): seed 0
#: holds 0.014 / 0.018 mm with 7 / 17 command changes (0.033 / 0.052 mm p-p) -> 0.022 /
#: 0.019 mm, 0 / 0; seed 1 0.029 / 0.018 mm, 6 / 4 -> 0.024 / 0.005 mm, 0 / 0.
#: bore32 PID / FL, c978f63 (h14u, 2026-11-25, seeds 0-4): 0/5 and 1/5 seeds pass. The same
#: balance extended to the aimed hold (notes/s13/h14u_v7_aim_balance.patch, NOT merged)
#: gave 3/5 and 4/5, but on the smooth-Stribeck lumped-line rig PID seed 0 hold 1 went
#: from 2 to 6 command changes (tests/test_hold.py's PID case fails) and seed 3 hold 2
#: from 0.029 mm to a 3.8 mm slide (a pulse after a changed end state); evidence only
#: from a level boundary more than q / 2 from r left that rig as it was but bore32 too.
FOREIGN_SPEC_FAILS = {
    ("bore32", "pid"): "creeps: 0.029 / 0.090 mm (q 0.049 mm), 9 / 0 command changes, "
                       "0.10 / 0.013 mm p-p (seed 0); seed 1 0.027 / 0.054 mm, 5 / 2 changes",
    ("bore32", "fl"): "creeps: 0.018 / 0.028 mm, 2 / 5 command changes, 0.089 / 0.103 mm p-p "
                      "(seed 0); seed 1 at rest within a quantum (0.029 / 0.025 mm, 0 / 0)",
    ("overlap5_10bit", "pid"): "PID arrives 2.4 mm short, the hold's pulses walk it a quantum "
                               "at a time: 0.58 / 0.15 mm (q 0.49 mm), 55 / 0 command changes, "
                               "2.1 mm p-p (seed 0); seed 1 0.65 / 0.18 mm, 11 / 27 changes",
    ("overlap5_10bit", "fl"): "FL arrives 1.7 mm short, hold 1 pulsed: 0.59 / 0.20 mm, 34 / 0 "
                              "command changes, 0.67 mm p-p (seed 0); seed 1 at rest "
                              "(0.26 / 0.03 mm, 0 / 0)",
}


@pytest.mark.parametrize("kind", FOREIGN_KINDS)
@pytest.mark.parametrize("name", sorted(fl.FOREIGN_RIGS))
def test_designed_controllers_meet_the_precision_holds_on_foreign_rigs(foreign_runs, name, kind,
                                                                       request):
    # the precision specification's holds: steady state (last 0.5 s) within one
    # position quantum, and at rest over the hold's second half (within a quantum,
    # at most the two command changes of the valve closing once)
    if (name, kind) in FOREIGN_SPEC_FAILS:
        request.applymarker(pytest.mark.xfail(reason=FOREIGN_SPEC_FAILS[name, kind],
                                              strict=False))
    _, holds, q, _, _, _ = foreign_runs[name, kind]
    for h in holds:
        assert h["steady_state_error"] <= q, holds
        assert h["peak_to_peak"] <= q and h["command_changes"] <= 2, holds
