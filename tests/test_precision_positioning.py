"""Issue 14 must-shows on the full plant of designs/precision_positioning.py.

The rig: designs/plants/rigs/precision_rig25.toml (dry friction 15/25 N, 2 % spool overlap,
1 m lines, 2 ms loop), seen through a 12-bit position sensor and pressures with
300 Pa noise, no velocity. The controller is what controllers.design returns for the
plant file (NMPC, the best of the three in designs/precision_positioning.py). A short
profile with what the must-shows judge: 60 mm steps both ways, one period of the
60 mm 0.5 Hz sine, and a 4 s hold at the end.

The sensor noise is seed 0 (evaluate_design's default) for the must-shows; seeds 1
and 2 check what holds for other noise realisations. Measured 2026-11-24 (NMPC with
its force estimate filtered over DISTURBANCE_TIME), worst steady state / worst sine
error / holds free of a limit cycle:

  seed 0: 0.117 / 0.82 mm / yes      seed 1: 0.097 / 1.31 mm / yes
  seed 2: 0.136 / 1.22 mm / yes      seed 3: 0.118 / 1.03 mm / yes
  seed 4: 0.240 / 0.86 mm / yes      (quantum 0.122 mm)

(before, with the deadbeat force estimate: seed 1 sine 2.42 mm, seed 2 steady state
0.36 mm and a stick-slip limit cycle in a hold, seed 0 a 0.53 mm limit cycle in the
hold after the first step.) The must-shows are NOT met for every noise realisation:
the steady state and the sine depend on stick-slip events at each stop (the hold
lock closes the valve only when a stop lands within half a quantum; a stuck piston
breaks away and jumps 0.3-1 mm). The strict xfail tests below say so, and turn into
failures when that is fixed. Issue 14 stays open on robustness.

Tried and not kept (measured on seeds 0-4 and the perturbed rig; each changes which
stop lands where, none makes all of them land within the band):
* lock only after the measured position stayed on one quantum for 10 ms (seed 4's
  coasting lock gone, 0.24 -> 0.105 mm, but seeds 0, 1, 3, 4 then hunt in a hold);
* that, and the NMPC's force estimate held while the piston is stuck (integral
  action only while moving): seeds 0 and 2 hunt (7.6 mm peak-to-peak in seed 0),
  perturbed sine 3.6 mm;
* NMPC position_tolerance 1 mm instead of 2 mm: every steady state within a quantum
  (worst 0.112 mm), sine 0.62-1.36 mm, but seed 4 and the perturbed rig hunt;
  0.5 mm: no hold hunts anywhere (perturbed rig included), but sine 1.26-1.70 mm
  and steady state up to 0.225 mm.
The stick-slip jump on this rig (0.3-1 mm: F_s - F_c released while a quantum of
travel and the 1 m lines delay the reaction) is larger than the lock band (half a
quantum): a stop outside the band is a coin toss. What is missing is a way to make
sub-quantum moves from a stuck piston, or a final approach that stops inside.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench import Plant, references
from workbench.controllers.evaluation import evaluate_design

RIGS = Path(__file__).resolve().parents[1] / "designs" / "plants" / "rigs"
PLANT = RIGS / "precision_rig25.toml"
C = 0.25


def profile():
    pts = [(0, C), (0.3, C), (0.3, C + 0.06), (1.8, C + 0.06), (1.8, C), (3.3, C),
           (3.3, C - 0.06), (4.8, C - 0.06)]
    pts += references.sine_points(4.8, C, 0.06, 0.5, 1)[1:]
    pts += [(10.8, C - 0.06)]
    p = references.profile(pts)
    return references.Reference(p.times, p.values, sections=(("sine", 4.8, 6.8),))


@pytest.fixture(scope="module")
def plant():
    return Plant.from_toml(PLANT)


@pytest.fixture(scope="module")
def nominal(plant):
    return evaluate_design(plant, "nmpc", reference=profile())


def test_steady_state_within_one_quantum_after_every_step(nominal):
    steps = [h for h in nominal.holds if h["segment"].startswith("step")]
    assert len(steps) == 3
    q = nominal.quantum                                       # 0.122 mm
    # mean |r - x| over the last 0.5 s of each hold (the precision specification)
    assert max(h["steady_state_error"] for h in steps) <= q, [h["steady_state_error"] for h in steps]


def test_worst_error_on_the_sine_at_most_1mm(nominal):
    assert nominal.validation.metrics.sine_error_max <= 1e-3


def test_no_limit_cycle_in_the_long_hold(nominal):
    last = nominal.holds[-1]
    assert last["end"] - last["start"] >= 2.0                 # second half of the 4 s hold
    # no position change beyond one quantum, no valve activity: the loop is at rest
    assert last["peak_to_peak"] <= nominal.quantum and last["command_changes"] == 0


def test_nmpc_median_computation_below_1ms(nominal):
    assert nominal.median_update_ms < 1.0


def test_nmpc_command_does_not_chatter(nominal):
    # high-frequency part of the command (minus its 50 ms moving mean) on the moving
    # sections (the ramp of the first step and the sine): 1.18 V with the deadbeat
    # force estimate, 0.64 V filtered over DISTURBANCE_TIME (seed 0; 0.25 V on the
    # rig without its 1 m lines: the rest is the lines' delay, not in the model)
    tr = nominal.validation.trajectory
    t, u = tr.time, np.asarray(tr["u"], dtype=float)
    hf = u - np.convolve(u, np.ones(25) / 25, mode="same")
    moving = ((t > 0.35) & (t < 1.2)) | ((t > 4.9) & (t < 6.7))
    assert np.std(hf[moving]) < 0.9


@pytest.fixture(scope="module")
def other_seeds(plant):
    return {seed: evaluate_design(plant, "nmpc", reference=profile(), seed=seed)
            for seed in (1, 2)}


def test_other_noise_seeds_hold_without_limit_cycle(other_seeds):
    for seed, ev in other_seeds.items():
        steps = [h for h in ev.holds if h["segment"].startswith("step")]
        assert ev.limit_cycle_free, (seed, ev.holds)
        # within the lock's release band (two quanta) after every step
        assert max(h["steady_state_error"] for h in steps) <= 2 * ev.quantum, seed
        # regression pin, not the must-show: measured 1.31 and 1.22 mm
        assert ev.validation.metrics.sine_error_max <= 1.5e-3, seed


@pytest.mark.xfail(strict=True, reason="issue 14 open: the must-shows hold for seed 0 "
                   "only (seed 1 sine 1.31 mm, seed 2 steady state 0.136 mm)")
def test_must_shows_for_other_noise_seeds(other_seeds):
    for ev in other_seeds.values():
        steps = [h for h in ev.holds if h["segment"].startswith("step")]
        assert max(h["steady_state_error"] for h in steps) <= ev.quantum
        assert ev.validation.metrics.sine_error_max <= 1e-3


@pytest.fixture(scope="module")
def perturbed(plant):
    # the rig is not the plant file: friction 1.5x, mass +10 %
    rig = plant.with_params(**{"friction.coulomb": 22.5, "friction.static": 37.5,
                               "load.mass": 1.32})
    return evaluate_design(plant, "nmpc", reference=profile(), rig=rig)


def test_perturbed_rig_ends_at_rest(perturbed):
    ev = perturbed
    assert ev.holds[-1]["peak_to_peak"] <= ev.quantum and ev.holds[-1]["command_changes"] == 0
    assert np.isfinite(ev.validation.metrics.sine_error_max)


@pytest.mark.xfail(strict=True, reason="issue 14 open: on the perturbed rig (static friction "
                   "37.5 N) the NMPC hunts in the hold after the first step (1.5 mm "
                   "peak-to-peak, steady state 0.40 mm)")
def test_perturbed_rig_settles_without_limit_cycle(perturbed):
    ev = perturbed
    steps = [h for h in ev.holds if h["segment"].startswith("step")]
    assert max(h["steady_state_error"] for h in steps) <= 2 * ev.quantum
    assert ev.limit_cycle_free
