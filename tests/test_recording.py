"""Tests of workbench.recording: the recording contract of formats.md section 3."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from workbench.errors import InputError
from workbench.recording import (
    KNOWN_COLUMNS,
    UNITS,
    Recording,
    fit,
    fit_signals,
    load_recording,
)

DATA = Path(__file__).parent / "data" / "recordings"

HEADER = "t,u,x,p_a,p_b,r"
ROWS = [
    "0.000,5.0,0.250,313500.0,313700.0,0.25",
    "0.001,5.1,0.251,313600.0,313600.0,0.25",
    "0.002,5.2,0.252,313700.0,313500.0,0.25",
    "0.003,5.3,0.253,313800.0,313400.0,0.25",
]


def write(tmp_path: Path, text: str, name: str = "rec.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def csv_with(tmp_path: Path, rows: list[str], header: str = HEADER,
             meta: str = "# sample_time: 0.001\n") -> Path:
    """A CSV whose data rows start on file line 3 (metadata line 1, header line 2)."""
    return write(tmp_path, meta + header + "\n" + "\n".join(rows) + "\n")


def replace_row(k: int, row: str) -> list[str]:
    rows = list(ROWS)
    rows[k] = row
    return rows


def sample_recording(n: int = 200, **extra: np.ndarray) -> Recording:
    rng = np.random.default_rng(1)
    t = np.arange(n) * 1e-3
    return Recording.from_arrays(
        t, metadata={"sample_time": "0.001", "rig": "bench 2"},
        u=5.0 + rng.standard_normal(n), x=0.25 + 0.1 * np.sin(7 * t),
        p_a=3e5 + 1e4 * rng.standard_normal(n), p_b=3e5 + 1e4 * rng.standard_normal(n),
        r=np.full(n, 0.3), **extra)


# ---- round trips ----------------------------------------------------------------------
def test_csv_round_trip_is_exact(tmp_path):
    rec = sample_recording(position_raw=np.linspace(-1.0, 1.0, 200))  # extra column kept
    path = rec.to_csv(tmp_path / "out.csv")
    back = load_recording(path)
    # Default writing uses the shortest text that reads back to the same float: exact.
    assert back == rec
    assert back.columns == rec.columns
    assert dict(back.metadata) == {"sample_time": "0.001", "rig": "bench 2"}
    assert back.source == str(path)
    assert not [p for p in tmp_path.iterdir() if p.name != "out.csv"]  # no temp left


def test_csv_round_trip_with_float_format(tmp_path):
    rec = sample_recording()
    back = load_recording(rec.to_csv(tmp_path / "out.csv", float_format="%.10g"))
    for name in rec.columns:
        # 10 significant digits: relative rounding error at most 5e-10 of each value.
        np.testing.assert_allclose(back[name], rec[name], rtol=6e-10, atol=0)


def test_metadata_with_line_breaks_round_trips(tmp_path):
    base = sample_recording(n=5)
    rec = Recording(base.columns, base.data, {"note": "first\nsecond", "empty": ""})
    assert load_recording(rec.to_csv(tmp_path / "m.csv")) == rec


def test_to_csv_is_atomic_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "keep.csv"
    path.write_text("old content\n")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        sample_recording(n=10).to_csv(path)
    assert path.read_text() == "old content\n"  # the old file is untouched
    assert [p.name for p in tmp_path.iterdir()] == ["keep.csv"]  # temp file removed


def test_mat_round_trip(tmp_path):
    rec = sample_recording()
    path = tmp_path / "rec.mat"
    # MATLAB stores vectors as 2-D: use column vectors, plus a scalar sample time.
    scipy.io.savemat(path, {**{c: rec[c].reshape(-1, 1) for c in rec.columns},
                            "sample_time": 0.001, "operator": "A. Smith"})
    back = load_recording(path)
    assert back.columns == rec.columns
    for name in rec.columns:
        np.testing.assert_array_equal(back[name], rec[name])  # doubles stored exactly
    assert back.sample_time == 0.001
    assert back.metadata["operator"] == "A. Smith"


def test_example_file_loads():
    rec = load_recording(DATA / "step_small.csv")
    assert rec.columns == ("t", "u", "x", "p_a", "p_b", "r")
    assert len(rec) == 50
    assert rec.sample_time == 0.01
    assert "made_with" in rec.metadata and "rig" in rec.metadata
    assert rec.duration == pytest.approx(0.49, rel=1e-12)  # t written with 2 decimals
    assert rec["x"][0] == 0.25 and rec["r"][-1] == 0.3


# ---- the recording object -------------------------------------------------------------
def test_recording_is_immutable():
    rec = sample_recording(n=10)
    with pytest.raises(ValueError):
        rec["x"][0] = 1.0
    with pytest.raises(TypeError):
        rec.data["x"] = np.zeros(10)  # type: ignore[index]
    with pytest.raises(TypeError):
        rec.metadata["sample_time"] = "1"  # type: ignore[index]
    with pytest.raises(AttributeError):
        rec.source = "other"  # type: ignore[misc]


def test_from_arrays_copies_its_inputs():
    x = np.linspace(0.1, 0.2, 5)
    rec = Recording.from_arrays(np.arange(5.0), u=np.zeros(5), x=x)
    x[0] = 9.0
    assert rec["x"][0] == 0.1


def test_accessors():
    rec = sample_recording(n=11)
    assert len(rec) == 11
    assert rec.t is rec["t"]
    assert "p_a" in rec and rec.has("p_a") and not rec.has("v") and "v" not in rec
    assert rec.duration == pytest.approx(0.010, rel=1e-12)  # 10 steps of 1 ms
    with pytest.raises(KeyError, match=r"no column 'v'.*t, u, x, p_a, p_b, r"):
        rec["v"]
    assert "samples=11" in repr(rec)
    assert set(UNITS) == set(KNOWN_COLUMNS)


def test_sample_time_from_median_step_without_metadata():
    t = np.array([0.0, 0.002, 0.004, 0.0065, 0.008])  # one jittered step
    rec = Recording.from_arrays(t, u=np.zeros(5), x=np.zeros(5))
    assert rec.sample_time == pytest.approx(0.002, rel=1e-12)  # median ignores jitter


def test_with_columns_and_to_pandas():
    rec = sample_recording(n=20)
    x2 = rec["x"] + 0.01
    new = rec.with_columns(x=x2, v=np.zeros(20))
    assert new.columns == rec.columns + ("v",)
    np.testing.assert_array_equal(new["x"], x2)
    np.testing.assert_array_equal(rec["x"], x2 - 0.01)  # the original is unchanged
    assert new.metadata == rec.metadata
    with pytest.raises(InputError, match="column 't'"):
        rec.with_columns(t=rec.t + 1)
    with pytest.raises(InputError, match=r"column 'v'.*has 3 samples but 't' has 20"):
        rec.with_columns(v=np.zeros(3))
    frame = new.to_pandas()
    assert frame.index.name == "t" and list(frame.columns) == list(new.columns[1:])
    np.testing.assert_array_equal(frame["p_a"].to_numpy(), new["p_a"])
    assert frame.attrs["units"]["p_a"] == "Pa"
    frame.iloc[0, 0] = -1.0  # the frame is a copy
    assert new["u"][0] != -1.0


# ---- CSV input errors: each names the file, the line/column and the problem -----------
def raises(path: Path, pattern: str):
    """pytest.raises for an InputError whose message starts with the file name."""
    return pytest.raises(InputError, match=re.escape(str(path)) + pattern)


def test_file_not_found(tmp_path):
    path = tmp_path / "missing.csv"
    with raises(path, ": file not found"):
        load_recording(path)


def test_empty_file(tmp_path):
    path = write(tmp_path, "")
    with raises(path, ": the file is empty"):
        load_recording(path)
    path = write(tmp_path, "\n  \n", "blank.csv")
    with raises(path, ": the file is empty"):
        load_recording(path)


def test_only_metadata(tmp_path):
    path = write(tmp_path, "# sample_time: 0.001\n# rig: 2\n")
    with raises(path, r", line 2: no header and no data"):
        load_recording(path)


def test_only_header(tmp_path):
    path = write(tmp_path, "# sample_time: 0.001\nt,u,x\n\n")
    with raises(path, r", line 2: no data rows after the header"):
        load_recording(path)


def test_single_row(tmp_path):
    path = csv_with(tmp_path, ROWS[:1])
    with raises(path, r", line 2 \(header\): only one sample"):
        load_recording(path)


def test_missing_required_column(tmp_path):
    rows = [",".join(r.split(",")[:2] + r.split(",")[3:]) for r in ROWS]  # drop x
    path = csv_with(tmp_path, rows, header="t,u,p_a,p_b,r")
    with raises(path, r", line 2 \(header\): missing required column 'x'; "
                      r"columns found: t, u, p_a, p_b, r"):
        load_recording(path)


def test_missing_required_column_case_hint(tmp_path):
    path = csv_with(tmp_path, ROWS, header="T,u,x,p_a,p_b,r")
    with raises(path, r".*missing required column 't'.*case-sensitive: found 'T'"):
        load_recording(path)


def test_duplicate_column(tmp_path):
    path = csv_with(tmp_path, ROWS, header="t,u,x,p_a,p_a,r")
    with raises(path, r", line 2 \(header\): duplicate column name 'p_a' "
                      r"\(columns 4 and 5\)"):
        load_recording(path)


def test_numbers_instead_of_header(tmp_path):
    path = write(tmp_path, "\n".join(ROWS) + "\n")
    with raises(path, r", line 1 \(header\): .*holds numbers.*not column names"):
        load_recording(path)


def test_non_numeric_cell(tmp_path):
    path = csv_with(tmp_path, replace_row(2, "0.002,5.2,abc,313700.0,313500.0,0.25"))
    with raises(path, r", line 5, column 'x': 'abc' is not a number"):
        load_recording(path)


def test_empty_cell(tmp_path):
    path = csv_with(tmp_path, replace_row(1, "0.001,,0.251,313600.0,313600.0,0.25"))
    with raises(path, r", line 4, column 'u': an empty cell is not a number"):
        load_recording(path)


def test_decimal_comma_hint(tmp_path):
    rows = [r.replace(",", ";") for r in ROWS]
    rows[0] = rows[0].replace("0.250", "0,250")
    path = csv_with(tmp_path, rows, header=HEADER.replace(",", ";"))
    with raises(path, r", line 3, column 'x': '0,250' is not a number "
                      r"\(decimal comma\?"):
        load_recording(path)


@pytest.mark.parametrize("row, count", [
    ("0.002,5.2,0.252,313700.0,313500.0,0.25,7", 7),  # one cell too many
    ("0.002,5.2,0.252,313700.0,313500.0", 5),         # one cell too few
])
def test_wrong_number_of_cells(tmp_path, row, count):
    path = csv_with(tmp_path, replace_row(2, row))
    with raises(path, rf", line 5: {count} cells in this row but the header has 6"):
        load_recording(path)


@pytest.mark.parametrize("text", ["nan", "NaN", "inf", "-inf"])
def test_nan_or_inf(tmp_path, text):
    path = csv_with(tmp_path, replace_row(3, f"0.003,5.3,0.253,313800.0,{text},0.25"))
    with raises(path, rf", line 6, column 'p_b': '{text}' \(-?(nan|inf)\) is not "
                      r"allowed"):
        load_recording(path)


@pytest.mark.parametrize("t2", ["0.001", "0.0005"])  # repeated, then going back
def test_time_not_increasing(tmp_path, t2):
    path = csv_with(tmp_path, replace_row(2, f"{t2},5.2,0.252,313700.0,313500.0,0.25"))
    with raises(path, rf", line 5, column 't': time is not strictly increasing: "
                      rf"t = {t2} s at line 5 comes after t = 0.001 s at line 4"):
        load_recording(path)


def test_line_numbers_count_blank_and_comment_lines(tmp_path):
    text = ("# sample_time: 0.001\n# just a comment\n\n" + HEADER + "\n"
            + ROWS[0] + "\n\n# a note in the data\n" + ROWS[1] + "  # trailing note\n"
            + "0.001,5.2,0.252,313700.0,313500.0,0.25\n")
    path = write(tmp_path, text)
    with raises(path, r", line 9, column 't': .*comes after t = 0.001 s at line 8"):
        load_recording(path)


def test_pressure_in_bar(tmp_path):
    rows = [r.replace("313500.0", "3.135").replace("313600.0", "3.136")
            .replace("313700.0", "3.137").replace("313800.0", "3.138") for r in ROWS]
    path = csv_with(tmp_path, rows)
    with raises(path, r", line 3, column 'p_a': pressure 3.135 is outside the plausible "
                      r"absolute range .* look like bar: multiply by 100000"):
        load_recording(path)


def test_pressure_gauge_in_bar(tmp_path):
    rows = replace_row(0, "0.000,5.0,0.250,0.0,2.137,0.25")
    rows = [r.replace("313600.0", "2.136").replace("313700.0", "2.137")
            .replace("313800.0", "2.138").replace("313500.0", "2.135") for r in rows]
    path = csv_with(tmp_path, rows)
    with raises(path, r", line 3, column 'p_a': .*gauge pressure in bar: multiply by "
                      r"100000 and add 101325 Pa"):
        load_recording(path)


def test_pressure_gauge_in_pa(tmp_path):
    rows = replace_row(1, "0.001,5.1,0.251,313600.0,1200.0,0.25")
    rows[2] = rows[2].replace("313500.0", "-5000.0")
    path = csv_with(tmp_path, rows)
    with raises(path, r", line 4, column 'p_b': pressure 1200 .*2 of 4 samples.*"
                      r"gauge pressure in Pa: add 101325 Pa"):
        load_recording(path)


def test_pressure_far_too_high(tmp_path):
    rows = [r.replace("313500.0", "3.135e8") for r in ROWS]
    path = csv_with(tmp_path, rows)
    with raises(path, r", line 3, column 'p_a': pressure 3.135e\+08 .*beyond any "
                      r"pneumatic supply: check the unit"):
        load_recording(path)


def test_malformed_metadata_line_is_a_comment(tmp_path):
    path = csv_with(tmp_path, ROWS, meta="# recorded on the old rig\n# sample_time: 0.001\n")
    rec = load_recording(path)
    assert dict(rec.metadata) == {"sample_time": "0.001"}
    assert len(rec) == 4


@pytest.mark.parametrize("value", ["-0.001", "0", "fast", "nan"])
def test_bad_sample_time(tmp_path, value):
    path = csv_with(tmp_path, ROWS, meta=f"# rig: 2\n# sample_time: {value}\n")
    with raises(path, rf", line 2, metadata 'sample_time': sample_time must be a "
                      rf"positive number of seconds, got '{value}'"):
        load_recording(path)


def test_conflicting_sample_times(tmp_path):
    path = csv_with(tmp_path, ROWS, meta="# sample_time: 0.001\n# sample_time: 0.002\n")
    with raises(path, r", line 1, metadata 'sample_time': sample_time is given more "
                      r"than once"):
        load_recording(path)


def test_not_text(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_bytes(b"t,u,x\n\xff\xfe\x00\x01\n")
    with raises(path, ": not a text file"):
        load_recording(path)


def test_unknown_suffix(tmp_path):
    path = write(tmp_path, HEADER + "\n" + "\n".join(ROWS), "rec.xlsx")
    with raises(path, r": unknown recording file type '.xlsx'"):
        load_recording(path)


def test_other_separators(tmp_path):
    reference = load_recording(csv_with(tmp_path, ROWS))
    for sep in ("\t", ";", "  "):
        rows = [r.replace(",", sep) for r in ROWS]
        path = write(tmp_path, HEADER.replace(",", sep) + "\n" + "\n".join(rows) + "\n",
                     "sep.txt")
        rec = load_recording(path)
        assert rec.columns == reference.columns
        for name in rec.columns:
            np.testing.assert_array_equal(rec[name], reference[name])


def test_fast_and_slow_parsers_agree(tmp_path):
    from workbench import recording_io as module

    rec = sample_recording(n=300)
    path = rec.to_csv(tmp_path / "r.csv")
    header_line = len(rec.metadata) + 1
    slow, lines = module._slow_parse(path, header_line, list(rec.columns), ",", str(path))
    assert lines == list(range(header_line + 1, header_line + 301))
    for name, column in zip(rec.columns, slow):
        np.testing.assert_array_equal(column, rec[name])  # both parsers are exact


# ---- arrays ---------------------------------------------------------------------------
def test_from_arrays_validates_like_a_file():
    t = np.arange(4) * 0.01
    with pytest.raises(InputError, match=r"^<memory>, column 'p_a', index 0: .*look "
                                         r"like bar"):
        Recording.from_arrays(t, u=np.zeros(4), x=np.zeros(4), p_a=np.full(4, 6.0))
    with pytest.raises(InputError, match=r"^sim, column 'x', index 2: value nan"):
        Recording.from_arrays(t, source="sim", u=np.zeros(4),
                              x=np.array([0.0, 0.1, np.nan, 0.2]))
    with pytest.raises(InputError, match=r"missing required column 'u'"):
        Recording.from_arrays(t, x=np.zeros(4))
    with pytest.raises(InputError, match=r"metadata 'sample_time'.*got '-1'"):
        Recording.from_arrays(t, u=np.zeros(4), x=np.zeros(4), metadata={"sample_time": -1})


# ---- .mat input errors ----------------------------------------------------------------
def mat(tmp_path: Path, **variables) -> Path:
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, variables)
    return path


def test_mat_missing_variable(tmp_path):
    path = mat(tmp_path, t=np.arange(5.0), u=np.zeros(5))
    with raises(path, r", variables: missing required variable 'x'; variables found: "
                      r"t, u"):
        load_recording(path)


def test_mat_length_mismatch(tmp_path):
    path = mat(tmp_path, t=np.arange(5.0), u=np.zeros(5), x=np.zeros(4))
    with raises(path, r", variable 'x': has 4 elements but 't' has 5"):
        load_recording(path)


def test_mat_non_numeric(tmp_path):
    path = mat(tmp_path, t=np.arange(5.0), u="five volts", x=np.zeros(5))
    with raises(path, r", variable 'u': is not numeric \(it holds text"):
        load_recording(path)


def test_mat_matrix_is_not_a_vector(tmp_path):
    path = mat(tmp_path, t=np.arange(6.0), u=np.zeros((2, 3)), x=np.zeros(6))
    with raises(path, r", variable 'u': expected a vector, got an array of size 2x3"):
        load_recording(path)


def test_mat_value_errors_name_the_element(tmp_path):
    path = mat(tmp_path, t=np.array([0.0, 0.1, 0.1, 0.3]), u=np.zeros(4), x=np.zeros(4))
    with raises(path, r", variable 't', element 3: time is not strictly increasing"):
        load_recording(path)


def test_mat_v73_hdf5(tmp_path):
    # The 128-byte header of a MATLAB v7.3 file (version 0x0200); the HDF5 body does
    # not matter because scipy refuses the file from its header.
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024"
    path = tmp_path / "rec.mat"
    path.write_bytes(header.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM" + b"\0" * 512)
    with raises(path, r": this is a MATLAB v7.3 \(HDF5\) file.*'-v7'"):
        load_recording(path)


def test_mat_not_a_mat_file(tmp_path):
    path = write(tmp_path, "t,u,x\n0,0,0\n", "rec.mat")
    with raises(path, r": cannot read as a MATLAB .mat file"):
        load_recording(path)


# ---- fit ------------------------------------------------------------------------------
def test_fit_limits():
    y = np.sin(np.linspace(0.0, 6.0, 101))
    assert fit(y, y) == 100.0  # ||y - y|| = 0 exactly
    ym = np.full_like(y, y.mean())
    # ||y - mean|| / ||y - mean|| rounds to 1 within a few ulps.
    assert fit(y, ym) == pytest.approx(0.0, abs=1e-12)


def test_fit_analytic_noise():
    t = np.linspace(0.0, 2.0, 501)
    y = np.sin(2 * np.pi * t)
    noise = np.cos(37 * t) * np.where(t < 1.0, 1.0, -0.5)  # a fixed, known vector
    c = 0.05
    expected = 100.0 * (1.0 - c * np.sqrt(np.sum(noise**2))
                        / np.sqrt(np.sum((y - np.sum(y) / y.size) ** 2)))
    # Same quantity computed two ways: agreement to rounding (1e-12 %).
    assert fit(y, y + c * noise) == pytest.approx(expected, abs=1e-12)
    assert fit(y, y + c * noise) < 100.0
    assert fit(y, -y) < 0.0  # worse than the mean


def test_fit_constant_measurement_is_nan():
    assert np.isnan(fit(np.full(10, 0.1), np.full(10, 0.1)))


def test_fit_errors():
    with pytest.raises(InputError, match=r"^fit: measured and model have different "
                                         r"shapes \(3,\) and \(2,\)"):
        fit([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(InputError, match=r"^fit: model signal has nan at index 1"):
        fit([1.0, 2.0, 3.0], [1.0, np.nan, 3.0])
    with pytest.raises(InputError, match=r"^fit: no samples"):
        fit([], [])


def test_fit_signals_on_a_recording_pair():
    measured = sample_recording(n=400)
    model = measured.with_columns(x=measured["x"] + 0.001, p_a=measured["p_a"] * 1.01)
    result = fit_signals(measured, model)
    assert list(result) == ["x", "p_a", "p_b"]
    assert result["p_b"] == 100.0
    for name in ("x", "p_a"):
        assert result[name] == fit(measured[name], model[name])
    assert fit_signals(measured, {"x": model["x"]}) == {"x": result["x"]}
    assert fit_signals(measured, model, names=["u"]) == {"u": 100.0}


def test_fit_signals_errors():
    measured = sample_recording(n=50)
    with pytest.raises(InputError, match=r"signal 'v': the measurement has no signal 'v'"):
        fit_signals(measured, measured, names=["v"])
    with pytest.raises(InputError, match=r"signal 'p_a': the model has no signal 'p_a'"):
        fit_signals(measured, {"x": measured["x"]}, names=["x", "p_a"])
    shifted = Recording.from_arrays(measured.t + 0.001, u=measured["u"], x=measured["x"])
    with pytest.raises(InputError, match=r"column 't': the model time base differs"):
        fit_signals(measured, shifted)
    with pytest.raises(InputError, match=r"signal 'x': measured and model have "
                                         r"different shapes"):
        fit_signals(measured, {"x": measured["x"][:-1]})


# ---- issue 15: units, plausibility, files as rigs write them ---------------------------
def rig_csv(tmp_path: Path, t, x, u=None, meta: str = "", header: str = "t,u,x",
            name: str = "rig.csv", trailing: str = "") -> Path:
    """A recording of a slow move (u = 5 V unless given), one row per sample."""
    u = np.full(len(t), 5.0) if u is None else u
    rows = "".join(f"{float(a)!r},{float(b)!r},{float(c)!r}{trailing}\n"
                   for a, b, c in zip(t, u, x))
    return write(tmp_path, meta + header + trailing + "\n" + rows, name)


@pytest.fixture(scope="module")
def situm_params():
    from workbench.params import PlantParams
    return PlantParams.from_toml(Path(__file__).parents[1] / "designs/plants/situm_rodless.toml")


T_1K = np.arange(2001) * 1e-3                  # 2 s at 1 kHz
X_M = 0.2 + 0.1 * T_1K / 2.0                   # 0.2 .. 0.3 m on a 0.5 m stroke


def test_position_in_mm_is_refused_against_the_stroke(tmp_path, situm_params):
    path = rig_csv(tmp_path, T_1K, X_M * 1e3)                  # x = 200 .. 300 "m"
    with raises(path, r", line 2, column 'x': 200 m is implausible .*mm\?"):
        load_recording(path)                                   # plant-free: |x| > 20 m
    small = rig_csv(tmp_path, T_1K, X_M * 1e3 / 100, name="cm.csv")   # 2 .. 3 "m"
    load_recording(small)                                      # plausible without a plant
    with raises(small, r", line 2, column 'x': 2 m is outside the stroke \[0, 0.5\] m"):
        load_recording(small, plant=situm_params)


def test_position_in_mm_with_the_plant_suggests_mm(tmp_path, situm_params):
    # 15 mm written as 15 "m": below the plant-free bound, refused by the 0.5 m stroke
    mm = rig_csv(tmp_path, T_1K, np.full(T_1K.size, 15.0), name="mm.csv")
    with raises(mm, r".*outside the stroke.*in mm\? declare it: '# units: x=mm' in the file, "
                    r"or --columns x=x:mm"):
        load_recording(mm, plant=situm_params)
    assert len(load_recording(mm, columns="x=x:mm", plant=situm_params)) == T_1K.size


def test_time_in_ms_is_refused_with_the_hint(tmp_path):
    t_ms = np.arange(0.0, 24001.0, 10.0)                        # a 24 s test at 100 Hz in ms
    path = rig_csv(tmp_path, t_ms, np.full(t_ms.size, 0.25))
    with raises(path, r", column 't': the median sample step is 10 s .*time in ms\?"):
        load_recording(path)
    ok = rig_csv(tmp_path, t_ms, np.full(t_ms.size, 0.25), meta="# units: t=ms\n",
                 name="declared.csv")
    rec = load_recording(ok)
    assert rec.duration == pytest.approx(24.0, rel=1e-12)      # converted: s
    assert rec.metadata["converted_to_si"] == "t from ms"


@pytest.mark.parametrize("scale, hint", [(1e3, "mV"), (2e5, "mV")])   # mV, and 1e6 V
def test_command_in_mv_or_absurd_volts_is_refused(tmp_path, scale, hint):
    path = rig_csv(tmp_path, T_1K, X_M, u=np.full(T_1K.size, 5.0) * scale)
    with raises(path, rf", line 2, column 'u': .* is implausible .*{hint}\?"):
        load_recording(path)


def test_command_outside_the_valve_range(tmp_path, situm_params):
    path = rig_csv(tmp_path, T_1K, X_M, u=np.full(T_1K.size, 12.0))   # valve: 0..10 V
    load_recording(path)
    with raises(path, r", line 2, column 'u': 12 V is outside the valve's command range"):
        load_recording(path, plant=situm_params)


def test_sample_time_header_over_a_1ms_time_column_is_refused(tmp_path):
    path = rig_csv(tmp_path, T_1K, X_M, meta="# sample_time: 0.01\n")
    with raises(path, r", line 1, metadata 'sample_time': sample_time 0.01 s contradicts "
                      r"the time column, whose median step is 0.001 s"):
        load_recording(path)


def test_huge_gap_in_time_is_refused_before_anything_allocates(tmp_path):
    t = T_1K.copy()
    t[1000:] += 1e6                                             # a 10^6 s gap
    path = rig_csv(tmp_path, t, X_M)
    with raises(path, r", line 1002, column 't': a gap of 1e\+06 s"):
        load_recording(path)
    # a window on one side of the gap is one continuous run
    assert len(load_recording(path, window=(None, 0.9995))) == 1000


def test_jitter_within_the_stated_tolerance_is_accepted(tmp_path):
    rng = np.random.default_rng(3)
    # +-2 % jitter on each step; a dropped sample (2 steps) too: both inside the tolerances
    steps = 1e-3 * (1.0 + 0.02 * rng.uniform(-1.0, 1.0, T_1K.size - 1))
    steps[500] = 2e-3
    t = np.concatenate([[0.0], np.cumsum(steps)])
    rec = load_recording(rig_csv(tmp_path, t, X_M, meta="# sample_time: 0.001\n"))
    assert rec.sample_time == 0.001
    # 6 % off the median step is beyond JITTER_TOLERANCE = 5 %: the header is refused
    bad = rig_csv(tmp_path, t, X_M, meta="# sample_time: 0.00106\n", name="bad.csv")
    with pytest.raises(InputError, match="contradicts the time column"):
        load_recording(bad)


def test_trailing_delimiters_are_not_a_column(tmp_path):
    plain = load_recording(rig_csv(tmp_path, T_1K[:50], X_M[:50]))
    trailing = load_recording(rig_csv(tmp_path, T_1K[:50], X_M[:50], trailing=",",
                                      name="trailing.csv"))
    assert trailing == plain and trailing.columns == ("t", "u", "x")
    # the slow parser (used once a row is bad) agrees
    path = write(tmp_path, "t,u,x,\n0,5,0.2,\n0.001,5,0.2,\n0.002,5,oops,\n", "bad.csv")
    with raises(path, r", line 4, column 'x': 'oops' is not a number"):
        load_recording(path)


def test_fifo_is_not_called_empty(tmp_path):
    path = tmp_path / "stream.csv"
    os.mkfifo(path)
    with raises(path, ": is not a regular file"):
        load_recording(path)


def test_time_window_keeps_line_numbers_of_the_file(tmp_path):
    x = X_M.copy()
    path = rig_csv(tmp_path, T_1K, x)
    rec = load_recording(path, window=(0.5, 1.0))
    assert rec.t[0] == 0.5 and rec.t[-1] == 1.0 and len(rec) == 501
    with raises(path, r", column 't': time window \[2, 3\] s holds 1 sample\(s\)"):
        load_recording(path, window=(2.0, 3.0))                 # only t = 2.0
    with raises(path, r": time window \[1, 0.5\] s is empty"):
        load_recording(path, window=(1.0, 0.5))


def test_column_mapping_renames_and_converts(tmp_path):
    path = rig_csv(tmp_path, T_1K * 1e3, X_M * 1e3, header="time_ms,cmd,pos_mm")
    rec = load_recording(path, columns="t=time_ms:ms,u=cmd,x=pos_mm:mm")
    assert rec.columns == ("t", "u", "x")
    np.testing.assert_allclose(rec["x"], X_M, rtol=1e-15)     # one multiplication
    np.testing.assert_allclose(rec.t, T_1K, rtol=1e-15, atol=1e-18)
    # the converted recording writes SI and reads back exactly (no second conversion)
    back = load_recording(rec.to_csv(tmp_path / "si.csv"))
    assert back == rec
    with raises(path, r", line 1 \(header\): missing required columns 't', 'u', 'x'.*"
                      r"--columns t=COLUMN"):
        load_recording(path)
    with pytest.raises(InputError, match="does not have; its columns are: time_ms"):
        load_recording(path, columns="x=position:mm")
    with pytest.raises(InputError, match="unknown length unit 'ms'"):
        load_recording(path, columns="x=pos_mm:ms")


@pytest.mark.parametrize("header, meta", [("t,u,x [mm],p_a (bar)", ""),
                                          ("t,u,x/mm,p_a / bar", ""),
                                          ("t,u,x,p_a", "# units: x=mm, p_a=bar\n")])
def test_units_in_the_header_or_metadata(tmp_path, header, meta):
    rows = "".join(f"{float(a)!r},5.0,{float(b)!r},3.5\n"
                   for a, b in zip(T_1K[:20], X_M[:20] * 1e3))
    rec = load_recording(write(tmp_path, meta + header + "\n" + rows))
    assert rec.columns == ("t", "u", "x", "p_a")
    np.testing.assert_allclose(rec["x"], X_M[:20], rtol=1e-15)
    assert np.all(rec["p_a"] == 3.5e5)


def test_arx_input_without_a_u_column(tmp_path):
    rows = "".join(f"{float(a)!r},{float(b)!r},3.5e5\n" for a, b in zip(T_1K[:20], X_M[:20]))
    path = write(tmp_path, "t,x,p_a\n" + rows)
    with raises(path, r", line 1 \(header\): missing required column 'u'"):
        load_recording(path)
    rec = load_recording(path, required=("p_a", "x"))
    assert rec.columns == ("t", "x", "p_a") and rec.required == ("t", "p_a", "x")
    assert rec.with_columns(v=np.zeros(20)).required == rec.required


def test_fit_of_a_constant_signal_is_null_in_json():
    import json
    measured = sample_recording(n=50).with_columns(p_b=np.full(50, 3e5))
    fits = fit_signals(measured, measured.with_columns(p_b=np.full(50, 3.1e5)))
    assert fits["p_b"] is None and fits["x"] == 100.0
    assert json.loads(json.dumps(fits, allow_nan=False))["p_b"] is None


def test_check_of_an_in_memory_recording(situm_params):
    rec = Recording.from_arrays(T_1K, u=np.full(T_1K.size, 5.0), x=X_M)
    assert rec.check(situm_params) is rec
    t = T_1K.copy()
    t[1000:] += 1e6
    gap = Recording.from_arrays(t, u=np.full(T_1K.size, 5.0), x=X_M)   # the contract holds
    with pytest.raises(InputError, match=r"column 't', index 1000: a gap of 1e\+06 s"):
        gap.check()
    with pytest.raises(InputError, match=r"column 'x', index 0: 200 m is implausible"):
        Recording.from_arrays(T_1K, u=np.full(T_1K.size, 5.0), x=X_M * 1e3).check(situm_params)


# ---- files as spreadsheet programs and interrupted loggers write them -----------------


@pytest.mark.parametrize("sep", [";", "\t"])
def test_decimal_comma_with_another_separator_is_read(tmp_path, sep):
    """European spreadsheets write ';' (or tab) separated cells with decimal commas:
    the same numbers as the comma-separated file, exactly (both parse one decimal
    string per cell)."""
    reference = load_recording(csv_with(tmp_path, ROWS))
    rows = [r.replace(",", sep).replace(".", ",") for r in ROWS]
    rec = load_recording(write(tmp_path, HEADER.replace(",", sep) + "\n" + "\n".join(rows)
                               + "\n", "comma.csv"))
    for name in reference.columns:
        np.testing.assert_array_equal(rec[name], reference[name])


def test_decimal_comma_only_when_no_cell_has_a_point(tmp_path):
    """A comma beside points elsewhere may be a thousands separator: not guessed."""
    rows = [r.replace(",", ";") for r in ROWS]
    rows[1] = rows[1].replace("313600.0", "313,600")
    path = write(tmp_path, HEADER.replace(",", ";") + "\n" + "\n".join(rows) + "\n")
    with raises(path, r", line 3, column 'p_a': '313,600' is not a number \(decimal comma"):
        load_recording(path)


def test_bom_crlf_and_utf16_files_read_the_same(tmp_path):
    reference = load_recording(csv_with(tmp_path, ROWS))
    text = "# sample_time: 0.001\n" + HEADER + "\n" + "\n".join(ROWS) + "\n"
    variants = {"bom.csv": ("\ufeff" + text).encode("utf-8"),
                "crlf.csv": text.replace("\n", "\r\n").encode("utf-8"),
                "utf16.csv": text.encode("utf-16"),           # with its byte-order mark
                "utf16be.csv": b"\xfe\xff" + text.encode("utf-16-be")}
    for name, data in variants.items():
        (tmp_path / name).write_bytes(data)
        rec = load_recording(tmp_path / name)
        assert rec.columns == reference.columns, name
        for col in rec.columns:
            np.testing.assert_array_equal(rec[col], reference[col])


def test_cut_off_last_line_is_named_as_such(tmp_path):
    """A logger stopped mid-write leaves a last line without its line end."""
    text = "# sample_time: 0.001\n" + HEADER + "\n" + "\n".join(ROWS) + "\n0.004,5.4,0.2"
    path = write(tmp_path, text)
    with raises(path, r", line 7: 3 cells in this row but the header has 6 .*the last "
                      r"line is cut off"):
        load_recording(path)
    # the same short row inside the file is not called cut off
    path = write(tmp_path, text + "54\n0.005,5.4,0.254,313900.0,313300.0,0.25\n", "mid.csv")
    with pytest.raises(InputError) as info:
        load_recording(path)
    assert "line 7: 3 cells" in str(info.value) and "cut off" not in str(info.value)
