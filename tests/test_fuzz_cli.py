"""Fuzz the command line (issue 15): every argument list gives a clean error or a valid
result, never a traceback and never a partial result set.

For each case, run in-process through :func:`workbench.cli.main`:

* the exit code is 0 (a result) or 2 (an error the user can fix);
* no exception escapes ``main`` and stderr holds no "Traceback";
* an error is one last line on stderr that says "error";
* after an error ``--out`` does not exist and no staging folder is left beside it;
  after a result every JSON file in it is strict JSON (no NaN, no Infinity).

The cases: hand-made ones (the issue's reproducers and their relatives) and
``hypothesis`` mutations of a valid command line of every command (values replaced by
hostile tokens, options dropped or repeated). The inputs are tiny (a 50-sample
recording, 1 drawn plant, a 3 x 2 map) so that valid cases finish in well under a second;
``diagnose`` and ``bench`` stop at the library call (their argument handling is what is
fuzzed here; their computations have their own tests).
"""

from __future__ import annotations

import contextlib
import io
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from workbench.cli import main

ROOT = Path(__file__).resolve().parents[1]
PLANT_SRC = ROOT / "designs" / "plants" / "rig25_mpye.toml"
REC_SRC = ROOT / "tests" / "data" / "recordings" / "step_small.csv"
TABLE_SRC = ROOT / "tests" / "data" / "valve" / "rig25_table.csv"
PLANT, REC = "PLANT", "REC"         # replaced by the copies of :func:`files`


class _Reached(Exception):
    """Raised by the stand-ins of diagnose and bench: the arguments were accepted."""


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, str]:
    """Copies of the plant, the recordings and the valve table, and hostile files; a
    case that writes over one of them fails (:func:`_check_case` compares them)."""
    d = tmp_path_factory.mktemp("fuzz_inputs")
    for name, src in (("plant.toml", PLANT_SRC), ("step.csv", REC_SRC), ("table.csv", TABLE_SRC)):
        (d / name).write_bytes(src.read_bytes())
    rng = np.random.default_rng(1)
    n = 120
    u = np.sign(rng.standard_normal(n))
    x = np.zeros(n)
    for k in range(2, n):
        x[k] = 1.5 * x[k - 1] - 0.7 * x[k - 2] + 0.5 * u[k - 1] + 0.01 * rng.standard_normal()
    (d / "arx.csv").write_text("t,u,x\n" + "\n".join(
        f"{0.01 * k:.2f},{a:.3f},{b:.6f}" for k, (a, b) in enumerate(zip(u, x))) + "\n")
    (d / "empty.csv").write_text("")
    (d / "binary.csv").write_bytes(bytes(range(256)) * 4)
    (d / "folder").mkdir()
    return {"PLANT": str(d / "plant.toml"), "REC": str(d / "step.csv"),
            "TABLE": str(d / "table.csv"), "ARX": str(d / "arx.csv"),
            "EMPTY": str(d / "empty.csv"), "BINARY": str(d / "binary.csv"),
            "FOLDER": str(d / "folder"), "MISSING": str(d / "no_such_file.csv")}


def _snapshot(argv: list[str], files: dict[str, str]) -> dict[str, bytes]:
    """The files the case reads (named in ``argv``, not as an output), with their bytes."""
    outs = {argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("--out", "--plant-toml")}
    return {k: Path(v).read_bytes() for k, v in files.items()
            if k in argv and k not in outs and Path(v).is_file()}


#: A valid, fast command line per command; OUT is replaced by a fresh folder.
BASE = {
    "check": ["check", PLANT, "--json"],
    "linearize": ["linearize", PLANT, "--x", "0.25", "--json"],
    "limits-model": ["limits", "--w0", "100", "--zeta", "0.5", "--sample-time", "0.01",
                     "--kp", "10", "--kv", "0.05", "--json"],
    "limits-plant": ["limits", PLANT, "--x", "0.25", "--json"],
    "simulate": ["simulate", PLANT, REC, "--out", "OUT", "--mode", "auto", "--no-plot",
                 "--quiet"],
    "map": ["map", PLANT, "--x-axis", "k0=1:30:3", "--y-axis", "mass=0.5:2:2", "--delay", "0",
            "--workers", "1", "--out", "OUT", "--no-plot", "--quiet"],
    "arx": ["identify", "arx", "ARX", "--input", "u", "--output", "x", "--orders", "2", "1",
            "1", "--split", "0.5", "--lags", "5", "--out", "OUT"],
    "arx-select": ["identify", "arx", "ARX", "--input", "u", "--select", "--na", "1:2",
                   "--nb", "1:2", "--nk", "0:1", "--criterion", "aic", "--json"],
    "rls": ["identify", "rls", "ARX", "--input", "u", "--orders", "2", "2", "1",
            "--forgetting", "0.99", "--p0", "auto", "--burn-in", "10", "--detrend", "none",
            "--out", "OUT", "--no-plot", "--quiet"],
    "robustness": ["robustness", PLANT, "--draws", "1", "--seed", "0", "--workers", "1",
                   "--ranges", "usual", "--out", "OUT", "--quiet"],
    "greybox": ["identify", "greybox", PLANT, REC, "--params", "load.mass", "--max-iter", "2",
                "--shooting-interval", "0.05", "--out", "OUT", "--quiet"],
    "valve-table": ["identify", "valve-table", PLANT, "--out", "OUT/table.csv", "--n-u", "5",
                    "--n-p", "4"],
    "diagnose": ["diagnose", PLANT, REC, "--out", "OUT", "--workers", "1", "--quiet"],
    # a rig's recording: column mapping with units and a time window
    "simulate-rig": ["simulate", PLANT, REC, "--columns", "x=x:m,u=u", "--window", "0:0.4",
                     "--out", "OUT", "--no-plot", "--quiet"],
    "arx-window": ["identify", "arx", "ARX", "--input", "u", "--output", "x", "--orders", "2",
                   "1", "1", "--window", "0.1:", "--columns", "t=t:s", "--json"],
    "bench": ["bench", "rls", "--quick", "--json"],
}

#: Tokens that replace a value: numbers at and beyond every edge, words, paths.
TOKENS = ["", " ", "0", "1", "-1", "-3", "2", "0.5", "0.25", "-0.5", "1e-9", "1e9", "1e-300",
          "-1e-300", "nan",
          "inf", "-inf", "1e309", "1000000", "abc", "1:2", "2:1", "k0=1:2:3", "mass=0:1:2",
          "x=1:2:0", "load.mass", "no.such", "u", "x", "r", "p_a", "auto", "mean", "I",
          "open", "é", "-", "--json", "a\x00b", "PLANT", "REC", "ARX", "EMPTY", "BINARY",
          "FOLDER", "MISSING", "OUT", "OUT/sub",
          "x=x:mm", "t=t:ms", "u=u:mV", "x=pos:mm", "x:mm", "p_a=x", "x=x:inch", "x=x,x=x",
          "0:0.02", ":", "0.5:", ":0.1", "5:6", "0.3:0.1", "--window", "--columns"]


def _resolve(argv: list[str], files: dict[str, str], out: Path) -> list[str]:
    return [files[a] if a in files else a.replace("OUT", str(out)) for a in argv]


def _check_case(argv: list[str], files: dict[str, str]) -> int:
    """Run one case (in an empty working folder) and assert the contract; return the
    exit code."""
    before = _snapshot(argv, files)
    with tempfile.TemporaryDirectory() as tmp, contextlib.chdir(tmp):
        out = Path(tmp) / "out"
        args = _resolve(argv, files, out)
        err, std = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
            try:
                code = main(args)
            except _Reached:
                code = None
        assert _snapshot(argv, files) == before, (args, "an input was overwritten")
        if code is None:
            return 0
        text = err.getvalue()
        assert "Traceback" not in text, (args, text)
        assert code in (0, 2), (args, code, text)
        left = sorted(str(p.relative_to(tmp)) for p in Path(tmp).rglob("*"))
        if code == 2:
            lines = text.strip().splitlines()
            assert lines and "error" in lines[-1], (args, text)
            assert left == [], (args, "written despite the error:", left)
        else:
            assert not [n for n in left if ".partial-" in n], (args, left)
            for f in Path(tmp).rglob("*.json"):
                json.loads(f.read_text(), parse_constant=lambda c: pytest.fail(
                    f"{f.name} holds {c}: not JSON ({args})"))
            if "--json" in args and std.getvalue().lstrip().startswith("{"):
                json.loads(std.getvalue(), parse_constant=lambda c: pytest.fail(
                    f"--json printed {c}: not JSON ({args})"))
        return code


@pytest.fixture(autouse=True)
def _no_long_runs(monkeypatch):
    """diagnose and bench stop at the library call (see the module docstring)."""
    import workbench.bench
    import workbench.diagnose

    def reached(*a, **k):
        raise _Reached()
    monkeypatch.setattr(workbench.diagnose, "diagnose", reached)
    monkeypatch.setattr(workbench.bench, "run", reached)


@pytest.mark.parametrize("name", sorted(BASE))
def test_every_base_command_line_is_valid(name, files):
    assert _check_case(BASE[name], files) == 0


HAND_MADE = [
    # the reproducers
    ["identify", "rls", "ARX", "--input", "u", "--burn-in", "-5", "--out", "OUT"],
    ["identify", "rls", "ARX", "--input", "u", "--burn-in", "1000000000", "--out", "OUT"],
    ["identify", "rls", "ARX", "--input", "u", "--forgetting", "1e-300", "--out", "OUT"],
    ["identify", "arx", "ARX", "--input", "u", "--orders", "2", "1", "1", "--lags", "1000000"],
    ["diagnose", "PLANT", "REC", "--out", "OUT", "--workers", "0"],
    ["diagnose", "PLANT", "REC", "--out", "OUT", "--workers", "-3"],
    ["robustness", "PLANT", "--seed", "-1"],
    ["limits", "--w0", "100", "--zeta", "0.5", "--sample-time", "0.01", "--kp", "10", "--kv",
     "0"],
    ["simulate", "PLANT", "REC", "--out", ""],
    ["simulate", "PLANT", "REC", "--out", "PLANT"],
    ["simulate", "PLANT", "REC", "--out", "REC/sub"],
    # files where they do not belong
    ["simulate", "REC", "REC", "--out", "OUT"],
    ["simulate", "PLANT", "PLANT", "--out", "OUT"],
    ["simulate", "PLANT", "EMPTY", "--out", "OUT"],
    ["simulate", "PLANT", "BINARY", "--out", "OUT"],
    ["simulate", "PLANT", "FOLDER", "--out", "OUT"],
    ["simulate", "PLANT", "MISSING", "--out", "OUT"],
    ["check", "BINARY"], ["check", "FOLDER"], ["check", "EMPTY"], ["check", "MISSING"],
    ["check", "a\x00b"],
    ["identify", "arx", "BINARY", "--orders", "1", "1", "1"],
    ["identify", "rls", "EMPTY", "--out", "OUT"],
    ["identify", "valve", "REC", "--approx", "I", "--no-tank"],
    ["identify", "valve", "MISSING"],
    ["identify", "greybox", "PLANT", "REC", "--params", "load.mas"],
    ["identify", "greybox", "PLANT", "REC", "--params", "load.mass", "--bounds", "load.mass=2:1"],
    ["identify", "greybox", "PLANT", "REC", "--params", "load.mass", "--shooting-interval",
     "-1"],
    ["identify", "greybox", "PLANT", "REC", "--params", "load.mass", "--max-iter", "0"],
    # numbers at the edges
    ["linearize", "PLANT", "--x", "nan"], ["linearize", "PLANT", "--x", "-0.1"],
    ["linearize", "PLANT", "--x", "1e309"],
    ["limits", "PLANT", "--x", "0.25", "--sample-time", "0"],
    ["limits", "PLANT", "--x", "0.25", "--k0", "-1"],
    ["limits", "--w0", "0", "--zeta", "0.5", "--sample-time", "0.01"],
    ["limits", "--w0", "100", "--zeta", "-0.5", "--sample-time", "0.01"],
    ["map", "PLANT", "--x-axis", "k0=1:30:1", "--y-axis", "mass=1:2:2", "--out", "OUT"],
    ["map", "PLANT", "--x-axis", "k0=1:30:3000", "--y-axis", "mass=1:2:2", "--out", "OUT"],
    ["map", "PLANT", "--x-axis", "nothing=1:2:3", "--y-axis", "mass=1:2:2", "--out", "OUT"],
    ["map", "PLANT", "--x-axis", "mass=-1:2:3", "--y-axis", "k0=1:2:2", "--out", "OUT"],
    ["robustness", "PLANT", "--vary", "load.mass=2:1", "--draws", "1", "--workers", "1"],
    ["robustness", "PLANT", "--vary", "load.mass=nan:1", "--draws", "1", "--workers", "1"],
    ["robustness", "PLANT", "--vary", "no.such=1:2", "--draws", "1"],
    ["identify", "arx", "ARX", "--input", "u", "--orders", "0", "0", "0"],
    ["identify", "arx", "ARX", "--input", "u", "--orders", "200", "1", "1"],
    ["identify", "arx", "ARX", "--input", "u", "--orders", "2", "1", "1", "--split", "nan"],
    ["identify", "rls", "ARX", "--input", "u", "--orders", "0", "0", "1", "--out", "OUT"],
    ["identify", "rls", "ARX", "--input", "u", "--p0", "-1", "--out", "OUT"],
    ["identify", "rls", "ARX", "--input", "u", "--p0", "nan", "--out", "OUT"],
    ["identify", "rls", "ARX", "--input", "no_col", "--out", "OUT"],
    ["identify", "valve-table", "PLANT", "--out", "OUT/t.csv", "--n-u", "0"],
    ["identify", "valve-table", "PLANT", "--out", "OUT/t.csv", "--n-p", "-3"],
    ["identify", "valve-table", "PLANT", "--out", "PLANT"],
    ["identify", "valve-table", "PLANT", "--out", "FOLDER"],
    ["identify", "valve-table", "PLANT", "--out", "OUT/t.csv", "--u", "1:2:0"],
    ["bench", "nothing"], ["no-such-command"], [],
]


@pytest.mark.parametrize("argv", HAND_MADE, ids=[" ".join(a)[:60] for a in HAND_MADE])
def test_hand_made_cases(argv, files):
    _check_case(argv, files)


@st.composite
def _mutated(draw):
    """A valid command line with some values replaced by tokens, some options dropped,
    an option repeated or an unknown one added."""
    name = draw(st.sampled_from(sorted(BASE)))
    argv = list(BASE[name])
    head = 2 if argv[0] == "identify" else 1
    for i in range(head, len(argv)):
        if draw(st.integers(0, 5)) == 0:
            argv[i] = draw(st.sampled_from(TOKENS))
    if draw(st.booleans()) and len(argv) > head + 1:
        del argv[draw(st.integers(head, len(argv) - 1))]
    if draw(st.integers(0, 3)) == 0:
        argv.insert(draw(st.integers(head, len(argv))), draw(st.sampled_from(TOKENS)))
    return argv


@settings(max_examples=300, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(argv=_mutated())
def test_mutated_command_lines(argv, files):
    _check_case(argv, files)
