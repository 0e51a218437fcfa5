"""Recordings of a servodrive run: load, validate and write them (fit: :mod:`workbench.signals`).

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
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from .errors import InputError
from .recording_io import KNOWN_COLUMNS, REQUIRED_COLUMNS, Where, read_csv, read_mat, write_atomic
from .recording_units import (also_suspect, apply_units, check_against_plant, check_plausible,
                              parse_column_map, time_hint, time_window, used_column)
from .signals import FIT_SIGNALS, fit, fit_signals

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

# KNOWN_COLUMNS (names with a meaning) and REQUIRED_COLUMNS come from recording_io.
#: SI unit of each known column.
UNITS: Mapping[str, str] = MappingProxyType({
    "t": "s", "u": "V", "x": "m", "p_a": "Pa", "p_b": "Pa", "r": "m", "p_s": "Pa",
    "v": "m/s",
})
#: Columns holding absolute pressures, checked against :data:`PRESSURE_RANGE`.
PRESSURE_COLUMNS: tuple[str, ...] = ("p_a", "p_b", "p_s")
#: Plausible absolute pressures in a pneumatic servodrive, Pa (formats.md section 3).
PRESSURE_RANGE: tuple[float, float] = (2.0e4, 5.0e6)

_P_ATM = 101325.0  # Pa, standard atmosphere, offset of gauge pressures
_SUFFIXES = {".csv": "csv", ".txt": "csv", ".mat": "mat"}


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
    required : tuple of str
        Columns that must be present: ``("t", "u", "x")`` unless a consumer needs
        others (``identify arx --input p_a`` needs ``t``, ``p_a`` and its output).

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
    required: tuple[str, ...] = field(default=REQUIRED_COLUMNS, repr=False, compare=False)

    def __post_init__(self) -> None:
        columns, data, metadata = _normalize(self.columns, self.data, self.metadata,
                                             self.source, Where())
        object.__setattr__(self, "required", _required(self.required))
        _validate(columns, data, metadata, self.source, Where(), self.required)
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
    def load(cls, path: str | os.PathLike[str], **options: Any) -> "Recording":
        """Load a recording, choosing the reader from the suffix.

        Parameters
        ----------
        path : str or path-like
            A ``.csv`` or ``.txt`` file (:meth:`from_csv`) or a ``.mat`` file
            (:meth:`from_mat`).
        **options
            ``columns``, ``window``, ``required``, ``plant``, ``plausible``: see
            :func:`load_recording`.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            For an unknown suffix and for everything the readers reject.

        Examples
        --------
        >>> rec = Recording.load("tests/data/recordings/step_small.csv")
        >>> rec.columns, len(rec), rec.sample_time
        (('t', 'u', 'x', 'p_a', 'p_b', 'r'), 50, 0.01)
        """
        path = Path(path)
        kind = _SUFFIXES.get(path.suffix.lower())
        if kind is None:
            raise InputError(
                f"unknown recording file type '{path.suffix or '(no suffix)'}': expected "
                "a .csv or .txt file (comma separated) or a MATLAB .mat file",
                source=str(path))
        return cls.from_csv(path, **options) if kind == "csv" else cls.from_mat(path, **options)

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str], **options: Any) -> "Recording":
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
        **options
            As for :func:`load_recording`.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            Naming the file, the 1-based line (counting metadata and header lines) and
            column, and the problem.
        """
        column_map = parse_column_map(options.get("columns"))
        return _checked(*read_csv(Path(path), lambda name, meta: used_column(
            name, column_map, meta.get("units"))), **options)

    @classmethod
    def from_mat(cls, path: str | os.PathLike[str], **options: Any) -> "Recording":
        """Read a MATLAB ``.mat`` recording (v4 to v7; not v7.3).

        Variables named as the columns (``t``, ``u``, ``x``, ...) are vectors of one
        length (row or column). An optional numeric scalar ``sample_time`` (s) and other
        scalar or text variables go into :attr:`metadata`; other numeric vectors of the
        same length are kept as extra columns; anything else is ignored.

        Parameters
        ----------
        path : str or path-like
            The ``.mat`` file.
        **options
            As for :func:`load_recording`.

        Returns
        -------
        Recording

        Raises
        ------
        InputError
            Naming the file, the variable (and 1-based element) and the problem, also
            for MATLAB v7.3 (HDF5) files, which must be saved again with ``-v7``.
        """
        return _checked(*read_mat(Path(path)), **options)

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

    def check(self, plant: Any = None) -> "Recording":
        """Check plausibility (as the file loaders do) and, given a plant, the stroke and
        the valve's command range; return the recording itself.

        For recordings built in memory (:meth:`from_arrays`), which are checked only
        against the contract, before they are replayed on a plant.

        Parameters
        ----------
        plant : Plant or PlantParams, optional

        Raises
        ------
        InputError
            See :func:`workbench.recording_units.check_plausible` and
            :func:`workbench.recording_units.check_against_plant`.
        """
        check_plausible(self.data, self.metadata, self.source, Where())
        if plant is not None:
            check_against_plant(self.data, getattr(plant, "params", plant), self.source,
                                Where())
        return self

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
        return Recording(columns, data, self.metadata, self.source, self.required)

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
        write_atomic(path, lines, rows)
        return path


def load_recording(path: str | os.PathLike[str], *, columns: Any = None,
                   window: tuple[float | None, float | None] | None = None,
                   required: tuple[str, ...] | None = None, plant: Any = None,
                   plausible: bool = True) -> Recording:
    """Load a recording from a ``.csv``, ``.txt`` or ``.mat`` file.

    Same as :meth:`Recording.load`. Units are converted to SI where the file or
    ``columns`` says so (:mod:`workbench.recording_units`), and the result is checked
    for plausibility: a file in the wrong units is refused with a hint, never read as
    a different run.

    Parameters
    ----------
    path : str or path-like
        The file.
    columns : str or mapping, optional
        Column mapping ``"x=pos_mm:mm,t=time_ms:ms"`` (target = file column, optional
        unit), see :func:`workbench.recording_units.parse_column_map`.
    window : (float or None, float or None), optional
        Keep only the samples with ``t0 <= t <= t1`` (s, after unit conversion; None
        is open). Plausibility is checked on the window, so a window can leave out a
        gap or a bad start.
    required : tuple of str, optional
        Columns that must be present (default ``t``, ``u``, ``x``); ``t`` always is.
    plant : Plant or PlantParams, optional
        Also check the position against the stroke and the command against the valve's
        range (:func:`workbench.recording_units.check_against_plant`).
    plausible : bool, optional
        Check sample step, gaps, ``sample_time`` and unit plausibility (default True).

    Returns
    -------
    Recording

    Raises
    ------
    InputError
        Naming the file, the line or variable and column, and the problem.
    """
    return Recording.load(path, columns=columns, window=window, required=required,
                          plant=plant, plausible=plausible)


# --------------------------------------------------------------------------------------
# Normalisation and validation, shared by every way in
# --------------------------------------------------------------------------------------
def _checked(raw_columns: Any, data: Any, metadata: Any, source: str, where: Where, *,
             columns: Any = None, window: Any = None, required: Any = None,
             plant: Any = None, plausible: bool = True) -> Recording:
    """A recording from a reader's raw result, checked with the file's locations."""
    need = _required(required)
    names, data, metadata = apply_units(list(raw_columns), data, metadata, source, where,
                                        parse_column_map(columns))
    columns_t, data_n, meta = _normalize(names, data, metadata, source, where)
    try:
        _validate(columns_t, data_n, meta, source, where, need)
        if window is not None:
            data_n, where = time_window(data_n, window, source, where)
        if plausible:
            check_plausible(data_n, meta, source, where)
    except InputError as exc:
        raise also_suspect(exc, data_n, PRESSURE_RANGE) from None
    if plant is not None:
        check_against_plant(data_n, getattr(plant, "params", plant), source, where)
    return Recording(columns_t, data_n, meta, source, need)


def _required(required: Any) -> tuple[str, ...]:
    """Required columns as a tuple that starts with 't'."""
    if required is None:
        return REQUIRED_COLUMNS
    names = (required,) if isinstance(required, str) else tuple(required)
    return ("t",) + tuple(n for n in dict.fromkeys(names) if n != "t")


def _normalize(columns: Any, data: Any, metadata: Any, source: str,
               where: Where) -> tuple[tuple[str, ...], dict[str, np.ndarray],
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
              metadata: Mapping[str, str], source: str, where: Where,
              required: tuple[str, ...] = REQUIRED_COLUMNS) -> None:
    """Check the contract of formats.md section 3; raise on the first violation."""
    missing = [c for c in required if c not in data]
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
            f"{', '.join(required)}{hint}{_map_hint(missing)}", source=source,
            location=where.header())

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
                         f"{where.sample(i - 1)}{time_hint(steps)}", source=source,
                         location=where.cell("t", i))

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


def _map_hint(missing: list[str]) -> str:
    """How to name a logger's columns."""
    example = ",".join(f"{m}=COLUMN" for m in missing[:2])
    return (f" (a logger's own column names map with --columns {example}, with an "
            "optional unit: x=pos_mm:mm)")


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
