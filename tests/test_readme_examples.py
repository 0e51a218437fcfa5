"""The README's examples run: its Python blocks execute, its command lines parse.

Issue 15: the README's library example built a PD with ``u_center = 0 V`` for a valve
centred at 5 V; validation ran the piston into the end stop and reported 1250 %
overshoot without a word. The library now refuses such a controller (tested below),
and the example runs here, so a README that drifts from the code turns the suite red.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")

#: Sizes shrunk for the suite, each replaced text must exist (so the README cannot
#: drift away from what is run): the Monte Carlo's 20 draws -> 3 (14 s -> 2 s).
SHRINK = {"n=20, seed=1": "n=3, seed=1"}


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README, flags=re.S)


def test_the_readme_has_the_examples_this_file_runs():
    assert len(_blocks("python")) >= 1
    assert any("workbench check" in b for b in _blocks("bash"))


@pytest.mark.parametrize("index", range(len(_blocks("python"))))
def test_python_block_runs(index, monkeypatch):
    code = _blocks("python")[index]
    for old, new in SHRINK.items():
        if old in code:
            code = code.replace(old, new)
    monkeypatch.chdir(ROOT)                      # the examples name files from the root
    namespace: dict = {"__name__": "readme_example"}
    exec(compile(code, f"README.md python block {index + 1}", "exec"), namespace)
    if "validate.validate(plant, pd)" in code:
        v = namespace["v"]
        # the PD of paper 000 on its own rig meets the default specification (its
        # overshoot limit included), where the u_center = 0 V version reported 1250 %
        assert v.passed, v.summary()
        assert max(s.overshoot for s in v.segments if s.segment.kind == "step") < 30.0


def _command_lines() -> list[list[str]]:
    lines = []
    for block in _blocks("bash"):
        for raw in block.splitlines():
            text = raw.split("  #", 1)[0].strip()
            if text.startswith("workbench "):
                lines.append(shlex.split(text)[1:])
    return lines


@pytest.mark.parametrize("argv", _command_lines(), ids=lambda a: " ".join(a[:2]))
def test_command_line_parses(argv):
    from workbench.cli import build_parser
    args = build_parser().parse_args(argv)       # SystemExit(2) on an unknown option
    assert callable(args.func)


def test_readme_pd_without_the_valve_centre_is_refused():
    from workbench import Plant, controllers, validate
    from workbench.errors import InputError
    plant = Plant.from_toml(ROOT / "designs/plants/situm_rodless.toml")
    pd = controllers.pd_zero_on_slow_pole(32.97, 1.1, kp=16.0, sample_time=0.01)  # u_center 0 V
    with pytest.raises(InputError, match=r"u_center = 0 V opens the valve by 100 % .* "
                                         r"end stop"):
        validate.validate(plant, pd, progress=False)


# ----------------------------------------------------------- recordings: the README's table
# The README's recordings section documents what is accepted and what is refused with
# which hint (formats.md, shared, does not): every row of its table is built here and
# loaded through the command line's own options (``simulate``'s parser, which every
# command that reads a recording shares), against the plant the README names.

PLANT = ROOT / "designs/plants/rig25_mpye.toml"
_N = 200
_T = np.arange(_N) * 1e-3                                 # s, 1 ms steps
_U = 5.0 + 0.5 * np.sin(30.0 * _T)                        # V
_X = 0.2 + 0.01 * np.sin(30.0 * _T)                       # m
_PA = 3.0e5 + 1.0e4 * np.sin(30.0 * _T)                   # Pa
_BAR, _ATM = 1e5, 101325.0


def _csv(path: Path, header: str, cols, meta: str = "", trailing: str = "") -> Path:
    rows = (",".join(f"{v:.12g}" for v in row) + trailing for row in zip(*cols))
    path.write_text(meta + header + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


#: README first cell -> (header, columns, metadata lines, extra options, trailing text).
RECORDING_CASES = {
    "header `t,u,x [mm],p_a [bar]`": ("t,u,x [mm],p_a [bar]", (_T, _U, _X * 1e3, _PA / _BAR), "", []),
    "header `t [ms],u,x (mm)`": ("t [ms],u,x (mm)", (_T * 1e3, _U, _X * 1e3), "", []),
    "`# units: t=ms, x=mm, p_a=bar_g`": ("t,u,x,p_a", (_T * 1e3, _U, _X * 1e3, (_PA - _ATM) / _BAR),
                                         "# units: t=ms, x=mm, p_a=bar_g\n", []),
    "header `time,cmd,pos_mm` with `--columns t=time,u=cmd,x=pos_mm:mm`":
        ("time,cmd,pos_mm", (_T, _U, _X * 1e3), "", ["--columns", "t=time,u=cmd,x=pos_mm:mm"]),
    "header `t,u,x,` (trailing delimiters)": ("t,u,x,", (_T, _U, _X), "", [], ","),
    "`--window 0.05:0.15`": ("t,u,x", (_T, _U, _X), "", ["--window", "0.05:0.15"]),
    "t jumps by 1 s after t = 0.1 s, with `--window :0.1`":
        ("t,u,x", (np.where(_T > 0.1, _T + 1.0, _T), _U, _X), "", ["--window", ":0.1"]),
    "t in ms, not declared": ("t,u,x", (_T * 1e3, _U, _X), "", []),
    "t jumps by 1 s after t = 0.1 s": ("t,u,x", (np.where(_T > 0.1, _T + 1.0, _T), _U, _X), "", []),
    "`# sample_time: 0.01` over 1 ms steps": ("t,u,x", (_T, _U, _X), "# sample_time: 0.01\n", []),
    "u in mV, not declared": ("t,u,x", (_T, _U * 1e3, _X), "", []),
    "x in mm, not declared": ("t,u,x", (_T, _U, _X * 1e3), "", []),
    "x = 0.6 m on the 0.5 m stroke": ("t,u,x", (_T, _U, _X + 0.4), "", []),
    "u = 12.5 V on the 0..10 V valve": ("t,u,x", (_T, _U + 7.5, _X), "", []),
    "p_a in bar, not declared": ("t,u,x,p_a", (_T, _U, _X, _PA / _BAR), "", []),
    "header `t,u,x [inch]`": ("t,u,x [inch]", (_T, _U, _X / 0.0254), "", []),
    "header `t,u,x [mm]` and `# units: x=cm`": ("t,u,x [mm]", (_T, _U, _X * 1e3), "# units: x=cm\n", []),
    "`--columns x:mm`": ("t,u,x", (_T, _U, _X), "", ["--columns", "x:mm"]),
    "`--columns pos=x`": ("t,u,x", (_T, _U, _X), "", ["--columns", "pos=x"]),
    "`--columns x=pos_mm:mm` on a file without `pos_mm`": ("t,u,x", (_T, _U, _X), "",
                                                          ["--columns", "x=pos_mm:mm"]),
    "`--window 0.15:0.05`": ("t,u,x", (_T, _U, _X), "", ["--window", "0.15:0.05"]),
    "`--window 5:6` (the file spans 0 .. 0.199 s)": ("t,u,x", (_T, _U, _X), "", ["--window", "5:6"]),
    "x = NaN at t = 0.05 s, with `--window 0.1:`":
        ("t,u,x", (_T, _U, np.where(np.isclose(_T, 0.05), np.nan, _X)), "", ["--window", "0.1:"]),
}


def _recording_rows() -> list[tuple[str, str]]:
    start = README.index("| the file or the command line | result |")
    rows = []
    for line in README[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows.append((cells[0], cells[1]))
    return rows


def test_every_documented_recording_case_is_tested_here():
    assert [r for r, _ in _recording_rows()] == list(RECORDING_CASES)


@pytest.mark.parametrize("case, result", _recording_rows(), ids=lambda v: v[:40])
def test_recording_case_as_the_readme_says(case, result, tmp_path, capsys):
    from workbench.cli import build_parser
    from workbench.cli.recording_args import load_from_args
    from workbench.errors import InputError
    from workbench.params import PlantParams
    header, cols, meta, extra, *trailing = RECORDING_CASES[case]
    path = _csv(tmp_path / "rec.csv", header, cols, meta, *trailing)
    argv = ["simulate", str(PLANT), str(path), "--out", str(tmp_path / "out"), *extra]
    plant = PlantParams.from_toml(PLANT)
    if result.startswith("accepted"):
        rec = load_from_args(build_parser().parse_args(argv), path, plant=plant)
        window = extra[extra.index("--window") + 1] if "--window" in extra else ":"
        lo, hi = (float(v) if v else None for v in window.split(":"))
        keep = (_T >= (lo if lo is not None else -np.inf)) & (_T <= (hi if hi is not None else np.inf))
        assert len(rec) == keep.sum()
        if "samples" in result:                               # "accepted: 101 samples"
            assert len(rec) == int(re.search(r"(\d+) samples", result).group(1))
        # in SI whatever the file's units: the arrays written above, to the 12 digits written
        for name, want in (("t", _T), ("u", _U), ("x", _X), ("p_a", _PA)):
            if name in rec.columns:
                np.testing.assert_allclose(rec[name], want[keep], rtol=1e-10, atol=1e-12)
        return
    hint = re.fullmatch(r'refused: "(.+)"', result).group(1)
    try:
        load_from_args(build_parser().parse_args(argv), path, plant=plant)
    except InputError as exc:
        message = str(exc)
    except SystemExit as exc:                                 # refused by the parser
        assert exc.code == 2
        message = capsys.readouterr().err
    else:
        pytest.fail(f"{case}: accepted, the README says {result}")
    assert hint in message, message
    if "outside the" in hint:          # 0.6 m / 12.5 V are no factor-1000 slip: no unit hint
        assert "mm?" not in message and "mV?" not in message, message


def test_the_readme_lists_every_unit_the_loader_knows():
    from workbench.recording_units import UNIT_SCALES
    start = README.index("Units by column:")
    text = README[start:README.index("\n\n", start)]
    listed = set(re.findall(r"[A-Za-z_/]+", text.split(":", 1)[1]))
    known = {u for table in UNIT_SCALES.values() for u in table}
    assert known <= listed, sorted(known - listed)
