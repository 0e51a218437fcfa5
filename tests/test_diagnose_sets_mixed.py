"""Recordings of several experiments with different signals diagnosed together (issue 12,
point 4): one with x, p_a and p_b, one with the position only, one with p_a only --
a rig engineer's usual set. Each signal counts only where it was recorded
(``Prepared.recorded``); each recording is predicted as it would be alone
(:mod:`workbench.diagnose.joined`). Recordings from the independent simulator
:mod:`foreign_rig` (numpy/scipy), 6 s at 1 kHz each of the 25 mm rig in its PD loop.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import foreign_rig
from workbench import Plant
from workbench.diagnose import synth
from workbench.diagnose.data import prepare_many
from workbench.diagnose.engine import INPUT_ROWS
from workbench.diagnose.nominal import predictors
from workbench.signals import noise_floor

DURATION = 6.0
KINDS = {"full": True, "x": False, "p_a": "p_a"}


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The plant file and three recordings of one foreign rig with a 0.05 deadband
    (full, position only, p_a only; other references and noise seeds)."""
    root = tmp_path_factory.mktemp("mixed")
    plant = synth.concealed_case("none", seed=0).write_nominal(root / "plant.toml")
    files = {}
    for i, (kind, pressures) in enumerate(KINDS.items()):
        rec = foreign_rig.record(plant, synth.rich_reference(5 + i, DURATION), DURATION,
                                 seed=5 + i, pressures=pressures,
                                 overrides={"valve.deadband": 0.05})
        files[kind] = rec.to_csv(root / f"{kind}.csv")
    return root, plant, files


def _prep(rig, kinds):
    from workbench.recording import load_recording
    _, plant, files = rig
    return prepare_many(Plant.from_toml(plant).with_friction("stick"),
                        [load_recording(files[k]) for k in kinds])


def test_each_signal_counts_only_where_it_was_recorded(rig):
    """Full + position only + p_a only joined: the signals are the union; each pressure
    is the recording where it was recorded and NaN elsewhere (its mask says where);
    its noise is the median of the noise floors of the recordings that have it
    (computed here from the files' columns); the short-horizon objective's residuals
    are exactly 0 where a signal was not recorded, and its cost is the per-signal mean
    over the recorded samples only (recomputed here from the model outputs)."""
    from workbench.recording import load_recording
    prep = _prep(rig, ["full", "x", "p_a"])
    recs = {k: load_recording(f) for k, f in rig[2].items()}
    assert prep.signals == ("x", "p_a", "p_b")
    cuts = list(prep.starts) + [prep.n]
    spans = dict(zip(["full", "x", "p_a"], zip(cuts[:-1], cuts[1:])))
    for side in ("p_a", "p_b"):
        have = [k for k in spans if side in recs[k]]
        for k, (a, b) in spans.items():
            assert prep.mask(side)[a:b].all() == (k in have)
            assert np.isnan(prep.measured(side)[a:b]).all() == (k not in have)
        a, b = spans["full"]
        assert np.array_equal(prep.measured(side)[a:b], np.asarray(recs["full"][side])[:b - a])
        assert prep.noise[side] == pytest.approx(
            np.median([noise_floor(np.asarray(recs[k][side])) for k in have]), rel=0.02)
    # the joined pressures the predictions start from are finite everywhere
    assert np.isfinite(prep.pas).all() and np.isfinite(prep.pbs).all()
    shpe, _ = predictors(prep)
    Y = np.vstack([prep.xs, prep.pas, prep.pbs])[:, shpe.index] + 1e-3   # any model
    r = shpe.residuals(Y).reshape(3, -1)
    for i, s in enumerate(prep.signals):
        off = ~prep.mask(s)[shpe.index][::shpe.decimate]
        assert off.any() == (s != "x") and np.all(r[i][off] == 0.0)
        ok = prep.mask(s)[shpe.index]
        want = np.mean(((prep.measured(s)[shpe.index][ok] - Y[i][ok]) / shpe.sigma[s]) ** 2)
        assert shpe.signal_costs(Y)[s] == pytest.approx(want, rel=1e-12)


def test_each_recording_is_predicted_as_it_would_be_alone(rig):
    """Closed loop: the position-only recording gets 1 s closed-loop segments (alone it
    would too: 0.2 s open-loop horizons let its unmeasured pressures drift), the full
    one 0.2 s open-loop horizons; pressures are re-anchored only where one is recorded,
    and on the plant's equilibrium at the start of the position-only recording."""
    prep = _prep(rig, ["full", "x"])
    shpe, seg = predictors(prep)
    row = {k: i for i, k in enumerate(INPUT_ROWS)}
    d = shpe.inputs.data
    part = np.searchsorted(prep.starts, shpe.index, side="right") - 1
    anch = d[row["anchor"]] > 0
    assert np.all(d[row["closed_loop"], part == 0] == 0.0)
    assert np.all(d[row["closed_loop"], part == 1] == 1.0)
    gap = np.diff(shpe.index[anch]) * prep.dt
    assert np.median(gap[part[anch][1:] == 0]) == pytest.approx(0.2, abs=0.02)
    assert np.median(gap[part[anch][1:] == 1]) == pytest.approx(1.0, abs=0.3)
    p_anch = d[row["anchor_p"]] > 0
    assert p_anch[part == 1].sum() == 1 and p_anch[np.flatnonzero(part == 1)[0]]
    assert p_anch[part == 0].sum() == anch[part == 0].sum()
    assert seg is not None and seg.kind == "segments"


def test_full_and_position_only_pair_names_the_effect(rig, tmp_path):
    """``workbench diagnose PLANT full.csv x.csv``: the deadband is named within 30 % (the
    issue's bound for one effect); diagnosis.json has the fit per recording, per signal
    it recorded (the position-only one: x alone), each explained (x fit after > 95 %
    and above before); the report says which signals each recording has. Candidates:
    the deadband and two that the full search weighed against it here (leakage, which
    only the pressures of the first recording can show, and the valve offset)."""
    from workbench.cli import main
    _, plant, files = rig
    out = tmp_path / "diag"
    code = main(["diagnose", str(plant), str(files["full"]), str(files["x"]), "--out",
                 str(out), "--quiet", "--effects", "valve_deadband", "leakage",
                 "valve_offset", "--no-report"])
    assert code == 0
    res = json.loads((out / "diagnosis.json").read_text())
    assert [f["effect"] for f in res["findings"]] == ["valve_deadband"]
    assert res["findings"][0]["parameters"]["deadband"] == pytest.approx(0.05, rel=0.3)
    per = res["recordings"]
    assert [sorted(r["fit_after"]) for r in per] == [["p_a", "p_b", "x"], ["x"]]
    for r in per:
        assert r["fit_after"]["x"] > 95.0 and r["fit_after"]["x"] > r["fit_before"]["x"]
    notes = json.loads((out / "details.json").read_text())["notes"]
    assert any("measure different signals" in n and "x, p_a, p_b" in n for n in notes)
