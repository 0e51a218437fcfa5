"""The design reports as rendered (issue 15): one number format per column (per unit in
a table of quantities), every number column with its unit, no column mixing
quantities of different units, and no PDF page left more than 40 % empty.

The designs run once per session in quick mode (``conftest.run_design``, the same
runs :mod:`tests.test_designs` and the paper tests judge), so these checks add only
the reading of their HTML and PDF to the suite. The rules are read back from the
rendered files by ``tests/report_scan.py``, written independently of
``workbench.report.columns``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from conftest import run_design
from report_scan import ScannedTable, number_style, problems, read_tables
from test_report_layout import page_fill

#: Each design with the arguments of its run in the suite (same runs, shared).
DESIGNS = {
    "situm_p_pd": (), "fl_position": (), "force_tracking": (),
    "nmpc_position": ("--no-jit",), "nonlinear_comparison": ("--no-jit", "--workers", "2"),
    "pressure_plan_position": (), "diagnose_concealed": (),
    "paper_000": (), "paper_001": (), "paper_002": (), "paper_003": (),
}

#: The rule of issue 15: at most 40 % of a page empty, except the last.
MIN_FILL = 0.6


@pytest.fixture(scope="module",
                params=[pytest.param(n, marks=pytest.mark.design(n)) for n in sorted(DESIGNS)])
def report(request, tmp_path_factory) -> tuple[str, Path]:
    name = request.param
    out = tmp_path_factory.mktemp(f"report_{name}")
    run_design(name, out, *DESIGNS[name])
    assert (out / "report.html").is_file() and (out / "report.pdf").is_file(), name
    return name, out


def test_design_tables_one_format_per_column_and_a_unit_for_every_column(report):
    name, out = report
    tables = read_tables(out / "report.html")
    assert any(t.kind == "table" for t in tables), f"{name}: no table read back"
    found = [p for t in tables for p in problems(t)]
    assert not found, f"{name}:\n" + "\n".join(found)


def test_design_pdf_pages_are_not_left_half_empty(report):
    name, out = report
    fills = page_fill(out / "report.pdf")
    assert len(fills) >= 2, name
    assert min(fills[:-1]) >= MIN_FILL, f"{name}: page fill {[round(f, 2) for f in fills]}"


# ------------------------------------------------------- the scanner catches what it must

def _table(header, rows, units=None) -> ScannedTable:
    return ScannedTable("table", "t", list(header), units, [list(r) for r in rows])


def test_scanner_catches_a_mixed_format_column():
    t = _table(["run", "error"], [["a", "0.00038778"], ["b", "2.3634e-8"]], ["", "mm"])
    assert any("more than one number format" in p for p in problems(t))
    ok = _table(["run", "error"], [["a", "3.878e-4"], ["b", "2.363e-8"]], ["", "mm"])
    assert problems(ok) == []


def test_scanner_catches_a_table_of_quantities_without_units():
    # situm_p_pd's linear-model table before: w0, zeta, Kv, T0, p in one column, the
    # units only in the caption
    t = _table(["quantity", "formula", "exact"],
               [["w0", "32.977", "28.068"], ["zeta", "1.083", "1.272"], ["p", "5.000", "3.786"]])
    assert sum("without their units" in p for p in problems(t)) == 2
    # a column of one quantity (a dimensionless gain) needs no unit row to be read
    gain = _table(["model", "DC gain"], [["ARX", "0.9843"], ["PCT", "1.0000"]])
    assert problems(gain) == []
    fixed = _table(["quantity", "unit", "formula", "exact"],
                   [["w0", "rad/s", "32.977", "28.068"], ["zeta", "-", "1.083", "1.272"],
                    ["p", "bar abs", "5.000", "3.786"]])
    assert problems(fixed) == []


def test_scanner_catches_another_unit_under_a_column_unit():
    # situm_p_pd's gain-limit table before: a phase margin in degrees in columns of 1/s
    t = _table(["limit", "model"], [["PCT", "62.269"], ["phase margin at K0 (deg)", "63.371"]],
               ["", "1/s"])
    assert any("unit of its own" in p for p in problems(t))
    # a parenthesis that is not a unit is a name
    named = _table(["limit", "model"], [["exact sampled-data (ZOH)", "53.845"]], ["", "1/s"])
    assert problems(named) == []


def test_scanner_per_unit_formats_in_a_table_of_quantities():
    rows = [["Kv", "m/s", "0.70", "0.630"], ["p_s", "Pa", "500000", "601300"],
            ["zeta", "-", "1.10", "1.160"]]
    assert problems(_table(["result", "unit", "paper", "workbench"], rows)) == []
    # but a ratio column with a unit of its own has one format, whatever the rows' units
    t = _table(["quantity", "unit", "a / b"], [["IAE", "mm s", "0.432"], ["max", "mm", "1.0064"]],
               ["", "", "-"])
    assert any("more than one number format" in p for p in problems(t))


@pytest.mark.parametrize("text, style", [
    ("0.0130", ("fixed", 4)), ("<= 16.75", ("fixed", 2)), ("8.64 FAIL", ("fixed", 2)),
    ("3.878e-4", ("sci", 3)), ("1e5", ("sci", 0)), ("42", ("int", 0)), ("0", ("zero", 0)),
    ("inf", ("special", 0)), ("n/a", ("special", 0)), ("0.04 / 0.018 mm", None),
    ("no (two valves)", None)])
def test_number_styles(text, style):
    assert number_style(text) == style
