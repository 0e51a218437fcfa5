"""A logger that writes rig units without saying so is refused once, with every column
that looks mis-scaled named (issue 12, point 4; session 11's blind sweep).

Found with a foreign-rig recording logged in ms, mm and gauge bar under bare column
names: ``workbench diagnose`` refused it naming only p_a; declared, the next run named
t; then x. The error now lists every column whose values look like another unit (by
the same plant-free bounds that refuse them one at a time) and the one ``# units:``
line that declares them all; that line loads the file as the SI one.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from workbench.errors import InputError
from workbench.recording import load_recording

P_ATM = 101325.0


def _columns(n=1500, dt=1e-3):
    """SI columns of a short made-up run (t s, u V, x/r m, p_a/p_b Pa absolute)."""
    t = np.arange(n) * dt
    x = 0.2 + 0.05 * np.sin(2 * np.pi * 0.5 * t)
    return {"t": t, "u": 5.0 + 0.5 * np.sin(2 * np.pi * t), "x": x, "r": x + 1e-3,
            "p_a": 4.4e5 + 2e4 * np.sin(2 * np.pi * 0.5 * t),
            "p_b": 4.3e5 - 2e4 * np.sin(2 * np.pi * 0.5 * t)}


def _write(path, cols, rig_units, header_line=""):
    """The columns in SI, or in ms / mm / gauge bar under their bare names."""
    scale = {"t": 1e3, "x": 1e3, "r": 1e3} if rig_units else {}
    out = []
    for name, y in cols.items():
        if rig_units and name.startswith("p_"):
            out.append((y - P_ATM) / 1e5)
        else:
            out.append(y * scale.get(name, 1.0))
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(header_line + ",".join(cols) + "\n")
        np.savetxt(fh, np.column_stack(out), delimiter=",", fmt="%.10g")
    return path


def test_every_mis_scaled_column_is_named_at_once(tmp_path):
    cols = _columns()
    f = _write(tmp_path / "rig.csv", cols, rig_units=True)
    with pytest.raises(InputError) as err:
        load_recording(f)
    text = str(err.value)
    assert str(f) in text and "column 'p_a'" in text          # the first check's cell
    for name, unit in (("t", "ms"), ("x", "mm"), ("r", "mm"), ("p_b", "bar_g")):
        assert f"'{name}' ({unit}?)" in text, text
    assert "'u'" not in text                                   # volts are volts
    line = re.search(r"'(# units: [^']+)'", text).group(1)
    assert line == "# units: t=ms, x=mm, r=mm, p_a=bar_g, p_b=bar_g"
    # the suggested line makes the file the SI recording
    fixed = load_recording(_write(tmp_path / "fixed.csv", cols, True, line + "\n"))
    si = load_recording(_write(tmp_path / "si.csv", cols, rig_units=False))
    for name in cols:
        np.testing.assert_allclose(fixed[name], si[name], rtol=1e-9, atol=1e-6,
                                   err_msg=name)


def test_one_mis_scaled_column_keeps_the_plain_message(tmp_path):
    """Only t in ms: the error is the time check's alone (nothing else is suspect)."""
    cols = _columns()
    f = tmp_path / "ms.csv"
    cols_ms = dict(cols, t=cols["t"] * 1e3)
    _write(f, cols_ms, rig_units=False)
    with pytest.raises(InputError) as err:
        load_recording(f)
    assert "is the time in ms?" in str(err.value)
    assert "Other columns" not in str(err.value)


def test_cli_refuses_rig_units_and_leaves_out_untouched(tmp_path, capsys):
    from workbench.cli import main
    from workbench.diagnose import synth
    plant = synth.concealed_case("none", seed=0).write_nominal(tmp_path / "plant.toml")
    f = _write(tmp_path / "rig.csv", _columns(), rig_units=True)
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    code = main(["diagnose", str(plant), str(f), "--out", str(out), "--quiet", "--no-report"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "'t' (ms?)" in err and "column 'p_a'" in err, err
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    assert (out / "keep.txt").read_text() == "mine"
