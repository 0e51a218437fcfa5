"""Recordings as they come from a rig's logger (issues 12 and 14, session 12): odd but
valid files load to exactly the samples of a clean copy, damaged ones are refused with
a message that names the file, the line and the cause (and what to do).

Every case is built from one small clean recording (tests/data/recordings/
step_small.csv, 50 samples); "the same samples" is checked against that file loaded
as it is, to the bit (the cases only change the framing, never a number).
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from workbench.errors import InputError, InputWarning
from workbench.recording import load_recording

ROOT = Path(__file__).resolve().parents[1]
CLEAN = ROOT / "tests" / "data" / "recordings" / "step_small.csv"
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"


def _lines() -> tuple[list[str], str, list[str]]:
    """(metadata and comment lines, header, data rows) of the clean recording."""
    lines = CLEAN.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    return lines[:k], lines[k], lines[k + 1:]


def _write(tmp_path: Path, name: str, text: str | bytes) -> Path:
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, newline="")
    return path


def _same_samples(rec) -> None:
    clean = load_recording(CLEAN)
    for c in clean.columns:
        np.testing.assert_array_equal(rec[c], clean[c], err_msg=c)


def _refused(path: Path, *patterns: str, **kw) -> str:
    """Load ``path``, expect an InputError naming the file; check each regex pattern."""
    with pytest.raises(InputError) as info:
        load_recording(path, **kw)
    text = str(info.value)
    assert text.startswith(str(path)), text
    for p in patterns:
        assert re.search(p, text), (p, text)
    return text


# ----------------------------------------------------------------------- odd, valid
def test_unused_text_columns_are_left_out_with_a_warning(tmp_path):
    """A logger's wall-clock stamp and state name beside the signals: the file loads,
    the two columns are left out (each with a warning naming its first text cell and
    line), the numeric unknown column is kept, the signals are bit-identical."""
    meta, header, rows = _lines()
    text = "\n".join(meta + [f"stamp,{header},state,temp"]
                     + [f"2026-11-25 10:00:{k:02d},{r},RUN,21.5" for k, r in enumerate(rows)])
    path = _write(tmp_path, "logger.csv", text + "\n")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_recording(path)
    _same_samples(rec)
    assert "stamp" not in rec.columns and "state" not in rec.columns
    np.testing.assert_array_equal(rec["temp"], np.full(len(rows), 21.5))
    msgs = [str(w.message) for w in caught if issubclass(w.category, InputWarning)]
    assert len(msgs) == 2, msgs
    first_row_line = len(meta) + 2
    assert f"column 'stamp'" in msgs[0] and "'2026-11-25 10:00:00'" in msgs[0]
    assert f"line {first_row_line}" in msgs[0] and str(path) in msgs[0]
    assert f"column 'state'" in msgs[1] and "'RUN'" in msgs[1]


def test_unused_column_with_empty_cells_is_left_out(tmp_path):
    """An unused sensor column that is empty on every other row (the fast reader sees
    NaN there, the slow one an empty cell): left out, signals intact."""
    meta, header, rows = _lines()
    text = "\n".join(meta + [f"{header},aux"]
                     + [f"{r},{'' if k % 2 else '1.0'}" for k, r in enumerate(rows)])
    with pytest.warns(InputWarning, match="column 'aux' is left out.*an empty cell"):
        rec = load_recording(_write(tmp_path, "aux.csv", text + "\n"))
    _same_samples(rec)
    assert "aux" not in rec.columns


@pytest.mark.parametrize("tail", [
    pytest.param("\n,,,,,\n,,,,,\n", id="spreadsheet empty rows"),
    pytest.param("\n\x1a", id="DOS ctrl-Z end mark"),
    pytest.param("\n,,,,,\n\n", id="empty row then blank"),
])
def test_blank_rows_of_spreadsheets_and_dos_end_mark_are_no_samples(tmp_path, tail):
    meta, header, rows = _lines()
    path = _write(tmp_path, "sheet.csv", "\n".join(meta + [header] + rows) + tail)
    _same_samples(load_recording(path))


def test_tab_file_ending_in_a_tab_only_line_loads(tmp_path):
    """Was refused as 'no data rows after the header' (the fast reader's suspect row
    was blank to the slow one, which then found no row at all)."""
    meta, header, rows = _lines()
    body = [line.replace(",", "\t") for line in [header] + rows]
    path = _write(tmp_path, "tabs.csv", "\n".join(meta + body) + "\n\t\t\t\t\t\n")
    _same_samples(load_recording(path))


def test_empty_row_mid_file_is_skipped_like_a_blank_line(tmp_path):
    meta, header, rows = _lines()
    path = _write(tmp_path, "mid.csv", "\n".join(meta + [header] + rows[:20] + [",,,,,"]
                                               + rows[20:]) + "\n")
    _same_samples(load_recording(path))


# ----------------------------------------------------------------------- damaged
@pytest.mark.parametrize("newline", [True, False], ids=["with line end", "without"])
def test_cut_off_last_line_is_named_as_such(tmp_path, newline):
    """An interrupted logger: the last row stops after two cells. The message names
    its line and says the rows before are complete (with or without a line end)."""
    meta, header, rows = _lines()
    cut = rows[-1][:8]
    path = _write(tmp_path, "cut.csv", "\n".join(meta + [header] + rows[:-1] + [cut])
                  + ("\n" if newline else ""))
    line = len(meta) + 1 + len(rows)
    _refused(path, rf"line {line}:", r"last line is cut off", r"rows before it are complete")


def test_short_row_mid_file_is_not_called_cut_off(tmp_path):
    meta, header, rows = _lines()
    short = ",".join(rows[10].split(",")[:4])
    path = _write(tmp_path, "short.csv", "\n".join(meta + [header] + rows[:10] + [short]
                                                 + rows[11:]) + "\n")
    text = _refused(path, rf"line {len(meta) + 12}:", r"4 cells in this row")
    assert "cut off" not in text


def test_nul_padding_after_a_power_loss_names_the_first_bad_line(tmp_path):
    """A logger on an SD card that lost power: the last block is NUL bytes."""
    meta, header, rows = _lines()
    body = "\n".join(meta + [header] + rows[:30]) + "\n"
    path = _write(tmp_path, "nul.csv", (body + "\x00" * 600).encode())
    line = len(meta) + 1 + 30 + 1
    _refused(path, rf"line {line}:", r"NUL characters", r"not closed properly",
             rf"rows before line {line} are complete")


def test_nul_bytes_amid_good_rows_mean_a_damaged_copy(tmp_path):
    meta, header, rows = _lines()
    path = _write(tmp_path, "nulmid.csv", "\n".join(meta + [header] + rows[:10]
                                                  + ["\x00" * 12] + rows[10:]) + "\n")
    text = _refused(path, rf"line {len(meta) + 12}:", r"NUL characters", r"damaged")
    assert "not closed properly" not in text


def test_repeated_header_mid_file_says_two_runs(tmp_path):
    meta, header, rows = _lines()
    path = _write(tmp_path, "twice.csv", "\n".join(meta + [header] + rows[:20] + [header]
                                                 + rows[20:]) + "\n")
    _refused(path, rf"line {len(meta) + 22}:", r"header .* again", r"more than one run")


def test_text_in_a_column_that_is_read_is_still_refused(tmp_path):
    """Leaving unused text columns out must not reach the signals: text in x, and in a
    column that --columns maps onto x, is an error naming line and column."""
    meta, header, rows = _lines()
    bad = rows[:5] + [rows[5].replace(rows[5].split(",")[2], "abc")] + rows[6:]
    path = _write(tmp_path, "x.csv", "\n".join(meta + [header] + bad) + "\n")
    _refused(path, rf"line {len(meta) + 7}, column 'x'", r"'abc' is not a number")
    renamed = _write(tmp_path, "pos.csv", "\n".join(meta + [header.replace(",x,", ",pos,")]
                                                    + bad) + "\n")
    _refused(renamed, r"column 'pos'", r"'abc' is not a number", columns="x=pos")


def test_column_named_in_the_units_line_is_read_strictly(tmp_path):
    meta, header, rows = _lines()
    text = "\n".join(["# units: pos=mm"] + [f"{header},pos"]
                     + [f"{r},{'n/a' if k == 3 else '1'}" for k, r in enumerate(rows)])
    _refused(_write(tmp_path, "u.csv", text + "\n"), r"column 'pos'", r"'n/a' is not a number")


def test_mixed_separators_in_the_header_are_named(tmp_path):
    path = _write(tmp_path, "mixed.csv", "t,u;x\n0,5;0.2\n0.01,5;0.2\n")
    _refused(path, r"line 1 \(header\)", r"'u;x' holds ';'", r"mixes separators")


def test_plant_file_given_as_the_recording(tmp_path):
    path = _write(tmp_path, "plant.csv", PLANT.read_text())
    _refused(path, r"TOML plant file", r"plant file first")


def test_cut_off_mat_file_and_csv_named_mat(tmp_path):
    clean = load_recording(CLEAN)
    good = tmp_path / "good.mat"
    scipy.io.savemat(good, {c: np.asarray(clean[c]) for c in clean.columns})
    raw = good.read_bytes()
    _refused(_write(tmp_path, "cut.mat", raw[:len(raw) // 2]), r"probably cut off")
    _refused(_write(tmp_path, "text.mat", CLEAN.read_bytes()), r"rename it to \.csv")


def test_windows_1252_file_is_read_with_a_warning(tmp_path):
    """A Windows logger's export: '\u00b0C' in a unit header and a comment in cp1252. The
    numbers are ASCII, so the samples are the clean file's; the warning names the
    first non-UTF-8 byte and its line."""
    meta, header, rows = _lines()
    text = "\n".join(meta + ["# Pr\u00fcfstand K\u00f6ln", f"{header},temp [\u00b0C]"]
                     + [f"{r},21.5" for r in rows]) + "\n"
    path = _write(tmp_path, "cp1252.csv", text.encode("cp1252"))
    with pytest.warns(InputWarning, match=rf"not UTF-8 \(byte 0xfc at line {len(meta) + 1}\)"
                                          r": read as Windows-1252"):
        rec = load_recording(path)
    _same_samples(rec)
    assert "temp [\u00b0C]" in rec.columns


def test_binary_file_is_not_read_as_windows_1252(tmp_path):
    """A spreadsheet saved as .xlsx and renamed .csv (a zip: control bytes)."""
    path = _write(tmp_path, "sheet.csv", b"PK\x03\x04\x14\x00\x06\x00" + bytes(range(32, 127)))
    _refused(path, r"not a text file")


def test_line_numbers_after_an_empty_row_stay_right(tmp_path):
    """Rows after a dropped ',,,,,' row are still located at their own file line: a
    time step back at the 30th sample is reported at its line, not one off."""
    meta, header, rows = _lines()
    bad = list(rows)
    bad[29], bad[30] = bad[30], bad[29]          # t decreases from the 30th to 31st row
    body = meta + [header] + bad[:10] + [",,,,,"] + bad[10:]
    path = _write(tmp_path, "back.csv", "\n".join(body) + "\n")
    line = len(meta) + 1 + 10 + 1 + 21           # header, 10 rows, the empty row, 21 more
    assert body[line - 1] == bad[30]
    _refused(path, rf"line {line}, column 't'", r"not strictly increasing")


def test_a_row_of_nan_words_is_not_an_empty_row(tmp_path):
    meta, header, rows = _lines()
    path = _write(tmp_path, "nanrow.csv", "\n".join(meta + [header] + rows[:10]
                                                  + [",".join(["nan"] * 6)] + rows[10:]) + "\n")
    _refused(path, rf"line {len(meta) + 12}, column 't'", r"'nan' \(nan\) is not allowed")
