"""Recording files: the CSV and MATLAB ``.mat`` parsers and the atomic writer.

The readers turn a file into raw columns, data and metadata together with a
*locator* (:class:`Where` and its subclasses) that names the line, column, variable
or element of a sample in error messages; :mod:`workbench.recording` checks the
result against the contract of ``formats.md`` section 3 and builds the
:class:`~workbench.recording.Recording`. Use ``Recording.load`` rather than these.
"""

from __future__ import annotations

import codecs
import functools
import itertools
import math
import os
import re
import stat
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from .errors import InputError

__all__ = ["KNOWN_COLUMNS", "REQUIRED_COLUMNS", "read_csv", "read_mat", "write_atomic"]

#: Column names with a meaning (formats.md section 3); others are kept as they are.
KNOWN_COLUMNS: tuple[str, ...] = ("t", "u", "x", "p_a", "p_b", "r", "p_s", "v")
#: Columns every recording must have.
REQUIRED_COLUMNS: tuple[str, ...] = ("t", "u", "x")


# --------------------------------------------------------------------------------------
# Where a sample came from: turns (column, index) into a location the user can find
# --------------------------------------------------------------------------------------
class Where:
    """Locations for in-memory arrays (0-based sample index)."""

    def header(self) -> str | None:
        return None

    def column(self, name: str) -> str:
        return f"column '{name}'"

    def sample(self, index: int) -> str:
        return f"index {index}"

    def cell(self, name: str, index: int) -> str:
        return f"column '{name}', index {index}"

    def meta(self, key: str) -> str:
        return f"metadata '{key}'"


class CsvWhere(Where):
    """Locations in a CSV file: 1-based file lines, counting metadata and header."""

    def __init__(self, path: Path, header_line: int, meta_lines: Mapping[str, int],
                 row_lines: list[int] | None = None) -> None:
        self.path = path
        self.header_line = header_line
        self.meta_lines = meta_lines
        self.row_lines = row_lines  # file line of every data row, when known

    def header(self) -> str:
        return f"line {self.header_line} (header)"

    def sample(self, index: int) -> str:
        return f"line {self._line_of(index)}"

    def cell(self, name: str, index: int) -> str:
        return f"line {self._line_of(index)}, column '{name}'"

    def meta(self, key: str) -> str:
        line = self.meta_lines.get(key)
        return f"line {line}, metadata '{key}'" if line else f"metadata '{key}'"

    def _line_of(self, index: int) -> int:
        if self.row_lines is None:
            # Only reached when reporting an error: scan the file once for row lines.
            self.row_lines = []
            with open(self.path, encoding=text_encoding(self.path)) as fh:
                for lineno, raw in enumerate(fh, start=1):
                    if lineno > self.header_line and _strip_comment(raw):
                        self.row_lines.append(lineno)
        return self.row_lines[index]


class MatWhere(Where):
    """Locations in a .mat file: variable names and 1-based (MATLAB) element numbers."""

    def header(self) -> str:
        return "variables"

    def column(self, name: str) -> str:
        return f"variable '{name}'"

    def sample(self, index: int) -> str:
        return f"element {index + 1}"

    def cell(self, name: str, index: int) -> str:
        return f"variable '{name}', element {index + 1}"

    def meta(self, key: str) -> str:
        return f"variable '{key}'"

#: What a reader returns: columns, data by column, metadata, source, locator.
Parsed = tuple[list[str], dict[str, np.ndarray], dict[str, str], str, Where]


# --------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------
def _check_file(path: Path) -> None:
    try:
        info = path.stat()
    except FileNotFoundError:
        raise InputError("file not found", source=str(path)) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})",
                         source=str(path)) from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError("is a directory, expected a recording file", source=str(path))
    if not stat.S_ISREG(info.st_mode):
        raise InputError("is not a regular file (a FIFO, socket or device): a recording is "
                         "read twice (a fast pass, and a second one to locate a bad line), "
                         "so save the stream to a file first", source=str(path))
    if info.st_size == 0:
        raise InputError("the file is empty", source=str(path))


def text_encoding(path: Path) -> str:
    """The text encoding to read ``path`` with: UTF-16 when the file starts with its
    byte-order mark (spreadsheet programs' "Unicode text"), UTF-8 with an optional BOM
    ("utf-8-sig") when the whole file is UTF-8, else Windows-1252, the default of
    Windows programs in western Europe ("Temp [\xb0C]", "Weg [\xb5m]" in a header or
    comment). Numbers and the workbench's column names are ASCII, the same in every
    one of these, so the choice only affects names and comments; :func:`read_csv`
    says when it read a file as Windows-1252."""
    with open(path, "rb") as fh:
        head = fh.read(2)
    if head in (b"\xff\xfe", b"\xfe\xff"):
        return "utf-16"
    info = path.stat()
    return "utf-8-sig" if _utf8_error(str(path), info.st_mtime_ns, info.st_size) is None \
        else "cp1252"


@functools.lru_cache(maxsize=8)
def _utf8_error(path: str, mtime_ns: int, size: int) -> tuple[int, int] | None:  # noqa: ARG001
    """(offset, line) of the first byte that is not UTF-8, or None for a UTF-8 file.
    Cached per file version (``mtime_ns``, ``size``): a load asks several times."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    offset, lines = 0, 1
    with open(path, "rb") as fh:
        while True:
            chunk = fh.read(1 << 20)
            try:
                decoder.decode(chunk, final=not chunk)
            except UnicodeDecodeError as exc:
                bad = offset + exc.start
                return bad, lines + chunk[:max(exc.start, 0)].count(b"\n")
            if not chunk:
                return None
            offset += len(chunk)
            lines += chunk.count(b"\n")


def _check_text(path: Path, src: str, encoding: str) -> None:
    """Refuse a file that is no text at all: control characters other than tab, CR,
    LF, Ctrl-Z and NUL (NUL padding: :func:`_slow_parse` explains it) in its first
    64 kB (a spreadsheet's .xlsx, a zip or a binary log renamed .csv). For a file read
    as Windows-1252, say so (:class:`~workbench.errors.InputWarning`)."""
    with open(path, encoding=encoding) as fh:
        head = fh.read(1 << 16)
    if re.search(r"[\x01-\x08\x0b\x0c\x0e-\x19\x1b-\x1f\x7f]", head):
        raise InputError("not a text file (it holds control characters); a recording CSV "
                         "is plain text, one row per sample", source=src)
    if encoding == "cp1252":
        _warn_cp1252(path, src)


def _warn_cp1252(path: Path, src: str) -> None:
    import warnings

    from .errors import InputWarning
    info = path.stat()
    offset, line = _utf8_error(str(path), info.st_mtime_ns, info.st_size)
    with open(path, "rb") as fh:
        fh.seek(offset)
        byte = fh.read(1)[0]
    warnings.warn(InputWarning(
        f"{src}: not UTF-8 (byte 0x{byte:02x} at line {line}): read as Windows-1252, the "
        f"usual encoding of Windows programs; numbers are read the same either way, only "
        f"names and comments could differ. Save it as UTF-8 to be sure"), stacklevel=4)


def _decimal(rows: str, sep: str | None) -> str:
    """"," when the rows write numbers with a decimal comma: only possible with another
    separator (";", tab, spaces), and only if no cell of the first data rows holds a
    point (a comma might otherwise be a thousands separator); else "."."""
    if sep == "," or "," not in rows or "." in rows:
        return "."
    return ","


def _first_rows(fh: Any, count: int = 20) -> str:
    """The first ``count`` data lines after the current position (comments stripped),
    joined by newlines ("" without data)."""
    rows: list[str] = []
    while len(rows) < count:
        raw = fh.readline()
        if raw == "":
            break
        text = _strip_comment(raw)
        if text:
            rows.append(text)
    return "\n".join(rows)


def _strip_comment(raw: str) -> str:
    """Text of a data line without a trailing '#' comment and surrounding space (and
    without the Ctrl-Z that DOS programs write as an end-of-file mark)."""
    return raw.split("#", 1)[0].strip().strip("\x1a").strip()


def read_csv(path: Path, used: Callable[[str, Mapping[str, str]], bool] | None = None
             ) -> Parsed:
    """Parse a CSV recording file (formats.md section 3); see ``Recording.from_csv``.

    Returns the raw columns, data, metadata, source and locations, not yet checked
    against the contract (:mod:`workbench.recording` does that).

    ``used(name, metadata)`` says whether a column is read (given by
    :mod:`workbench.recording`: :func:`~workbench.recording_units.used_column`; None:
    every column is). A column that is not read and holds text or empty cells -- a
    logger's wall-clock time stamp, a state name, an unused sensor -- is left out with
    an :class:`~workbench.errors.InputWarning`: formats.md lets a recording have more
    columns, and no result depends on one that is never read. Every cell of a column
    that is read must be a finite number.
    """
    src = str(path)
    _check_file(path)
    try:
        encoding = text_encoding(path)
        _check_text(path, src, encoding)
        with open(path, encoding=encoding) as fh:
            metadata, meta_lines, header, header_line = _read_preamble(fh, src)
            columns, sep = _parse_header(header, header_line, src)
            loose = frozenset(k for k, name in enumerate(columns)
                              if used is not None and not used(name, metadata))
            trailing = 1 if sep and header.rstrip().endswith(sep) else 0
            start = fh.tell()
            decimal = _decimal(_first_rows(fh), sep)
            fh.seek(start)
            arrays = _fast_parse(fh, len(columns), sep, trailing, decimal, loose)
        where = CsvWhere(path, header_line, meta_lines)
        if isinstance(arrays, tuple):
            # pandas pointed at one bad row: check only that line, which raises ...
            kind, k = arrays
            if kind == "row":
                _slow_parse(path, header_line, columns, sep, src, only_row=k, decimal=decimal,
                            loose=loose)
            else:
                _slow_parse(path, header_line, columns, sep, src,
                            only_line=header_line + k, decimal=decimal, loose=loose)
            arrays = None  # ... unless pandas and Python disagree: then scan it all
        if arrays is not None:
            arrays = _drop_empty_rows(arrays, where, columns, sep, src, decimal, loose)
        if arrays is None:
            arrays, where.row_lines = _slow_parse(path, header_line, columns, sep, src,
                                                  decimal=decimal, loose=loose)
        data = dict(zip(columns, arrays))
        columns = _drop_text_columns(columns, data, loose, where, sep, src)
    except UnicodeDecodeError as exc:
        raise InputError(f"not a text file: neither UTF-8 nor Windows-1252 (byte "
                         f"0x{exc.object[exc.start]:02x} cannot be decoded); a recording "
                         "CSV is plain text", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", source=src) from None
    return columns, {c: data[c] for c in columns}, metadata, src, where


def _drop_empty_rows(arrays: list[np.ndarray], where: "CsvWhere", columns: list[str],
                     sep: str | None, src: str, decimal: str, loose: frozenset[int]
                     ) -> list[np.ndarray] | None:
    """``arrays`` without the rows pandas read as all-NaN that are a spreadsheet's empty
    rows (",,,,,": blank, as :func:`_slow_parse` reads them); such a row that holds
    text (``nan,nan,...``) is checked by the slow parser, which reports it. None (the
    caller parses it all slowly) when pandas' rows and the file's data lines do not
    pair one to one (a tab-only line: a row to pandas, a blank line to the file)."""
    empty = np.ones(len(arrays[0]), dtype=bool)
    for arr in arrays:
        empty &= np.isnan(arr)
    if not empty.any():
        return arrays
    where._line_of(0)                       # the file's data lines, once
    if len(where.row_lines) != len(empty):
        where.row_lines = None
        return None
    lines = [where._line_of(int(i)) for i in np.flatnonzero(empty)]
    with open(where.path, encoding=text_encoding(where.path)) as fh:
        texts = dict((n, raw) for n, raw in enumerate(fh, start=1) if n in set(lines))
    for line in lines:
        if _strip_comment(texts[line]).replace(sep or " ", "").replace('"', "").strip():
            _slow_parse(where.path, where.header_line, columns, sep, src, only_line=line,
                        decimal=decimal, loose=loose)   # raises for "nan,nan,..."
    where.row_lines = [n for n, e in zip(where.row_lines, empty) if not e]
    return [arr[~empty] for arr in arrays]


def _drop_text_columns(columns: list[str], data: dict[str, np.ndarray],
                       loose: frozenset[int], where: "CsvWhere", sep: str | None,
                       src: str) -> list[str]:
    """``columns`` without the unread ones that hold a non-number, each with a warning
    naming its first such cell."""
    import warnings

    from .errors import InputWarning
    kept = []
    for k, name in enumerate(columns):
        bad = np.flatnonzero(~np.isfinite(data[name])) if k in loose else ()
        if not len(bad):
            kept.append(name)
            continue
        line = where._line_of(int(bad[0]))
        cell = _cell_text(where.path, line, k, sep)
        what = "an empty cell" if not cell else f"{cell!r}"
        warnings.warn(InputWarning(
            f"{src}: column '{name}' is left out: it is not a column the workbench reads "
            f"and it does not hold numbers only ({what} at line {line}, {len(bad)} such "
            f"cells); map it with --columns if it is a signal"), stacklevel=2)
    return kept


def _cell_text(path: Path, line: int, k: int, sep: str | None) -> str:
    """The text of cell ``k`` (0-based) at file line ``line``, stripped."""
    with open(path, encoding=text_encoding(path)) as fh:
        raw = next(itertools.islice(fh, line - 1, None), "")
    cells = _strip_comment(raw).split(sep) if sep else _strip_comment(raw).split()
    return cells[k].strip().strip('"').strip() if k < len(cells) else ""


def _read_preamble(fh: Any, src: str) -> tuple[dict[str, str], dict[str, int], str, int]:
    """Read metadata lines up to the header; leave ``fh`` just after the header."""
    metadata: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    lineno = 0
    comments = 0
    while True:
        raw = fh.readline()
        if raw == "":
            break
        lineno += 1
        text = raw.strip()
        if not text:
            continue
        if text.startswith("#"):
            comments += 1
            key, colon, value = text[1:].partition(":")
            key, value = key.strip(), value.strip()
            if not colon or not key:
                continue  # a plain comment, not "key: value"
            if key in metadata:
                if value not in metadata[key].split("\n"):
                    metadata[key] += "\n" + value  # repeated key: keep every value
            else:
                metadata[key] = value
                meta_lines[key] = lineno
            continue
        return metadata, meta_lines, text, lineno
    if comments == 0:
        raise InputError("the file is empty (only blank lines)", source=src)
    raise InputError(f"no header and no data: the file has only '#' comment or metadata "
                     f"lines; expected a header such as '{','.join(KNOWN_COLUMNS[:6])}' "
                     "followed by one row per sample", source=src, location=f"line {lineno}")


#: A TOML line ("[load]", "mass = 1.2", 'name = "rig"'): a plant file read as a recording.
_TOML_LINE = re.compile(r"^(\[[A-Za-z_][\w.]*\]|[A-Za-z_][\w.]*\s*=(?!=).*)$")


def _parse_header(header: str, line: int, src: str) -> tuple[list[str], str | None]:
    """Column names and separator (None: white space) from the header line."""
    for sep in (",", "\t", ";"):
        if sep in header:
            break
    else:
        sep = None
    cells = header.split(sep) if sep else header.split()
    names = [c.strip().strip('"').strip("'").strip() for c in cells]
    while len(names) > 1 and not names[-1]:
        names.pop()  # trailing delimiters, as some loggers write them: no column
    location = f"line {line} (header)"
    if _TOML_LINE.match(header):
        raise InputError(f"the first line that is not a '#' comment reads {header[:60]!r}, "
                         "a line of a TOML plant file, not a recording's header: is this "
                         "the plant file? Commands take the plant file first, e.g. "
                         "workbench diagnose PLANT.toml RECORDING.csv --out DIR",
                         source=src, location=location)
    if all(_is_number(c) for c in names):
        raise InputError(f"the first line that is not a '#' comment holds numbers "
                         f"({header[:60]!r}), not column names; add a header such as "
                         f"'{','.join(KNOWN_COLUMNS[:6])}'", source=src, location=location)
    for k, name in enumerate(names, start=1):
        if not name:
            raise InputError(f"column {k} of the header has no name", source=src,
                             location=location)
        for other in (",", ";", "\t"):
            parts = [c.strip() for c in name.split(other)]
            if other != sep and len(parts) > 1 and set(parts) & set(KNOWN_COLUMNS):
                raise InputError(f"header cell {name!r} holds {other!r} while the header "
                                 f"separates its cells by {sep or 'spaces'!r}: the file "
                                 "mixes separators; use one throughout", source=src,
                                 location=location)
    first: dict[str, int] = {}
    for k, name in enumerate(names, start=1):
        if name in first:
            raise InputError(f"duplicate column name '{name}' (columns {first[name]} and "
                             f"{k}); each column must appear once", source=src,
                             location=location)
        first[name] = k
    return names, sep


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _fast_parse(fh: Any, ncols: int, sep: str | None, trailing: int = 0, decimal: str = ".",
                loose: frozenset[int] = frozenset()
                ) -> list[np.ndarray] | tuple[str, int] | None:
    """Parse the data rows with pandas' C reader.

    Returns the columns as float64 arrays; or ``("row", i)``, the 0-based index of the
    first data row that is not all finite numbers (a NaN/inf, a text or empty cell, too
    few cells; the columns of ``loose`` may hold anything, NaN where it is not a
    number); or ``("line", k)`` when pandas stopped at the k-th line after the header
    (too many cells); or None if pandas failed otherwise or found the wrong number of
    columns. The caller checks the suspect row with the slow parser, which reports it.
    pandas takes the number of fields from the first row: a first row with more
    fields than the header (plus ``trailing`` empty fields after a trailing delimiter)
    is reported before pandas builds a frame of that width.
    """
    import warnings

    import pandas as pd
    from pandas.api import types

    start = fh.tell()
    for k in itertools.count(1):
        raw = fh.readline()
        text = _strip_comment(raw)
        if raw == "" or text:
            break
    if text and len(text.split(sep) if sep else text.split()) > ncols + trailing:
        return ("line", k)
    fh.seek(start)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pd.errors.DtypeWarning)  # mixed: text cells
            frame = pd.read_csv(fh, sep=sep if sep else r"\s+", header=None,
                                engine="c", comment="#", skip_blank_lines=True,
                                index_col=False, decimal=decimal)
    except UnicodeDecodeError:
        raise
    except pd.errors.ParserError as exc:
        match = re.search(r"Expected \d+ fields in line (\d+)", str(exc))
        return ("line", int(match.group(1))) if match else None
    except Exception:  # malformed somewhere: the slow path finds and reports where
        return None
    if frame.shape[1] == ncols + trailing > ncols and frame.iloc[:, ncols:].isna().all(axis=None):
        frame = frame.iloc[:, :ncols]  # trailing delimiters: empty cells after the last
    if frame.shape[1] != ncols or frame.shape[0] < 1:
        return None
    arrays = []
    for k in range(ncols):
        col = frame.iloc[:, k]
        if types.is_bool_dtype(col.dtype):
            arr = np.full(col.shape[0], np.nan)  # True/False: report the first row
        elif types.is_numeric_dtype(col.dtype):
            arr = col.to_numpy(dtype=np.float64)
        else:  # text somewhere in the column: NaN where a cell is not a number
            arr = pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64,
                                                               na_value=np.nan)
        arrays.append(arr)
    finite = np.ones(frame.shape[0], dtype=bool)
    empty = frame.isna().all(axis=1).to_numpy()   # no cell at all: ",,,,," (or "nan,...")
    for k, arr in enumerate(arrays):
        if k not in loose:                  # ``loose`` columns may hold text: NaN there
            finite &= np.isfinite(arr)
    if not (finite | empty).all():
        return ("row", int(np.argmin(finite | empty)))
    return arrays


def _slow_parse(path: Path, header_line: int, columns: list[str], sep: str | None,
                src: str, only_row: int | None = None, only_line: int | None = None,
                decimal: str = ".", loose: frozenset[int] = frozenset()
                ) -> tuple[list[np.ndarray], list[int]]:
    """Parse row by row, raising on the first bad line; also return each row's line.

    With ``only_row`` (0-based data row) or ``only_line`` (1-based file line), skip to
    that row without parsing the others, and check only it. ``decimal``: "," for
    numbers written with a decimal comma (:func:`_decimal`). A cell of a ``loose``
    column (by index) that is not a finite number is read as NaN, not refused.
    """
    ncols = len(columns)
    rows: list[list[float]] = []
    row_lines: list[int] = []
    count = -1
    with open(path, encoding=text_encoding(path)) as fh:
        for lineno, raw in enumerate(fh, start=1):
            if lineno <= header_line:
                continue
            text = _strip_comment(raw)
            if not text or (sep and not text.replace(sep, "").replace('"', "").strip()):
                continue    # blank, or a spreadsheet's empty row (",,,,,"): no sample
            count += 1
            if only_row is not None and count != only_row:
                continue
            if only_line is not None and lineno != only_line:
                continue
            if "\x00" in raw:
                raise InputError(_nul_message(fh, lineno), source=src,
                                 location=f"line {lineno}")
            cells = text.split(sep) if sep else text.split()
            while len(cells) > ncols and not cells[-1].strip():
                cells.pop()  # a trailing delimiter
            if len(cells) != ncols:
                cut = ""
                if len(cells) < ncols and (not raw.endswith("\n") or _at_end(fh)):
                    cut = (": the last line is cut off (the logger stopped while writing "
                           "it?); delete that line, the rows before it are complete")
                raise InputError(f"{len(cells)} cells in this row but the header has "
                                 f"{ncols} ({','.join(columns)}){cut}", source=src,
                                 location=f"line {lineno}")
            row = []
            for k, (name, cell) in enumerate(zip(columns, cells)):
                cell = cell.strip().strip('"').strip()
                if decimal == ",":
                    cell = cell.replace(",", ".")
                try:
                    value = float(cell)
                except ValueError:
                    if k in loose:
                        row.append(math.nan)
                        continue
                    what = "an empty cell" if not cell else f"{cell!r}"
                    hint = ""
                    if [c.strip().strip('"').strip() for c in cells] == columns:
                        raise InputError(
                            f"the header ({','.join(columns)}) again: the file holds "
                            "more than one run (the logger was restarted and appended?); "
                            "split it here into two files (workbench diagnose reads "
                            "several recordings of one rig together)", source=src,
                            location=f"line {lineno}")
                    if "," in cell and sep != ",":
                        hint = " (decimal comma? write numbers with a decimal point)"
                    raise InputError(f"{what} is not a number{hint}", source=src,
                                     location=f"line {lineno}, column '{name}'") from None
                if not math.isfinite(value) and k not in loose:
                    raise InputError(f"{cell!r} ({value}) is not allowed: every cell must "
                                     "be a finite number", source=src,
                                     location=f"line {lineno}, column '{name}'")
                row.append(value)
            rows.append(row)
            row_lines.append(lineno)
            if only_row is not None or only_line is not None:
                break
    if not rows and (only_row is not None or only_line is not None):
        return [], []       # the suspect line is fine after all: the caller scans it all
    if not rows:
        raise InputError(f"no data rows after the header (line {header_line}): a "
                         "recording needs one row per sample", source=src,
                         location=f"line {header_line}")
    values = np.array(rows, dtype=np.float64)
    return [values[:, k] for k in range(ncols)], row_lines


def _at_end(fh: Any) -> bool:
    """Whether no data line follows in ``fh`` (only blank and '#' lines): consumes it.
    Only called on the way to an error, to tell a cut-off last line from a short row."""
    return not any(_strip_comment(raw.replace("\x00", "")) for raw in fh)


def _nul_message(fh: Any, lineno: int) -> str:
    """The error for NUL characters at ``lineno``: consumes ``fh``.

    A logger that lost power (or was killed) while writing to an SD card or a FAT
    file system leaves the file's last block filled with NUL bytes: the rows before
    are complete. NULs amid good rows mean a damaged copy instead."""
    tail_only = all(not raw.replace("\x00", "").strip() or "\x00" in raw for raw in fh)
    if tail_only:
        return ("NUL characters (\\x00) from here to the end of the file: the file was "
                "not closed properly (the logger lost power or was killed while "
                f"writing?); the rows before line {lineno} are complete: cut the file "
                "there, or ask the logger for a clean copy")
    return ("NUL characters (\\x00) in this line, and good rows after it: the file is "
            "damaged (an incomplete copy or transfer?); copy it again from the logger")


def read_mat(path: Path) -> Parsed:
    """Parse a MATLAB ``.mat`` recording (v4 to v7); see ``Recording.from_mat``."""
    src = str(path)
    _check_file(path)
    import scipy.io

    try:
        raw = scipy.io.loadmat(str(path), squeeze_me=False, chars_as_strings=True)
    except NotImplementedError:
        raise InputError("this is a MATLAB v7.3 (HDF5) file, which cannot be read; in "
                         "MATLAB save it again as v7: save(filename, 't', 'u', 'x', ..., "
                         "'-v7')", source=src) from None
    except Exception as exc:  # scipy raises ValueError, TypeError, OSError, ...
        raise InputError(f"cannot read as a MATLAB .mat file ({exc}){_mat_hint(path)}",
                         source=src) from None
    where = MatWhere()
    variables = {k: v for k, v in raw.items() if not k.startswith("__")}
    missing = [c for c in REQUIRED_COLUMNS if c not in variables]
    if missing:
        listed = ", ".join(f"'{c}'" for c in missing)
        raise InputError(f"missing required variable{'s' if len(missing) > 1 else ''} "
                         f"{listed}; variables found: {', '.join(variables) or '(none)'}; "
                         f"required: {', '.join(REQUIRED_COLUMNS)}", source=src,
                         location=where.header())

    def vector(name: str) -> np.ndarray:
        value = np.asarray(variables[name])
        if value.dtype.kind not in "iuf":
            raise InputError(f"is not numeric (it holds {_mat_kind(value)}); expected a "
                             "vector of doubles", source=src, location=where.column(name))
        vec = np.squeeze(value)
        if vec.ndim != 1:
            raise InputError(f"expected a vector, got an array of size "
                             f"{'x'.join(map(str, value.shape))}", source=src,
                             location=where.column(name))
        return vec.astype(np.float64)

    t = vector("t")
    n = t.shape[0]
    columns: list[str] = []
    data: dict[str, np.ndarray] = {}
    metadata: dict[str, str] = {}
    for name, value in variables.items():
        arr = np.asarray(value)
        if name == "sample_time":
            if arr.dtype.kind not in "iuf" or arr.size != 1:
                raise InputError(f"sample_time must be a numeric scalar (s), got "
                                 f"{_mat_kind(arr)}", source=src, location=where.meta(name))
            metadata[name] = repr(float(arr.ravel()[0]))
        elif name in KNOWN_COLUMNS:
            vec = vector(name)
            if vec.shape[0] != n:
                raise InputError(f"has {vec.shape[0]} elements but 't' has {n}; every "
                                 "signal needs one value per sample", source=src,
                                 location=where.column(name))
            columns.append(name)
            data[name] = vec
        elif arr.dtype.kind in "iuf" and arr.size == 1:
            metadata[name] = repr(float(arr.ravel()[0]))
        elif arr.dtype.kind in "iuf" and np.squeeze(arr).ndim == 1 and arr.size == n:
            columns.append(name)
            data[name] = np.squeeze(arr).astype(np.float64)
        elif arr.dtype.kind == "U" and arr.size == 1:
            metadata[name] = " ".join(str(arr.ravel()[0]).split())
        # anything else (structs, cells, matrices, other lengths) is not a signal
    return columns, data, metadata, src, where


def _mat_hint(path: Path) -> str:
    """Why a .mat file may not parse: text inside (a CSV with the wrong suffix), or a
    MATLAB header and then too few bytes (a save or copy that was cut off)."""
    with open(path, "rb") as fh:
        head = fh.read(128)
    if head.startswith(b"MATLAB 5.0 MAT-file"):
        return ("; it has a MATLAB header but the data cannot be read: the file is "
                "probably cut off (an interrupted save or copy); save or copy it again")
    try:
        head.decode("utf-8")
    except UnicodeDecodeError:
        return ""
    return "; the file holds text: a CSV recording with a .mat suffix? rename it to .csv"


def _mat_kind(value: np.ndarray) -> str:
    kind = {"U": "text", "S": "text", "O": "a cell array", "V": "a struct",
            "b": "logicals", "c": "complex numbers"}.get(value.dtype.kind,
                                                         f"dtype {value.dtype}")
    return f"{kind} of size {'x'.join(map(str, value.shape))}"


def write_atomic(path: Path, head: list[str], rows: Iterable[str]) -> None:
    """Write ``head`` then ``rows`` to a temporary file next to ``path``, then rename."""
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError("cannot write: the directory does not exist", source=str(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as out:
            out.writelines(head)
            out.writelines(rows)
            out.flush()
            os.fsync(out.fileno())
        try:  # mkstemp makes the file private; give it the usual permissions
            mode = path.stat().st_mode & 0o777 if path.exists() else 0o644
            os.chmod(tmp, mode)
        except OSError:
            pass
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
