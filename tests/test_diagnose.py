"""Mismatch diagnosis (issue 6): concealed effects are named, refitted and improve the fit.

Each concealed case is a 10 s, 1 kHz closed-loop recording of the 25 mm rig (PD loop
kp = 5 V/m, kd = 0.1 V s/m at 10 ms) with sensor noise and 12-bit quantisation on x
and the pressures. The effect's values are drawn (seeded) from realistic ranges by
:func:`workbench.diagnose.synth.concealed_case`, but the recording of every
concealed-effect case is made by the independent simulator :mod:`foreign_rig`
(tests/foreign_rig.py: numpy/scipy, its own valve, lines in 5 pi-segments, (p, m)
energy balance, smooth friction law), not by the workbench's own model, so a wrong
law shared by the simulator and the diagnosis cannot pass unseen (issue 17). The
other tests here use :mod:`workbench.diagnose.synth` recordings. The diagnosis gets
only the nominal plant file and the CSV. Recordings are made once per test session.

Tolerances: the fitted value of the checked keys within 30 % of the concealed one
(the issue's bound), for the keys of ``synth.CHECKED_KEYS`` and :data:`ALSO_CHECKED`;
exactly one finding (one effect is concealed); "fit improves": the mean fit over the
recorded signals rises and no signal loses more than 0.5 percentage points (a
pressure-only effect may leave the position fit at 99.9 % unchanged within rounding).
None of these had to change for the foreign recordings.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.diagnose import synth

import foreign_rig

#: Seconds of each concealed-effect recording. 20 s until session 14; 10 s costs 40 % less
#: (valve_offset, one loaded machine: 61 -> 36 CPU s) and every case still passes every
#: bound below (all 11 cases run at 10 s, 2026-11-25): half the data is the harder test.
DURATION = 10.0

#: (concealed kind, seed). Seeds are fixed for reproducibility; the draws are the
#: generator's (values printed on failure).
CASES = [("none", 3), ("dry_friction", 3), ("valve_deadband", 3), ("valve_offset", 3),
         ("valve_dynamics", 3), ("line_dynamics", 3), ("leakage", 3), ("supply_droop", 3),
         ("heat_transfer", 3), ("mass_error", 3), ("leakage_cross", 3)]

#: Foreign-only cases: (synth kind, concealed values). A worn piston seal passing
#: 2e-9 kg/(s Pa) x 1 bar = 2e-4 kg/s (10 l/min ANR, 0.5 % of the valve's full flow).
FOREIGN_VALUES = {"leakage_cross": ("leakage", {"leakage.cross_piston": 2e-9})}

#: Fitted values checked here (besides ``synth.CHECKED_KEYS``), each within 30 % of the
#: concealed value (the issue's bound), computed in the test from the JSON: every
#: concealed value that the recording identifies (the Stribeck velocity of dry
#: friction is left out: it shapes only the few ms after break-away).
ALSO_CHECKED = {"dry_friction": ("friction.static",),
                "valve_dynamics": ("valve.bandwidth", "valve.damping"),
                "line_dynamics": ("lines.length", "lines.diameter"),
                "supply_droop": ("supply.reservoir_volume", "supply.regulator_conductance"),
                "heat_transfer": ("gas.heat_transfer_coefficient",),
                "leakage_cross": ("leakage.cross_piston",)}

#: Tighter bounds (relative) where the foreign rig shares the law with the workbench's
#: model (ISO 6358 edges, spool overlap and offset, 2nd-order spool, rigid mass, laminar
#: cross leak) and only the integrator and sensor noise differ. Measured errors on the
#: foreign recordings (seed 3, 20 s): coulomb 0.09 %, static 0.7 % (with the smooth friction
#: law), deadband 0.008 %, null offset 0.007 %, bandwidth 0.3 %, damping 0.3 %, leak to
#: atmosphere 0.004 %, mass 0.0005 %, cross leak 2.1 %, heat coefficient 3.2 % (the
#: (p, m) energy balance); 5 % (10 % for the last two) leaves a margin of 3 or more.
#: Lines (length +11 %, diameter -4.6 %: 5 pi-segments against the diagnosis's 3) and
#: supply droop (volume +12.5 %, conductance +6.6 %: the regulator works near p_dw/p_up
#: = 1, where the two laminar patches of psi differ) keep the issue's 30 %.
TIGHT = {"friction.coulomb": 0.05, "friction.static": 0.05, "valve.deadband": 0.05,
         "valve.null_offset": 0.05, "valve.bandwidth": 0.05, "valve.damping": 0.05,
         "leakage.conductance_to_atmosphere": 0.05, "load.mass": 0.05,
         "leakage.cross_piston": 0.10, "gas.heat_transfer_coefficient": 0.10}

_CACHE: dict[tuple, tuple] = {}


@pytest.fixture(scope="session")
def diag_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("diagnose")


def concealed(kind: str, seed: int, root: Path, duration: float = DURATION, **kw):
    """(case, plant file, recording file), made once per session."""
    key = (kind, seed, duration, tuple(sorted(kw.items())))
    if key not in _CACHE:
        case = synth.concealed_case(kind, seed=seed)
        d = root / f"{kind}_{seed}_{int(duration)}_{len(_CACHE)}"
        d.mkdir(parents=True, exist_ok=True)
        rec = synth.record(case, seed=seed, duration=duration, **kw)
        _CACHE[key] = (case, case.write_nominal(d / "plant.toml"), rec.to_csv(d / "recording.csv"),
                       rec)
    return _CACHE[key]


def _fit_improved(before: dict, after: dict) -> bool:
    mean_b = np.mean([before[k] for k in before])
    mean_a = np.mean([after[k] for k in before])
    return mean_a > mean_b and all(after[k] >= before[k] - 0.5 for k in before)


def foreign_concealed(kind: str, seed: int, root: Path, duration: float = DURATION):
    """(case, plant file, recording file): the concealed values drawn by
    :func:`synth.concealed_case` (the draw only), the recording made by the independent
    simulator :mod:`foreign_rig` (its own valve, lines, chambers, friction law), once
    per session."""
    key = ("foreign", kind, seed, duration)
    if key not in _CACHE:
        synth_kind, values = FOREIGN_VALUES.get(kind, (kind, None))
        case = synth.concealed_case(synth_kind, seed=seed, values=values)
        d = root / f"foreign_{kind}_{seed}_{int(duration)}"
        d.mkdir(parents=True, exist_ok=True)
        plant_file = case.write_nominal(d / "plant.toml")
        vals = dict(case.values)
        fr = None
        if kind == "dry_friction":
            fr = {"coulomb": vals.pop("friction.coulomb"), "static": vals.pop("friction.static"),
                  "stribeck": vals.pop("friction.stribeck_velocity")}
        ref = synth.rich_reference(seed, duration, case.nominal["cylinder.stroke"])
        rec = foreign_rig.record(plant_file, ref, duration, seed=seed + 7, overrides=vals,
                                 friction=fr)
        _CACHE[key] = (case, plant_file, rec.to_csv(d / "recording.csv"), rec)
    return _CACHE[key]


@pytest.mark.independent          # its own recording: may run on either worker (conftest)
@pytest.mark.parametrize("kind,seed", CASES, ids=[c[0] for c in CASES])
def test_concealed_effect_is_diagnosed(kind, seed, diag_dir):
    from workbench.diagnose import diagnose
    case, plant_file, rec_file, _ = foreign_concealed(kind, seed, diag_dir)
    d = diagnose(plant_file, rec_file)
    res = d.to_dict()
    sc = synth.score(case, res)
    info = f"concealed {case.values}; got {json.dumps(res['findings'])[:400]}"
    assert sc["correct"], f"named {sc['named']} instead of {sc['expected']}: {info}"
    if kind == "none":
        assert res["findings"] == []
        assert res["fit_after"] == res["fit_before"]
        return
    # synth's checked keys are those of its own draw (not of a FOREIGN_VALUES case)
    assert sc["checked_ok"] or kind in FOREIGN_VALUES, \
        f"fitted values off by {sc['relative_errors']}: {info}"
    # one effect is concealed: nothing else may be named
    assert len(res["findings"]) == 1, info
    par = res["findings"][0]["parameters"]
    for key in ALSO_CHECKED.get(kind, ()):
        true = case.values[key]
        assert abs(par[key.split(".", 1)[1]] - true) <= 0.3 * abs(true), f"{key}: {info}"
    for key in (k for k in case.values if k in TIGHT):
        got = par[key] if kind == "mass_error" else par[key.split(".", 1)[1]]
        assert abs(got - case.values[key]) <= TIGHT[key] * abs(case.values[key]), \
            f"{key} beyond {TIGHT[key]:.0%}: {info}"
    if kind in ("leakage", "leakage_cross"):
        # the leak put on the right path: the other path's flow (to atmosphere from 5 bar,
        # ISO 6358 choked q = C p rho0; across the piston at 1 bar, q = c dp) < 5 % of the
        # concealed path's at the same pressures
        q_atm = par["conductance_to_atmosphere"] * 5e5 * 1.185
        q_cross = par.get("cross_piston", 0.0) * 1e5
        if kind == "leakage":
            q_true = case.values["leakage.conductance_to_atmosphere"] * 5e5 * 1.185
            assert q_cross < 0.05 * q_true, info
        else:
            assert q_atm < 0.05 * case.values["leakage.cross_piston"] * 1e5, info
    assert _fit_improved(res["fit_before"], res["fit_after"]), \
        f"fit before {res['fit_before']} after {res['fit_after']}"
    f0 = res["findings"][0]
    assert 0.0 < f0["confidence"] <= 1.0
    assert f0["where"] and all(a <= b for a, b in f0["where"])
    assert f0["fit_after"] == res["fit_after"] or len(res["findings"]) > 1


def test_json_contract_and_files(diag_dir, tmp_path, monkeypatch):
    """diagnosis.json has exactly the keys of formats.md section 4; the augmented plant
    file loads and has the effect; the CLI writes report.html."""
    import workbench.diagnose as wd
    from workbench.__main__ import main
    from workbench import Plant
    case, plant_file, rec_file, rec = concealed("valve_offset", 5, diag_dir, duration=8.0)
    out = tmp_path / "out"
    seen = []
    real = wd.diagnose
    monkeypatch.setattr(wd, "diagnose", lambda *a, **kw: seen.append(real(*a, **kw)) or seen[-1])
    rc = main(["diagnose", str(plant_file), str(rec_file), "--out", str(out), "--quiet"])
    assert rc == 0
    res = json.loads((out / "diagnosis.json").read_text())
    _check_diagnosis_values(res, json.loads((out / "details.json").read_text()), seen[0], rec)
    assert list(res) == ["plant", "recording", "fit_before", "fit_after", "findings"]
    assert set(res["fit_before"]) == {"x", "p_a", "p_b"}
    assert res["findings"], "an offset of 0.1-0.3 V must be found even in 8 s"
    f = res["findings"][0]
    assert list(f) == ["effect", "confidence", "parameters", "where", "evidence", "fit_after"]
    assert f["effect"] == "valve_offset" and list(f["parameters"]) == ["null_offset"]
    aug = Plant.from_toml(out / "plant.augmented.toml")
    assert "valve_offset" in aug.effects
    assert aug.params["valve.null_offset"] == pytest.approx(f["parameters"]["null_offset"],
                                                            rel=1e-5)
    html = (out / "report.html").read_text()
    assert "Candidates ranked by evidence" in html and "valve_offset" in html
    assert (out / "report.pdf").stat().st_size > 10_000


def _nrmse(y, ym):
    """formats.md section 4: 100 (1 - ||y - y_model|| / ||y - mean(y)||), over the samples
    the replay reached (finite)."""
    y, ym = np.asarray(y, float), np.asarray(ym, float)
    ok = np.isfinite(ym)
    y, ym = y[ok], ym[ok]
    return 100.0 * (1.0 - np.linalg.norm(y - ym) / np.linalg.norm(y - y.mean()))


def _check_diagnosis_values(res, details, d, rec):
    """The values of diagnosis.json (issue 17), each recomputed here: the fits from the
    nominal and augmented replays by the NRMSE formula (written to 2 decimals: 0.006
    allows the rounding), the last finding's fit is the overall fit after, parameters
    and their 95 % intervals against the ranked candidate in details.json (at least value +-
    1.96 std, or v exp(+-1.96 std / v) for a log-scaled value), the confidence by the
    formula of evidence.confidence written out, and the intervals inside the recording."""
    import math
    assert res["plant"] == d.plant_file and res["recording"] == d.recording_file
    for key, run in (("fit_before", d.replay_nominal), ("fit_after", d.replay_augmented)):
        assert set(res[key]) == {"x", "p_a", "p_b"}
        for s, v in res[key].items():
            assert v == pytest.approx(_nrmse(rec[s], run[s]), abs=6e-3), (key, s)
    assert res["findings"][-1]["fit_after"] == res["fit_after"]
    cands = details["candidates"]
    t0, t1 = float(rec.t[0]), float(rec.t[-1])
    for i, (f, fo) in enumerate(zip(res["findings"], d.findings)):
        r = next(c for c in cands if c["candidate"] == fo.name)
        assert r["effect"] == f["effect"] and r["significant"]
        for k, v in f["parameters"].items():
            key = next(q for q in r["values"] if q.split(".")[-1] == k)
            # written to 6 significant digits
            assert v == pytest.approx(r["values"][key], rel=1e-5), k
            lo, hi = r["ci95"][key]
            sd, val = r["std"][key], r["values"][key]
            if math.isclose(hi - val, val - lo, rel_tol=1e-6):
                half = 1.96 * sd
            else:                                          # log-scaled: v exp(+-1.96 sd / v)
                half = val * (math.exp(1.96 * sd / val) - 1.0)
            # 1.96 or scipy's 1.959964 (a grey-box polish): 1e-4 relative covers both;
            # wider where an evaluated value fits inside the likelihood region
            # (refit._evaluated_span: tests/test_diagnose_interval.py), never narrower
            assert hi - val == pytest.approx(half, rel=1e-4) or hi - val > half, k
            assert lo <= val <= hi, k
        runner = next((c for c in cands if c["candidate"] != fo.name), None) if i == 0 else None

        def logistic(x):
            return 1.0 / (1.0 + math.exp(-0.5 * x)) if x < 60 else 1.0
        w = logistic(r["dbic"])
        if runner is not None and runner["dbic"] is not None and math.isfinite(runner["dbic"]):
            dd = r["dbic"] - runner["dbic"]
            w = min(1.0 / (1.0 + math.exp(-0.5 * dd)) if abs(dd) < 60 else float(dd > 0), w)
        w *= 0.6 + 0.4 * min(max(r["gain"], 0.0), 1.0)
        if r["consistency"] is not None and r["consistency"] < 0.5:
            w *= 0.85
        assert 0.0 <= f["confidence"] <= 0.99
        assert f["confidence"] == pytest.approx(min(w, 0.99), abs=5e-4)   # rounded to 3
        assert f["where"], "a finding shows somewhere"
        for a, b in f["where"]:
            assert t0 <= a < b <= t1
        assert all(f["where"][j][1] <= f["where"][j + 1][0] for j in range(len(f["where"]) - 1))


def test_position_only_recording_still_reveals_friction(diag_dir):
    """Without pressures: a note says what is lost, and dry friction is still named."""
    from workbench.diagnose import diagnose
    case, _, _, rec = concealed("dry_friction", 4, diag_dir, duration=16.0)
    pos_only = rec.__class__.from_arrays(rec.t, u=rec["u"], x=rec["x"], r=rec["r"],
                                         metadata=dict(rec.metadata))
    d = diagnose(case.nominal_plant, pos_only)
    assert any("pressures" in n for n in d.notes)
    assert list(d.fit_before) == ["x"]
    assert d.findings and d.findings[0].effect == "dry_friction", d.summary()
    assert d.findings[0].parameters["coulomb"] == pytest.approx(case.values["friction.coulomb"],
                                                                rel=0.3)


def test_too_short_recording_is_refused(diag_dir):
    from workbench.diagnose import diagnose
    from workbench.errors import InputError
    case, _, _, rec = concealed("none", 6, diag_dir, duration=8.0)
    n = 1500
    short = rec.__class__.from_arrays(rec.t[:n], **{c: rec[c][:n] for c in rec.columns if c != "t"},
                                      metadata=dict(rec.metadata))
    with pytest.raises(InputError, match="too short"):
        diagnose(case.nominal_plant, short)


def test_reference_without_controller_replays_open_loop(diag_dir, tmp_path):
    """r recorded but no [controller]: a clear note, open-loop re-anchored replay, and the
    effect is still found from the recorded command."""
    from workbench import Plant
    from workbench.diagnose import diagnose
    case, _, _, rec = concealed("valve_deadband", 7, diag_dir, duration=12.0)
    plain = case.nominal.replace(**{k: None for k in case.nominal.values
                                    if k.startswith("controller.")})
    plant_file = tmp_path / "no_controller.toml"
    plain.to_toml(plant_file)
    d = diagnose(Plant.from_toml(plant_file), rec)
    assert any("no [controller]" in n for n in d.notes)
    assert "open loop" in d.mode
    assert d.findings and d.findings[0].effect == "valve_deadband", d.summary()
    assert d.findings[0].parameters["deadband"] == pytest.approx(case.values["valve.deadband"],
                                                                 rel=0.3)


def test_candidate_values_map_to_plant_keys():
    from workbench.diagnose.candidates import candidates
    params = synth.nominal_params()
    cands = {c.name: c for c in candidates(params)}
    fr = cands["dry_friction"]
    pv = fr.plant_values({"friction.coulomb": 20.0, "friction.static_excess": 0.5,
                          "friction.stribeck_velocity": 0.01})
    assert pv == {"friction.coulomb": 20.0, "friction.static": 30.0,
                  "friction.stribeck_velocity": 0.01}
    assert fr.reported({"friction.coulomb": 20.0, "friction.static_excess": 0.5,
                        "friction.stribeck_velocity": 0.01}) == \
        {"coulomb": 20.0, "static": 30.0, "stribeck_velocity": 0.01}
    m = cands["parameter_error:load.mass"]
    assert m.reported({"load.mass": 3.0}) == {"load.mass": 3.0}
    ln = cands["line_dynamics"]
    assert set(ln.reported({"lines.length": 2.0, "lines.diameter": 4e-3})) == {"length", "diameter"}
    # every effect of formats.md section 2 is a candidate
    from workbench.params import EFFECT_NAMES
    assert set(EFFECT_NAMES) <= {c.effect for c in cands.values()}
    # transforms round-trip within the bounds
    for c in cands.values():
        z = c.z0()
        vals = c.values(z)
        assert np.allclose(c.z0(vals), z)


def test_engine_matches_cvodes_open_loop():
    """The fixed-step engine (ROS2, 1 ms) follows the CVODES reference on an open-loop
    command sequence (moves both ways, stops) within 0.2 mm (more than the quantisation
    step of the 12-bit position sensor, 0.12 mm) and 1 kPa (twice the pressure noise);
    with dry friction too (its stick-slip stepping)."""
    from workbench import Plant, simulate
    from workbench.diagnose.engine import Engine, EngineInputs, INPUT_ROWS
    base = synth.nominal_params()
    for params in (base, base.replace(**{"friction.coulomb": 15.0, "friction.static": 22.0,
                                         "friction.stribeck_velocity": 0.01})):
        plant = Plant(params)
        t = np.arange(1500) * 1e-3
        u = np.where(t < 0.2, 5.0, np.where(t < 0.5, 5.25, np.where(t < 0.9, 4.8, 5.03)))
        z0 = plant.initial_state(0.25)
        ref = simulate.open_loop(plant, t, u, x0=z0, progress=False)
        d = np.zeros((len(INPUT_ROWS), len(t)))
        d[INPUT_ROWS.index("u_rec")] = u
        y = Engine(plant, 1e-3, None).run(z0, EngineInputs(d), plant.p0)
        assert np.ptp(ref["x"]) > 0.1                 # it did move
        assert np.max(np.abs(y[0] - ref["x"])) < 2e-4
        assert np.max(np.abs(y[1] - ref["p_a"])) < 1e3


def test_intervals_and_regimes():
    from workbench.diagnose.locate import intervals
    t = np.arange(1000) * 0.01
    s = np.zeros(1000)
    s[100:150] = 5.0
    s[155:160] = 5.0          # merged with the first (gap 0.05 s < 0.2 s)
    s[600:700] = 3.0
    iv = intervals(s, t, 1.0)
    assert iv == [[1.0, 1.59], [6.0, 6.99]]
    assert intervals(np.zeros(10), t[:10], 1.0) == []


def test_quantised_noise_estimate():
    from workbench.diagnose.data import _noise_std
    rng = np.random.default_rng(0)
    y = np.linspace(0.1, 0.3, 20000) + rng.normal(0, 20e-6, 20000)
    lsb = 0.5 / 4096
    yq = np.round(y / lsb) * lsb
    # quantisation dominates: LSB/sqrt(12) = 35 um, combined with 20 um: ~40 um
    assert 25e-6 < _noise_std(yq) < 50e-6
