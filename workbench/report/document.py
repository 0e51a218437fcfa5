"""The report document: small immutable blocks, shared numbering, number formatting.

A :class:`Report` is a title, an optional overall :class:`Status` banner, numbered
:class:`Section` objects holding blocks (:class:`Heading`, :class:`Paragraph`,
:class:`KeyValues`, :class:`Table`, :class:`Figure`, :class:`Status`,
:class:`Preformatted`) and a provenance list. Nothing here computes results: the
blocks hold values that were computed elsewhere, and :func:`fmt` only formats them.

Both renderers (:mod:`.html`, :mod:`.pdf`) walk the same :func:`outline`, so the
two files have the same sections, numbering and captions in the same order.
"""

from __future__ import annotations

import io
import math
import numbers
import os
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any, Iterable, Mapping, Sequence, Union

import numpy as np

from ..errors import WorkbenchError
from .columns import STATUS_WORDS, TableView, table_view

__all__ = [
    "ReportError", "Report", "Section", "Heading", "Paragraph", "KeyValues", "Table",
    "Figure", "Status", "Preformatted", "fmt", "outline", "OUTCOMES",
]

#: Allowed outcomes of a :class:`Status` banner, in order of severity.
OUTCOMES = ("PASS", "NOTE", "FAIL", "ERROR")

#: Other spellings accepted for an outcome, and the outcome shown.
_OUTCOME_ALIASES = {k.upper(): v for k, v in STATUS_WORDS.items()}

#: Default resolution of figures rendered from matplotlib, dots per inch.
FIGURE_DPI = 170

#: Largest figure accepted, pixels per side (a guard against a figure in metres).
_MAX_PIXELS = 8000


class ReportError(WorkbenchError, ValueError):
    """A report could not be built or written; the message says which block and why."""


# --------------------------------------------------------------------------- values

Cell = Union[float, int, str, bool, None]


def _is_bool(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not _is_bool(value)


def fmt(value: Any, unit: str | None = None, digits: int = 4) -> str:
    """Format a value the same way everywhere in a report.

    Parameters
    ----------
    value : float, int, str, bool or None
        Value to show. Floats are rounded to ``digits`` significant digits, shown
        in plain notation for 1e-3 <= abs(value) < 1e5 (trailing zeros dropped) and
        in engineering notation otherwise (exponent a multiple of 3: ``62.5e-9``).
        Integers are shown in full. ``inf`` is shown as ``inf``/``-inf``, ``nan``
        and ``None`` as ``n/a``. ``True``/``False`` are shown as ``PASS``/``FAIL``.
        Strings are returned unchanged.
    unit : str, optional
        Unit appended after a space (``"0.25 m"``); not appended to ``n/a``,
        ``PASS``/``FAIL`` or strings.
    digits : int
        Significant digits of floats, >= 1.

    Returns
    -------
    str

    Examples
    --------
    >>> fmt(0.123456, "m"), fmt(6.25e-8), fmt(float("inf")), fmt(None, "bar")
    ('0.1235 m', '62.5e-9', 'inf', 'n/a')
    """
    if digits < 1:
        raise ReportError(f"fmt: digits must be >= 1, got {digits}")
    if value is None:
        return "n/a"
    if _is_bool(value):
        return "PASS" if value else "FAIL"
    if isinstance(value, str):
        return value
    if isinstance(value, numbers.Integral):
        text = str(int(value))
    elif isinstance(value, numbers.Real):
        text = _fmt_float(float(value), digits)
        if text == "n/a":
            return text
    else:
        return str(value)
    return f"{text} {unit}" if unit else text


def _fmt_float(x: float, digits: int) -> str:
    if math.isnan(x):
        return "n/a"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    if x == 0.0:
        return "0"
    # Round to the significant digits first, then choose the notation on the
    # rounded value (so 99999.7 becomes 100e3, not 100000).
    # (decimal exponent and mantissa read from the text, not from log10 and a division:
    # exact for subnormal numbers, where 10.0 ** eng underflows to 0)
    mant_text, exp_text = f"{x:.{digits - 1}e}".split("e")
    x, exp10 = float(f"{x:.{digits - 1}e}"), int(exp_text)
    if -3 <= exp10 < 5:
        decimals = max(digits - 1 - exp10, 0)
        return _strip(f"{x:.{decimals}f}")
    eng = 3 * math.floor(exp10 / 3)
    mant = float(mant_text) * 10 ** (exp10 - eng)
    decimals = max(digits - 1 - (exp10 - eng), 0)
    return f"{_strip(f'{mant:.{decimals}f}')}e{eng}"


def _strip(text: str) -> str:
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _canonical(text: str) -> str:
    """A verdict word in the one vocabulary (``"PASSED"`` -> ``"PASS"``), other text as is."""
    return STATUS_WORDS.get(text.strip().lower(), text)


def _text(value: Any, what: str) -> str:
    if not isinstance(value, str):
        raise ReportError(f"{what} must be text, got {type(value).__name__} {value!r}")
    return value


def _optional_text(value: Any, what: str) -> str | None:
    return None if value is None else _text(value, what)


def _check_cell(value: Any, where: str) -> Cell:
    if value is None or isinstance(value, str) or _is_bool(value) or _is_number(value):
        return value
    raise ReportError(f"{where}: a value must be a number, text, True/False "
                      f"or None (n/a), got {type(value).__name__} {value!r}")


# --------------------------------------------------------------------------- blocks

class Block:
    """Base class of everything a :class:`Section` can hold."""

    __slots__ = ()


@dataclass(frozen=True)
class Heading(Block):
    """A numbered sub-heading inside a section (``2.1 Step responses``).

    Parameters
    ----------
    text : str
        Heading text.
    """

    text: str

    def __post_init__(self) -> None:
        _text(self.text, "Heading text")


@dataclass(frozen=True)
class Paragraph(Block):
    """Plain text (never markup): ``<``, ``&`` and the like are shown as typed.

    Line breaks in ``text`` are kept.

    Parameters
    ----------
    text : str
        The text.
    """

    text: str

    def __post_init__(self) -> None:
        _text(self.text, "Paragraph text")


@dataclass(frozen=True)
class Preformatted(Block):
    """Monospaced text kept exactly as given (tracebacks, command output).

    Parameters
    ----------
    text : str
        The text; long lines are wrapped, never clipped.
    """

    text: str

    def __post_init__(self) -> None:
        _text(self.text, "Preformatted text")


@dataclass(frozen=True)
class Status(Block):
    """A coloured banner: overall verdict of a report, or a callout inside a section.

    Parameters
    ----------
    outcome : {"PASS", "NOTE", "FAIL", "ERROR"}
        Case-insensitive; ``"PASSED"``/``"FAILED"`` are accepted and shown as
        ``PASS``/``FAIL`` (one vocabulary in every report). ``PASS`` green, ``FAIL`` red, ``ERROR`` dark red (the design did not run to
        the end), ``NOTE`` grey-blue (information only).
    message : str
        What passed or what failed, e.g. ``"design failed at step 'gain limits':
        no equilibrium at x = 0.25 m"``.
    """

    outcome: str
    message: str = ""

    def __post_init__(self) -> None:
        outcome = _text(self.outcome, "Status outcome").strip().upper()
        outcome = _OUTCOME_ALIASES.get(outcome, outcome)
        if outcome not in OUTCOMES:
            raise ReportError(f"Status outcome must be one of {', '.join(OUTCOMES)}, "
                              f"got {self.outcome!r}")
        object.__setattr__(self, "outcome", outcome)
        _text(self.message, "Status message")


@dataclass(frozen=True)
class KeyValues(Block):
    """Label/value pairs shown as a two-column list (plant summary, settings).

    Parameters
    ----------
    items : mapping or sequence of (label, value) or (label, value, unit)
        Values are numbers, text or None, formatted with :func:`fmt` (``unit``
        appended, e.g. ``("supply pressure", 6.0, "bar")``). A bool is a setting
        here, not a verdict: it is shown as ``yes``/``no``.
    digits : int
        Significant digits of float values.
    """

    items: Sequence[tuple[str, Cell, str | None]]
    digits: int = 4

    def __post_init__(self) -> None:
        raw = self.items.items() if isinstance(self.items, Mapping) else self.items
        items = []
        for i, item in enumerate(raw):
            item = tuple(item) if isinstance(item, (tuple, list)) else (item,)
            if len(item) not in (2, 3):
                raise ReportError(f"KeyValues item {i + 1} must be (label, value) or "
                                  f"(label, value, unit), got {item!r}")
            label = _text(item[0], f"KeyValues item {i + 1} label")
            value = _check_cell(item[1], f"KeyValues item {i + 1} ({label!r})")
            unit = _optional_text(item[2] if len(item) == 3 else None,
                                  f"KeyValues item {i + 1} unit")
            items.append((label, value, unit))
        object.__setattr__(self, "items", tuple(items))

    def formatted(self) -> tuple[tuple[str, str, Cell], ...]:
        """``(label, text, value)`` for each item, the text formatted with :func:`fmt`."""
        return tuple((label, ("yes" if value else "no") if _is_bool(value)
                      else _canonical(fmt(value, unit, self.digits)), value)
                     for label, value, unit in self.items)


@dataclass(frozen=True)
class Table(Block):
    """A numbered table (``Table n: caption``) of numbers, text and pass/fail cells.

    Parameters
    ----------
    columns : sequence of str
        Column headings.
    rows : sequence of sequences
        One sequence per row, as many cells as columns. A cell is a float or int
        (right-aligned), a str, a bool (shown as a green PASS or red FAIL) or None
        (``n/a``). The numbers of a column share one format, chosen from all of
        them (:func:`.columns.column_format`); text that is just a number
        (``"0.0012"``, ``"<= 16.75"``) counts as a number, verdict words
        (``"passed"``, ``"FAILED"``) as PASS/FAIL, and a column with no value in
        any row is not shown (see :meth:`view`).
    caption : str, optional
        Caption shown above the table as ``Table n: caption``.
    units : sequence of str or None, optional
        Unit of each column, shown in a second header row as ``[mm]``; None or
        ``""`` for a column without unit.
    digits : int
        Significant digits of float cells.
    """

    columns: Sequence[str]
    rows: Sequence[Sequence[Cell]]
    caption: str | None = None
    units: Sequence[str | None] | None = None
    digits: int = 4

    def __post_init__(self) -> None:
        name = f"Table {self.caption!r}" if self.caption else "Table"
        columns = tuple(_text(c, f"{name}: column heading") for c in self.columns)
        if not columns:
            raise ReportError(f"{name} has no columns")
        rows = []
        for i, row in enumerate(self.rows):
            if isinstance(row, (str, bytes)) or not isinstance(row, Iterable):
                raise ReportError(f"{name}: row {i + 1} must be a sequence of cells, got {row!r}")
            row = tuple(row)
            if len(row) != len(columns):
                raise ReportError(f"{name}: row {i + 1} has {len(row)} cells, "
                                  f"the table has {len(columns)} columns {list(columns)}")
            rows.append(tuple(_check_cell(v, f"{name}, row {i + 1}, column {columns[j]!r}")
                              for j, v in enumerate(row)))
        units = None
        if self.units is not None:
            units = tuple("" if u is None else _text(u, f"{name}: unit") for u in self.units)
            if len(units) != len(columns):
                raise ReportError(f"{name}: {len(units)} units for {len(columns)} columns")
        object.__setattr__(self, "columns", columns)
        object.__setattr__(self, "rows", tuple(rows))
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "caption", _optional_text(self.caption, "Table caption"))

    def column_kinds(self) -> tuple[str, ...]:
        """``"num"``, ``"status"`` or ``"text"`` per column (all columns, see :meth:`view`)."""
        return table_view(self.columns, self.units, self.rows, self.digits, False).kinds

    def formatted_rows(self) -> tuple[tuple[str, ...], ...]:
        """Cell texts of all columns, one number format per column (see :meth:`view`)."""
        return table_view(self.columns, self.units, self.rows, self.digits, False).texts

    def view(self) -> TableView:
        """What the renderers show: columns with a value, kinds, one format per column.

        Columns with nothing in any row (None, NaN, blank text) are dropped,
        unless every column is; headers keep formulas and number-unit
        pairs on one line (:func:`.columns.keep_formulas`).
        """
        return table_view(self.columns, self.units, self.rows, self.digits)


@dataclass(frozen=True)
class Figure(Block):
    """A numbered figure (``Figure n: caption``), stored once as PNG.

    A matplotlib figure is rendered to PNG when the block is made (at ``dpi``,
    tight bounding box, white background) and then closed; the same PNG goes into
    the HTML (as a data URI) and the PDF (scaled to the column width).

    Parameters
    ----------
    image : matplotlib.figure.Figure, bytes or path-like
        The figure, PNG data, or the path of a PNG file.
    caption : str
        Caption shown below the figure as ``Figure n: caption``.
    width : float
        Width as a fraction of the text column, 0 < width <= 1.
    dpi : int
        Resolution for a matplotlib figure, dots per inch.
    close : bool
        Close a matplotlib figure after rendering it (frees its memory in pyplot).
    """

    image: bytes = field(repr=False)
    caption: str = ""
    width: float = 1.0
    dpi: int = FIGURE_DPI
    close: bool = field(default=True, repr=False, compare=False)
    #: Size of the PNG, pixels (width, height).
    pixels: tuple[int, int] = field(init=False, default=(0, 0))

    def __post_init__(self) -> None:
        what = f"Figure {self.caption!r}" if self.caption else "Figure"
        _text(self.caption, f"{what}: caption")
        if not (isinstance(self.width, numbers.Real) and 0.0 < self.width <= 1.0):
            raise ReportError(f"{what}: width is a fraction of the column, "
                              f"0 < width <= 1, got {self.width!r}")
        png = self._to_png(self.image, what)
        pixels = _png_size(png, what)
        object.__setattr__(self, "image", png)
        object.__setattr__(self, "pixels", pixels)

    def _to_png(self, image: Any, what: str) -> bytes:
        if isinstance(image, (bytes, bytearray, memoryview)):
            return bytes(image)
        if isinstance(image, (str, os.PathLike)):
            try:
                with open(image, "rb") as fh:
                    return fh.read()
            except OSError as exc:
                raise ReportError(f"{what}: cannot read the image file {os.fspath(image)!r}: "
                                  f"{exc.strerror or exc}") from exc
        if hasattr(image, "savefig"):
            buf = io.BytesIO()
            try:
                image.savefig(buf, format="png", dpi=self.dpi, bbox_inches="tight",
                              facecolor="white")
            finally:
                if self.close:
                    import matplotlib.pyplot as plt
                    plt.close(image)
            return buf.getvalue()
        raise ReportError(f"{what}: image must be a matplotlib Figure, PNG bytes or the path "
                          f"of a PNG file, got {type(image).__name__}")


def _png_size(png: bytes, what: str) -> tuple[int, int]:
    """Check that ``png`` decodes completely as a PNG and return (width, height) pixels."""
    from PIL import Image, UnidentifiedImageError

    if not png.startswith(b"\x89PNG\r\n\x1a\n"):
        raise ReportError(f"{what}: the image is not a PNG (it does not start with the PNG "
                          "signature)")
    try:
        with Image.open(io.BytesIO(png)) as im:
            im.load()
            size = im.size
    except (OSError, UnidentifiedImageError, ValueError) as exc:
        raise ReportError(f"{what}: the PNG cannot be decoded: {exc}") from exc
    if not (0 < size[0] <= _MAX_PIXELS and 0 < size[1] <= _MAX_PIXELS):
        raise ReportError(f"{what}: the image is {size[0]} x {size[1]} pixels; at most "
                          f"{_MAX_PIXELS} per side (was the figure size given in inches?)")
    return size


_BLOCKS = (Heading, Paragraph, Preformatted, Status, KeyValues, Table, Figure)


@dataclass(frozen=True)
class Section:
    """A numbered top-level section (``2 Stability``) and its blocks, in order.

    Parameters
    ----------
    title : str
        Section title.
    blocks : sequence of blocks
        :class:`Heading`, :class:`Paragraph`, :class:`Preformatted`,
        :class:`Status`, :class:`KeyValues`, :class:`Table`, :class:`Figure`.
    """

    title: str
    blocks: Sequence[Block] = ()

    def __post_init__(self) -> None:
        _text(self.title, "Section title")
        blocks = tuple(self.blocks)
        for i, b in enumerate(blocks):
            if not isinstance(b, _BLOCKS):
                raise ReportError(
                    f"Section {self.title!r}, block {i + 1}: expected one of "
                    f"{', '.join(c.__name__ for c in _BLOCKS)}, got {type(b).__name__}")
        object.__setattr__(self, "blocks", blocks)


@dataclass(frozen=True)
class Report:
    """A whole report: title, overall verdict, numbered sections, provenance.

    Parameters
    ----------
    title : str
        Title, also in the PDF page header and the HTML ``<title>``.
    subtitle : str, optional
        One line under the title (plant, rig, design script).
    status : Status, optional
        Overall verdict shown as a banner under the title.
    sections : sequence of Section
        Numbered sections, in order.
    provenance : sequence of (label, value)
        Shown as the last numbered section, "Provenance"; see
        :func:`workbench.report.provenance`.
    date : str, optional
        Date shown under the title and in the PDF header; default the ``date``
        item of ``provenance``, else the time of rendering.
    """

    title: str
    subtitle: str | None = None
    status: Status | None = None
    sections: Sequence[Section] = ()
    provenance: Sequence[tuple[str, Any]] = ()
    date: str | None = None

    def __post_init__(self) -> None:
        _text(self.title, "Report title")
        _optional_text(self.subtitle, "Report subtitle")
        if self.status is not None and not isinstance(self.status, Status):
            raise ReportError(f"Report status must be a Status, got {type(self.status).__name__}")
        if isinstance(self.sections, Section):
            raise ReportError("Report sections must be a sequence of Section, got one Section "
                              "(wrap it in a list)")
        sections = tuple(self.sections)
        for i, s in enumerate(sections):
            if not isinstance(s, Section):
                raise ReportError(f"Report section {i + 1} must be a Section (title and "
                                  f"blocks), got {type(s).__name__}")
        prov = []
        for i, item in enumerate(self.provenance):
            if not (isinstance(item, (tuple, list)) and len(item) == 2):
                raise ReportError(f"Report provenance item {i + 1} must be (label, value), "
                                  f"got {item!r}")
            prov.append((_text(item[0], f"provenance item {i + 1} label"),
                         _check_cell(item[1], f"provenance item {i + 1}")))
        object.__setattr__(self, "sections", sections)
        object.__setattr__(self, "provenance", tuple(prov))
        _optional_text(self.date, "Report date")

    def shown_date(self) -> str:
        """The date shown in the report (see ``date``)."""
        if self.date:
            return self.date
        for label, value in self.provenance:
            if label == "date" and isinstance(value, str):
                return value
        return datetime.now().astimezone().isoformat(timespec="seconds")


# --------------------------------------------------------------------------- outline

@dataclass(frozen=True)
class Item:
    """One block with its number in the report (``"2.1"``, ``"Table 3"``, ...)."""

    block: Block
    label: str | None = None
    anchor: str | None = None


@dataclass(frozen=True)
class NumberedSection:
    """A section with its number and anchor, and its numbered items."""

    number: str
    title: str
    anchor: str
    items: tuple[Item, ...]

    @property
    def subheadings(self) -> tuple[Item, ...]:
        return tuple(i for i in self.items if isinstance(i.block, Heading))


PROVENANCE_TITLE = "Provenance"


def outline(report: Report) -> tuple[NumberedSection, ...]:
    """Number sections, sub-headings, tables and figures once, for both renderers.

    Sections are numbered 1, 2, ...; headings inside section n are n.1, n.2, ...;
    tables and figures are numbered through the whole report. Provenance, when
    present, is the last section.
    """
    out = []
    n_table = n_figure = 0
    sections = list(report.sections)
    if report.provenance:
        sections.append(Section(PROVENANCE_TITLE, (KeyValues(report.provenance),)))
    for i, sec in enumerate(sections, start=1):
        items = []
        n_head = 0
        for block in sec.blocks:
            if isinstance(block, Heading):
                n_head += 1
                items.append(Item(block, f"{i}.{n_head}", f"sec-{i}-{n_head}"))
            elif isinstance(block, Table):
                n_table += 1
                items.append(Item(block, f"Table {n_table}", f"table-{n_table}"))
            elif isinstance(block, Figure):
                n_figure += 1
                items.append(Item(block, f"Figure {n_figure}", f"figure-{n_figure}"))
            else:
                items.append(Item(block))
        out.append(NumberedSection(str(i), sec.title, f"sec-{i}", tuple(items)))
    return tuple(out)


def caption(item: Item) -> str:
    """``"Table n: caption"`` / ``"Figure n: caption"`` (just the label without caption)."""
    text = getattr(item.block, "caption", None)
    return f"{item.label}: {text}" if text else str(item.label)
