"""Position-only recordings count their information by time covered (issue 12, session 11).

Found by the blind sweep: 8 s of a position-only recording at 200 Hz with timing jitter
(tests/foreign_rig.py: smooth Stribeck friction 18/26 N, the 25 mm rig in its PD loop)
gave "no finding": dry friction removed 51 % of the prediction error at dBIC 9 < 10.
The information criteria count 3 independent observations per prediction window and
signal (:attr:`workbench.diagnose.predict.Predictor.n_eff`); a position-only recording
is predicted in 1 s closed-loop segments, five horizons long, and each counted as one
horizon (8 windows: n_eff 24). Counted by its length (3 per 0.2 s, still below the 49
per segment the residuals' autocorrelation gives) the friction is named.
"""

from __future__ import annotations

import numpy as np
import pytest

import foreign_rig
from workbench.diagnose import synth
from workbench.diagnose.data import prepare
from workbench.diagnose.nominal import predictors
from workbench.diagnose.predict import HORIZON
from workbench.plant import Plant
from workbench.recording import Recording

FRICTION = {"coulomb": 18.0, "static": 26.0, "stribeck": 0.01}


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    root = tmp_path_factory.mktemp("posonly")
    plant_file = synth.concealed_case("none", seed=0).write_nominal(root / "plant.toml")
    return plant_file, Plant.from_toml(plant_file)


def _logged(plant_file, duration, seed, period, jitter, friction=None):
    """The foreign rig logged on its own clock, position only (20 um noise, 12 bits)."""
    ref = synth.rich_reference(seed, duration)
    t, Z, U, rng = foreign_rig.simulate_logged(plant_file, ref, duration, seed=seed,
                                               friction=friction or FRICTION,
                                               log_period=period, jitter=jitter)
    lsb = 0.5 / 4096
    x = np.round((Z[:, 0] + rng.normal(0, 20e-6, len(t))) / lsb) * lsb
    return Recording.from_arrays(t, u=U, x=x, r=ref(t), metadata={"source": "foreign"})


def test_closed_loop_segments_count_their_length_in_horizons(rig):
    plant_file, plant = rig
    prep = prepare(plant, _logged(plant_file, 6.0, 4, 1e-3, 0.0))
    shpe, _ = predictors(prep)
    assert shpe.kind == "segments"
    # seconds each window covers, from its first simulated sample to the next window's
    ends = np.append(shpe.starts[1:], len(shpe.index))
    seconds = (ends - shpe.starts) * shpe.step * prep.dt
    assert seconds.mean() == pytest.approx(1.0, abs=0.2)       # 1 s segments
    # each window counts its length in whole horizons, at least one (the recording's end)
    assert shpe.n_eff == pytest.approx(3 * np.maximum(np.round(seconds / HORIZON), 1).sum(),
                                       rel=1e-9)
    # five horizons per segment: five times the old count of one per window
    assert shpe.n_eff > 4 * 3 * shpe.windows


def test_horizon_windows_keep_three_per_window_and_signal(rig):
    plant_file, plant = rig
    rec = foreign_rig.record(plant_file, synth.rich_reference(4, 4.0), 4.0, seed=4)
    shpe, _ = predictors(prepare(plant, rec))
    assert shpe.kind == "horizons"
    assert shpe.n_eff == 3 * shpe.windows * 3


def test_short_position_only_recording_at_200_hz_names_the_friction(rig):
    """8 s at 200 Hz with +-20 % timing jitter: friction is named (was: no finding, with
    all candidates as with these two). The values of a position-only recording of a
    hunting loop are looser than with pressures, so here only the effect is asserted,
    and that nothing else is (the values: the next test). Two candidates keep the test short (8.7 CPU s;
    all of them: 108 s wall on the loaded machine)."""
    from workbench.diagnose import diagnose
    plant_file, _ = rig
    rec = _logged(plant_file, 8.0, 7, 5e-3, 0.2)
    d = diagnose(plant_file, rec, effects=["dry_friction", "valve_deadband"], workers=1)
    assert [f.effect for f in d.findings] == ["dry_friction"], d.summary()


@pytest.mark.parametrize("seed, friction", [
    (7, FRICTION), (3, {"coulomb": 25.0, "static": 30.0, "stribeck": 0.02})],
    ids=["18-26N", "25-30N"])
def test_position_only_friction_values_come_from_the_lowest_cost(rig, seed, friction):
    """Position only, 8 s at 200 Hz with +-20 % jitter: the Coulomb and static friction
    within 30 % of the rig's (the issue's bound for one effect; the smooth law's peak
    below F_s is 23.9 N for 18/26 N: tanh(v/2 mm/s) times the Stribeck curve).

    The closed-loop segment cost is rough in the friction values (a break-away a
    sample earlier changes the rest of a 1 s segment), so the least squares from the
    best grid point stopped in a dent of it: 12.9/14.5 N (static -44 %) and 18.4/18.4 N
    (-39 %); the pattern search of :func:`workbench.diagnose.refit._pattern_search`
    reaches the lower cost near the rig's values (measured 19.5/25.9 N, 25.3/30.3 N).
    """
    from workbench.diagnose import diagnose
    plant_file, _ = rig
    rec = _logged(plant_file, 8.0, seed, 5e-3, 0.2, friction)
    d = diagnose(plant_file, rec, effects=["dry_friction", "valve_deadband"], workers=1)
    assert [f.effect for f in d.findings] == ["dry_friction"], d.summary()
    found = d.findings[0].parameters
    assert found["coulomb"] == pytest.approx(friction["coulomb"], rel=0.3), d.summary()
    assert found["static"] == pytest.approx(friction["static"], rel=0.3), d.summary()
