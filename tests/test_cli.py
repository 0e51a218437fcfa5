"""Command line: check, linearize, simulate, --help."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.__main__ import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"
SITUM = ROOT / "designs" / "plants" / "situm_rodless.toml"


def test_check_prints_summary(capsys):
    assert main(["check", str(PLANT)]) == 0
    out = capsys.readouterr().out
    for word in ("plant file OK", "piston area", "max force", "l/min ANR", "effects"):
        assert word in out


def test_check_reports_bad_file(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(PLANT.read_text().replace("mass = 1.2", "mass = -1.2"))
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "[load] mass" in err and "> 0" in err


def test_linearize_json(capsys):
    assert main(["linearize", str(SITUM), "--x", "0.25", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["equilibrium"]) >= {"u", "p_a", "p_b"}
    A = np.array(out["A"])
    assert A.shape == (4, 4) and np.array(out["B"]).shape == (4, 1)
    assert len(out["eigenvalues"]) == 4
    assert set(out["reduced_model"]) >= {"Kv", "w0", "zeta"}


def test_linearize_rejects_position_outside_stroke(capsys):
    assert main(["linearize", str(SITUM), "--x", "0.9"]) == 2
    assert "outside the stroke" in capsys.readouterr().err


def test_simulate_replays_closed_loop_recording(tmp_path, capsys):
    from workbench import Plant, controllers, simulate
    plant = Plant.from_toml(PLANT)
    run = simulate.closed_loop(plant, controllers.from_plant(plant),
                               simulate.steps([0.2, 0.3], hold=0.5), x0=0.25,
                               output_times=np.arange(0.0, 1.0 + 1e-9, 0.001))
    rec_path = tmp_path / "rec.csv"
    run.to_csv(rec_path, columns=("t", "u", "x", "p_a", "p_b", "r"))
    out = tmp_path / "out"
    assert main(["simulate", str(PLANT), str(rec_path), "--out", str(out), "--quiet"]) == 0
    fits = json.loads((out / "fit.json").read_text())
    assert set(fits) == {"x", "p_a", "p_b"}
    # the recording was made by this very model: the replay reproduces it (fit ~100 %)
    assert min(fits.values()) > 99.0
    header = [ln for ln in (out / "simulation.csv").read_text().splitlines()
              if not ln.startswith("#")][0]
    assert header.split(",") == ["t", "u", "x", "p_a", "p_b", "r"]
    assert (out / "simulation.png").exists()


def test_simulate_open_loop_without_reference(tmp_path):
    t = np.arange(0.0, 0.3, 0.001)
    u = np.where(t < 0.1, 5.0, 5.5)
    rec = tmp_path / "ol.csv"
    rec.write_text("t,u,x\n" + "\n".join(f"{a:.3f},{b:.3f},0.25" for a, b in zip(t, u)) + "\n")
    out = tmp_path / "o"
    assert main(["simulate", str(PLANT), str(rec), "--out", str(out), "--quiet",
                 "--no-plot"]) == 0
    fits = json.loads((out / "fit.json").read_text())
    assert set(fits) == {"x"}


@pytest.mark.parametrize("cmd", ["check", "simulate", "linearize", "bench"])
def test_help_is_complete(cmd, capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args([cmd, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "usage:" in out and "SI" in out


def test_python_dash_m_entry_point():
    res = subprocess.run([sys.executable, "-m", "workbench", "--version"], capture_output=True,
                         text=True, check=False)
    assert res.returncode == 0 and "workbench" in res.stdout


def test_limits_help_is_complete(capsys):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["limits", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "usage:" in out and "SI" in out
    for opt in ("--x", "--w0", "--zeta", "--sample-time", "--k0", "--kp", "--kv", "--json",
                "null"):
        assert opt in out
