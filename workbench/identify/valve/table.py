"""The valve table: measured q_m(p, u) as a CSV file with ``# key: value`` metadata."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable, Mapping

import numpy as np

from ...errors import InputError
from ...physics import gas

__all__ = ["COLUMNS", "MIN_POINTS", "G_PER_KG", "ValveTable", "load_valve_table"]

#: Columns of a valve table and their SI units.
COLUMNS: Mapping[str, str] = MappingProxyType({"u": "V", "p": "Pa", "q_m": "kg/s"})
#: Fewest points a table may have (and at least 2 distinct commands and pressures).
MIN_POINTS = 6
#: Grams per kilogram: paper 003 states flow errors in g/s.
G_PER_KG = 1e3
#: Metadata keys read as numbers (SI): name -> (unit, meaning).
_NUMERIC_META = {
    "supply_pressure": ("Pa", "supply pressure of the characterisation, absolute"),
    "atmospheric_pressure": ("Pa", "exhaust (atmospheric) pressure, absolute"),
    "temperature": ("K", "supply air temperature"),
    "command_center": ("V", "command that centres the spool"),
    "command_span": ("V", "|u - centre| that opens an edge fully"),
}


@dataclass(frozen=True, eq=False)
class ValveTable:
    """Measured valve characteristic q_m(p, u), validated and immutable.

    Parameters
    ----------
    u : array_like, shape (n,)
        Commands, V.
    p : array_like, shape (n,)
        Port pressures, Pa absolute (> 0).
    q_m : array_like, shape (n,)
        Mass flows into the port through the valve, kg/s.
    metadata : mapping of str to str
        ``# key: value`` header lines. Read as numbers when present:
        ``supply_pressure``, ``atmospheric_pressure`` (Pa), ``temperature`` (K),
        ``command_center``, ``command_span`` (V).
    source : str
        Where the table came from, for messages.

    Raises
    ------
    InputError
        Arrays of different lengths, NaN or inf, a pressure <= 0, fewer than
        :data:`MIN_POINTS` points or fewer than 2 distinct commands or pressures,
        a bad numeric metadata value. (:func:`load_valve_table` reports the file line.)
    """

    u: np.ndarray
    p: np.ndarray
    q_m: np.ndarray
    metadata: Mapping[str, str] = field(default_factory=dict)
    source: str = "<memory>"

    def __post_init__(self) -> None:
        arrays = {}
        for name in COLUMNS:
            a = np.array(getattr(self, name), dtype=float).ravel()
            a.flags.writeable = False
            arrays[name] = a
        n = {len(a) for a in arrays.values()}
        if len(n) != 1:
            raise InputError("columns u, p, q_m have different lengths "
                             + ", ".join(f"{k}: {len(v)}" for k, v in arrays.items()),
                             source=self.source)
        for name, a in arrays.items():
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise InputError(f"column '{name}' has a NaN or infinite value at index "
                                 f"{bad[0]}", source=self.source)
        _check_values(arrays["u"], arrays["p"], self.source, lambda i: f"index {i}")
        meta = {str(k): str(v) for k, v in dict(self.metadata).items()}
        for key in _NUMERIC_META:
            if key in meta:
                _meta_number(key, meta[key], self.source, f"metadata '{key}'")
        for name, a in arrays.items():
            object.__setattr__(self, name, a)
        object.__setattr__(self, "metadata", MappingProxyType(meta))

    # ---------------------------------------------------------------- access
    def __len__(self) -> int:
        return int(self.u.shape[0])

    def _meta(self, key: str, default: float) -> float:
        if key in self.metadata:
            return _meta_number(key, self.metadata[key], self.source, f"metadata '{key}'")
        return float(default)

    @property
    def supply_pressure(self) -> float:
        """Supply pressure, Pa: metadata ``supply_pressure``, else the highest table pressure."""
        return self._meta("supply_pressure", float(np.max(self.p)))

    @property
    def atmospheric_pressure(self) -> float:
        """Exhaust pressure, Pa: metadata ``atmospheric_pressure``, else 101325 Pa."""
        return self._meta("atmospheric_pressure", gas.P_ATM)

    @property
    def temperature(self) -> float:
        """Supply air temperature, K: metadata ``temperature``, else 293.15 K."""
        return self._meta("temperature", gas.T_REF)

    @property
    def command_center(self) -> float:
        """Command of the centred spool, V: metadata, else the middle of the table's commands."""
        return self._meta("command_center", 0.5 * (np.min(self.u) + np.max(self.u)))

    @property
    def command_span(self) -> float:
        """Half-range of the command, V: metadata, else half the table's command range."""
        return self._meta("command_span", 0.5 * (np.max(self.u) - np.min(self.u)))

    @property
    def pressure_range(self) -> tuple[float, float]:
        """(lowest, highest) table pressure, Pa."""
        return float(np.min(self.p)), float(np.max(self.p))

    @property
    def command_range(self) -> tuple[float, float]:
        """(lowest, highest) table command, V."""
        return float(np.min(self.u)), float(np.max(self.u))

    def columns(self) -> list[tuple[float, np.ndarray, np.ndarray]]:
        """Per distinct command: (u, pressures sorted, flows), repeated pressures averaged."""
        out = []
        for uu in np.unique(self.u):
            sel = self.u == uu
            ps, inv = np.unique(self.p[sel], return_inverse=True)
            qs = np.bincount(inv, weights=self.q_m[sel]) / np.bincount(inv)
            out.append((float(uu), ps, qs))
        return out

    @classmethod
    def from_arrays(cls, u, p, q_m, metadata: Mapping[str, Any] | None = None,
                    source: str = "<memory>") -> "ValveTable":
        """Build a table from arrays (SI); metadata values are stored as text."""
        meta = {k: (repr(float(v)) if isinstance(v, (float, np.floating)) else str(v))
                for k, v in (metadata or {}).items()}
        return cls(u=u, p=p, q_m=q_m, metadata=meta, source=source)

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write the table (metadata lines, header ``u,p,q_m``, rows), atomically.

        Numbers are written with the shortest text that reads back to the same float.
        """
        from ...params import atomic_write_text
        lines = []
        for key, value in self.metadata.items():
            for part in str(value).split("\n"):
                lines.append(f"# {key}: {part}".rstrip())
        lines.append(",".join(COLUMNS))
        lines += [f"{a!r},{b!r},{c!r}" for a, b, c in
                  zip(self.u.tolist(), self.p.tolist(), self.q_m.tolist())]
        atomic_write_text(path, "\n".join(lines) + "\n")
        return Path(path)

    def __repr__(self) -> str:
        lo, hi = self.pressure_range
        return (f"ValveTable(source={self.source!r}, points={len(self)}, "
                f"u {self.command_range[0]:g}..{self.command_range[1]:g} V, "
                f"p {lo:g}..{hi:g} Pa)")


def _meta_number(key: str, text: str, source: str, where: str) -> float:
    unit, doc = _NUMERIC_META[key]
    try:
        val = float(text)
    except ValueError:
        raise InputError(f"expected a number in {unit} ({doc}), got {text!r}",
                         source=source, location=where) from None
    if not (math.isfinite(val) and (val > 0 or key == "command_center")):
        raise InputError(f"expected a {'finite' if key == 'command_center' else 'positive'} "
                         f"number in {unit} ({doc}), got {text!r}", source=source,
                         location=where)
    return val


def _check_values(u: np.ndarray, p: np.ndarray, source: str, where: Callable[[int], str]):
    bad = np.flatnonzero(p <= 0)
    if bad.size:
        i = int(bad[0])
        raise InputError(f"pressure {p[i]:g} Pa is not positive: pressures are absolute, in "
                         "Pa (a gauge value needs + 101325 Pa)", source=source,
                         location=f"{where(i)}, column 'p'")
    if len(u) < MIN_POINTS:
        raise InputError(f"too few points: {len(u)}; a valve table needs at least "
                         f"{MIN_POINTS} (paper 003 used 201)", source=source)
    if len(np.unique(u)) < 2 or len(np.unique(p)) < 2:
        raise InputError(f"too few distinct values: {len(np.unique(u))} commands and "
                         f"{len(np.unique(p))} pressures; a characteristic needs at least "
                         "2 of each", source=source)
    if np.max(p) < 100.0:
        raise InputError(f"largest pressure is {np.max(p):g} Pa: pressures must be in Pa "
                         "absolute (a value in bar needs * 1e5)", source=source,
                         location="column 'p'")


def load_valve_table(path: str | os.PathLike) -> ValveTable:
    """Read and validate a valve table CSV.

    The file has optional ``# key: value`` metadata lines, a header naming the columns
    (``u``, ``p``, ``q_m`` in any order; extra columns are ignored), then one row per
    point. Blank lines and other ``#`` comments are skipped; rows need not be sorted.

    Raises
    ------
    InputError
        Naming the file and the 1-based line (and column): file not found, missing
        column, a cell that is not a number, NaN or inf, a pressure <= 0, a row with
        the wrong number of cells, too few points.
    """
    path = Path(path)
    src = str(path)
    if path.exists() and not path.is_file():  # a directory, FIFO (would block), device
        raise InputError("is not a regular file; a valve table is a CSV text file",
                         source=src)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (undecodable byte at offset {exc.start}); a "
                         "valve table is a CSV text file", source=src) from None
    except FileNotFoundError:
        raise InputError("file not found", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror}", source=src) from None
    meta: dict[str, str] = {}
    meta_line: dict[str, int] = {}
    header: list[str] | None = None
    rows: list[list[float]] = []
    row_lines: list[int] = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            body = line[1:].strip()
            key, sep, value = body.partition(":")
            if header is None and sep and key.strip() and " " not in key.strip():
                meta[key.strip()] = value.strip()
                meta_line[key.strip()] = lineno
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = cells
            missing = [c for c in COLUMNS if c not in header]
            if missing:
                raise InputError(
                    f"missing column{'s' if len(missing) > 1 else ''} "
                    + ", ".join(f"'{c}'" for c in missing)
                    + f"; the header is {line!r}, a valve table needs u (V), p (Pa "
                    "absolute) and q_m (kg/s, into the port)",
                    source=src, location=f"line {lineno} (header)")
            idx = [header.index(c) for c in COLUMNS]
            header_line = lineno
            continue
        if len(cells) != len(header):
            raise InputError(f"expected {len(header)} cells (as the header on line "
                             f"{header_line}), got {len(cells)}", source=src,
                             location=f"line {lineno}")
        vals = []
        for name, i in zip(COLUMNS, idx):
            try:
                v = float(cells[i])
            except ValueError:
                raise InputError(f"expected a number, got {cells[i]!r}", source=src,
                                 location=f"line {lineno}, column '{name}'") from None
            if not math.isfinite(v):
                raise InputError(f"expected a finite number, got {cells[i]!r}", source=src,
                                 location=f"line {lineno}, column '{name}'")
            vals.append(v)
        rows.append(vals)
        row_lines.append(lineno)
    if header is None:
        raise InputError("no header line: expected a line naming the columns u,p,q_m",
                         source=src)
    data = np.array(rows, dtype=float).reshape(-1, 3)
    _check_values(data[:, 0], data[:, 1], src, lambda i: f"line {row_lines[i]}")
    for key in _NUMERIC_META:
        if key in meta:
            _meta_number(key, meta[key], src, f"line {meta_line[key]}, metadata '{key}'")
    return ValveTable(u=data[:, 0], p=data[:, 1], q_m=data[:, 2], metadata=meta, source=src)
