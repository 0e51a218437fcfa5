"""Render a :class:`~.document.Report` as an A4 PDF with reportlab platypus.

Same sections, numbering and captions as the HTML (both walk
:func:`~.document.outline`). Every page has a header (title, date) and a footer
(``page i of n``); long tables split across pages with the header rows repeated;
cell text is wrapped, never clipped. Text uses DejaVu Sans from matplotlib's data
folder (Greek letters, minus, <=, degree ... render), falling back to Helvetica.
"""

from __future__ import annotations

import io
import os
from xml.sax.saxutils import escape

from reportlab.lib import colors
from reportlab.lib.enums import TA_CENTER, TA_LEFT, TA_RIGHT
from reportlab.lib.pagesizes import A4
from reportlab.lib.styles import ParagraphStyle
from reportlab.lib.units import mm
from reportlab.pdfbase import pdfmetrics
from reportlab.pdfgen import canvas as rl_canvas
from reportlab.platypus import (BaseDocTemplate, Frame, Image, PageTemplate,
                                Paragraph as RLParagraph, Preformatted as RLPreformatted,
                                Spacer, Table as RLTable, TableStyle)
from reportlab.platypus.tableofcontents import TableOfContents

from .pdf_flow import KeepGroup, float_figures
from .document import (Figure, Heading, Item, KeyValues, Paragraph, Preformatted, Report,
                       ReportError, Status, Table, _is_bool, outline)

__all__ = ["render_pdf"]

PAGE = A4
MARGIN_X = 18 * mm
MARGIN_TOP = 20 * mm
MARGIN_BOTTOM = 18 * mm
FRAME_W = PAGE[0] - 2 * MARGIN_X
FRAME_H = PAGE[1] - MARGIN_TOP - MARGIN_BOTTOM

INK = colors.HexColor("#1b1f23")
MUTED = colors.HexColor("#5f6670")
HAIR = colors.HexColor("#c9ced4")
OUTCOME_COLOURS = {  # (rule, background)
    "PASS": (colors.HexColor("#1a7f37"), colors.HexColor("#e8f4ec")),
    "FAIL": (colors.HexColor("#c62828"), colors.HexColor("#fbeaea")),
    "ERROR": (colors.HexColor("#8e1b1b"), colors.HexColor("#f7e3e3")),
    "NOTE": (colors.HexColor("#35607f"), colors.HexColor("#eaf0f5")),
}
PASS_HEX = "#1a7f37"
FAIL_HEX = "#c62828"
MUTED_HEX = "#5f6670"

CELL_PAD = 4.0  # pt, left and right padding of table cells
TABLE_FONT_SIZES = (8.6, 7.6, 6.8)  # pt, tried in turn until a table fits the width


# --------------------------------------------------------------------------- fonts

_FONTS: dict[str, str] | None = None


def _fonts() -> dict[str, str]:
    """Register DejaVu Sans (+ bold, oblique, mono) once; Helvetica if not found."""
    global _FONTS
    if _FONTS is not None:
        return _FONTS
    fonts = {"sans": "Helvetica", "bold": "Helvetica-Bold", "mono": "Courier"}
    try:
        import matplotlib
        from reportlab.lib.fonts import addMapping
        from reportlab.pdfbase.ttfonts import TTFont

        ttf = os.path.join(matplotlib.get_data_path(), "fonts", "ttf")
        files = {"WB-Sans": "DejaVuSans.ttf", "WB-Sans-Bold": "DejaVuSans-Bold.ttf",
                 "WB-Sans-Oblique": "DejaVuSans-Oblique.ttf",
                 "WB-Sans-BoldOblique": "DejaVuSans-BoldOblique.ttf",
                 "WB-Mono": "DejaVuSansMono.ttf"}
        for name, fname in files.items():
            pdfmetrics.registerFont(TTFont(name, os.path.join(ttf, fname)))
        addMapping("WB-Sans", 0, 0, "WB-Sans")
        addMapping("WB-Sans", 1, 0, "WB-Sans-Bold")
        addMapping("WB-Sans", 0, 1, "WB-Sans-Oblique")
        addMapping("WB-Sans", 1, 1, "WB-Sans-BoldOblique")
        addMapping("WB-Sans-Bold", 1, 0, "WB-Sans-Bold")
        fonts = {"sans": "WB-Sans", "bold": "WB-Sans-Bold", "mono": "WB-Mono"}
    except Exception:  # noqa: BLE001 - any font problem: fall back to the PDF core fonts
        pass
    _FONTS = fonts
    return fonts


# --------------------------------------------------------------------------- styles

class _Styles:
    def __init__(self) -> None:
        f = _fonts()
        self.sans, self.bold, self.mono = f["sans"], f["bold"], f["mono"]
        base = dict(fontName=self.sans, textColor=INK)
        self.title = ParagraphStyle("title", fontName=self.bold, fontSize=19, leading=23,
                                    spaceAfter=4, textColor=INK)
        self.subtitle = ParagraphStyle("subtitle", fontSize=11.5, leading=15, spaceAfter=2,
                                       **base)
        self.date = ParagraphStyle("date", fontName=self.sans, fontSize=9, leading=12,
                                   textColor=MUTED, spaceAfter=6)
        self.h2 = ParagraphStyle("h2", fontName=self.bold, fontSize=13.5, leading=17,
                                 spaceBefore=14, spaceAfter=6, keepWithNext=1, textColor=INK)
        self.h3 = ParagraphStyle("h3", fontName=self.bold, fontSize=11, leading=14,
                                 spaceBefore=10, spaceAfter=4, keepWithNext=1, textColor=INK)
        self.body = ParagraphStyle("body", fontSize=10, leading=13.5, spaceBefore=2,
                                   spaceAfter=6, **base)
        self.pre = ParagraphStyle("pre", fontName=self.mono, fontSize=7.8, leading=9.6,
                                  textColor=INK, backColor=colors.HexColor("#f5f6f7"),
                                  borderColor=HAIR, borderWidth=0.5, borderPadding=5,
                                  spaceBefore=6, spaceAfter=10, leftIndent=5, rightIndent=5)
        self.caption = ParagraphStyle("caption", fontSize=9.5, leading=12.5, spaceBefore=6,
                                      spaceAfter=4, keepWithNext=1, **base)
        self.fig_caption = ParagraphStyle("fig_caption", parent=self.caption,
                                          alignment=TA_CENTER, keepWithNext=0, spaceAfter=10)
        self.banner = ParagraphStyle("banner", fontSize=10.5, leading=14, **base)
        self.cell, self.head, self.unit = self.sized(TABLE_FONT_SIZES[0])
        self.kv_label = ParagraphStyle("kv_label", parent=self.cell["text"], textColor=MUTED)
        self.toc_title = ParagraphStyle("toc_title", fontName=self.bold, fontSize=11,
                                        leading=14, spaceBefore=8, spaceAfter=4, textColor=INK)
        self.toc_levels = [
            ParagraphStyle("toc0", fontName=self.sans, fontSize=9.5, leading=12.5,
                           leftIndent=0, firstLineIndent=0, textColor=INK),
            ParagraphStyle("toc1", fontName=self.sans, fontSize=9, leading=11.5,
                           leftIndent=18, firstLineIndent=0, textColor=INK),
        ]


    def sized(self, size: float) -> tuple[dict, dict, dict]:
        """Cell, header and unit-row styles at a font size, by column kind."""
        aligns = (("text", TA_LEFT), ("num", TA_RIGHT), ("status", TA_CENTER))
        cell = dict(fontName=self.sans, fontSize=size, leading=round(1.23 * size, 1),
                    textColor=INK)
        out = []
        for name, extra in (("cell", {}), ("head", {"fontName": self.bold}),
                            ("unit", {"textColor": MUTED})):
            out.append({a: ParagraphStyle(f"{name}_{a}_{size}", alignment=al, **{**cell, **extra})
                        for a, al in aligns})
        return tuple(out)


def _esc(text: str) -> str:
    """Plain text to reportlab paragraph markup (escaped, line breaks kept)."""
    return escape(text).replace("\n", "<br/>")


# --------------------------------------------------------------------------- canvas

def _canvas_maker(title: str, date: str):
    """A canvas class drawing the header (title, date) and footer (page i of n)."""

    class _PagedCanvas(rl_canvas.Canvas):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self._pages: list[dict] = []

        def showPage(self):  # noqa: N802 - reportlab API
            self._pages.append(dict(self.__dict__))
            self._startPage()

        def save(self):
            n = len(self._pages)
            for i, state in enumerate(self._pages, start=1):
                self.__dict__.update(state)
                self._decorate(i, n)
                super().showPage()
            super().save()

        def _decorate(self, i: int, n: int) -> None:
            f = _fonts()
            w, h = PAGE
            self.saveState()
            self.setFont(f["sans"], 8)
            self.setFillColor(MUTED)
            y = h - MARGIN_TOP + 6 * mm
            date_w = self.stringWidth(date, f["sans"], 8)
            room = FRAME_W - date_w - 10 * mm
            text = title
            if self.stringWidth(text, f["sans"], 8) > room:
                while text and self.stringWidth(text + "…", f["sans"], 8) > room:
                    text = text[:-1]
                text = text.rstrip() + "…"
            self.drawString(MARGIN_X, y, text)
            self.drawRightString(w - MARGIN_X, y, date)
            self.setStrokeColor(HAIR)
            self.setLineWidth(0.5)
            self.line(MARGIN_X, y - 2.5 * mm, w - MARGIN_X, y - 2.5 * mm)
            yb = MARGIN_BOTTOM - 8 * mm
            self.line(MARGIN_X, yb + 4 * mm, w - MARGIN_X, yb + 4 * mm)
            self.drawRightString(w - MARGIN_X, yb, f"page {i} of {n}")
            self.restoreState()

    return _PagedCanvas


class _Doc(BaseDocTemplate):
    """Doc template that feeds the table of contents and the PDF outline."""

    def __init__(self, buf, **kwargs):
        super().__init__(buf, pagesize=PAGE, leftMargin=MARGIN_X, rightMargin=MARGIN_X,
                         topMargin=MARGIN_TOP, bottomMargin=MARGIN_BOTTOM, **kwargs)
        frame = Frame(MARGIN_X, MARGIN_BOTTOM, FRAME_W, FRAME_H, id="body",
                      leftPadding=0, rightPadding=0, topPadding=0, bottomPadding=0)
        self.addPageTemplates([PageTemplate(id="page", frames=[frame])])

    def handle_flowable(self, flowables):  # noqa: D102 - reportlab API
        frame = getattr(self, "frame", None)
        if frame is not None:
            float_figures(flowables, frame, self.canv, FRAME_H)
        super().handle_flowable(flowables)

    def afterFlowable(self, flowable):  # noqa: N802 - reportlab API
        toc = getattr(flowable, "_wb_toc", None)
        if toc is None:
            return
        level, text, key = toc
        self.canv.bookmarkPage(key)
        self.canv.addOutlineEntry(text, key, level=level, closed=level > 0)
        self.notify("TOCEntry", (level, _esc(text), self.page, key))  # TOC lines are markup


# --------------------------------------------------------------------------- blocks

def _col_widths(cells: list[list[str]], fonts: list[list[str]], size: float,
                kinds: tuple[str, ...], total: float, fill: float,
                n_head: int = 0) -> tuple[list[float], int]:
    """Column widths (pt) from the text widths, and how well they fit.

    Each column has a natural width (widest cell on one line), a soft least width
    (its longest word, capped at 40 % of ``total``) and a hard least width (in
    body rows of ``"num"``/``"nowrap"`` columns, the widest cell: numbers never
    wrap). The first ``n_head`` rows (headers) only count for natural and soft
    widths. If the natural widths fit, they are stretched to at least
    ``fill * total``; otherwise columns shrink towards the soft, then the hard
    least widths.

    Returns
    -------
    widths : list of float
        Column widths, pt, summing to at most ``total``.
    fit : int
        2 no word is split, 1 numbers are whole but some long words are split,
        0 even numbers do not fit (try a smaller font).
    """
    ncol = len(kinds)
    natural, soft, hard = [0.0] * ncol, [0.0] * ncol, [0.0] * ncol
    for i, (row, row_fonts) in enumerate(zip(cells, fonts)):
        for j, (text, font) in enumerate(zip(row, row_fonts)):
            lines = text.split("\n") or [""]
            wid = max(pdfmetrics.stringWidth(ln, font, size) for ln in lines)
            natural[j] = max(natural[j], wid)
            words = text.split(" ")  # not at no-break spaces (formulas, 10 ms)
            soft[j] = max(soft[j], max(pdfmetrics.stringWidth(w, font, size) for w in words))
            if i >= n_head and kinds[j] in ("num", "nowrap"):
                hard[j] = max(hard[j], wid)
    # cell padding; text right of a number gets 2 * CELL_PAD more (see _table)
    pad = [2 * CELL_PAD + 1.0 + (2 * CELL_PAD if j and kinds[j - 1] == "num"
                                 and kinds[j] != "num" else 0.0) for j in range(ncol)]
    floor = 3 * size
    hard = [max(min(h + p, 0.4 * total), floor) for h, p in zip(hard, pad)]
    soft = [max(min(w + p, 0.4 * total), h) for w, h, p in zip(soft, hard, pad)]
    natural = [max(n + p, w) for n, w, p in zip(natural, soft, pad)]

    def between(lo: list[float], hi: list[float]) -> list[float]:
        extra = [b - a for a, b in zip(lo, hi)]
        k = (total - sum(lo)) / sum(extra) if sum(extra) > 0 else 0.0
        return [a + e * k for a, e in zip(lo, extra)]

    if sum(natural) <= total:
        k = max(sum(natural), fill * total) / sum(natural)
        return [n * k for n in natural], 2
    if sum(soft) <= total:
        return between(soft, natural), 2
    if sum(hard) <= total:
        return between(hard, soft), 1
    return [h * total / sum(hard) for h in hard], 0


def _cell_markup(text: str, value) -> str:
    if value is None or text == "n/a":
        return f'<font color="{MUTED_HEX}">{_esc(text)}</font>'
    if _is_bool(value):
        colour = PASS_HEX if value else FAIL_HEX
        return f'<font color="{colour}"><b>{_esc(text)}</b></font>'
    return _esc(text)


def _base_table_style(n_head: int, n_rows: int) -> list:
    style = [
        ("VALIGN", (0, 0), (-1, -1), "TOP"),
        ("LEFTPADDING", (0, 0), (-1, -1), CELL_PAD),
        ("RIGHTPADDING", (0, 0), (-1, -1), CELL_PAD),
        ("TOPPADDING", (0, 0), (-1, -1), 2.2),
        ("BOTTOMPADDING", (0, 0), (-1, -1), 2.6),
    ]
    if n_head:
        style += [("LINEABOVE", (0, 0), (-1, 0), 1.0, INK),
                  ("LINEBELOW", (0, n_head - 1), (-1, n_head - 1), 0.7, INK),
                  ("VALIGN", (0, 0), (-1, n_head - 1), "BOTTOM")]
        if n_head > 1:
            style.append(("TOPPADDING", (0, 1), (-1, n_head - 1), 0))
    if n_rows:
        if n_rows > 1:
            style.append(("LINEBELOW", (0, n_head), (-1, -2), 0.35, HAIR))
        style.append(("LINEBELOW", (0, -1), (-1, -1), 1.0, INK))
    return style


def _table(it: Item, st: _Styles) -> list:
    v = it.block.view()
    kinds = v.kinds
    has_units = v.units is not None and any(v.units)
    units = [f"[{u}]" if u else "" for u in v.units] if has_units else []
    head_txt = [list(v.columns)] + ([units] if has_units else [])
    head_fonts = [[st.bold] * len(kinds)] + ([[st.sans] * len(kinds)] if has_units else [])
    body_fonts = [[st.bold if _is_bool(x) else st.sans for x in row] for row in v.values]
    # Wide tables: a smaller font before splitting words, and before splitting numbers.
    best = None
    for size in TABLE_FONT_SIZES:
        widths, fit = _col_widths(head_txt + [list(r) for r in v.texts], head_fonts + body_fonts,
                                  size, kinds, FRAME_W, fill=1.0, n_head=len(head_txt))
        if best is None or fit > best[2]:
            best = (size, widths, fit)
        if fit == 2:
            break
    size, widths, _ = best
    cell, hd, un = st.sized(size)
    head = [[RLParagraph(_esc(c), hd[k]) for c, k in zip(v.columns, kinds)]]
    if has_units:
        head.append([RLParagraph(_esc(u), un[k]) for u, k in zip(units, kinds)])
    body = [[RLParagraph(_cell_markup(t, x), cell[k]) for t, x, k in zip(row_t, row_v, kinds)]
            for row_t, row_v in zip(v.texts, v.values)]
    style = _base_table_style(len(head), len(body))
    for j in range(1, len(kinds)):  # air between a number and the text to its right
        if kinds[j - 1] == "num" and kinds[j] != "num":
            style.append(("LEFTPADDING", (j, 0), (j, -1), 3 * CELL_PAD))
    table = RLTable(head + body, colWidths=widths, repeatRows=len(head), hAlign="LEFT",
                    style=TableStyle(style))
    return [KeepGroup([RLParagraph(_caption_markup(it), st.caption)], table, [Spacer(1, 8)],
                      FRAME_H)]


def _caption_markup(it: Item) -> str:
    text = getattr(it.block, "caption", None)
    label = f'<a name="{it.anchor}"/><b>{escape(it.label)}{":" if text else ""}</b>'
    return f"{label} {_esc(text)}" if text else label


def _key_values(b: KeyValues, st: _Styles) -> list:
    rows, txt, fonts = [], [], []
    for label, text, _ in b.formatted():
        rows.append([RLParagraph(_esc(label), st.kv_label),
                     RLParagraph(_cell_markup(text, None if text == "n/a" else text),
                                 st.cell["text"])])
        txt.append([label, text])
        fonts.append([st.sans, st.sans])
    if not rows:
        return []
    widths, _ = _col_widths(txt, fonts, st.cell["text"].fontSize, ("nowrap", "text"),
                            FRAME_W, fill=0.55)
    style = _base_table_style(0, len(rows)) + [("LINEABOVE", (0, 0), (-1, 0), 1.0, INK)]
    return [KeepGroup([], RLTable(rows, colWidths=widths, hAlign="LEFT", style=TableStyle(style)),
                      [Spacer(1, 8)], FRAME_H)]


def _figure(it: Item, st: _Styles) -> list:
    b: Figure = it.block
    pw, ph = b.pixels
    w = FRAME_W * b.width
    h = w * ph / pw
    max_h = FRAME_H - 60  # leave room for the caption on the same page
    if h > max_h:
        w, h = w * max_h / h, max_h
    img = Image(io.BytesIO(b.image), width=w, height=h)
    img.hAlign = "CENTER"
    cap = RLParagraph(_caption_markup(it), st.fig_caption)
    return [KeepGroup([Spacer(1, 4)], img, [cap], FRAME_H, png=b.image)]


def _banner(b: Status, st: _Styles) -> list:
    rule, back = OUTCOME_COLOURS[b.outcome]
    text = f'<font color="{rule.hexval().replace("0x", "#")}"><b>{b.outcome}</b></font>'
    if b.message:
        text += f"&nbsp;&nbsp;&nbsp;{_esc(b.message)}"
    t = RLTable([[RLParagraph(text, st.banner)]], colWidths=[FRAME_W], hAlign="LEFT",
                style=TableStyle([("BACKGROUND", (0, 0), (-1, -1), back),
                                  ("LINEBEFORE", (0, 0), (0, -1), 5, rule, 0),
                                  ("LEFTPADDING", (0, 0), (-1, -1), 10),
                                  ("RIGHTPADDING", (0, 0), (-1, -1), 10),
                                  ("TOPPADDING", (0, 0), (-1, -1), 6),
                                  ("BOTTOMPADDING", (0, 0), (-1, -1), 7)]))
    return [Spacer(1, 4), t, Spacer(1, 8)]


def _preformatted(b: Preformatted, st: _Styles) -> list:
    char_w = pdfmetrics.stringWidth("M", st.mono, st.pre.fontSize)
    inner = FRAME_W - st.pre.leftIndent - st.pre.rightIndent - 2 * st.pre.borderPadding
    return [RLPreformatted(b.text.expandtabs(4), st.pre,
                           maxLineLength=max(int(inner / char_w) - 1, 20), newLineChars="")]


def _item(it: Item, st: _Styles) -> list:
    b = it.block
    if isinstance(b, Heading):
        p = RLParagraph(f'<a name="{it.anchor}"/>{escape(it.label)}&nbsp;&nbsp;'
                        f"{_esc(b.text)}", st.h3)
        p._wb_toc = (1, f"{it.label}  {b.text}", it.anchor)
        return [p]
    if isinstance(b, Paragraph):
        return [RLParagraph(_esc(b.text), st.body)]
    if isinstance(b, Preformatted):
        return _preformatted(b, st)
    if isinstance(b, Status):
        return _banner(b, st)
    if isinstance(b, KeyValues):
        return _key_values(b, st)
    if isinstance(b, Table):
        return _table(it, st)
    if isinstance(b, Figure):
        return _figure(it, st)
    raise ReportError(f"cannot render a {type(b).__name__} block in PDF")


def _glue(story: list) -> list:
    """Put headings and captions (keepWithNext) into the lead of a following group.

    reportlab keeps a keepWithNext flowable with the next one only if that is
    not itself a container, so a heading before a figure could be left alone at
    the foot of a page; the group (:class:`.pdf_flow.KeepGroup`) keeps them with
    the figure, or with the first rows of a table.
    """
    out: list = []
    pending: list = []
    for f in story:
        if isinstance(f, KeepGroup) and pending:
            out.append(f.with_lead(pending))
            pending = []
        elif getattr(f, "getKeepWithNext", lambda: False)() and not isinstance(f, KeepGroup):
            pending.append(f)
        else:
            out += pending
            pending = []
            out.append(f)
    return out + pending


def render_pdf(report: Report) -> bytes:
    """The report as an A4 PDF.

    Parameters
    ----------
    report : Report
        The document.

    Returns
    -------
    bytes
        The PDF file content.
    """
    st = _Styles()
    date = report.shown_date()
    story: list = [RLParagraph(_esc(report.title), st.title)]
    if report.subtitle:
        story.append(RLParagraph(_esc(report.subtitle), st.subtitle))
    story.append(RLParagraph(_esc(date), st.date))
    if report.status is not None:
        story += _banner(report.status, st)
    sections = outline(report)
    if sections:
        toc = TableOfContents(levelStyles=st.toc_levels, dotsMinLevel=0, rightColumnWidth=28)
        story += [RLParagraph("Contents", st.toc_title), toc, Spacer(1, 6)]
    for sec in sections:
        h = RLParagraph(f'<a name="{sec.anchor}"/>{escape(sec.number)}&nbsp;&nbsp;'
                        f"{_esc(sec.title)}", st.h2)
        h._wb_toc = (0, f"{sec.number}  {sec.title}", sec.anchor)
        story.append(h)
        for it in sec.items:
            try:
                story += _item(it, st)
            except ReportError:
                raise
            except Exception as exc:
                what = it.label or type(it.block).__name__
                raise ReportError(f"PDF: section {sec.number} {sec.title!r}, {what}: "
                                  f"{type(exc).__name__}: {exc}") from exc
    story = _glue(story)
    buf = io.BytesIO()
    doc = _Doc(buf, title=report.title, author="workbench", subject=report.subtitle or "",
               creator="workbench.report")
    doc.multiBuild(story, canvasmaker=_canvas_maker(report.title, date))
    return buf.getvalue()
