"""Report package: HTML and PDF with the same content, written atomically.

The sample report (:func:`sample_report`) looks like a real design report: plant
summary, a limits table with units, a metrics table with PASS/FAIL, three
matplotlib figures, a 60-row table that must split across PDF pages, provenance.
Its curves are synthetic (a damped second-order step), since only rendering is
tested here.

PDF text and the position of every line of text are read back with ``pypdf`` (the
``test`` extra of pyproject.toml), so these checks always run; a line's right edge is
its start plus its width measured by reportlab from the embedded font's own TrueType
file (matplotlib's DejaVu, the fonts the report embeds), not by the code under test.
"""

from __future__ import annotations

import hashlib
import html as html_lib
import io
import os
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from pypdf import PdfReader  # noqa: E402

from workbench import report as rp  # noqa: E402
from workbench.report import pdf as rp_pdf  # noqa: E402
from workbench.report.provenance import PACKAGES  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
PLANT = REPO / "designs" / "plants" / "situm_rodless.toml"

TITLE = "PD position loop, 15 mm rodless rig"
LONG_ROWS = 60
FIGURE_CAPTIONS = ("Closed-loop steps 250 -> 100 -> 400 mm, position x and reference r",
                   "Valve command u (saturated at 0 and 10 V)",
                   "Chamber pressures p_a and p_b")


# --------------------------------------------------------------------------- sample

def _step(t, t0, x0, x1, w0=22.0, zeta=0.55):
    """Position of a damped second-order step from x0 to x1 at t0 (synthetic), m."""
    tau = np.clip(t - t0, 0.0, None)
    wd = w0 * np.sqrt(1 - zeta ** 2)
    y = 1 - np.exp(-zeta * w0 * tau) * (np.cos(wd * tau) + zeta / np.sqrt(1 - zeta ** 2)
                                        * np.sin(wd * tau))
    return x0 + (x1 - x0) * y


def sample_figures():
    """Three figures like a design makes: position, command, pressures (units on axes)."""
    t = np.linspace(0.0, 6.0, 1201)
    r = np.where(t < 0.5, 0.25, np.where(t < 3.0, 0.10, 0.40))
    x = np.where(t < 3.0, _step(t, 0.5, 0.25, 0.10), _step(t, 3.0, 0.10, 0.40))
    u = np.clip(5.0 + 40.0 * (r - x) - 2.0 * np.gradient(x, t), 0.0, 10.0)
    p_a = 3.5e5 + 1.5e5 * np.tanh(8 * (r - x)) + 0.3e5 * np.sin(3 * t)
    p_b = 7.1e5 - p_a

    f1, ax = plt.subplots(figsize=(8.0, 3.2), constrained_layout=True)
    ax.plot(t, r * 1e3, "k--", lw=1, label="reference r")
    ax.plot(t, x * 1e3, color="tab:blue", label="position x")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("position [mm]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)

    f2, ax = plt.subplots(figsize=(8.0, 2.6), constrained_layout=True)
    ax.step(t, u, where="post", color="tab:red")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("command u [V]")
    ax.grid(True, alpha=0.3)

    f3, ax = plt.subplots(figsize=(8.0, 3.0), constrained_layout=True)
    ax.plot(t, p_a / 1e5, label="p_a")
    ax.plot(t, p_b / 1e5, label="p_b")
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("pressure [bar abs]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return list(zip((f1, f2, f3), FIGURE_CAPTIONS))


def sample_report(figures=True, status=None) -> rp.Report:
    """A realistic PD design report (synthetic numbers)."""
    plant = rp.KeyValues([
        ("plant", "situm_rodless (15 mm rodless, paper 000)"),
        ("bore", 15.0, "mm"), ("stroke", 500.0, "mm"), ("moving mass", 0.75, "kg"),
        ("supply pressure", 6.0, "bar"), ("valve sonic conductance", 6.25e-8, "m^3/(s Pa)"),
        ("viscous friction", 40.0, "N s/m"), ("dry friction", False),
        ("effects", "valve_dynamics, line_dynamics"),
    ])
    limits = rp.Table(
        ["limit", "K0", "kp", "w0", "zeta", "source"],
        [["continuous (Hurwitz)", float("inf"), float("inf"), 22.31, 0.0712, "exact tangent model"],
         ["PCT (paper 000)", 14.2, 0.5213, 22.31, 0.0712, "eq. (31)"],
         ["sampled-data, T = 10 ms", 11.874, 0.43591, 22.31, 0.0712, "exact discretisation"],
         ["sampled-data, T = 5 ms", 19.03, 0.6986, 22.31, 0.0712, "exact discretisation"],
         ["chosen (0.5 x PCT)", 7.1, 0.26065, None, None, "design rule"],
         ["valve saturation", 123456.789, 4.532e3, None, None, "u in [0, 10] V"]],
        caption="Gain limits at x = 250 mm", units=["", "1/s", "V/m", "rad/s", "", ""])
    metrics = rp.Table(
        ["metric", "value", "limit", "pass"],
        [["overshoot", 8.73, 10.0, True],
         ["settling time (2 %)", 0.412, 0.5, True],
         ["steady-state error", 0.31, 0.1, False],
         ["gain margin", 2.0, 1.5, True],
         ["phase margin", 38.2, 45.0, False]],
        caption="Closed-loop metrics against the requirements", units=["", "", "", ""])
    sweep = rp.Table(
        ["x", "p_a", "p_b", "w0", "zeta", "K0 PCT", "K0 sampled", "stable"],
        [[0.01 * i, 3.5 + 0.01 * i, 3.6 - 0.005 * i, 20 + 0.1 * i, 0.07 + 0.001 * i,
          14.2 - 0.05 * i, 11.9 - 0.04 * i, i % 17 != 5] for i in range(LONG_ROWS)],
        caption="Operating-point sweep over the stroke (exact tangent models)",
        units=["m", "bar", "bar", "rad/s", "", "1/s", "1/s", ""])
    sections = [
        rp.Section("Plant", [
            rp.Paragraph("Rodless cylinder of paper 000 with a proportional directional "
                         "valve, P/PD position loop sampled at 10 ms."),
            plant]),
        rp.Section("Stability", [
            rp.Paragraph("Gain limits from the exact tangent model at mid-stroke; the "
                         "sampled-data limit is the binding one."),
            limits,
            rp.Heading("Operating-point sweep"),
            sweep]),
        rp.Section("Closed loop", [
            rp.Heading("Requirements"),
            metrics,
            rp.Status("FAIL", "steady-state error 0.31 mm > 0.1 mm; phase margin 38.2 deg "
                              "< 45 deg"),
            rp.Heading("Step responses"),
            *([rp.Figure(f, c) for f, c in sample_figures()] if figures else [])]),
    ]
    return rp.Report(
        TITLE, subtitle="designs/situm_pd.py, plant designs/plants/situm_rodless.toml",
        status=status or rp.Status("FAIL", "2 of 5 closed-loop requirements not met"),
        sections=sections,
        provenance=rp.provenance(plant_file=PLANT if PLANT.exists() else None,
                                 command_line=["python", "designs/situm_pd.py"]))


@pytest.fixture(scope="module")
def sample():
    return sample_report()


@pytest.fixture(scope="module")
def written(sample, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    html_path, pdf_path = rp.write(sample, out)
    return out, html_path, pdf_path


def pdf_text(path: Path) -> str:
    """Text of every page, pages separated by form feeds (as pdftotext writes them)."""
    return "\f".join(page.extract_text() for page in PdfReader(path).pages)


def _string_width(text: str, base_font: str, size: float) -> float:
    """Width in pt of ``text`` in the PDF font ``base_font`` (subset prefix allowed).

    Measured by reportlab from the TrueType file of that name in matplotlib's font
    folder (DejaVu, what the report embeds), or from the AFM metrics of a PDF core font.
    """
    from reportlab.pdfbase import pdfmetrics
    from reportlab.pdfbase.ttfonts import TTFont
    name = base_font.lstrip("/").split("+")[-1]
    if name not in pdfmetrics.getRegisteredFontNames() and name not in pdfmetrics.standardFonts:
        ttf = Path(matplotlib.get_data_path()) / "fonts" / "ttf" / f"{name}.ttf"
        pdfmetrics.registerFont(TTFont(name, str(ttf)))
    return pdfmetrics.stringWidth(text, name, size)


def pdf_text_boxes(path: Path) -> list[tuple[float, float, str]]:
    """(x_min, x_max, text) in pt of every line of text drawn, all pages.

    pypdf reports each line with the matrices in force where it starts; the right
    edge adds the line's width at its font size (no character or word spacing: the
    report sets none in tables).
    """
    boxes = []

    def visit(text, cm, tm, font, size):
        line = text.rstrip("\n")
        if not line.strip() or font is None:
            return
        scale = cm[0] * tm[0]
        x0 = cm[0] * tm[4] + cm[2] * tm[5] + cm[4]
        boxes.append((x0, x0 + scale * _string_width(line, font["/BaseFont"], size), line))

    for page in PdfReader(path).pages:
        page.extract_text(visitor_text=visit)
    return boxes


def pdf_pages(data: bytes) -> int:
    """Page count from the page objects (reportlab writes them uncompressed)."""
    return len(re.findall(rb"/Type\s*/Page(?![a-zA-Z])", data))


def norm(text: str) -> str:
    return re.sub(r"\s+", " ", text)


# --------------------------------------------------------------------------- fmt

@pytest.mark.parametrize("value, unit, digits, expected", [
    (0.123456, "m", 4, "0.1235 m"),
    (0.25, None, 4, "0.25"),            # trailing zeros dropped
    (6.25e-8, None, 4, "62.5e-9"),      # engineering exponent, multiple of 3
    (123456.789, None, 4, "123.5e3"),
    (99999.7, None, 4, "100e3"),        # notation chosen after rounding
    (0.00099999, None, 4, "0.001"),
    (-2.5e6, "Pa", 4, "-2.5e6 Pa"),
    (-0.0, None, 4, "0"),
    (12, "mm", 4, "12 mm"),             # integers in full
    (123456789, None, 4, "123456789"),
    (float("inf"), "1/s", 4, "inf 1/s"),
    (float("-inf"), None, 4, "-inf"),
    (float("nan"), "m", 4, "n/a"),      # no unit on n/a
    (None, "bar", 4, "n/a"),
    (True, None, 4, "PASS"),
    (np.bool_(False), None, 4, "FAIL"),
    (np.float32(1.5), None, 4, "1.5"),
    ("text", "m", 4, "text"),
    (3.14159, None, 2, "3.1"),
])
def test_fmt(value, unit, digits, expected):
    assert rp.fmt(value, unit, digits) == expected


# --------------------------------------------------------------------------- document

def test_blocks_are_immutable_and_checked():
    t = rp.Table(["a", "b"], [[1, 2.0]])
    with pytest.raises(AttributeError):
        t.caption = "x"
    assert isinstance(t.rows, tuple) and isinstance(t.rows[0], tuple)
    with pytest.raises(rp.ReportError, match=r"row 2 has 1 cells, the table has 2 columns"):
        rp.Table(["a", "b"], [[1, 2], [3]], caption="limits")
    with pytest.raises(rp.ReportError, match=r"column 'b'.*got dict"):
        rp.Table(["a", "b"], [[1, {"x": 1}]])
    with pytest.raises(rp.ReportError, match=r"2 units for 3 columns"):
        rp.Table(["a", "b", "c"], [], units=["m", "s"])
    with pytest.raises(rp.ReportError, match="Status outcome must be one of"):
        rp.Status("OK", "fine")
    with pytest.raises(rp.ReportError, match=r"Section 'x', block 1: expected one of"):
        rp.Section("x", ["just a string"])
    with pytest.raises(rp.ReportError, match="not a PNG"):
        rp.Figure(b"GIF89a....", "caption")
    with pytest.raises(rp.ReportError, match="cannot be decoded"):
        png = _png()
        rp.Figure(png[: len(png) // 2], "truncated")


def _png(w=4.0, h=2.0) -> bytes:
    fig, ax = plt.subplots(figsize=(w, h))
    ax.plot([0, 1], [0, 1])
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=50)
    plt.close(fig)
    return buf.getvalue()


def test_figure_renders_matplotlib_once_and_closes_it():
    fig, ax = plt.subplots(figsize=(4, 2))
    ax.plot([0, 1], [1, 0])
    f = rp.Figure(fig, "a line", dpi=100)
    assert f.image.startswith(b"\x89PNG")
    assert not plt.fignum_exists(fig.number)  # closed after rendering
    # tight bounding box: at most the nominal 400 x 200 px, most of it kept
    assert 300 < f.pixels[0] <= 400 and 150 < f.pixels[1] <= 200


def test_numbering_is_shared(sample):
    from workbench.report.document import outline
    labels = [it.label for sec in outline(sample) for it in sec.items if it.label]
    assert labels == ["Table 1", "2.1", "Table 2", "3.1", "Table 3", "3.2",
                      "Figure 1", "Figure 2", "Figure 3"]
    assert [s.title for s in outline(sample)][-1] == "Provenance"


# --------------------------------------------------------------------------- html

def test_writes_both_files_and_nothing_else(written):
    out, html_path, pdf_path = written
    assert html_path == out / "report.html" and pdf_path == out / "report.pdf"
    assert sorted(p.name for p in out.iterdir()) == ["report.html", "report.pdf"]


def test_html_is_self_contained(written):
    html = written[1].read_text(encoding="utf-8")
    assert "http://" not in html and "https://" not in html
    srcs = re.findall(r'src\s*=\s*"([^"]*)"', html)
    assert len(srcs) == 3 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert "<script" not in html.lower() and "<link" not in html.lower()
    assert "@import" not in html and "url(" not in html


def test_html_has_all_content(sample, written):
    html = html_lib.unescape(re.sub(r"<[^>]+>", " ", written[1].read_text(encoding="utf-8")))
    text = norm(html)
    for sec in ["1 Plant", "2 Stability", "3 Closed loop", "4 Provenance",
                "2.1 Operating-point sweep", "3.2 Step responses"]:
        assert text.count(sec) >= 2, sec  # in the contents and as a heading
    for n, cap in enumerate(FIGURE_CAPTIONS, start=1):
        assert f"Figure {n}: {cap}" in text
    for n, cap in enumerate(["Gain limits at x = 250 mm",
                             "Operating-point sweep over the stroke (exact tangent models)",
                             "Closed-loop metrics against the requirements"], start=1):
        assert f"Table {n}: {cap}" in text
    tables = [b for s in sample.sections for b in s.blocks if isinstance(b, rp.Table)]
    for t in tables:
        for row in t.formatted_rows():
            for cell in row:
                assert cell in text, cell
    assert "FAIL 2 of 5 closed-loop requirements not met" in text
    assert "[rad/s]" in text and "62.5e-9 m^3/(s Pa)" in text


def test_html_pass_fail_coloured(written):
    html = written[1].read_text(encoding="utf-8")
    assert html.count('<span class="pass">PASS</span>') >= 3
    assert html.count('<span class="fail">FAIL</span>') >= 2
    assert '<td class="num">inf</td>' in html


def test_escaping_of_markup_in_text(tmp_path):
    evil = "<script>alert('x')</script> & <b>not bold</b>"
    doc = rp.Report("a < b & c", sections=[rp.Section("<h1>", [
        rp.Paragraph(evil), rp.Table(["<i>col</i>"], [[evil]], caption="<em>cap</em>"),
        rp.Preformatted("if a < b:\n    raise ValueError('<x>')")])])
    html_path, pdf_path = rp.write(doc, tmp_path)
    html = html_path.read_text(encoding="utf-8")
    assert "<script>" not in html and "<b>not bold</b>" not in html and "<i>col" not in html
    assert "&lt;script&gt;" in html
    assert "<title>a &lt; b &amp; c</title>" in html
    text = pdf_text(pdf_path)
    assert "<script>alert('x')</script> & <b>not bold</b>" in norm(text)
    assert "<em>cap</em>" in text
    assert norm(text).count("1 <h1>") == 2  # heading and contents line
    assert "raise ValueError('<x>')" in text


# --------------------------------------------------------------------------- pdf

def test_pdf_is_a_pdf_with_sensible_page_count(written):
    data = written[2].read_bytes()
    assert data.startswith(b"%PDF-")
    assert data.rstrip().endswith(b"%%EOF")
    # title + contents + 3 tables (one of 60 rows) + 3 figures + provenance:
    # more than 3 pages, and far fewer than one page per block row.
    assert 4 <= pdf_pages(data) <= 10


def test_pdf_has_same_content(sample, written):
    text = pdf_text(written[2])
    flat = norm(text)
    n = pdf_pages(written[2].read_bytes())
    assert f"page 1 of {n}" in text and f"page {n} of {n}" in text
    for sec in ["1 Plant", "2 Stability", "3 Closed loop", "4 Provenance",
                "2.1 Operating-point sweep", "3.2 Step responses"]:
        assert flat.count(sec) >= 2, sec  # contents + heading
    for n_fig, cap in enumerate(FIGURE_CAPTIONS, start=1):
        assert f"Figure {n_fig}: {cap}" in flat
    assert "Table 2: Operating-point sweep over the stroke" in flat
    tables = [b for s in sample.sections for b in s.blocks if isinstance(b, rp.Table)]
    words = set(flat.split())
    for t in tables:
        for row in t.formatted_rows():
            for cell in row:
                assert all(w in words for w in cell.split()), cell


def test_long_table_repeats_header_on_every_page(written):
    pages = pdf_text(written[2]).split("\f")
    with_header = [i for i, p in enumerate(pages) if "K0 sampled" in p]
    assert len(with_header) >= 2, "the 60-row table should split across pages"
    assert with_header == list(range(with_header[0], with_header[-1] + 1))  # consecutive
    for i in with_header:
        assert "[rad/s]" in pages[i]  # the units row is repeated too
    # the first and the last rows are both there (0 m and 0.59 m)
    assert "0.59" in pages[with_header[-1]]


def test_pdf_long_words_are_wrapped_not_clipped(tmp_path):
    sha = "f1ca4ae0d19c3bf7e5cd8fc3b2a1e5b50dcc145d8c77233700c8fb66d7526496" * 2
    path = "designs/plants/" + "very_long_name_" * 8
    doc = rp.Report("wrap", sections=[rp.Section("s", [
        rp.Table(["file", "hash", "x"], [[path, sha, 1.0]])])])
    _, pdf_path = rp.write(doc, tmp_path)
    joined = re.sub(r"\s+", "", pdf_text(pdf_path))
    assert sha in joined and path in joined  # every character is drawn, in order
    # ... and inside the text frame (18 mm margins on A4 = 595 x 842 pt).
    boxes = pdf_text_boxes(pdf_path)
    assert any(sha[:20] in t for _, _, t in boxes)      # the boxes include the table's lines
    x_max = [b[1] for b in boxes]
    x_min = [b[0] for b in boxes]
    margin = 18 / 25.4 * 72
    assert x_max and max(x_max) <= 595.3 - margin + 0.5 and min(x_min) >= margin - 0.5
    # the measure itself is right: the right-aligned page footer ends on the margin
    # (A4 = 595.28 pt wide), to 0.5 pt (measured 0.02 pt)
    footer = [b for b in boxes if b[2].startswith("page 1 of")]
    assert footer and abs(footer[0][1] - (595.28 - margin)) < 0.5


def test_pdf_numbers_never_wrap_in_wide_tables(tmp_path):
    # 12 columns with long headings do not fit A4 at the normal size: the font
    # shrinks and headings may wrap, but every number stays on one line.
    cols = [f"column {i} with a long heading" for i in range(12)]
    row = [1.23456789 * 10.0 ** (i - 5) for i in range(11)] + ["/very/long/path" * 6]
    table = rp.Table(cols, [row] * 3, units=["m"] * 12)
    _, pdf_path = rp.write(rp.Report("wide", sections=[rp.Section("s", [table])]), tmp_path)
    tokens = set(pdf_text(pdf_path).split())
    for cell in table.formatted_rows()[0][:11]:
        assert cell in tokens, cell


def test_key_values_show_settings_not_verdicts():
    kv = rp.KeyValues([("dry friction", False), ("bore", 0.015, "m"), ("note", None, "m")])
    assert [t for _, t, _ in kv.formatted()] == ["no", "0.015 m", "n/a"]


# --------------------------------------------------------------------------- atomicity

def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.parametrize("renderer", ["pdf", "html"])
def test_failed_render_leaves_previous_report(tmp_path, monkeypatch, renderer):
    rp.write(rp.Report("first", sections=[rp.Section("a", [rp.Paragraph("one")])]), tmp_path)
    before = _snapshot(tmp_path)
    assert set(before) == {"report.html", "report.pdf"}

    def boom(*args, **kwargs):
        raise RuntimeError("figure exploded")

    if renderer == "pdf":
        monkeypatch.setattr(rp_pdf, "_figure", boom)
    else:
        from workbench.report import html as rp_html
        real_item = rp_html._item
        monkeypatch.setattr(rp_html, "_item", lambda it: boom() if isinstance(
            it.block, rp.Figure) else real_item(it))
    doc = rp.Report("second", sections=[rp.Section("b", [
        rp.Paragraph("two"), rp.Figure(_png(), "the exploding one")])])
    with pytest.raises(rp.ReportError,
                       match=r"section 1 'b', Figure 1: RuntimeError: figure exploded"):
        rp.write(doc, tmp_path)
    assert _snapshot(tmp_path) == before  # byte-identical, and no temporary files


def test_failed_file_write_removes_temporaries(tmp_path, monkeypatch):
    doc = rp.Report("x", sections=[rp.Section("a", [rp.Paragraph("one")])])
    rp.write(doc, tmp_path)
    before = _snapshot(tmp_path)
    real_replace = os.replace
    calls = []

    def failing_replace(src, dst):
        calls.append(dst)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(rp.ReportError, match="No space left on device"):
        rp.write(doc, tmp_path)
    monkeypatch.setattr(os, "replace", real_replace)
    assert calls and _snapshot(tmp_path) == before


# --------------------------------------------------------------------------- failures

def _crash():
    raise ValueError("no equilibrium at x = 0.25 m: valve flow cannot balance leakage")


def test_write_failure_says_what_failed(tmp_path):
    try:
        _crash()
    except ValueError as exc:
        err = exc
    partial = [rp.Section("Plant", [rp.KeyValues([("bore", 15.0, "mm")])])]
    html_path, pdf_path = rp.write_failure(tmp_path, TITLE, err, step="operating point",
                                           partial_sections=partial)
    html = html_lib.unescape(html_path.read_text(encoding="utf-8"))
    msg = ("design failed at step 'operating point': ValueError: no equilibrium at "
           "x = 0.25 m: valve flow cannot balance leakage")
    assert msg in html
    assert 'class="banner error"' in html
    assert "_crash" in html  # the traceback names the failing function
    assert "2 Plant" in norm(re.sub(r"<[^>]+>", " ", html))
    assert pdf_path.read_bytes().startswith(b"%PDF")
    assert msg in norm(pdf_text(pdf_path))


def test_write_failure_survives_unrenderable_partial_sections(tmp_path, monkeypatch):
    monkeypatch.setattr(rp_pdf, "_figure", lambda *a: 1 / 0)
    partial = [rp.Section("Step responses", [rp.Figure(_png(), "steps")])]
    html_path, pdf_path = rp.write_failure(tmp_path, "design", "solver diverged",
                                           step="simulation", partial_sections=partial)
    html = html_path.read_text(encoding="utf-8")
    assert "design failed at step &#39;simulation&#39;: solver diverged" in html
    assert "could not be rendered and were left out" in html
    assert "<figure" not in html and "<h2><span class=\"num-label\">2</span>" not in html
    assert pdf_path.read_bytes().startswith(b"%PDF")


# --------------------------------------------------------------------------- provenance

def test_provenance_items(tmp_path):
    plant = tmp_path / "p.toml"
    plant.write_bytes(b"name = 'x'\n")
    items = dict(rp.provenance(plant_file=plant, command_line=["python", "d.py", "--quick"],
                               extra=[("sample time", "10 ms")]))
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d", items["date"])
    assert items["plant file"] == str(plant)
    assert items["plant sha256"] == hashlib.sha256(b"name = 'x'\n").hexdigest()
    assert items["command line"] == "python d.py --quick"
    assert items["sample time"] == "10 ms"
    for name in PACKAGES:
        assert items[name] and items[name] != "not installed", name
    assert items["numpy"] == np.__version__


def test_git_revision_tolerates_no_checkout(tmp_path):
    assert rp.git_revision(tmp_path).startswith("unknown")
    rev = rp.git_revision(REPO)
    assert re.fullmatch(r"[0-9a-f]{4,40}( \(dirty\))?|unknown \(.*\)", rev)


@pytest.mark.parametrize("x", [5e-324, 1e-310, -2.5e-320, 2.2250738585072014e-308])
def test_subnormal_numbers_format_and_read_back(x):
    # 10.0 ** eng underflows to 0 for these: the old formatter divided by it
    from workbench.report.document import _fmt_float
    text = _fmt_float(x, 4)
    assert float(text) == pytest.approx(x, rel=1e-3)   # 4 significant digits


# --------------------------------------------------------------------------- progress

class _Clock:
    """A fake ``time.perf_counter``: each item of work advances it by a set time."""

    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def _lines(text: str) -> list[str]:
    return [ln.split("] ", 1)[1] for ln in text.splitlines()]


def test_progress_never_silent_longer_than_its_interval(monkeypatch, capsys):
    from workbench.report import design as rd
    clock = _Clock()
    monkeypatch.setattr(rd.time, "perf_counter", clock)
    # items of 0.9 s: a line after items 3, 6, 9 (>= 2 s since the last) and after the last
    for _ in rd.progress(range(10), "draw"):
        clock.now += 0.9
    err = capsys.readouterr()
    assert err.out == ""                                 # progress is on stderr only
    assert _lines(err.err) == ["  draw 3/10 (2.7 s)", "  draw 6/10 (5.4 s)",
                               "  draw 9/10 (8.1 s)", "  draw 10/10 (9.0 s)"]


def test_progress_quiet_for_quick_loops_and_counts_without_a_length(monkeypatch, capsys):
    from workbench.report import design as rd
    clock = _Clock()
    monkeypatch.setattr(rd.time, "perf_counter", clock)
    for _ in rd.progress(range(5), "item"):
        clock.now += 0.1                                 # 0.5 s in all: no line
    assert capsys.readouterr().err == ""
    for _ in rd.progress((k for k in range(2)), "run"):
        clock.now += 2.5                                 # no len(): "k" without "/N"
    assert _lines(capsys.readouterr().err) == ["  run 1 (2.5 s)", "  run 2 (5.0 s)"]


def test_step_announces_itself_and_its_end_on_stderr(monkeypatch, capsys):
    from workbench.report import design as rd
    clock = _Clock()
    monkeypatch.setattr(rd.time, "perf_counter", clock)
    with rd.step("quick step"):
        clock.now += 0.5
    with rd.step("slow step"):
        clock.now += 3.25
    err = capsys.readouterr()
    assert err.out == ""
    assert _lines(err.err) == ["quick step ...", "slow step ...", "slow step: done in 3.2 s"]
    with pytest.raises(ValueError) as info:              # a failing step names itself
        with rd.step("broken", quiet=True):
            raise ValueError("x")
    assert info.value.design_step == "broken" and capsys.readouterr().err == ""
