"""workbench.output: result sets whole or not at all, inputs never overwritten."""

from __future__ import annotations

import os

import pytest

from workbench.errors import InputError
from workbench.output import Terminated, check_output_dir, result_set


def test_new_folder_appears_only_on_success(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        with result_set(out) as stage:
            (stage / "a.csv").write_text("x")
            raise KeyboardInterrupt
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []          # no staging folder left behind


def test_existing_folder_keeps_old_files_on_terminate(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "a.csv").write_text("old")
    (out / "keep.txt").write_text("user's")
    with pytest.raises(Terminated):
        with result_set(out) as stage:
            (stage / "a.csv").write_text("new")
            (stage / "b.csv").write_text("new")
            raise Terminated
    assert sorted(p.name for p in out.iterdir()) == ["a.csv", "keep.txt"]
    assert (out / "a.csv").read_text() == "old"
    with result_set(out) as stage:
        (stage / "a.csv").write_text("new")
        (stage / "sub").mkdir()
        (stage / "sub" / "c.txt").write_text("c")
    assert (out / "a.csv").read_text() == "new"
    assert (out / "sub" / "c.txt").read_text() == "c"
    assert (out / "keep.txt").read_text() == "user's"
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_input_is_never_overwritten(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    rec = out / "simulation.csv"
    rec.write_text("t,x\n0,0\n")
    with pytest.raises(InputError, match="overwrite the input"):
        with result_set(out, inputs=[rec]) as stage:
            (stage / "simulation.csv").write_text("t,x\n0,1\n")
    assert rec.read_text() == "t,x\n0,0\n"


@pytest.mark.parametrize("make, pattern", [
    (lambda d: "", "empty"),
    (lambda d: ((d / "f").write_text(""), d / "f")[1], "not a folder"),
    (lambda d: ((d / "f").write_text(""), d / "f" / "sub")[1], "is a file"),
])
def test_bad_output_folder_is_refused_before_work(tmp_path, make, pattern):
    with pytest.raises(InputError, match=pattern):
        check_output_dir(make(tmp_path))


def test_unwritable_output_folder_is_refused(tmp_path, monkeypatch):
    # os.access is patched, not chmod: the CI may run as root, who may write anywhere
    ro = tmp_path / "ro"
    ro.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: os.fspath(path) != os.fspath(ro))
    with pytest.raises(InputError, match="permission denied"):
        check_output_dir(ro / "run")


# ---------------------------------------------------------------------- the commands (issue 15)
from pathlib import Path  # noqa: E402

import json  # noqa: E402

import numpy as np  # noqa: E402

from workbench.cli import main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"
STEP = ROOT / "tests" / "data" / "recordings" / "step_small.csv"


@pytest.fixture(scope="module")
def arx_csv(tmp_path_factory) -> Path:
    """400 samples of a known 2nd-order ARX system driven by a random binary input."""
    rng = np.random.default_rng(0)
    n = 400
    u = np.sign(rng.standard_normal(n))
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.5 * u[k - 1] + 0.01 * rng.standard_normal()
    path = tmp_path_factory.mktemp("arx") / "arx.csv"
    path.write_text("t,u,x\n" + "\n".join(f"{0.01 * k:.2f},{a:.3f},{b:.6f}"
                                          for k, (a, b) in enumerate(zip(u, y))) + "\n")
    return path


def _commands(out: str, arx_csv: Path) -> dict[str, list[str]]:
    """Every command that writes a result set, with valid inputs and ``--out out``."""
    return {
        "simulate": ["simulate", str(PLANT), str(STEP), "--out", out, "--quiet"],
        "rls": ["identify", "rls", str(arx_csv), "--input", "u", "--out", out, "--quiet"],
        "arx": ["identify", "arx", str(arx_csv), "--input", "u", "--orders", "2", "1", "1",
                "--out", out],
        "robustness": ["robustness", str(PLANT), "--draws", "1", "--workers", "1",
                       "--out", out, "--quiet"],
        "map": ["map", str(PLANT), "--x-axis", "k0=1:30:2", "--y-axis", "mass=0.5:2:2",
                "--workers", "1", "--out", out, "--quiet"],
        "greybox": ["identify", "greybox", str(PLANT), str(STEP), "--params", "load.mass",
                    "--out", out, "--quiet"],
    }


def _nothing_computed(monkeypatch):
    """Any computation (loading the plant or the recording) fails the test."""
    from workbench import plant, recording

    def started(*a, **k):
        raise AssertionError("the computation started before --out was checked")
    monkeypatch.setattr(plant.Plant, "from_toml", classmethod(lambda cls, *a, **k: started()))
    monkeypatch.setattr(recording, "load_recording", started)
    monkeypatch.setattr(recording.Recording, "load", classmethod(lambda cls, *a, **k: started()))


@pytest.mark.parametrize("command", ["simulate", "rls", "arx", "robustness", "map", "greybox"])
@pytest.mark.parametrize("where", ["file", "under_file", "empty"])
def test_bad_out_is_refused_before_the_computation(tmp_path, arx_csv, monkeypatch, capsys,
                                                   command, where):
    # on 8c8e7dd: a traceback (FileExistsError, NotADirectoryError) after the computation
    a_file = tmp_path / "taken"
    a_file.write_text("mine\n")
    out = {"file": str(a_file), "under_file": str(a_file / "sub"), "empty": ""}[where]
    _nothing_computed(monkeypatch)
    assert main(_commands(out, arx_csv)[command]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "error" in err and len(err.strip().splitlines()) == 1, err
    assert a_file.read_text() == "mine\n"


@pytest.mark.skipif(not Path("/sys/kernel").is_dir(), reason="needs Linux sysfs")
def test_unwritable_out_is_refused_before_the_computation(tmp_path, arx_csv, monkeypatch,
                                                          capsys):
    # sysfs takes no new files, not even from root (a chmod-ed folder would not stop root)
    _nothing_computed(monkeypatch)
    assert main(_commands("/sys/kernel/workbench_out", arx_csv)["simulate"]) == 2
    err = capsys.readouterr().err
    assert "--out /sys/kernel/workbench_out: cannot write in /sys/kernel" in err, err
    assert not Path("/sys/kernel/workbench_out").exists()


def test_simulate_never_overwrites_the_recording_it_reads(tmp_path, capsys):
    # issue 15: `simulate PLANT D/simulation.csv --out D` overwrote the recording
    d = tmp_path / "D"
    d.mkdir()
    rec = d / "simulation.csv"
    rec.write_bytes(STEP.read_bytes())
    assert main(["simulate", str(PLANT), str(rec), "--out", str(d), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "would overwrite the input" in err and "simulation.csv" in err
    assert rec.read_bytes() == STEP.read_bytes()
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["D", "simulation.csv"]


def _strict(text: str):
    def refuse(token):
        raise ValueError(f"not JSON: {token}")
    return json.loads(text, parse_constant=refuse)


def test_fit_json_is_strict_json_when_a_signal_is_constant(tmp_path):
    # issue 15: fit.json held a bare NaN (x constant: the NRMSE fit is undefined)
    t = np.arange(0.0, 0.2, 0.001)
    rec = tmp_path / "ol.csv"
    rec.write_text("t,u,x\n" + "\n".join(f"{a:.3f},5.2,0.25" for a in t) + "\n")
    out = tmp_path / "o"
    assert main(["simulate", str(PLANT), str(rec), "--out", str(out), "--quiet",
                 "--no-plot"]) == 0
    assert _strict((out / "fit.json").read_text()) == {"x": None}


@pytest.mark.parametrize("command", ["simulate", "rls", "arx", "robustness", "map"])
def test_a_failure_while_writing_leaves_the_old_results(tmp_path, arx_csv, monkeypatch,
                                                        capsys, command):
    # issue 15: results were atomic per file: a full disk left some of the set
    from workbench import plots
    from workbench.identify import plots as iplots
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("previous run\n")

    def disk_full(*a, **k):
        raise OSError(28, "No space left on device")
    for mod in (plots, iplots):
        for name in dir(mod):
            if name.endswith("_figure"):
                monkeypatch.setattr(mod, name, disk_full)
    monkeypatch.setattr(plots, "save_figure", disk_full)
    assert main(_commands(str(out), arx_csv)[command]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["old.txt", "out"]


@pytest.mark.parametrize("command, files", [
    ("simulate", ["fit.json", "simulation.csv", "simulation.png"]),
    ("rls", ["estimates.csv", "report.md", "rls.png", "summary.json"]),
    ("arx", ["arx.json", "residuals.png", "validation.png"]),
    ("map", ["map.csv", "map.json", "map.png"])])
def test_result_sets_are_complete_and_strict_json(tmp_path, arx_csv, command, files):
    out = tmp_path / "out"
    assert main(_commands(str(out), arx_csv)[command]) == 0
    assert sorted(p.name for p in tmp_path.rglob("*")) == sorted(files + ["out"])
    for f in files:
        if f.endswith(".json"):
            _strict((out / f).read_text())


def test_rls_tiny_forgetting_is_refused_and_nothing_written(tmp_path, arx_csv, capsys):
    # issue 15: --forgetting 1e-300 crashed after writing estimates.csv full of NaN
    out = tmp_path / "rls"
    for lam in ("1e-300", "0.5"):
        assert main(["identify", "rls", str(arx_csv), "--input", "u", "--forgetting", lam,
                     "--out", str(out), "--quiet"]) == 2
        err = capsys.readouterr().err
        # 2 2 1 has 4 parameters: lambda must remember at least 4 samples, 1/(1-l) >= 4
        assert "fewer than the 4 parameters" in err and "0.75" in err
    assert list(tmp_path.iterdir()) == []
    assert main(["identify", "rls", str(arx_csv), "--input", "u", "--forgetting", "0.75",
                 "--out", str(out), "--quiet", "--no-plot"]) == 0


def test_library_blocks_leave_sigterm_and_custom_handlers_alone():
    import signal
    from workbench.output import stop_on_signals
    # Python's own Ctrl-C handler, as in a terminal (a test run started as a shell's
    # background job has SIGINT ignored, which the blocks leave alone as well)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        term = signal.getsignal(signal.SIGTERM)
        with stop_on_signals():                      # a library call (simulate, replay, ...)
            assert signal.getsignal(signal.SIGTERM) is term
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler

        def mine(signum, frame):
            pass
        old = signal.signal(signal.SIGINT, mine)
        try:
            with stop_on_signals(sigterm=True):      # the command line
                assert signal.getsignal(signal.SIGINT) is mine
                if term is signal.SIG_DFL:           # (a test runner may have its own)
                    assert signal.getsignal(signal.SIGTERM) is not term
            assert signal.getsignal(signal.SIGTERM) is term
        finally:
            signal.signal(signal.SIGINT, old)
    finally:
        signal.signal(signal.SIGINT, before)


def test_a_run_that_cannot_fit_in_memory_is_refused_before_allocating():
    # issue 15: `[controller] sample_time = 1e-9` made simulate allocate 23 GB until the
    # OOM killer stopped it; on 8c8e7dd this raised numpy's MemoryError (or swapped)
    import types
    from workbench import Plant, simulate
    plant = Plant.from_toml(PLANT)
    ctrl = types.SimpleNamespace(sample_time=1e-9)           # never sampled: refused first
    with pytest.raises(InputError, match=r"2\.4e\+10 control samples.*sample_time \(s, not ms\)"):
        simulate.closed_loop(plant, ctrl, simulate.steps([0.2, 0.3], hold=12.0))
    for bad in (0.0, float("nan"), -0.01):
        with pytest.raises(InputError, match="sample time must be a finite number > 0"):
            simulate.closed_loop(plant, types.SimpleNamespace(sample_time=bad),
                                 simulate.steps([0.2], hold=1.0))
