"""Blind robustness: recordings of rigs the workbench was not built around, simulated by
other code (tests/foreign_rig.py: scipy, its own valve, friction and line laws).

Found with a battery of such recordings run through ``workbench diagnose`` (32 and 63 mm
bores, 200-500 mm strokes, 1.5-15 kg, LuGre friction, distributed lines, 200 Hz-2 kHz
with jitter, gauge-bar and mm columns, plant files 5-8 % off): on the small rig
(32 mm bore, 200 mm stroke, 1.5 kg: fast transients) the diagnosis named the concealed
deadband exactly and then invented a ``parameter_error`` (mass +5 %, viscous friction
-3 %, plant file exact). The cause was the engine's 2 ms step at valve openings
(local error up to 50-90 um, tests/test_diagnose_foreign_engine.py), which a heavier
mass absorbed; the engine now refines those steps.
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
    no parameter_error is (on main's engine: deadband 0.0600 and a parameter_error of
    mass 1.575 kg, +5 %, which fit the engine's error at valve openings). Candidates
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
