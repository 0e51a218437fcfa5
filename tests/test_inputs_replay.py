"""A recorded command that is constant (session 12): the wrong channel logged as ``u``,
or a logger that wrote the centre value throughout. ``replay.command_agreement`` must
not call it "the plant file's controller reproduces the command" (it counted any
constant u as 100 %), or diagnose replays in closed loop on ``r``, never looks at u,
and can say "no finding" for a recording whose command could not have moved the
piston.

The controller is the plant file's PD (rig25_mpye: kp = 5 V/m, kd = 0.1 V s/m, 10 ms,
centre 5 V); its commands are computed here from its definition in formats.md
section 1, independently of the code under test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.plant import Plant
from workbench.recording import Recording
from workbench.replay import command_agreement

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"
KP, KD, T, CENTER = 5.0, 0.1, 0.01, 5.0


def _pd(r: np.ndarray, x: np.ndarray) -> np.ndarray:
    """formats.md: u = center + kp e + kd (e_k - e_{k-1}) / T, e = r - x, clipped."""
    e = r - x
    de = np.diff(e, prepend=e[0]) / T
    return np.clip(CENTER + KP * e + KD * de, 0.0, 10.0)


def _recording(u: np.ndarray, x: np.ndarray, r: np.ndarray) -> Recording:
    t = np.arange(len(x)) * T
    return Recording.from_arrays(t, u=u, x=x, r=r, metadata={"sample_time": T})


def test_constant_command_while_the_controller_would_move_the_piston_disagrees():
    plant = Plant.from_toml(PLANT)
    t = np.arange(300) * T
    r = np.where(t < 1.0, 0.2, 0.3)
    x = 0.2 + 0.1 * (t >= 1.0) * (1.0 - np.exp(-(t - 1.0) / 0.1))
    assert np.ptp(_pd(r, x)) > 0.4          # the PD's own command moves (0.5 V step)
    agree = command_agreement(plant, _recording(np.full_like(t, CENTER), x, r))
    assert agree < 90.0, agree              # diagnose's threshold (replay.CONTROLLER_AGREEMENT)


def test_constant_command_that_is_the_controllers_own_agrees():
    """At rest on the reference the PD commands its centre: a constant u of 5 V is what
    it would do, and agrees fully."""
    plant = Plant.from_toml(PLANT)
    x = np.full(100, 0.25)
    agree = command_agreement(plant, _recording(np.full(100, CENTER), x, x.copy()))
    assert agree == 100.0


def test_moving_command_of_the_controller_still_agrees():
    """The usual case is unchanged: the recorded u is the PD's command."""
    plant = Plant.from_toml(PLANT)
    t = np.arange(300) * T
    r = np.where(t < 1.0, 0.2, 0.3)
    x = 0.2 + 0.1 * (t >= 1.0) * (1.0 - np.exp(-(t - 1.0) / 0.1))
    assert command_agreement(plant, _recording(_pd(r, x), x, r)) > 99.0
