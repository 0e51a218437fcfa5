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
SITUM = ROOT / "designs" / "plants" / "situm_rodless_nominal.toml"


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


# ---------------------------------------------------------------------- broken command modules
def test_broken_command_module_is_an_error_not_a_missing_command(monkeypatch, capsys):
    """A command module that cannot be imported stops the CLI with its cause (exit 1)."""
    monkeypatch.setitem(sys.modules, "workbench.cli.diagnose", None)   # import -> ImportError
    assert main(["check", str(PLANT)]) == 1          # even a command of another module
    err = capsys.readouterr().err
    assert "workbench.cli.diagnose" in err and "cannot be loaded" in err
    assert "Traceback" in err and "ModuleNotFoundError" in err


def _fake_module(name, register=None):
    import types
    mod = types.ModuleType(name)
    if register is not None:
        mod.register = register
    return mod


def _raising_register(subparsers):
    raise RuntimeError("half-written command")


@pytest.mark.parametrize("register,cause,word", [(None, AttributeError, "register"),
                                                 (_raising_register, RuntimeError,
                                                  "half-written command")])
def test_command_module_failure_names_the_cause(monkeypatch, register, cause, word):
    """No register() or a register() that fails: an error naming module and cause."""
    from workbench.cli import CommandModuleError
    monkeypatch.setitem(sys.modules, "workbench.cli.robustness",
                        _fake_module("workbench.cli.robustness", register))
    with pytest.raises(CommandModuleError, match="workbench.cli.robustness") as exc:
        build_parser()
    assert isinstance(exc.value.__cause__, cause)
    assert word in str(exc.value)


def test_every_command_group_registers():
    """The top-level commands are exactly those of the command modules (none missing)."""
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(sub.choices) == {"check", "linearize", "simulate", "limits", "map", "identify",
                                "diagnose", "robustness", "design", "bench"}


# ---------------------------------------------------------------------- bench registry
def test_bench_registry_matches_the_command():
    from workbench import bench
    from workbench.errors import InputError
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    name_arg = next(a for a in sub.choices["bench"]._actions if a.dest == "name")
    assert tuple(name_arg.choices) == bench.NAMES
    with pytest.raises(InputError, match="no benchmark 'nope'"):
        bench.run("nope")


@pytest.mark.parametrize("name", ["simulate", "sweep", "rls", "greybox", "mpc", "diagnose"])
def test_every_benchmark_module_loads(name):
    """Each registered benchmark imports and exposes bench(quick=...) (nothing is run)."""
    import inspect

    from workbench import bench
    fun = bench.load(name)
    assert "quick" in inspect.signature(fun).parameters


def test_bench_module_that_fails_to_import_is_reported(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "workbench.bench.sweep", None)
    assert main(["bench", "sweep", "--quick"]) == 2
    assert "benchmark 'sweep' is not available" in capsys.readouterr().err


# ---------------------------------------------------------------------- replay (library)
def test_replay_keeps_the_recording_columns(tmp_path):
    """Open-loop replay: the simulated columns replace the recorded ones, the others
    (here an unknown 'extra') are copied; the time base is the recording's."""
    from workbench import Plant
    from workbench.recording import Recording
    from workbench.replay import replay
    t = np.arange(0.0, 0.2, 0.001)
    rec = Recording.from_arrays(t, u=np.where(t < 0.1, 5.0, 5.5), x=np.full_like(t, 0.25),
                                extra=np.sin(t))
    res = replay(Plant.from_toml(PLANT), rec, mode="open", progress=False)
    assert res.mode == "open_loop"
    assert res.recording.columns == rec.columns
    np.testing.assert_array_equal(res.recording.t, rec.t)
    np.testing.assert_array_equal(res.recording["extra"], rec["extra"])
    np.testing.assert_array_equal(res.recording["u"], rec["u"])     # the command applied
    assert res.recording["x"][0] == pytest.approx(0.25, abs=1e-9)    # starts where recorded


def test_replay_closed_loop_needs_a_reference():
    from workbench import Plant
    from workbench.errors import InputError
    from workbench.recording import Recording
    from workbench.replay import replay
    t = np.arange(0.0, 0.05, 0.001)
    rec = Recording.from_arrays(t, u=np.full_like(t, 5.0), x=np.full_like(t, 0.25))
    with pytest.raises(InputError, match="needs an 'r' column"):
        replay(Plant.from_toml(PLANT), rec, mode="closed")


# ---------------------------------------------------------------------- map controller
def test_map_controller_from_plant_file_and_overrides(tmp_path):
    """Gains from the plant file's [controller] (read here with tomllib), overridden one by
    one; without a [controller] a sample time and a gain are needed unless swept."""
    import tomllib

    import tomli_w

    from workbench import Plant
    from workbench.errors import InputError
    from workbench.stability.loop import map_controller
    plant = Plant.from_toml(PLANT)
    doc = tomllib.loads(PLANT.read_text())
    ctrl = doc.pop("controller")
    got = map_controller(plant)
    assert got["kp"] == ctrl["kp"] and got["kd"] == ctrl["kd"]
    assert got["sample_time"] == ctrl["sample_time"]
    assert map_controller(plant, kd=0.3, sample_time=0.002) == {
        "kp": ctrl["kp"], "kd": 0.3, "ki": got["ki"], "sample_time": 0.002}
    bare_file = tmp_path / "bare.toml"
    bare_file.write_text(tomli_w.dumps(doc))
    bare = Plant.from_toml(bare_file)
    with pytest.raises(InputError, match="no sample time"):
        map_controller(bare, kp=1.0)
    with pytest.raises(InputError, match="no gain"):
        map_controller(bare, sample_time=0.01)
    assert map_controller(bare, {"k0", "sample_time"}) == {
        "kp": 1.0, "kd": 0.0, "ki": 0.0, "sample_time": 0.01}      # placeholders, swept


# ---------------------------------------------------------------------- issue 15: refusals
ARX_ROWS = "t,u,x\n" + "\n".join(f"{0.01 * k:.2f},{(-1) ** (k // 3)},{0.001 * k % 0.3:.4f}"
                                  for k in range(200)) + "\n"


@pytest.mark.parametrize("argv, words", [
    (["identify", "rls", "{rec}", "--input", "u", "--burn-in", "-5", "--out", "{out}"],
     ["--burn-in", ">= 0"]),
    (["identify", "rls", "{rec}", "--input", "u", "--burn-in", "1000000000", "--out", "{out}"],
     ["--burn-in 1000000000", "200 samples"]),
    (["identify", "arx", "{rec}", "--input", "u", "--orders", "2", "1", "1", "--lags",
      "1000000", "--out", "{out}"], ["--lags 1000000", "at most 24 lags"]),
    (["identify", "arx", "{rec}", "--input", "u", "--orders", "2", "-1", "1"],
     ["--orders", ">= 0"]),
    (["robustness", str(PLANT), "--seed", "-1"], ["--seed", ">= 0"]),
    (["robustness", str(PLANT), "--draws", "0"], ["--draws", ">= 1"]),
    (["diagnose", str(PLANT), "{rec}", "--out", "{out}", "--workers", "0"],
     ["--workers", ">= 1"]),
    (["diagnose", str(PLANT), "{rec}", "--out", "{out}", "--workers", "-3"],
     ["--workers", ">= 1"]),
    (["limits", "--w0", "100", "--zeta", "0.5", "--sample-time", "0.01", "--kp", "10",
      "--kv", "0"], ["--kv", "positive"]),
    (["limits", "--w0", "nan", "--zeta", "0.5", "--sample-time", "0.01"], ["--w0", "finite"]),
    (["map", str(PLANT), "--x-axis", "k0=1:9:3", "--y-axis", "mass=1:2:2", "--delay", "-1",
      "--out", "{out}"], ["--delay", ">= 0"]),
    (["simulate", str(PLANT), "{rec}", "--out", ""], ["--out", "empty"]),
])
def test_bad_arguments_are_one_clear_line(tmp_path, capsys, argv, words):
    # on 8c8e7dd: clamped silently (rls --burn-in, arx --lags, diagnose --workers), a
    # traceback (robustness --seed -1) or the wrong name (limits --kv 0 blamed k0)
    rec = tmp_path / "rec.csv"
    rec.write_text(ARX_ROWS)
    out = tmp_path / "out"
    argv = [a.format(rec=rec, out=out) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert "Traceback" not in err and "error" in last
    for w in words:
        assert w in last, last
    assert "k0" not in last or "--k0" in last
    assert not out.exists()


def test_cli_choices_match_the_library():
    # the parser is built without importing the estimators; their constants are copied
    from workbench.cli.identify import arx as cli_arx, rls as cli_rls
    from workbench.identify.arx import CRITERIA
    from workbench.identify.rls import DEFAULT_CANDIDATES
    assert cli_arx.CRITERIA == CRITERIA
    assert cli_rls.DEFAULT_CANDIDATES == DEFAULT_CANDIDATES


def test_help_loads_no_heavy_module():
    """`workbench --help` builds every parser without casadi, scipy, matplotlib, control
    (issue 15: 3-8 s per call; each of these takes 0.06 .. 0.7 s to import)."""
    code = ("import sys, time; t = time.perf_counter(); from workbench.cli import build_parser;"
            "build_parser(); dt = time.perf_counter() - t;"
            "print([m for m in ('casadi', 'scipy', 'matplotlib', 'control', 'dask', 'tqdm',"
            " 'reportlab') if m in sys.modules], dt)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    heavy, seconds = res.stdout.rsplit(" ", 1)
    assert heavy == "[]", res.stdout
    # ~0.15 s measured on an idle core; 1 s is the bound
    assert float(seconds) < 1.0


def test_robustness_shows_progress_unless_quiet(monkeypatch, capsys):
    # issue 15: progress=None reached tqdm(disable=not progress), i.e. never shown
    import tqdm.auto
    from workbench import robustness as rb
    seen = []
    real = tqdm.auto.tqdm

    def spy(*a, **k):
        seen.append(k.get("disable"))
        return real(*a, **{**k, "disable": True})
    monkeypatch.setattr(tqdm.auto, "tqdm", spy)
    judge = lambda p, c: rb.Outcome(True)                       # noqa: E731
    from workbench import Plant
    plant = Plant.from_toml(PLANT)
    rb.monte_carlo(plant, {"c": lambda p: None}, n=1, judge=judge, progress=None)
    rb.monte_carlo(plant, {"c": lambda p: None}, n=1, judge=judge, progress=False)
    assert seen == [None, True]     # None: tqdm decides (shown on a terminal)
    monkeypatch.setattr(rb, "monte_carlo", lambda *a, **k: (_ for _ in ()).throw(
        KeyboardInterrupt()))
    assert main(["robustness", str(PLANT), "--draws", "3"]) == 130
    err = capsys.readouterr().err
    assert "robustness: validating" in err and "3 drawn plants" in err


def test_non_utf8_plant_file_is_one_line_naming_it(tmp_path, capsys):
    # issue 15: a plant file saved as Latin-1 (a degree sign in a comment) gave a
    # UnicodeDecodeError traceback
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(PLANT.read_bytes().replace(b"\n", b"  # 20 \xb0C\n", 1))
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "latin1.toml" in err and "UTF-8" in err


def test_nul_in_an_argument_is_refused(capsys):
    assert main(["check", "plant\x00.toml"]) == 2
    assert "NUL" in capsys.readouterr().err
