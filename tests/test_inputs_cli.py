"""Every command that reads a recording or a plant file, fed the damaged inputs of a
rig (session 12): exit 2, one line on stderr that names the file and the cause, no
traceback, and the output folder exactly as it was (an existing one keeps its files
byte for byte, a new one is not created, no staging folder is left beside it).

Run in-process through :func:`workbench.cli.main`; every case stops while reading its
inputs, before any computation, so the whole file takes seconds.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"
CLEAN = ROOT / "tests" / "data" / "recordings" / "step_small.csv"

#: Commands reading a recording (REC) with a valid plant file (PLANT); OUT: the folder.
RECORDING_COMMANDS = {
    "simulate": ["simulate", "PLANT", "REC", "--out", "OUT", "--quiet", "--no-plot"],
    "identify arx": ["identify", "arx", "REC", "--input", "u", "--output", "x",
                     "--orders", "2", "1", "1", "--out", "OUT"],
    "identify rls": ["identify", "rls", "REC", "--input", "u", "--output", "x",
                     "--orders", "2", "2", "1", "--out", "OUT", "--quiet"],
    "identify greybox": ["identify", "greybox", "PLANT", "REC", "--params", "load.mass",
                         "--out", "OUT", "--quiet"],
    "diagnose": ["diagnose", "PLANT", "REC", "--out", "OUT", "--quiet", "--workers", "1"],
}
#: Commands reading a plant file (PLANT), with a valid recording where one is needed.
PLANT_COMMANDS = {
    "check": ["check", "PLANT"],
    "linearize": ["linearize", "PLANT", "--x", "0.25", "--json"],
    "limits": ["limits", "PLANT", "--x", "0.25", "--json"],
    "map": ["map", "PLANT", "--x-axis", "kp=1:10:3", "--y-axis", "mass=0.5:2:2",
            "--out", "OUT", "--no-plot", "--quiet", "--workers", "1"],
    **{k: v for k, v in RECORDING_COMMANDS.items() if "PLANT" in v},
    "robustness": ["robustness", "PLANT", "--draws", "1", "--out", "OUT", "--quiet",
                   "--workers", "1"],
    "design": ["design", "PLANT", "--kind", "pid", "--quick", "--out", "OUT"],
}


def _clean_lines() -> tuple[list[str], list[str]]:
    lines = CLEAN.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return lines[:k + 1], lines[k + 1:]


def _bad_recordings(d: Path) -> dict[str, tuple[Path, str]]:
    """name -> (file, a phrase the error must hold)."""
    head, rows = _clean_lines()
    cut = d / "cut.csv"
    cut.write_text("\n".join(head + rows[:-1] + [rows[-1][:7]]) + "\n")
    nul = d / "nul.csv"
    nul.write_bytes(("\n".join(head + rows[:30]) + "\n").encode() + b"\x00" * 512)
    swapped = d / "plant_as_recording.csv"
    swapped.write_text(PLANT.read_text())
    twice = d / "twice.csv"
    twice.write_text("\n".join(head + rows[:20] + head[-1:] + rows[20:]) + "\n")
    empty = d / "empty.csv"
    empty.write_text("")
    return {"cut-off last line": (cut, "last line is cut off"),
            "NUL padding": (nul, "not closed properly"),
            "plant file as recording": (swapped, "TOML plant file"),
            "two runs": (twice, "more than one run"),
            "empty": (empty, "the file is empty")}


def _bad_plants(d: Path) -> dict[str, tuple[Path, str]]:
    text = PLANT.read_text()
    units = d / "units.toml"
    units.write_text(text.replace("bore = 0.025", 'bore = "25 mm"'))
    swapped = d / "recording_as_plant.csv"
    swapped.write_text(CLEAN.read_text())
    empty = d / "empty.toml"
    empty.write_text("# to do\n")
    syntax = d / "syntax.toml"
    syntax.write_text(text.replace("[load]", "[load"))
    return {"unit as text": (units, "bore = 0.025"),
            "recording as plant": (swapped, "looks like a recording"),
            "empty": (empty, "holds no keys"),
            "syntax": (syntax, "the line reads '[load'")}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("inputs")
    return {"recordings": _bad_recordings(d), "plants": _bad_plants(d)}


def _state(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` and every staging folder beside it."""
    state = {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*")
             if p.is_file()} if folder.exists() else {}
    state.update({p.name: b"" for p in folder.parent.iterdir() if ".partial-" in p.name})
    return state


def _run(argv: list[str]) -> tuple[int, str]:
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        code = main(argv)
    return code, err.getvalue()


def _check_refused(template: list[str], subs: dict[str, str], out: Path, bad: Path,
                   phrase: str, command: str) -> None:
    """Run with an existing output folder (a file in it), then with a new one."""
    out.mkdir(parents=True)
    (out / "old.txt").write_text("an earlier result")
    for folder in (out, out.parent / "new"):
        before = _state(folder)
        argv = [subs.get(a, a.replace("OUT", str(folder))) for a in template]
        code, err = _run(argv)
        assert code == 2, (argv, code, err)
        assert "Traceback" not in err, err
        last = err.strip().splitlines()[-1]
        assert last.startswith(f"workbench {command}: error: {bad}"), last
        assert phrase in last, (phrase, last)
        assert _state(folder) == before, "the output folder changed"
        assert not (folder.parent / "new").exists() or folder == out


@pytest.mark.parametrize("command", RECORDING_COMMANDS)
@pytest.mark.parametrize("case", ["cut-off last line", "NUL padding",
                                  "plant file as recording", "two runs", "empty"])
def test_damaged_recording_is_refused_and_nothing_written(tmp_path, inputs, command, case):
    bad, phrase = inputs["recordings"][case]
    _check_refused(RECORDING_COMMANDS[command], {"PLANT": str(PLANT), "REC": str(bad)},
                   tmp_path / "out", bad, phrase, command)


@pytest.mark.parametrize("command", PLANT_COMMANDS)
@pytest.mark.parametrize("case", ["unit as text", "recording as plant", "empty", "syntax"])
def test_bad_plant_file_is_refused_and_nothing_written(tmp_path, inputs, command, case):
    bad, phrase = inputs["plants"][case]
    _check_refused(PLANT_COMMANDS[command], {"PLANT": str(bad), "REC": str(CLEAN)},
                   tmp_path / "out", bad, phrase, command)


def test_left_out_column_is_one_warning_line_and_the_command_runs(tmp_path):
    """A logger's time-stamp column: the command succeeds, and says on one stderr line
    which column it left out and why (formats.md: more columns are allowed)."""
    rng = np.random.default_rng(0)
    u = 5.0 + np.sign(rng.standard_normal(200))
    x = np.zeros(200)
    for k in range(2, 200):     # a stable 2nd-order ARX system, so the fit is well posed
        x[k] = 1.5 * x[k - 1] - 0.7 * x[k - 2] + 0.01 * (u[k - 1] - 5.0)
    rec = tmp_path / "logger.csv"
    rec.write_text("stamp,t,u,x\n" + "\n".join(
        f"10:00:{k * 0.01:05.2f},{k * 0.01:.2f},{a:.3f},{b + 0.2:.6f}"
        for k, (a, b) in enumerate(zip(u, x))) + "\n")
    code, err = _run(["identify", "arx", str(rec), "--input", "u", "--output", "x",
                      "--orders", "2", "1", "1", "--json"])
    assert code == 0, err
    warnings = [line for line in err.splitlines() if ": warning: " in line]
    assert len(warnings) == 1, err
    assert warnings[0].startswith(f"workbench identify arx: warning: {rec}: column 'stamp' "
                                  "is left out"), warnings[0]
    assert "'10:00:00.00' at line 2" in warnings[0]
