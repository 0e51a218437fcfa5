"""Read the tables of a rendered report back from its HTML and judge their columns.

Used by ``tests/test_report_designs.py`` on the design reports (issue 15: "number
formats that change within one column", columns mixing quantities of different
units). The rules, written here independently of ``workbench.report.columns``:

* **one number format per column**: every number of a column is fixed notation
  with the same number of decimals, or scientific notation with the same mantissa
  length. In a table of quantities (a ``unit`` column naming several units) a
  column without a unit of its own may use one format per unit (one per quantity);
* **a table of quantities says each row's unit**: a table whose rows are different
  quantities (its first heading is ``quantity``, ``parameter``, ``result``, ``item``,
  ``check``, ``metric``) has a ``unit`` column, unless every number column gives its
  unit in the header row or its heading (``settling time (s)``); a column of whole
  numbers (counts, seeds) needs none;
* **no row of another unit under a column unit**: a row whose label names a unit
  of its own (``phase margin (deg)``) in a table whose number columns give theirs
  in the header mixes two quantities in one column.

Key-value tables (``class="kv"``: one quantity per row, the unit beside each
value) are not judged by these column rules.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from html.parser import HTMLParser
from pathlib import Path

#: A number as a cell shows it, with an optional relation before it and a verdict after.
NUMBER = re.compile(r"^(?:<=|>=|<|>|~|=|\u2264|\u2265)?\s*(?P<num>-?(?:\d+(?:\.(?P<dec>\d+))?"
                    r"(?:e(?P<exp>-?\d+))?|inf))(?:\s+(?:PASS|FAIL))?$")
#: Units a heading or a row label may name in brackets: "(deg)", "[mm]", "(%)".
UNIT_WORDS = {"-", "%", "deg", "rad", "s", "ms", "us", "min", "m", "mm", "cm", "um", "N",
              "kN", "V", "mV", "Pa", "kPa", "MPa", "bar", "bar abs", "mbar", "kg", "g", "g/s",
              "kg/s", "1/s", "rad/s", "Hz", "m/s", "mm/s", "m/s^2", "N/mm", "N/m", "N s/m",
              "V/m", "V s/m", "V/s", "l", "l/min", "l/min ANR", "K", "J", "W", "m^3",
              "cm^3", "m/(V s)", "mm s", "N s", "dB"}
#: First headings of a table that lists one quantity per row.
QUANTITY_HEADINGS = {"quantity", "quantities", "parameter", "parameters", "result", "item",
                     "check", "metric", "figure"}
_BRACKETED = re.compile(r"[\[(]\s*([^\[\]()]+?)\s*[\])]")
SPECIAL = {"inf", "-inf", "n/a"}


@dataclass
class ScannedTable:
    """One ``<table>``: its kind, caption, headings, unit row and body rows (texts)."""

    kind: str                      # "kv" or "table"
    caption: str = ""
    header: list[str] = field(default_factory=list)
    units: list[str] | None = None
    rows: list[list[str]] = field(default_factory=list)


class _Reader(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tables: list[ScannedTable] = []
        self._caption: list[str] | None = None
        self._row: list[str] | None = None
        self._row_class = ""
        self._in_head = False
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table":
            self.tables.append(ScannedTable("kv" if a.get("class") == "kv" else "table"))
        elif tag == "caption":
            self._caption = []
        elif tag == "thead":
            self._in_head = True
        elif tag == "tr":
            self._row, self._row_class = [], a.get("class") or ""
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag == "caption" and self._caption is not None:
            if self.tables:
                self.tables[-1].caption = " ".join("".join(self._caption).split())
            self._caption = None
        elif tag == "thead":
            self._in_head = False
        elif tag in ("td", "th") and self._cell is not None and self._row is not None:
            self._row.append(" ".join("".join(self._cell).split()))
            self._cell = None
        elif tag == "tr" and self._row is not None and self.tables:
            t = self.tables[-1]
            if self._row_class == "units":
                t.units = [u.strip("[]") for u in self._row]
            elif self._in_head and not t.header:
                t.header = self._row
            else:
                t.rows.append(self._row)
            self._row = None

    def handle_data(self, data):
        for buf in (self._cell, self._caption):
            if buf is not None:
                buf.append(data.replace("\u00a0", " "))


def read_tables(html_path: Path) -> list[ScannedTable]:
    """Every table of a rendered report, in order."""
    reader = _Reader()
    reader.feed(Path(html_path).read_text(encoding="utf-8"))
    return reader.tables


def number_style(text: str) -> tuple[str, int] | None:
    """("fixed", decimals), ("sci", mantissa decimals), ("int", 0) or ("zero", 0) for a
    number cell; ("special", 0) for inf / n/a; None for text."""
    t = text.strip()
    if t in SPECIAL:
        return ("special", 0)
    m = NUMBER.match(t)
    if m is None:
        return None
    num = m.group("num")
    if num in ("inf", "-inf"):
        return ("special", 0)
    if m.group("exp") is not None:
        return ("sci", len(m.group("dec") or ""))
    if m.group("dec") is not None:
        return ("fixed", len(m.group("dec")))
    return ("zero", 0) if float(num) == 0.0 else ("int", 0)


def names_unit(text: str) -> bool:
    """True when ``text`` names a unit: a bracketed unit (``(deg)``, ``[mm]``) or ``%``."""
    return "%" in text.split() or any(m.group(1) in UNIT_WORDS
                                      for m in _BRACKETED.finditer(text))


def _unit_column(table: ScannedTable) -> int | None:
    for j, h in enumerate(table.header):
        if h.strip().lower() in ("unit", "units"):
            return j
    return None


def problems(table: ScannedTable) -> list[str]:
    """What breaks the rules above in one table (empty: nothing)."""
    if table.kind == "kv" or not table.header:
        return []
    name = f"table {table.caption or table.header!r}"
    out = []
    uc = _unit_column(table)
    row_units = [r[uc] if uc is not None and uc < len(r) else "" for r in table.rows]
    several_units = uc is not None and len(set(row_units)) > 1
    header_units = table.units or [""] * len(table.header)
    has_header_unit_numbers = False
    quantities = table.header[0].strip().lower() in QUANTITY_HEADINGS
    for j, head in enumerate(table.header):
        if j == uc:
            continue
        cells = [(r[j], row_units[i]) for i, r in enumerate(table.rows)
                 if j < len(r) and r[j].strip()]
        styles = [(number_style(c), u) for c, u in cells]
        nums = [(s, u) for s, u in styles if s is not None and s[0] != "special"]
        if not nums or any(s is None for s, _ in styles):
            continue            # a text column (the renderer formats only number columns)
        own = bool(header_units[j].strip()) if j < len(header_units) else False
        has_header_unit_numbers |= own
        groups: dict[str, set] = {}
        for s, u in nums:
            if s[0] == "zero":
                continue
            key = u if (several_units and not own) else ""
            groups.setdefault(key, set()).add(s)
        for key, found in groups.items():
            kinds = {s for s in found if s[0] != "int"}
            if len(kinds) > 1 or (kinds and any(s[0] == "int" for s in found)):
                where = f" (rows in {key})" if key else ""
                out.append(f"{name}, column {head!r}{where}: more than one number format "
                           f"{sorted(found)}")
        whole = all(s[0] in ("int", "zero") for s, _ in nums)
        if (quantities and not (own or uc is not None or names_unit(head) or whole)):
            out.append(f"{name}, column {head!r}: numbers of the quantities in the rows "
                       "without their units (add a unit column)")
    if has_header_unit_numbers and uc is None:
        for r in table.rows:
            if r and names_unit(r[0]):
                out.append(f"{name}, row {r[0]!r}: names a unit of its own under columns "
                           "that give theirs in the header (another quantity in the column)")
    return out
