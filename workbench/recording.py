"""Recordings of a servodrive run: load, validate and write them; fit metrics.

A recording is a set of equally long signals sampled at the instants ``t``. It is the
contract of ``formats.md`` section 3: a CSV file (``# key: value`` metadata lines, a
header, one row per sample) or a MATLAB ``.mat`` file with the same variable names.
Everything is SI and pressures are absolute.

Every loader checks the whole file before returning and raises
:class:`~workbench.errors.InputError` naming the file, the line (or variable) and
column, and the problem; there is never a partial result.

Examples
--------
>>> import numpy as np
>>> from workbench.recording import Recording, fit
>>> t = np.arange(5) * 0.01
>>> rec = Recording.from_arrays(t, u=np.full(5, 5.0), x=np.linspace(0.2, 0.3, 5),
...                             metadata={"sample_time": 0.01})
>>> rec.columns, len(rec), rec.sample_time
(('t', 'u', 'x'), 5, 0.01)
>>> fit(rec["x"], rec["x"])
100.0
"""

from __future__ import annotations

import math
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Iterable, Mapping

import numpy as np

from .errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    import pandas

__all__ = [
    "KNOWN_COLUMNS",
    "REQUIRED_COLUMNS",
    "PRESSURE_COLUMNS",
    "PRESSURE_RANGE",
    "FIT_SIGNALS",
    "UNITS",
    "Recording",
    "load_recording",
    "fit",
    "fit_signals",
]

#: Column names with a meaning (formats.md section 3); others are kept as they are.
KNOWN_COLUMNS: tuple[str, ...] = ("t", "u", "x", "p_a", "p_b", "r", "p_s", "v")
#: Columns every recording must have.
REQUIRED_COLUMNS: tuple[str, ...] = ("t", "u", "x")
#: SI unit of each known column.
UNITS: Mapping[str, str] = MappingProxyType({
    "t": "s", "u": "V", "x": "m", "p_a": "Pa", "p_b": "Pa", "r": "m", "p_s": "Pa",
    "v": "m/s",
})
#: Columns holding absolute pressures, checked against :data:`PRESSURE_RANGE`.
PRESSURE_COLUMNS: tuple[str, ...] = ("p_a", "p_b", "p_s")
#: Plausible absolute pressures in a pneumatic servodrive, Pa (formats.md section 3).
PRESSURE_RANGE: tuple[float, float] = (2.0e4, 5.0e6)
#: Signals compared by :func:`fit_signals` by default (the measured outputs).
FIT_SIGNALS: tuple[str, ...] = ("x", "p_a", "p_b")

_P_ATM = 101325.0  # Pa, standard atmosphere, offset of gauge pressures
_SUFFIXES = {".csv": "csv", ".txt": "csv", ".mat": "mat"}


# --------------------------------------------------------------------------------------
# Where a sample came from: turns (column, index) into a location the user can find
# --------------------------------------------------------------------------------------
class _Where:
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


class _CsvWhere(_Where):
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
            with open(self.path, encoding="utf-8-sig") as fh:
                for lineno, raw in enumerate(fh, start=1):
                    if lineno > self.header_line and _strip_comment(raw):
                        self.row_lines.append(lineno)
        return self.row_lines[index]


class _MatWhere(_Where):
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


# --------------------------------------------------------------------------------------
# The recording
# --------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Recording:
    """Sampled signals of one run of a servodrive, validated and immutable.

    Build one with :meth:`load` (or :func:`load_recording`), :meth:`from_csv`,
    :meth:`from_mat` or :meth:`from_arrays`; the constructor validates too.

    Parameters
    ----------
    columns : tuple of str
        Column names in file order. Must contain ``t`` (s), ``u`` (V) and ``x`` (m);
        the other known names are ``p_a``, ``p_b``, ``p_s`` (Pa, absolute), ``r`` (m)
        and ``v`` (m/s), see :data:`UNITS`. Unknown columns are kept as they are.
    data : mapping of str to array_like
        One 1-D array per column, all of the same length (at least 2 samples), finite.
        Stored as read-only float64 copies.
    metadata : mapping of str to str
        ``key: value`` pairs from the file header. ``sample_time`` (s), if present,
        must be a positive number.
    source : str
        Where the recording came from (a file path), used in error messages.

    Raises
    ------
    InputError
        If the signals break the contract of ``formats.md`` section 3: a required column
        missing, a NaN or inf, time not strictly increasing, pressures outside
        :data:`PRESSURE_RANGE` (gauge or bar), a bad ``sample_time``.

    Notes
    -----
    Two recordings are equal (``==``) when their columns, data and metadata are equal;
    ``source`` is not compared, so a recording equals itself read back from a file.
    """

    columns: tuple[str, ...]
    data: Mapping[str, np.ndarray]
    metadata: Mapping[str, str]
    source: str = "<memory>"

    def __post_init__(self) -> None:
        columns, data, metadata = _normalize(self.columns, self.data, self.metadata,
                                             self.source, _Where())
        _validate(columns, data, metadata, self.source, _Where())
        for array in data.values():
            array.flags.writeable = False
        object.__setattr__(self, "columns", columns)
        object.__setattr__(self, "data", MappingProxyType(data))
        object.__setattr__(self, "metadata", MappingProxyType(metadata))
        object.__setattr__(self, "source", str(self.source))

    # ---- construction ---------------------------------------------------------------
    @classmethod
    def from_arrays(cls, t: Any, source: str = "<memory>",
                    metadata: Mapping[str, Any] | None = None,
                    **signals: Any) -> "Recording":
        """Make a recording from arrays, validated like a file.

        Parameters
        ----------
        t : array_like, shape (n,)
            Sample instants, s, strictly increasing.
        source : str, optional
            Name used in error messages.
        metadata : mapping, optional
            ``key: value`` pairs; values are converted with ``str``.
        **signals : array_like, shape (n,)
            The other columns by name, in order; ``u`` (V) and ``x`` (m) are required.
            Shapes ``(n, 1)`` and ``(1, n)`` are flattened.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            As for a file; locations are 0-based sample indices.
        """
        data = {"t": t, **signals}
        meta = {} if metadata is None else metadata
        return cls(tuple(data), data, meta, source)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Recording":
        """Load a recording, choosing the reader from the suffix.

        Parameters
        ----------
        path : str or path-like
            A ``.csv`` or ``.txt`` file (:meth:`from_csv`) or a ``.mat`` file
            (:meth:`from_mat`).

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            For an unknown suffix and for everything the readers reject.

        Examples
        --------
        >>> rec = Recording.load("tests/data/recordings/step_small.csv")  # doctest: +SKIP
        """
        path = Path(path)
        kind = _SUFFIXES.get(path.suffix.lower())
        if kind is None:
            raise InputError(
                f"unknown recording file type '{path.suffix or '(no suffix)'}': expected "
                "a .csv or .txt file (comma separated) or a MATLAB .mat file",
                source=str(path))
        return cls.from_csv(path) if kind == "csv" else cls.from_mat(path)

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str]) -> "Recording":
        """Read a CSV recording (formats.md section 3).

        The file has optional ``# key: value`` metadata lines, then a header naming the
        columns, then one row per sample. Blank lines and ``#`` comments are skipped;
        comment lines without ``:`` before the header are not metadata. Cells are
        separated by commas (or, when the header has no comma, by tabs, semicolons or
        white space).

        Parameters
        ----------
        path : str or path-like
            The CSV file.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            Naming the file, the 1-based line (counting metadata and header lines) and
            column, and the problem.
        """
        return _read_csv(Path(path))

    @classmethod
    def from_mat(cls, path: str | os.PathLike[str]) -> "Recording":
        """Read a MATLAB ``.mat`` recording (v4 to v7; not v7.3).

        Variables named as the columns (``t``, ``u``, ``x``, ...) are vectors of one
        length (row or column). An optional numeric scalar ``sample_time`` (s) and other
        scalar or text variables go into :attr:`metadata`; other numeric vectors of the
        same length are kept as extra columns; anything else is ignored.

        Parameters
        ----------
        path : str or path-like
            The ``.mat`` file.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            Naming the file, the variable (and 1-based element) and the problem, also
            for MATLAB v7.3 (HDF5) files, which must be saved again with ``-v7``.
        """
        return _read_mat(Path(path))

    # ---- access ---------------------------------------------------------------------
    @property
    def t(self) -> np.ndarray:
        """Sample instants, s (read-only)."""
        return self.data["t"]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[name]
        except KeyError:
            raise KeyError(f"recording {self.source} has no column '{name}'; its columns "
                           f"are: {', '.join(self.columns)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self.data

    def has(self, name: str) -> bool:
        """Whether the recording has the column ``name``."""
        return name in self.data

    def __len__(self) -> int:
        return int(self.data["t"].shape[0])

    @property
    def sample_time(self) -> float:
        """Sample time, s: metadata ``sample_time`` if given, else the median step of t."""
        if "sample_time" in self.metadata:
            return float(self.metadata["sample_time"])
        return float(np.median(np.diff(self.t)))

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Recording):
            return NotImplemented
        return (self.columns == other.columns
                and dict(self.metadata) == dict(other.metadata)
                and all(np.array_equal(self.data[c], other.data[c]) for c in self.columns))

    __hash__ = None  # type: ignore[assignment]  # equality is by value, arrays inside

    def __repr__(self) -> str:
        return (f"Recording(source={self.source!r}, columns={self.columns!r}, "
                f"samples={len(self)}, duration={self.duration:.6g} s)")

    # ---- derived recordings and export ----------------------------------------------
    def with_columns(self, **arrays: Any) -> "Recording":
        """Return a new recording with columns replaced or added, on the same ``t``.

        Parameters
        ----------
        **arrays : array_like, shape (n,)
            New values by column name (SI units, see :data:`UNITS`). Existing columns
            keep their place; new ones are appended in the order given.

        Returns
        -------
        Recording
            Validated like any recording; metadata and source are kept.

        Raises
        ------
        InputError
            If ``t`` is given, or the new columns are invalid.
        """
        if "t" in arrays:
            raise InputError("with_columns keeps the time base; build a new recording "
                             "with Recording.from_arrays to change t",
                             source=self.source, location="column 't'")
        data: dict[str, Any] = dict(self.data)
        data.update(arrays)
        columns = self.columns + tuple(n for n in arrays if n not in self.data)
        return Recording(columns, data, self.metadata, self.source)

    def to_pandas(self) -> "pandas.DataFrame":
        """Return the signals as a :class:`pandas.DataFrame` indexed by ``t`` (s).

        The frame holds copies; ``attrs`` has ``source``, ``metadata`` and ``units``.
        """
        import pandas as pd

        index = pd.Index(np.array(self.t), name="t")
        frame = pd.DataFrame({c: np.array(self.data[c]) for c in self.columns if c != "t"},
                             index=index)
        frame.attrs = {"source": self.source, "metadata": dict(self.metadata),
                       "units": {c: UNITS[c] for c in self.columns if c in UNITS}}
        return frame

    def to_csv(self, path: str | os.PathLike[str],
               float_format: str | None = None) -> Path:
        """Write the recording as a CSV file (formats.md section 3), atomically.

        Metadata come first as ``# key: value`` lines (a value with line breaks is
        written as one line per part, which reads back to the same value), then the
        header, then one row per sample. The file is written to a temporary file in the
        same directory and moved into place, so a reader never sees half a file.

        Parameters
        ----------
        path : str or path-like
            Destination; replaced if it exists.
        float_format : str, optional
            ``%``-format for the numbers, e.g. ``"%.10g"``. By default every number is
            written with the shortest text that reads back to exactly the same float.

        Returns
        -------
        pathlib.Path
            The path written.
        """
        path = Path(path)
        lines: list[str] = []
        for key, value in self.metadata.items():
            for part in str(value).split("\n"):
                lines.append(f"# {key}: {part}".rstrip() + "\n")
        lines.append(",".join(self.columns) + "\n")
        cols = [self.data[c].tolist() for c in self.columns]
        if float_format is None:
            rows = (",".join(r) + "\n" for r in zip(*[map(repr, c) for c in cols]))
        else:
            try:
                float_format % 1.0
            except (TypeError, ValueError) as exc:
                raise InputError(f"float_format {float_format!r} is not a %-format for "
                                 f"one number ({exc})", source=str(path)) from None
            fmt = ",".join([float_format] * len(cols)) + "\n"
            rows = (fmt % r for r in zip(*cols))
        _write_atomic(path, lines, rows)
        return path


def load_recording(path: str | os.PathLike[str]) -> Recording:
    """Load a recording from a ``.csv``, ``.txt`` or ``.mat`` file.

    Same as :meth:`Recording.load`.

    Parameters
    ----------
    path : str or path-like
        The file.

    Returns
    -------
    Recording

    Raises
    ------
    InputError
        Naming the file, the line or variable and column, and the problem.
    """
    return Recording.load(path)


# --------------------------------------------------------------------------------------
# Fit metrics
# --------------------------------------------------------------------------------------
def fit(measured: Any, model: Any) -> float:
    """Normalised fit in percent: ``100 * (1 - ||y - y_model|| / ||y - mean(y)||)``.

    The definition of ``formats.md`` section 4. 100 is a perfect match, 0 is no better
    than the mean of the measurement, and it is negative when worse.

    Parameters
    ----------
    measured : array_like
        Measured signal ``y`` (any unit).
    model : array_like
        Model output ``y_model`` in the same unit, same shape.

    Returns
    -------
    float
        The fit, %. ``nan`` when the measurement is constant (``||y - mean(y)|| = 0``),
        because the fit is then undefined.

    Raises
    ------
    InputError
        If the shapes differ, the arrays are empty, or either holds a NaN or inf.

    Examples
    --------
    >>> fit([0.0, 1.0, 2.0], [0.0, 1.0, 2.0])
    100.0
    >>> fit([0.0, 1.0, 2.0], [1.0, 1.0, 1.0])
    0.0
    """
    return _fit(measured, model, source=None, location=None)


def fit_signals(measured: Recording, model: Recording | Mapping[str, Any],
                names: Iterable[str] | None = None) -> dict[str, float]:
    """Fit (:func:`fit`, %) of each signal of a measurement against a model.

    Parameters
    ----------
    measured : Recording
        The measurement.
    model : Recording or mapping of str to array_like
        Model outputs on the same samples. If it is a recording (or has a ``t``
        entry), its time base must match the measurement's to within a thousandth of
        a sample time (s), which allows for rounding in a file but not a shift.
    names : iterable of str, optional
        Signals to compare; each must be in both. By default those of
        :data:`FIT_SIGNALS` (``x``, ``p_a``, ``p_b``) present in both.

    Returns
    -------
    dict of str to float
        Fit per signal, %, in the order of ``names``.

    Raises
    ------
    InputError
        If a named signal is missing, the time bases differ, or a signal pair cannot be
        compared (see :func:`fit`).
    """
    if not isinstance(measured, Recording):
        raise TypeError(f"measured must be a Recording, not {type(measured).__name__}")
    model_data = model.data if isinstance(model, Recording) else model
    src = measured.source
    if "t" in model_data:
        tm = np.asarray(model_data["t"], dtype=float).ravel()
        if tm.shape != measured.t.shape:
            raise InputError(f"the model has {tm.size} samples, the measurement "
                             f"{len(measured)}: simulate on the recorded instants",
                             source=src, location="column 't'")
        # A thousandth of a sample: rounding of t in a file, never a whole-sample shift.
        tol = 1e-3 * measured.sample_time
        gap = np.abs(tm - measured.t)
        if not np.all(gap <= tol):
            i = int(np.argmax(~(gap <= tol)))
            raise InputError(f"the model time base differs from the measurement: "
                             f"t = {float(tm[i])!r} s vs {float(measured.t[i])!r} s "
                             f"at index {i}; "
                             "simulate on the recorded instants", source=src,
                             location="column 't'")
    if names is None:
        selected = [n for n in FIT_SIGNALS if n in measured.data and n in model_data]
    else:
        selected = [names] if isinstance(names, str) else list(names)
        for n in selected:
            if n not in measured.data:
                raise InputError(f"the measurement has no signal '{n}'; its columns "
                                 f"are: {', '.join(measured.columns)}", source=src,
                                 location=f"signal '{n}'")
            if n not in model_data:
                raise InputError(f"the model has no signal '{n}'; it has: "
                                 f"{', '.join(map(str, model_data))}", source=src,
                                 location=f"signal '{n}'")
    return {n: _fit(measured.data[n], model_data[n], source=src,
                    location=f"signal '{n}'") for n in selected}


def _fit(measured: Any, model: Any, source: str | None, location: str | None) -> float:
    where = {"source": source, "location": location}
    prefix = "" if source or location else "fit: "
    try:
        y = np.asarray(measured, dtype=np.float64)
        ym = np.asarray(model, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{prefix}cannot compare non-numeric data ({exc})",
                         **where) from None
    if y.shape != ym.shape:
        raise InputError(f"{prefix}measured and model have different shapes "
                         f"{y.shape} and {ym.shape}", **where)
    if y.size == 0:
        raise InputError(f"{prefix}no samples to compare", **where)
    for label, arr in (("measured", y), ("model", ym)):
        bad = ~np.isfinite(arr)
        if bad.any():
            i = int(np.flatnonzero(bad.ravel())[0])
            raise InputError(f"{prefix}{label} signal has {arr.ravel()[i]} at index {i}; "
                             "the fit needs finite values", **where)
    if np.all(y == y.flat[0]):
        return float("nan")  # ||y - mean(y)|| = 0: the fit is undefined
    den = float(np.linalg.norm(y - y.mean()))
    return float(100.0 * (1.0 - np.linalg.norm(y - ym) / den))


# --------------------------------------------------------------------------------------
# Normalisation and validation, shared by every way in
# --------------------------------------------------------------------------------------
def _normalize(columns: Any, data: Any, metadata: Any, source: str,
               where: _Where) -> tuple[tuple[str, ...], dict[str, np.ndarray],
                                       dict[str, str]]:
    """Columns as a tuple, data as private float64 1-D copies, metadata as str->str."""
    source = str(source)
    columns = tuple(columns)
    for name in columns:
        if not isinstance(name, str) or not name.strip():
            raise InputError(f"column names must be non-empty text, got {name!r}",
                             source=source, location=where.header())
    seen: set[str] = set()
    for name in columns:
        if name in seen:
            raise InputError(f"column '{name}' appears more than once", source=source,
                             location=where.header())
        seen.add(name)
    if not isinstance(data, Mapping):
        raise InputError(f"data must be a mapping of column name to array, got "
                         f"{type(data).__name__}", source=source)
    extra = [k for k in data if k not in seen]
    absent = [c for c in columns if c not in data]
    if extra or absent:
        raise InputError(f"columns {list(columns)} and data keys {list(data)} differ",
                         source=source, location=where.header())
    arrays: dict[str, np.ndarray] = {}
    for name in columns:
        try:
            arr = np.array(data[name], dtype=np.float64)  # always a private copy
        except (TypeError, ValueError) as exc:
            raise InputError(f"values are not numbers ({exc})", source=source,
                             location=where.column(name)) from None
        if arr.ndim == 2 and 1 in arr.shape:
            arr = arr.ravel()
        if arr.ndim != 1:
            raise InputError(f"expected a vector of samples, got an array of shape "
                             f"{arr.shape}", source=source, location=where.column(name))
        arrays[name] = arr
    if metadata is None:
        metadata = {}
    if not isinstance(metadata, Mapping):
        raise InputError(f"metadata must be a mapping, got {type(metadata).__name__}",
                         source=source)
    meta: dict[str, str] = {}
    for key, value in metadata.items():
        if (not isinstance(key, str) or not key or key != key.strip() or ":" in key
                or "\n" in key):
            raise InputError(f"metadata key {key!r} must be non-empty text without "
                             "':', line breaks or surrounding spaces", source=source)
        meta[key] = value if isinstance(value, str) else str(value)
    return columns, arrays, meta


def _validate(columns: tuple[str, ...], data: Mapping[str, np.ndarray],
              metadata: Mapping[str, str], source: str, where: _Where) -> None:
    """Check the contract of formats.md section 3; raise on the first violation."""
    missing = [c for c in REQUIRED_COLUMNS if c not in data]
    if missing:
        listed = ", ".join(f"'{c}'" for c in missing)
        hint = ""
        lower = {c.lower(): c for c in columns}
        near = [f"'{lower[m]}'" for m in missing if m in lower]
        if near:
            hint = f" (names are case-sensitive: found {', '.join(near)})"
        raise InputError(
            f"missing required column{'s' if len(missing) > 1 else ''} {listed}; "
            f"columns found: {', '.join(columns) or '(none)'}; required: "
            f"{', '.join(REQUIRED_COLUMNS)}{hint}", source=source, location=where.header())

    n = data["t"].shape[0]
    for name in columns:
        if data[name].shape[0] != n:
            raise InputError(f"has {data[name].shape[0]} samples but 't' has {n}",
                             source=source, location=where.column(name))
    if n == 0:
        raise InputError("no data rows: the recording has a header but no samples",
                         source=source, location=where.header())
    if n == 1:
        raise InputError("only one sample: a recording needs at least 2", source=source,
                         location=where.header())

    for name in columns:
        bad = ~np.isfinite(data[name])
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"value {float(data[name][i])} is not allowed: every value "
                             f"must be a finite number ({int(bad.sum())} bad in this "
                             "column)",
                             source=source, location=where.cell(name, i))

    t = data["t"]
    steps = np.diff(t)
    if not np.all(steps > 0):
        i = int(np.flatnonzero(~(steps > 0))[0]) + 1
        raise InputError(f"time is not strictly increasing: t = {float(t[i])!r} s at "
                         f"{where.sample(i)} comes after t = {float(t[i - 1])!r} s at "
                         f"{where.sample(i - 1)}", source=source, location=where.cell("t", i))

    low, high = PRESSURE_RANGE
    for name in PRESSURE_COLUMNS:
        if name not in data:
            continue
        y = data[name]
        lo, hi = float(y.min()), float(y.max())
        if lo >= low and hi <= high:
            continue
        bad = (y < low) | (y > high)
        i = int(np.flatnonzero(bad)[0])
        count = int(bad.sum())
        raise InputError(
            f"pressure {y[i]:.6g} is outside the plausible absolute range "
            f"{low:.0e}..{high:.0e} Pa ({count} of {n} samples; the column spans "
            f"{lo:.6g}..{hi:.6g}): {_pressure_hint(lo, hi, count, n)}",
            source=source, location=where.cell(name, i))

    if "sample_time" in metadata:
        text = metadata["sample_time"]
        if "\n" in text:
            raise InputError(f"sample_time is given more than once with different values "
                             f"({', '.join(text.splitlines())})", source=source,
                             location=where.meta("sample_time"))
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"sample_time must be a positive number of seconds, got "
                             f"{text!r}", source=source, location=where.meta("sample_time"))


def _pressure_hint(lo: float, hi: float, count: int, n: int) -> str:
    """Suggest the unit conversion that would bring [lo, hi] into PRESSURE_RANGE."""
    low, high = PRESSURE_RANGE

    def fits(scale: float, offset: float) -> bool:
        return lo * scale + offset >= low and hi * scale + offset <= high

    if hi < 20.0:  # a pneumatic drive runs at up to ~10 bar
        candidates = [("bar", 1e5, 0.0), ("gauge pressure in bar", 1e5, _P_ATM),
                      ("MPa", 1e6, 0.0)]
    elif hi < low:  # every value below the range, but not bar
        candidates = [("kPa", 1e3, 0.0), ("gauge pressure in kPa", 1e3, _P_ATM),
                      ("mbar (hPa)", 1e2, 0.0), ("gauge pressure in mbar", 1e2, _P_ATM),
                      ("psi", 6894.757, 0.0), ("gauge pressure in psi", 6894.757, _P_ATM)]
    elif hi <= high:  # Pa, but some values low
        candidates = [("gauge pressure in Pa", 1.0, _P_ATM)]
    else:
        candidates = []
    found = [(label, scale, offset) for label, scale, offset in candidates
             if fits(scale, offset)][:2]
    if not found:
        if hi > high:
            hint = (f"values above {high:.0e} Pa (50 bar) are beyond any pneumatic "
                    "supply: check the unit and scaling of the sensor (too large by a "
                    "factor of 10 or 1000?)")
        elif hi < 20.0:
            hint = ("the values look like bar: multiply by 1e5 (and add 101325 Pa if "
                    "they are gauge pressures)")
        else:
            hint = "check the unit and the sensor; absolute pressures in Pa are expected"
    else:
        parts = []
        for label, scale, offset in found:
            steps = []
            if scale != 1.0:
                steps.append(f"multiply by {scale:g}")
            if offset:
                steps.append(f"add {offset:g} Pa (atmosphere)")
            parts.append(f"{label}: {' and '.join(steps)} to get absolute Pa")
        hint = "the values look like " + "; or like ".join(parts)
    if 0 < count < 0.01 * n:
        hint += f" (only {count} samples are out of range: a sensor dropout?)"
    return hint


# --------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------
def _check_file(path: Path) -> None:
    if not path.exists():
        raise InputError("file not found", source=str(path))
    if path.is_dir():
        raise InputError("is a directory, expected a recording file", source=str(path))
    if path.stat().st_size == 0:
        raise InputError("the file is empty", source=str(path))


def _strip_comment(raw: str) -> str:
    """Text of a data line without a trailing '#' comment and surrounding space."""
    return raw.split("#", 1)[0].strip()


def _read_csv(path: Path) -> Recording:
    src = str(path)
    _check_file(path)
    try:
        with open(path, encoding="utf-8-sig") as fh:
            metadata, meta_lines, header, header_line = _read_preamble(fh, src)
            columns, sep = _parse_header(header, header_line, src)
            arrays = _fast_parse(fh, len(columns), sep)
        where = _CsvWhere(path, header_line, meta_lines)
        if isinstance(arrays, tuple):
            # pandas pointed at one bad row: check only that line, which raises ...
            kind, k = arrays
            if kind == "row":
                _slow_parse(path, header_line, columns, sep, src, only_row=k)
            else:
                _slow_parse(path, header_line, columns, sep, src,
                            only_line=header_line + k)
            arrays = None  # ... unless pandas and Python disagree: then scan it all
        if arrays is None:
            arrays, where.row_lines = _slow_parse(path, header_line, columns, sep, src)
    except UnicodeDecodeError as exc:
        raise InputError(f"not a UTF-8 text file (undecodable byte at offset {exc.start}); "
                         "a recording CSV is plain text", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", source=src) from None
    data = dict(zip(columns, arrays))
    columns_t, data_n, meta = _normalize(columns, data, metadata, src, where)
    _validate(columns_t, data_n, meta, src, where)
    return Recording(columns_t, data_n, meta, src)


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


def _parse_header(header: str, line: int, src: str) -> tuple[list[str], str | None]:
    """Column names and separator (None: white space) from the header line."""
    for sep in (",", "\t", ";"):
        if sep in header:
            break
    else:
        sep = None
    cells = header.split(sep) if sep else header.split()
    names = [c.strip().strip('"').strip("'").strip() for c in cells]
    location = f"line {line} (header)"
    if all(_is_number(c) for c in names):
        raise InputError(f"the first line that is not a '#' comment holds numbers "
                         f"({header[:60]!r}), not column names; add a header such as "
                         f"'{','.join(KNOWN_COLUMNS[:6])}'", source=src, location=location)
    for k, name in enumerate(names, start=1):
        if not name:
            raise InputError(f"column {k} of the header has no name", source=src,
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


def _fast_parse(fh: Any, ncols: int, sep: str | None
                ) -> list[np.ndarray] | tuple[str, int] | None:
    """Parse the data rows with pandas' C reader.

    Returns the columns as float64 arrays; or ``("row", i)``, the 0-based index of the
    first data row that is not all finite numbers (a NaN/inf, a text or empty cell, too
    few cells); or ``("line", k)`` when pandas stopped at the k-th line after the header
    (too many cells); or None if pandas failed otherwise or found the wrong number of
    columns. The caller checks the suspect row with the slow parser, which reports it.
    """
    import warnings

    import pandas as pd
    from pandas.api import types

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pd.errors.DtypeWarning)  # mixed: text cells
            frame = pd.read_csv(fh, sep=sep if sep else r"\s+", header=None,
                                engine="c", comment="#", skip_blank_lines=True,
                                index_col=False)
    except UnicodeDecodeError:
        raise
    except pd.errors.ParserError as exc:
        match = re.search(r"Expected \d+ fields in line (\d+)", str(exc))
        return ("line", int(match.group(1))) if match else None
    except Exception:  # malformed somewhere: the slow path finds and reports where
        return None
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
    for arr in arrays:
        finite &= np.isfinite(arr)
    if not finite.all():
        return ("row", int(np.argmin(finite)))
    return arrays


def _slow_parse(path: Path, header_line: int, columns: list[str], sep: str | None,
                src: str, only_row: int | None = None, only_line: int | None = None
                ) -> tuple[list[np.ndarray], list[int]]:
    """Parse row by row, raising on the first bad line; also return each row's line.

    With ``only_row`` (0-based data row) or ``only_line`` (1-based file line), skip to
    that row without parsing the others, and check only it.
    """
    ncols = len(columns)
    rows: list[list[float]] = []
    row_lines: list[int] = []
    count = -1
    with open(path, encoding="utf-8-sig") as fh:
        for lineno, raw in enumerate(fh, start=1):
            if lineno <= header_line:
                continue
            text = _strip_comment(raw)
            if not text:
                continue
            count += 1
            if only_row is not None and count != only_row:
                continue
            if only_line is not None and lineno != only_line:
                continue
            cells = text.split(sep) if sep else text.split()
            if len(cells) != ncols:
                raise InputError(f"{len(cells)} cells in this row but the header has "
                                 f"{ncols} ({','.join(columns)})", source=src,
                                 location=f"line {lineno}")
            row = []
            for name, cell in zip(columns, cells):
                cell = cell.strip().strip('"').strip()
                try:
                    value = float(cell)
                except ValueError:
                    what = "an empty cell" if not cell else f"{cell!r}"
                    hint = ""
                    if "," in cell and sep != ",":
                        hint = " (decimal comma? write numbers with a decimal point)"
                    raise InputError(f"{what} is not a number{hint}", source=src,
                                     location=f"line {lineno}, column '{name}'") from None
                if not math.isfinite(value):
                    raise InputError(f"{cell!r} ({value}) is not allowed: every cell must "
                                     "be a finite number", source=src,
                                     location=f"line {lineno}, column '{name}'")
                row.append(value)
            rows.append(row)
            row_lines.append(lineno)
            if only_row is not None or only_line is not None:
                break
    if not rows:
        raise InputError(f"no data rows after the header (line {header_line}): a "
                         "recording needs one row per sample", source=src,
                         location=f"line {header_line}")
    values = np.array(rows, dtype=np.float64)
    return [values[:, k] for k in range(ncols)], row_lines


def _read_mat(path: Path) -> Recording:
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
        raise InputError(f"cannot read as a MATLAB .mat file ({exc})", source=src) from None
    where = _MatWhere()
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
    columns_t, data_n, meta = _normalize(columns, data, metadata, src, where)
    _validate(columns_t, data_n, meta, src, where)
    return Recording(columns_t, data_n, meta, src)


def _mat_kind(value: np.ndarray) -> str:
    kind = {"U": "text", "S": "text", "O": "a cell array", "V": "a struct",
            "b": "logicals", "c": "complex numbers"}.get(value.dtype.kind,
                                                         f"dtype {value.dtype}")
    return f"{kind} of size {'x'.join(map(str, value.shape))}"


def _write_atomic(path: Path, head: list[str], rows: Iterable[str]) -> None:
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
