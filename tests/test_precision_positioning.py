"""Issue 14 must-shows on the full plant of designs/precision_positioning.py.

The rig: designs/plants/rigs/precision_rig25.toml (dry friction 15/25 N, 2 % spool overlap,
1 m lines, 2 ms loop), seen through a 12-bit position sensor and pressures with
300 Pa noise, no velocity. The controller is what controllers.design returns for the
plant file (NMPC, the best of the three in designs/precision_positioning.py). A short
profile with what the must-shows judge: 60 mm steps both ways, one period of the
60 mm 0.5 Hz sine, and a 4 s hold at the end.

The sensor noise is seed 0 (evaluate_design's default). The must-shows are NOT met
for every noise realisation: with seed 1 the worst sine error was 2.4 mm, with seed 2
the worst steady state 0.36 mm (3 quanta) -- measured 2026-11-24, issue 14 stays open
on robustness; these tests pin what seed 0 achieves so a regression shows.
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


def test_perturbed_rig_still_settles_without_limit_cycle(plant):
    # the rig is not the plant file: friction 1.5x, mass +10 %
    rig = plant.with_params(**{"friction.coulomb": 22.5, "friction.static": 37.5,
                               "load.mass": 1.32})
    ev = evaluate_design(plant, "nmpc", reference=profile(), rig=rig)
    steps = [h for h in ev.holds if h["segment"].startswith("step")]
    # within two quanta (the design's release band) after every step, at rest at the end
    assert max(h["steady_state_error"] for h in steps) <= 2 * ev.quantum
    assert ev.holds[-1]["peak_to_peak"] <= ev.quantum and ev.holds[-1]["command_changes"] == 0
    assert np.isfinite(ev.validation.metrics.sine_error_max)
