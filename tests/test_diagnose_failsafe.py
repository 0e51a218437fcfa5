"""Never a silent all-clear (issue 12, point 5), and nothing half-written.

A replay that diverges, leaves the stroke, produces non-finite values or fits worse
than a constant is an error with its cause (or a finding), never "no finding"; a
failed run leaves the output folder exactly as it was. Recordings: the synthetic rig
with a concealed valve deadband (seed 7), replayed open loop on a plant file without
[controller] -- the case where the former engine overflowed (|x| up to 1e149 m) and the
diagnosis reported "no finding" at a fit of -1e154 %.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.diagnose import synth


@pytest.fixture(scope="module")
def deadband_open(tmp_path_factory):
    """(plant file without [controller], recording CSV) of a 8 s deadband recording."""
    root = tmp_path_factory.mktemp("failsafe")
    case = synth.concealed_case("valve_deadband", seed=7)
    rec = synth.record(case, seed=7, duration=8.0)
    plain = case.nominal.replace(**{k: None for k in case.nominal.values
                                    if k.startswith("controller.")})
    plant_file = root / "no_controller.toml"
    plain.to_toml(plant_file)
    rec_file = root / "rec.csv"
    rec.to_csv(rec_file)
    return plant_file, rec_file


def _snapshot(folder):
    """Every path under ``folder`` and beside it (a staging folder left behind shows)."""
    return sorted(str(p.relative_to(folder.parent)) for p in folder.parent.rglob("*"))


def _out_with_sentinel(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("earlier result")
    return out


def test_engine_stays_bounded_at_the_end_stop():
    """The diagnosis engine (ROS2, 2 ms steps, as the refits use it) drives the piston
    into the end stop at x = stroke and back. The former engine returned NaN here (the
    chamber at its 5 cm^3 dead volume has a pressure time constant well under a step and
    the linearly implicit step overshot to negative pressure); the guarded step redoes
    such a sample with 8x smaller steps. Reference: CVODES (:func:`workbench.simulate.
    open_loop`, adaptive BDF). Bounds: 1 mm on x (8 sensor quanta; the 2 ms step lags
    the 300 Hz stop contact), pressures within 2 kPa rms (4x the sensor noise) and 25 kPa
    at worst (the few samples right at the reversal in the dead volume)."""
    from workbench import Plant, simulate
    from workbench.diagnose.engine import Engine, EngineInputs, INPUT_ROWS
    base = synth.nominal_params()
    plant = Plant(base.replace(**{k: None for k in base.values if k.startswith("controller.")}))
    h = 2e-3
    t = np.arange(500) * h
    u = np.where(t < 0.6, 5.3, np.where(t < 0.8, 4.6, 5.0))
    z0 = plant.initial_state(0.35)
    ref = simulate.open_loop(plant, t, u, x0=z0, progress=False)
    d = np.zeros((len(INPUT_ROWS), len(t)))
    d[INPUT_ROWS.index("u_rec")] = u
    y = Engine(plant, h, None).run(z0, EngineInputs(d), plant.p0)
    assert np.max(ref["x"]) > plant.stroke - 1e-4          # it did reach the stop
    assert np.all(np.isfinite(y))
    assert np.max(np.abs(y[0] - ref["x"])) < 1e-3
    for row, name in ((1, "p_a"), (2, "p_b")):
        err = y[row] - ref[name]
        assert np.sqrt(np.mean(err ** 2)) < 2e3, name
        assert np.max(np.abs(err)) < 25e3, name


def test_check_replay_names_each_failure():
    """Unit check of :func:`workbench.diagnose.health.check_replay` on made-up replays:
    each failure is named with its time span; a good replay passes."""
    from workbench.diagnose.health import check_replay
    t = np.linspace(0.0, 2.0, 201)
    meas = {"x": 0.25 + 0.1 * np.sin(3 * t)}
    good = check_replay(t, meas, {"x": meas["x"] + 1e-4}, 0.5, ("x",))
    assert good.ok and good.cause() == ""
    nan = meas["x"].copy()
    nan[150:] = np.nan
    c = check_replay(t, meas, {"x": nan}, 0.5, ("x",))
    assert not c.ok and "not finite at 51 samples (1.50-2.00 s)" in c.cause()
    out = meas["x"].copy()
    out[100:] = 0.9                                       # 0.4 m beyond a 0.5 m stroke
    c = check_replay(t, meas, {"x": out}, 0.5, ("x",))
    assert any("leaves the stroke" in f and "0.4 m" in f for f in c.failures)
    flat = np.full_like(t, 0.25) + 0.3 * np.cos(3 * t)   # fits worse than the mean
    c = check_replay(t, meas, {"x": flat}, 0.5, ("x",))
    assert c.worse and "worse than the recording's own mean" in c.cause()


def test_noise_floor_fit_is_analytic():
    """A sine of amplitude A has std A / sqrt(2): the perfect model's fit with noise sigma
    is 100 (1 - sigma sqrt(2) / A) (to the 0.1 % the function rounds to)."""
    from workbench.diagnose.health import floor_fit
    t = np.linspace(0.0, 100.0, 100001)
    assert floor_fit(2.0 * np.sin(t), 0.05) == pytest.approx(100 * (1 - 0.05 * np.sqrt(2) / 2),
                                                           abs=0.06)


def test_open_loop_replay_that_ran_away_is_now_a_finding(deadband_open):
    """The issue's "-2.7e134 %, no finding" path: the nominal replay is finite and
    bounded, fits worse than a constant (the rig's deadband stops a piston the model
    drives into the stop), and the diagnosis names the deadband instead of an all-clear."""
    from workbench.diagnose import diagnose
    plant_file, rec_file = deadband_open
    d = diagnose(plant_file, rec_file, effects=["valve_deadband", "valve_offset"])
    assert all(np.isfinite(v) and v > -1e4 for v in d.fit_before.values()), d.fit_before
    assert d.findings and d.findings[0].effect == "valve_deadband", d.summary()
    assert any("nominal replay failed" in n for n in d.notes), d.notes
    assert min(d.fit_after.values()) > 50.0, d.fit_after


def test_worse_than_constant_without_explanation_is_an_error(deadband_open, tmp_path, capsys):
    """Only a candidate that cannot explain it (heat transfer): the nominal fit stays
    below 0 %, which is an error naming the cause (exit 2), and --out is left as it was."""
    from workbench.cli import main
    plant_file, rec_file = deadband_open
    out = _out_with_sentinel(tmp_path)
    before = _snapshot(out)
    code = main(["diagnose", str(plant_file), str(rec_file), "--out", str(out), "--quiet",
                 "--effects", "heat_transfer", "--no-report"])
    err = capsys.readouterr().err
    assert code == 2
    assert "worse than the recording's own mean" in err and "no candidate" in err, err
    assert _snapshot(out) == before


@pytest.mark.parametrize("broken", ["nan", "beyond_stroke"])
def test_failed_replay_is_an_error_and_writes_nothing(broken, deadband_open, tmp_path, capsys,
                                                      monkeypatch):
    """A replay with non-finite values or a piston 20 % beyond its stroke (forced here:
    the engine no longer produces them on this case) is an error with its cause, whether
    or not a candidate is found, and nothing new appears in --out."""
    from workbench.cli import main
    from workbench.diagnose import core
    real = core.replay

    def broken_replay(plant, prep):
        sim = real(plant, prep)
        x = sim["x"].copy()
        x[len(x) // 2:] = np.nan if broken == "nan" else 1.2 * plant.stroke
        return {**sim, "x": x}

    monkeypatch.setattr(core, "replay", broken_replay)
    plant_file, rec_file = deadband_open
    out = _out_with_sentinel(tmp_path)
    before = _snapshot(out)
    code = main(["diagnose", str(plant_file), str(rec_file), "--out", str(out), "--quiet",
                 "--effects", "valve_deadband", "--no-report"])
    err = capsys.readouterr().err
    assert code == 2
    assert ("not finite" if broken == "nan" else "leaves the stroke") in err, err
    assert _snapshot(out) == before


def test_a_failure_while_writing_leaves_nothing(deadband_open, tmp_path, monkeypatch):
    """The report fails half-way (after diagnosis.json and the plant were staged): the
    output folder keeps exactly its earlier content."""
    from workbench.diagnose import diagnose, report
    plant_file, rec_file = deadband_open
    d = diagnose(plant_file, rec_file, effects=["valve_deadband"], polish_values=False)

    def fail(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(report, "write_report", fail)
    out = _out_with_sentinel(tmp_path)
    before = _snapshot(out)
    with pytest.raises(RuntimeError, match="disk full"):
        d.write(out)
    assert _snapshot(out) == before
    monkeypatch.undo()
    paths = d.write(out, report=False)
    assert {p.name for p in out.iterdir()} == {"keep.txt", "diagnosis.json",
                                               "plant.augmented.toml", "details.json"}
    assert all(p.exists() for p in paths.values())
