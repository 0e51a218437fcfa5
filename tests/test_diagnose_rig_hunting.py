"""Stick-slip hunting: where the recorded loop hunts against stiction, the remaining
mismatch is said to be there, and the fit is given with and without those stretches
(issue 12, "what remains").

A free-running replay cannot reproduce the phase of a stick-slip limit cycle: whether
a stuck piston breaks away at one sample or the next is decided by a small force
margin. Measured on the bench's single-effect case (dry friction, seed 11, 24 s): the
rig's *true* friction values, replayed, fit p_a / p_b 46 / 65 % overall, and all the
mismatch lies in 10-16 s, where the PD loop hunts around held references.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from workbench.diagnose import synth
from workbench.diagnose.health import HUNT_STICK, hunting, unexplained


def _prep(x, r, dt=1e-3, noise=1e-5, stroke=0.5):
    """The fields :func:`hunting` reads, for a position trace ``x`` (m) on reference ``r``."""
    from workbench.signals import derivative
    rec = {"r": np.asarray(r, dtype=float)}
    return SimpleNamespace(closed=True, rec=rec, xs=np.asarray(x, dtype=float),
                           v=derivative(np.asarray(x, dtype=float), dt, 3, 31), dt=dt,
                           noise={"x": noise}, plant=SimpleNamespace(stroke=stroke),
                           starts=[0])


def _ramp(x0, x1, n):
    """A smooth slip from x0 to x1 over n samples (cosine profile)."""
    return x0 + (x1 - x0) * 0.5 * (1 - np.cos(np.linspace(0, np.pi, n)))


def test_hunting_is_told_from_settling_and_oscillation():
    """Three holds of 2 s (1 kHz), each after a step of the reference: a hunt (approach,
    stuck 0.4 s 3 mm short, slip 6 mm past, stuck, slip back), a plain settling
    (approach and rest) and a decaying oscillation of 30 mm (no stick phase). Only the
    hunt is a stretch: from the stick phase before its first re-slip to the end of the
    hold."""
    n = 2000
    hunt = np.concatenate([_ramp(0.10, 0.197, 150), np.full(400, 0.197), _ramp(0.197, 0.203, 70),
                           np.full(400, 0.203), _ramp(0.203, 0.199, 70)])
    hunt = np.concatenate([hunt, np.full(n - len(hunt), 0.199)])
    settle = np.concatenate([_ramp(0.2, 0.3, 150), np.full(n - 150, 0.3)])
    t = np.arange(n) * 1e-3
    osc = 0.2 + 0.03 * np.exp(-t / 0.8) * np.cos(2 * np.pi * 2.0 * t)
    x = np.concatenate([hunt, settle, osc])
    r = np.concatenate([np.full(n, 0.2), np.full(n, 0.3), np.full(n, 0.2)])
    prep = _prep(x, r)
    found = hunting(prep, v_rest=3e-3)
    # from the end of the approach slip (sample 150; its speed falls below v_rest a
    # few samples before, by the cosine profile and the 31-sample derivative) to the
    # end of the hold
    assert len(found) == 1 and abs(found[0][0] - 150) <= 10 and found[0][1] == n, found
    assert HUNT_STICK <= 0.4                      # the hunt's stick phases qualify
    # open loop: no reference, no hunting
    prep.closed = False
    assert hunting(prep, v_rest=3e-3) == []


@pytest.fixture(scope="module")
def friction_case():
    case = synth.concealed_case("dry_friction", seed=11)
    return case, synth.record(case, seed=11, duration=24.0)


def test_hunting_holds_the_mismatch_of_the_right_friction_model(friction_case, tmp_path):
    """The bench's friction case replayed on the rig's true values: the hunting
    stretches hold nearly all of the remaining error (measured 100 / 99 % of it for
    p_a / p_b; bound 90 %) and cover h12a's 10-16 s; outside them the true model fits
    96.3 / 96.4 % (bound 90 %) against 46.4 / 64.5 % overall (bound: below 70 %), and
    the statement says so."""
    from workbench.diagnose.data import prepare
    from workbench.diagnose.locate import regimes
    from workbench.diagnose.replays import replay
    from workbench.diagnose.witness import Witness
    from workbench.plant import Plant
    case, rec = friction_case
    plant = Plant(case.nominal).with_friction("stick")
    prep = prepare(plant, rec)
    wit = Witness.build(prep)
    stretches = hunting(prep, wit.v_rest)
    mask = np.zeros(prep.n, dtype=bool)
    for a, b in stretches:
        mask[a:b] = True
    assert mask[(prep.t > 10.5) & (prep.t < 15.5)].mean() > 0.9, stretches
    assert mask.mean() < 0.6                     # not the whole recording
    true = Plant(case.nominal.replace(**case.values)).with_friction("stick")
    sim = replay(true, prep)
    table, said = unexplained({s: prep.measured(s) for s in prep.signals}, sim, prep.noise,
                              regimes(prep, wit.v_rest), prep.signals, "the true model",
                              mask, "10-16 s")
    for s in ("p_a", "p_b"):
        assert table[s]["fit"] < 70.0 and table[s]["fit_outside_hunting"] > 90.0, table[s]
        assert table[s]["hunting_share"] > 0.9, table[s]
    text = " ".join(said)
    assert "stick-slip hunting" in text and "outside the hunting stretches" in text


def test_no_hunting_without_friction():
    """Recordings of the synthetic rig without dry friction -- nominal, a valve
    deadband (the loop stops in it), and a mass 3x the nominal (the loop oscillates by
    28 mm, its turn-arounds slow but never still): no hunting stretch."""
    from workbench.diagnose.data import prepare
    from workbench.diagnose.witness import Witness
    from workbench.plant import Plant
    for kind in ("valve_deadband", "mass_error"):
        case = synth.concealed_case(kind, seed=3)
        prep = prepare(Plant(case.nominal).with_friction("stick"),
                       synth.record(case, seed=3, duration=20.0))
        assert hunting(prep, Witness.build(prep).v_rest) == [], kind
