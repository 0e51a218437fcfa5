"""Table columns: one number format per column, one status vocabulary, unbroken formulas.

Rules the renderers share (both :mod:`.html` and :mod:`.pdf` use them, through
:meth:`~.document.Table.view`):

* **One number format per column.** :func:`column_format` chooses the format from
  all the numbers of a column at once: fixed decimals, as many as the smallest
  magnitude needs for ``digits`` significant digits, when the column spans at
  most :data:`FIXED_SPAN` decades inside ``1e-3 <= |x| < 1e6``; scientific
  notation with a shared mantissa length otherwise (the dynamic range demands
  it). Trailing zeros shared by every number of the column are dropped, so a
  column of whole numbers stays ``100, 30, 5``. A column of integers is shown
  in full.
* **Numbers given as text are numbers.** A text cell that is just a number
  (``"0.00084788"``, ``"<= 16.75"``, ``"inf"``, ``"8.6447 FAIL"``) is formatted
  with its column, so a design that formatted values itself still gets one
  format per column.
* **A table of quantities** (a ``unit`` column naming several units, one quantity
  per row): the number columns without a unit of their own share one format per
  unit (a row's paper and workbench values alike, and rows of one unit); a column
  with a unit in the header row (a ratio, ``"-"``) has one format for all its rows.
* **One status vocabulary.** ``PASS``/``FAIL`` (and ``NOTE``/``ERROR`` in
  banners); ``"passed"``, ``"PASSED"``, ``"fail"``, ``"FAILED"`` ... are accepted and
  shown as ``PASS``/``FAIL``.
* **Empty cells.** ``None``, NaN, ``""``, ``"-"``, ``"n/a"`` are missing values
  (they do not make a number column text). A column with nothing in any row
  (None, NaN or blank text) is dropped from the rendered table; a column of
  ``"-"`` or ``"n/a"`` typed by the design says something and is kept.
* **Headers break between words, never inside a formula or between a number and
  its unit** (:func:`keep_formulas`): those spaces become no-break spaces.
"""

from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["TableView", "table_view", "STATUS_WORDS", "FIXED_SPAN", "NBSP", "status_word", "is_empty", "number_text",
           "column_format", "keep_formulas"]

#: Accepted spellings of a verdict (lower case) and the word shown for each.
STATUS_WORDS = {"pass": "PASS", "passed": "PASS", "fail": "FAIL", "failed": "FAIL"}

#: Widest span of a column shown in fixed decimals, decades between the largest
#: and the smallest nonzero magnitude (beyond it: scientific notation).
FIXED_SPAN = 3

#: No-break space (U+00A0): a header never wraps there.
NBSP = "\u00a0"

_PLACEHOLDERS = {"", "-", "\u2013", "\u2014", "n/a", "na", "nan"}
_NUMBER = re.compile(r"^(?P<pre>(?:<=|>=|<|>|\u2264|\u2265|~|\u2248|=)\s*)?"
                     r"(?P<num>[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?inf)"
                     r"(?P<post>\s+(?:pass|passed|fail|failed))?$", re.IGNORECASE)


def _is_bool(value: Any) -> bool:
    return isinstance(value, (bool, np.bool_))


def status_word(value: Any) -> str | None:
    """``"PASS"``/``"FAIL"`` for a bool or an accepted verdict word, else None."""
    if _is_bool(value):
        return "PASS" if value else "FAIL"
    if isinstance(value, str):
        return STATUS_WORDS.get(value.strip().lower())
    return None


def is_empty(value: Any) -> bool:
    """True for None, NaN and the text placeholders of a missing value."""
    if value is None:
        return True
    if isinstance(value, str):
        return value.strip().lower() in _PLACEHOLDERS
    if isinstance(value, numbers.Real) and not _is_bool(value):
        return math.isnan(float(value))
    return False


def _blank(value: Any) -> bool:
    """Nothing at all: None, NaN or blank text (a typed "-" or "n/a" is something)."""
    if isinstance(value, str):
        return not value.strip()
    return is_empty(value)


def number_text(value: Any) -> tuple[str, float | int, str] | None:
    """``(prefix, number, suffix)`` when ``value`` is a number or a text that is one.

    The prefix is a relation written before the number (``"<= "``), kept as
    typed; the suffix a verdict after it (``"8.64 failed"``), shown as
    ``" FAIL"``. Integers (not bool) stay ``int``; numeric text with a decimal
    point or an exponent becomes ``float``, plain digits ``int``.
    """
    if isinstance(value, numbers.Real) and not _is_bool(value):
        return "", value if isinstance(value, numbers.Integral) else float(value), ""
    if not isinstance(value, str):
        return None
    m = _NUMBER.match(value.strip())
    if m is None:
        return None
    num = m.group("num")
    number = int(num) if re.fullmatch(r"[+-]?\d+", num) else float(num)
    post = m.group("post")
    return m.group("pre") or "", number, " " + status_word(post) if post else ""


def _decade(x: float, digits: int) -> int:
    """Decade of ``x`` after rounding to ``digits`` significant digits."""
    return math.floor(math.log10(abs(float(f"{x:.{digits - 1}e}"))))


def _shared_decimals(decimals: int, render: Callable[[int], list[str]]) -> int:
    """Fewest decimals, down from ``decimals``, dropping only zeros shared by every text."""
    while decimals > 0 and all(_mantissa(t).endswith("0") for t in render(decimals)):
        decimals -= 1
    return decimals


def _mantissa(text: str) -> str:
    return text.split("e")[0]


def column_format(values: Sequence[float | int], digits: int = 4) -> Callable[[Any], str]:
    """The one format of a column of numbers, as a function number -> text.

    Parameters
    ----------
    values : sequence of float or int
        All numbers of the column (None and NaN may be included; they are shown
        as ``n/a``, ``inf`` as ``inf``).
    digits : int
        Significant digits of the smallest nonzero magnitude (fixed notation) or
        of every mantissa (scientific notation), >= 1.

    Returns
    -------
    callable
        ``f(x) -> str`` for any value of the column.

    Examples
    --------
    >>> f = column_format([16.75, 0.18313, 12.006]); [f(v) for v in (16.75, 0.18313, 0)]
    ['16.7500', '0.1831', '0.0000']
    >>> f = column_format([0.00038778, 2.3634e-08]); f(0.00038778), f(2.3634e-08)
    ('3.878e-4', '2.363e-8')
    """
    finite = [v for v in values if v is not None and not _is_bool(v)
              and math.isfinite(float(v))]
    if finite and all(isinstance(v, numbers.Integral) for v in finite):
        return _special(lambda x: str(int(x)))
    nonzero = [float(v) for v in finite if float(v) != 0.0]
    if not nonzero:
        return _special(lambda x: "0" if float(x) == 0.0 else str(x))
    lo = min(_decade(v, digits) for v in nonzero)
    hi = max(_decade(v, digits) for v in nonzero)
    if hi - lo <= FIXED_SPAN and lo >= -3 and hi <= 5:
        decimals = _shared_decimals(max(digits - 1 - lo, 0),
                                    lambda d: [f"{v:.{d}f}" for v in finite])
        return _special(lambda x: _no_negative_zero(f"{float(x):.{decimals}f}"))
    mant = _shared_decimals(max(digits - 1, 0), lambda d: [_sci(v, d) for v in nonzero])
    return _special(lambda x: "0" if float(x) == 0.0 else _sci(float(x), mant))


def _sci(x: float, mant: int) -> str:
    m, e = f"{x:.{mant}e}".split("e")
    return f"{m}e{int(e)}"


def _no_negative_zero(text: str) -> str:
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _special(body: Callable[[Any], str]) -> Callable[[Any], str]:
    def fmt(x: Any) -> str:
        if x is None or (not _is_bool(x) and isinstance(x, numbers.Real)
                         and math.isnan(float(x))):
            return "n/a"
        if math.isinf(float(x)):
            return "inf" if float(x) > 0 else "-inf"
        return body(x)
    return fmt


# --------------------------------------------------------------------------- tables

@dataclass(frozen=True)
class TableView:
    """A table as shown: the kept columns, their kinds and the text of every cell.

    ``values`` holds, per cell, what decides its colour: True/False for a verdict
    (bool or verdict word), None for an empty cell, else the cell as given.
    """

    columns: tuple[str, ...]
    units: tuple[str, ...] | None
    kinds: tuple[str, ...]
    texts: tuple[tuple[str, ...], ...]
    values: tuple[tuple[Any, ...], ...]
    dropped: tuple[str, ...] = ()


def _column_kind(cells: list) -> str:
    full = [c for c in cells if not is_empty(c)]
    if full and all(number_text(c) is not None for c in full):
        return "num"
    if full and all(status_word(c) is not None for c in full):
        return "status"
    return "text"


def _column_texts(cells: list, digits: int, groups: Sequence[Any] | None = None,
                  shared: dict | None = None) -> tuple[list[str], list[Any]]:
    """Texts and values of one column; ``groups`` (one key per row, e.g. the row's
    unit) gives one format per group instead of one for the whole column, taken
    from ``shared`` (group -> format) when given."""
    numbers_ = [number_text(c) for c in cells]
    keys = list(groups) if groups is not None else [None] * len(cells)
    fmts = dict(shared) if shared is not None else {
        k: column_format([n[1] for n, kk in zip(numbers_, keys) if n is not None and kk == k],
                         digits) for k in set(keys)}
    texts, values = [], []
    for c, n, k in zip(cells, numbers_, keys):
        fmt = fmts[k]
        word = status_word(c)
        if word is not None:
            texts.append(word)
            values.append(word == "PASS")
        elif n is not None:
            texts.append(n[0] + fmt(n[1]) + n[2])
            values.append(None if texts[-1] == "n/a" else c)
        elif is_empty(c):
            shown = "" if c is None else str(c).strip()
            texts.append("n/a" if shown.lower() in ("", "n/a", "na", "nan") else shown)
            values.append(None)
        else:
            texts.append(str(c))
            values.append(c)
    return texts, values


def _quantity_per_row(columns: Sequence[str], cols: list[list]) -> list[str] | None:
    """The row's unit when the table has a ``unit`` column naming more than one unit.

    Such a table lists a different quantity in each row (a paper's results: a
    velocity, a pressure, a pole), so a number column holds several quantities: its
    numbers share one format per quantity (rows of the same unit), not one for the
    whole column, where a pressure of 6e5 Pa would force 0.7 m/s into 7.000e-1. A
    column with a unit of its own in the header row (a ratio, ``"-"``) is one
    quantity and keeps one format (:func:`table_view`).
    """
    for j, name in enumerate(columns):
        if str(name).strip().lower() in ("unit", "units"):
            keys = ["" if is_empty(c) else str(c).strip() for c in cols[j]]
            return keys if len(set(keys)) > 1 else None
    return None


def _formats_per_quantity(columns: list[list], groups: Sequence[str], digits: int) -> dict:
    """One format per quantity (row unit) from the numbers of every given column: the
    paper's value and the workbench's in one row share a format, as do rows of one unit."""
    pool: dict[str, list] = {k: [] for k in groups}
    for cells in columns:
        for c, k in zip(cells, groups):
            n = number_text(c)
            if n is not None:
                pool[k].append(n[1])
    return {k: column_format(v, digits) for k, v in pool.items()}


def table_view(columns: Sequence[str], units: Sequence[str] | None, rows: Sequence[Sequence],
               digits: int = 4, drop_empty: bool = True) -> TableView:
    """Kinds, one format per column and the dropped empty columns of a table.

    Parameters
    ----------
    columns, units, rows
        As in :class:`~.document.Table` (already checked).
    digits : int
        Significant digits (see :func:`column_format`).
    drop_empty : bool
        Drop the columns with no value in any row (all are kept when every
        column is empty, so a table with no rows still shows its header).
    """
    ncol = len(columns)
    cols = [[r[j] for r in rows] for j in range(ncol)]
    keep = [j for j in range(ncol) if not (drop_empty and rows
                                           and all(_blank(c) for c in cols[j]))]
    keep = keep or list(range(ncol))
    kinds, texts, values = [], [], []
    groups = _quantity_per_row(columns, cols)
    # a column whose header gives its own unit (a ratio "-", a count) holds one
    # quantity in every row: one format for it, whatever the unit column says
    own = [units is not None and bool(str(units[j]).strip()) for j in range(ncol)]
    shared = None if groups is None else _formats_per_quantity(
        [cols[j] for j in keep if not own[j] and _column_kind(cols[j]) == "num"], groups, digits)
    for j in keep:
        kinds.append(_column_kind(cols[j]))
        if own[j] or groups is None:
            t, v = _column_texts(cols[j], digits)
        else:
            t, v = _column_texts(cols[j], digits, groups,
                                 shared if kinds[-1] == "num" else None)
        texts.append(t)
        values.append(v)
    unit_row = None if units is None else tuple(keep_formulas(units[j]) for j in keep)
    return TableView(columns=tuple(keep_formulas(columns[j]) for j in keep), units=unit_row,
                     kinds=tuple(kinds), texts=tuple(zip(*texts)) if rows else (),
                     values=tuple(zip(*values)) if rows else (),
                     dropped=tuple(columns[j] for j in range(ncol) if j not in keep))


# --------------------------------------------------------------------------- headers

_OPERATORS = set("=<>+-*/^|~\u00b7\u00d7\u2264\u2265\u2248\u00b1\u2212")
_STOPWORDS = {"of", "at", "to", "in", "on", "and", "or", "the", "per", "for", "vs", "a",
              "an", "is", "by", "as", "if", "no", "not", "with"}
_NUM = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?%?$")
_MAX_CHUNK = 32  # characters: a longer "formula" keeps only its operator bonds


def _is_operator(token: str) -> bool:
    """``=``, ``<=``, ``-``, ``/`` ... or a lone ``x`` (a product: ``bandwidth x T``)."""
    return token == "x" or (bool(token) and all(c in _OPERATORS for c in token))


def _depths(tokens: list[str]) -> list[bool]:
    """For each space between tokens: is it inside (), [], {} or |...|?"""
    inside, depth, bars = [], 0, 0
    for tok in tokens[:-1]:
        for c in tok:
            if c in "([{":
                depth += 1
            elif c in ")]}":
                depth = max(depth - 1, 0)
            elif c == "|":
                bars ^= 1
        inside.append(depth > 0 or bars == 1)
    return inside


def keep_formulas(text: str) -> str:
    """``text`` with the spaces inside formulas and number-unit pairs made no-break.

    A space is kept from breaking when a token next to it is an operator
    (``=``, ``-``, ``<=``, ``/`` ...), when it is inside brackets or ``|...|``
    (unless the text reads as prose: it holds a comma), or when it follows a
    number (``10 ms``). A formula found this way also takes in the short symbol
    tokens around it (``K0 = kp Kv``, ``max |x - x_r|``). A chunk longer than 32
    characters keeps only the bonds next to operators and numbers, and is broken
    at its other spaces if still too long. Line breaks in ``text`` are kept.

    Examples
    --------
    >>> keep_formulas("max |x - x_r| fraction of step").replace(NBSP, "~")
    'max~|x~-~x_r| fraction of step'
    """
    if "\n" in text:
        return "\n".join(keep_formulas(line) for line in text.split("\n"))
    tokens = text.split(" ")
    if len(tokens) < 2:
        return text
    inside = _depths(tokens)
    strong = [_is_operator(a) or _is_operator(b) or bool(_NUM.match(a)) and bool(b)
              for a, b in zip(tokens, tokens[1:])]
    prose = "," in text  # brackets holding a list read as prose
    bond = [s or (inside[i] and not prose) for i, s in enumerate(strong)]
    if any(bond):  # short symbols next to a formula belong to it: "K0 = kp Kv"
        short = [0 < len(t) <= 3 and t.lower() not in _STOPWORDS and not _NUM.match(t)
                 for t in tokens]
        for _ in range(2):
            for i in range(len(bond)):
                left = bond[i - 1] if i > 0 else False
                right = bond[i + 1] if i + 1 < len(bond) else False
                if not bond[i] and ((short[i] and right) or (short[i + 1] and left)):
                    bond[i] = True
    # a chunk too long to stay on one line keeps only its operator bonds
    chunk_len = _chunk_lengths(tokens, bond)
    bond = [b and (chunk_len[i] <= _MAX_CHUNK or strong[i]) for i, b in enumerate(bond)]
    chunk_len = _chunk_lengths(tokens, bond)
    bond = [b and chunk_len[i] <= _MAX_CHUNK for i, b in enumerate(bond)]
    out = [tokens[0]]
    for i, b in enumerate(bond):
        out += [NBSP if b else " ", tokens[i + 1]]
    return "".join(out)


def _chunk_lengths(tokens: list[str], bond: list[bool]) -> list[int]:
    """For each space between tokens: length of the chunk it would be part of."""
    lengths, start = [0] * len(bond), 0
    for i in range(len(tokens)):
        if i == len(bond) or not bond[i]:
            n = sum(len(t) for t in tokens[start:i + 1]) + (i - start)
            for k in range(start, i):
                lengths[k] = n
            start = i + 1
    return lengths
