"""Blind robustness: recordings of rigs the workbench was not built around, simulated by
other code (tests/foreign_rig.py: scipy, its own valve, friction and line laws).

Found with a battery of such recordings run through ``workbench diagnose`` (32 and 63 mm
bores, 200-500 mm strokes, 1.5-15 kg, LuGre friction, distributed lines, 200 Hz-2 kHz
with jitter, gauge-bar and mm columns, plant files 5-8 % off): on the small rig
(32 mm bore, 200 mm stroke, 1.5 kg: fast transients) the diagnosis named the concealed
deadband exactly and then invented a ``parameter_error`` (mass +5 %, viscous friction
-3 %, plant file exact). The cause was the engine's 2 ms ROS2 step at valve openings
(local error up to 50-90 um), which a heavier mass absorbed; the engine steps with
ROS4 now (order 4: 0.02 um there).
"""

from __future__ import annotations

import numpy as np
import pytest

import foreign_rig
from workbench.diagnose import synth
from workbench.recording import Recording

#: The small rig: 32 mm bore, 200 mm stroke, 1.5 kg, the MPYE-size valve of rig25_mpye,
#: a PD loop that passes its steps without hunting (kp 12 V/m, kd 0.25 V s/m).
SMALL = {"cylinder.bore": 0.032, "cylinder.stroke": 0.2, "load.mass": 1.5,
         "load.viscous_friction": 60.0, "cylinder.dead_volume_a": 6e-6,
         "cylinder.dead_volume_b": 6e-6, "controller.kp": 12.0, "controller.kd": 0.25}


def _small_rig_recording(plant_file, overrides, duration=8.0, seed=3):
    """The foreign rig at 1 kHz, logged with 20 um / 500 Pa noise and 12-bit sensors."""
    ref = synth.rich_reference(seed, duration, stroke=SMALL["cylinder.stroke"])
    t, Z, U, rng = foreign_rig.simulate_logged(plant_file, ref, duration, seed=seed,
                                               overrides=overrides)
    n = len(t)
    lsb_x, lsb_p = SMALL["cylinder.stroke"] / 4096, 1e6 / 4096
    cols = {"u": U, "r": ref(t),
            "x": np.round((Z[:, 0] + rng.normal(0, 20e-6, n)) / lsb_x) * lsb_x,
            "p_a": np.round((Z[:, 2] + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p,
            "p_b": np.round((Z[:, 3] + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p}
    return Recording.from_arrays(t, metadata={"sample_time": 1e-3}, **cols)


def test_small_rig_deadband_without_invented_nominal_errors(tmp_path):
    """Deadband 0.06 concealed, plant file exact: the deadband is named within 2 % and
    no parameter_error is (with ROS2 at one 2 ms step per sample: deadband 0.0600 and a
    parameter_error of mass 1.575 kg, +5 %, which fit the step's error at valve
    openings; with the engine's ROS4 the plain step is within 0.02 um of Radau at such
    an opening, tests/test_diagnose_rig_engine.py). Candidates
    restricted to the two that competed, 8 s of recording, to keep the test short."""
    from workbench.diagnose import diagnose
    plant_file = tmp_path / "small.toml"
    synth.nominal_params().replace(**SMALL).to_toml(plant_file)
    rec = _small_rig_recording(plant_file, {"valve.deadband": 0.06})
    d = diagnose(plant_file, rec, effects=["valve_deadband", "parameter_error"], workers=1)
    res = d.to_dict()
    named = [f["effect"] for f in res["findings"]]
    assert named == ["valve_deadband"], d.summary()
    assert res["findings"][0]["parameters"]["deadband"] == pytest.approx(0.06, rel=0.02)
    assert res["fit_after"]["p_a"] > 90.0, d.summary()     # measured 93.8 (was 90.4)


def test_noise_at_rest_includes_its_coloured_part():
    """health.rest_noise against the noise's own statistics, on 20 s at 1 kHz at rest
    with a leak's exponential decay (time constant 3 s, 50 kPa) underneath: white
    noise of 500 Pa reads 500 Pa within 5 % (the windows' statistical error, about
    1/sqrt(2 x 197) per window, averages down over 100 windows; the decay's curvature
    in 0.2 s, 50 kPa x (0.2/3)^2 / 8 = 28 Pa, is taken out by the quadratic). AR(1)
    noise of pole 0.95 and standard deviation 1500 Pa reads what a quadratic over 200
    samples leaves of it, sqrt(trace((I - P) S) / 197) with S its covariance (1080 Pa:
    the slowest part goes into the quadratic), within 8 %; the sample-to-sample
    estimate of workbench.signals sees 2.5 x less."""
    from scipy.signal import lfilter
    from workbench.diagnose.health import rest_noise
    from workbench.signals import noise_floor
    rng = np.random.default_rng(0)
    n = 20000
    t = np.arange(n) * 1e-3
    decay = 3e5 + 5e4 * np.exp(-t / 3.0)
    rest = np.ones(n, dtype=bool)
    white = decay + rng.normal(0, 500.0, n)
    assert rest_noise(white, rest, 200) == pytest.approx(500.0, rel=0.05)
    ar = lfilter([np.sqrt(1 - 0.95 ** 2)], [1, -0.95], rng.normal(0, 1500.0, n))
    got = rest_noise(decay + ar, rest, 200)
    k = np.arange(200)
    S = 1500.0 ** 2 * 0.95 ** np.abs(k[:, None] - k[None, :])
    V = np.vander(np.linspace(-1, 1, 200), 3)
    expected = np.sqrt(np.trace((np.eye(200) - V @ np.linalg.pinv(V)) @ S) / 197)
    assert 1000.0 < expected < 1150.0
    assert got == pytest.approx(expected, rel=0.08)
    assert noise_floor(decay + ar) < got / 2.5
    assert rest_noise(white, np.zeros(n, dtype=bool), 200) == 0.0     # no rest: not used


def test_coloured_sensor_noise_is_not_an_unexplained_mismatch(tmp_path):
    """The reference rig without any effect, logged with coloured pressure noise (AR(1),
    pole 0.95, 1500 Pa) and 10-bit sensors: the replay's pressure error is that noise,
    2.5-3 x the sample-to-sample estimate. Before, the diagnosis said "the nominal model
    does not explain the recording: p_a fits 84.6 %, the noise floor allows 95.9 %";
    now it says the noise is coloured and, measured against its spread at rest, the
    nominal model explains the recording (one candidate, to keep the test short)."""
    from workbench.diagnose import diagnose
    plant_file = tmp_path / "plant.toml"
    synth.nominal_params().to_toml(plant_file)
    ref = synth.rich_reference(3, 8.0)
    t, Z, U, rng = foreign_rig.simulate_logged(plant_file, ref, 8.0, seed=3)
    foreign_rig.log_csv(tmp_path / "rec.csv", plant_file, t, Z, U, rng, reference=ref,
                        colour=0.95, bits=10, x_noise=40e-6, p_noise=1500.0)
    d = diagnose(plant_file, str(tmp_path / "rec.csv"), effects=["valve_offset"], workers=1)
    assert not d.to_dict()["findings"], d.summary()
    text = d.summary()
    assert "the noise of p_a is coloured" in text and "the noise of p_b is coloured" in text
    assert "still unexplained: p_" not in text, text
    assert "explains the recording within its noise" in text, text


def test_command_updates_are_put_on_the_controller_clock():
    """A 10 ms controller (updates at 3 ms + k 10 ms) logged at 200 Hz with +-10 %
    jitter: each update is known only to lie between two samples. data.uniform with the
    controller's period puts every update on one clock consistent with all of them
    (phase scanned in steps of 25 us) and the resampled command equals the true one
    on the 5 ms grid (except at grid times within 25 us of an update: none here). Held from the last sample, as before, 50 % of
    the updates arrive one sample late (the blind battery's 63 mm rig: the plant file's
    PD then 'did not reproduce the recorded command' (fit of u 80 %), the replay fell
    back to open loop and a parameter_error of mass -8.6 % was invented)."""
    from workbench.diagnose.data import command_switches, uniform
    rng = np.random.default_rng(1)
    n = 2000
    t = np.arange(n) * 5e-3
    t[1:-1] += rng.uniform(-0.5e-3, 0.5e-3, n - 2)
    updates = 3e-3 + 1e-2 * np.arange(1000)
    values = 5.0 + rng.normal(0, 0.5, 1000)

    def command(tt):
        k = np.searchsorted(updates, tt, side="right") - 1
        return np.where(k >= 0, values[np.maximum(k, 0)], 5.0)
    u = command(t)
    when, j = command_switches(t, u, 0.01)
    # the brackets admit any phase in (0.5, 4.5) ms: the middle, 2.5 ms, is kept; what
    # matters is that each update lands in the grid interval of the true one
    assert np.max(np.abs(when - updates[np.searchsorted(updates, when - 2e-3)])) < 1.5e-3
    rec = Recording.from_arrays(t, u=u, x=np.full(n, 0.1))
    grid = np.arange(int(np.floor(t[-1] / 5e-3 + 1e-9)) + 1) * 5e-3
    near = np.min(np.abs(grid[:, None] - updates[None, :]), axis=1) < 2.6e-5
    good = uniform(rec, 5e-3, 0.01)["u"]
    assert np.array_equal(good[~near], command(grid)[~near])
    held = uniform(rec, 5e-3)["u"]
    assert np.mean(held[~near] != command(grid)[~near]) > 0.2
