"""Recordings as rigs write them: column units, column mapping, time windows, plausibility.

A rig's logger rarely writes SI columns named ``t, u, x``. Three ways to say what a
file holds, all converted to SI on loading (formats.md section 3, extended
compatibly: a file without them reads as before):

* a unit in the header cell: ``t [ms], u, x [mm], p_a [bar]`` (also ``x (mm)``);
* a metadata line: ``# units: t=ms, x=mm, p_a=bar_g``;
* a column mapping given by the user (``--columns x=pos_mm:mm,t=time``), which renames
  a logger's column to a workbench column and optionally gives its unit.

:func:`check_plausible` then refuses what is not a servodrive recording in SI: a
sample step of seconds (time in ms?), a gap in ``t`` (the recording is not one run,
and replaying it would allocate memory for the whole gap), a ``sample_time`` header
that contradicts the time column, a command of hundreds of volts (mV?), a position of
metres beyond any cylinder (mm?). With the plant's parameters it also checks the
position against the stroke and the command against the valve's command range.
Every refusal is an :class:`~workbench.errors.InputError` naming the file, the line
and column, and the likely conversion.
"""

from __future__ import annotations

import re
import math
from typing import Any, Mapping

import numpy as np

from .errors import InputError
from .recording_io import Where

__all__ = ["QUANTITY", "UNIT_SCALES", "JITTER_TOLERANCE", "GAP_FACTOR", "MAX_SAMPLE_STEP",
           "MAX_COMMAND", "MAX_POSITION", "STROKE_MARGIN", "COMMAND_MARGIN",
           "parse_column_map", "apply_units", "check_plausible", "check_against_plant",
           "time_window", "time_hint", "unit_suspects", "also_suspect", "used_column"]

_P_ATM = 101325.0  # Pa, offset of gauge pressures

#: Physical quantity of each known column.
QUANTITY: dict[str, str] = {"t": "time", "u": "voltage", "x": "length", "r": "length",
                            "p_a": "pressure", "p_b": "pressure", "p_s": "pressure",
                            "v": "velocity"}
#: Unit name -> (scale, offset) to SI, per quantity: si = value * scale + offset.
UNIT_SCALES: dict[str, dict[str, tuple[float, float]]] = {
    "time": {"s": (1.0, 0.0), "ms": (1e-3, 0.0), "us": (1e-6, 0.0), "min": (60.0, 0.0)},
    "length": {"m": (1.0, 0.0), "mm": (1e-3, 0.0), "cm": (1e-2, 0.0), "um": (1e-6, 0.0)},
    "voltage": {"V": (1.0, 0.0), "mV": (1e-3, 0.0)},
    "pressure": {"Pa": (1.0, 0.0), "kPa": (1e3, 0.0), "MPa": (1e6, 0.0), "bar": (1e5, 0.0),
                 "mbar": (1e2, 0.0), "psi": (6894.757, 0.0), "Pa_g": (1.0, _P_ATM),
                 "kPa_g": (1e3, _P_ATM), "bar_g": (1e5, _P_ATM), "psi_g": (6894.757, _P_ATM)},
    "velocity": {"m/s": (1.0, 0.0), "mm/s": (1e-3, 0.0)},
}

#: Sample steps may differ from the median step by this fraction (logger jitter) before
#: a ``sample_time`` header is said to contradict the time column.
JITTER_TOLERANCE = 0.05
#: A step longer than this many median steps is a gap: the file is not one continuous run.
GAP_FACTOR = 10.0
#: Longest plausible median sample step, s: a servodrive's time constants are 10-100 ms,
#: and no rig samples its position loop slower than 10 Hz.
MAX_SAMPLE_STEP = 0.1
#: Largest plausible |u|, V: valve commands are 0-10 V or +-10 V (24 V at the most).
MAX_COMMAND = 100.0
#: Largest plausible |x|, m: the longest pneumatic cylinders have strokes of a few metres.
MAX_POSITION = 20.0
#: Position may leave [0, stroke] by this fraction of the stroke (sensor offset, end-stop
#: compliance) before it is refused; a unit slip (mm for m) is a factor of 1000.
STROKE_MARGIN = 0.05
#: Command may leave [command_min, command_max] by this fraction of the range (DAC
#: offset, noise on a recorded analogue command).
COMMAND_MARGIN = 0.05

_HEADER_UNIT = re.compile(r"^\s*([^\[\(]+?)\s*[\[\(]\s*([^\]\)]+?)\s*[\]\)]\s*$")
#: "x/mm": quantity over unit (ISO 80000-1), as axis labels and many loggers write it.
_HEADER_SLASH = re.compile(r"^\s*([A-Za-z_]+)\s*/\s*([A-Za-z_]+)\s*$")


def used_column(raw: str, column_map: Mapping[str, tuple[str, str | None]] | None = None,
                units_text: str | None = None) -> bool:
    """Whether the file column ``raw`` is read as a workbench signal: a known column
    (``x``), one with a unit in its header (``x [mm]``), the source of a ``--columns``
    item, or a name in the file's ``# units:`` line. Any other column is only carried
    along (and may be left out when it does not hold numbers)."""
    if raw in QUANTITY:
        return True
    match = _HEADER_UNIT.match(raw) or _HEADER_SLASH.match(raw)
    if match and match.group(1) in QUANTITY:
        return True
    if column_map and any(raw == col for col, _ in column_map.values()):
        return True
    return bool(units_text) and raw in re.split(r"[,;=\s]+", units_text)


def _convert_one(name: str, unit: str, source: str, location: str | None
                 ) -> tuple[float, float]:
    quantity = QUANTITY.get(name)
    if quantity is None:
        raise InputError(f"a unit ({unit!r}) is given for column '{name}', which has no "
                         f"defined quantity; units apply to {', '.join(QUANTITY)}",
                         source=source, location=location)
    table = UNIT_SCALES[quantity]
    if unit not in table:
        raise InputError(f"unknown {quantity} unit {unit!r} for column '{name}'; known: "
                         f"{', '.join(table)}", source=source, location=location)
    return table[unit]


def parse_column_map(spec: str | Mapping[str, Any] | None, source: str = "--columns"
                     ) -> dict[str, tuple[str, str | None]]:
    """Parse a column mapping: ``"x=pos_mm:mm,t=time_ms:ms,u=cmd"``.

    Parameters
    ----------
    spec : str or mapping or None
        ``TARGET=SOURCE[:UNIT]`` items separated by commas, or a mapping of target to
        ``SOURCE`` or ``(SOURCE, UNIT)``. TARGET is a workbench column (``t``, ``u``,
        ``x``, ``p_a``, ...), SOURCE a column of the file, UNIT one of
        :data:`UNIT_SCALES` for the target's quantity (SI when omitted).

    Returns
    -------
    dict of str to (str, str or None)
        Target -> (file column, unit).

    Raises
    ------
    InputError
        Naming ``source`` and the malformed item.
    """
    if spec is None:
        return {}
    items: list[tuple[str, str, str | None]] = []
    if isinstance(spec, Mapping):
        for target, value in spec.items():
            col, unit = (value, None) if isinstance(value, str) else tuple(value)
            items.append((str(target), str(col), None if unit is None else str(unit)))
    else:
        for part in str(spec).split(","):
            if not part.strip():
                continue
            target, eq, rest = part.partition("=")
            col, _, unit = rest.partition(":")
            if not eq or not target.strip() or not col.strip():
                raise InputError(f"{part.strip()!r} is not TARGET=COLUMN[:UNIT] (e.g. "
                                 "x=pos_mm:mm)", source=source)
            items.append((target.strip(), col.strip(), unit.strip() or None))
    out: dict[str, tuple[str, str | None]] = {}
    for target, col, unit in items:
        if target not in QUANTITY:
            raise InputError(f"'{target}' is not a workbench column; map onto one of "
                             f"{', '.join(QUANTITY)}", source=source)
        if target in out:
            raise InputError(f"column '{target}' is mapped twice", source=source)
        if unit is not None:
            _convert_one(target, unit, source, None)
        out[target] = (col, unit)
    return out


def _metadata_units(metadata: Mapping[str, str], source: str, where: Where
                    ) -> dict[str, str]:
    text = metadata.get("units")
    if text is None:
        return {}
    out: dict[str, str] = {}
    for part in re.split(r"[,;\s]+", text.strip()):
        if not part:
            continue
        name, eq, unit = part.partition("=")
        if not eq or not name or not unit:
            raise InputError(f"{part!r} is not COLUMN=UNIT (e.g. 'units: t=ms, x=mm')",
                             source=source, location=where.meta("units"))
        out[name] = unit
    return out


def apply_units(columns: list[str], data: Mapping[str, np.ndarray],
                metadata: Mapping[str, str], source: str, where: Where,
                column_map: Mapping[str, tuple[str, str | None]] | None = None
                ) -> tuple[list[str], dict[str, np.ndarray], dict[str, str]]:
    """Rename and convert a reader's raw columns to the workbench's SI columns.

    Units come from header cells (``x [mm]``), from a ``# units:`` metadata line and
    from ``column_map`` (:func:`parse_column_map`); one column may get its unit from
    one place only. The ``units`` metadata key is replaced by ``converted_to_si``
    (what was converted), so writing the result and reading it back is exact.

    Returns
    -------
    columns, data, metadata
        As the reader gave them, renamed and in SI.

    Raises
    ------
    InputError
        For an unknown unit, a mapped column that does not exist, a target column that
        exists already, or a unit given twice.
    """
    column_map = dict(column_map or {})
    names = list(columns)
    arrays = {c: np.asarray(data[c], dtype=np.float64) for c in columns}
    units: dict[str, tuple[str, str]] = {}   # column -> (unit, where it was given)
    for k, raw in enumerate(list(names)):
        match = _HEADER_UNIT.match(raw) or _HEADER_SLASH.match(raw)
        if match and match.group(1) in QUANTITY:
            base = match.group(1)
            if base in names:
                raise InputError(f"columns '{raw}' and '{base}' are the same signal",
                                 source=source, location=where.header())
            names[k] = base
            arrays[base] = arrays.pop(raw)
            units[base] = (match.group(2), f"header '{raw}'")
    for target, (col, unit) in column_map.items():
        if col not in names:
            raise InputError(f"--columns maps '{target}' to column '{col}', which the file "
                             f"does not have; its columns are: {', '.join(names)}",
                             source=source, location=where.header())
        if target != col and target in names:
            raise InputError(f"--columns maps '{col}' onto '{target}', but the file has a "
                             f"column '{target}' already; map that one to another name or "
                             "drop the mapping", source=source, location=where.header())
        names[names.index(col)] = target
        arrays[target] = arrays.pop(col)
        if unit is not None:
            if target in units and units[target][0] != unit:
                raise InputError(f"unit of '{target}' given twice: {units[target][0]!r} "
                                 f"({units[target][1]}) and {unit!r} (--columns)",
                                 source=source, location=where.header())
            units[target] = (unit, "--columns")
    for name, unit in _metadata_units(metadata, source, where).items():
        if name not in names:
            raise InputError(f"gives a unit for '{name}', which is not a column ("
                             f"{', '.join(names)})", source=source,
                             location=where.meta("units"))
        if name in units and units[name][0] != unit:
            raise InputError(f"unit of '{name}' given twice: {units[name][0]!r} "
                             f"({units[name][1]}) and {unit!r}", source=source,
                             location=where.meta("units"))
        units[name] = (unit, "units")
    meta = {k: v for k, v in metadata.items() if k != "units"}
    done = []
    for name, (unit, origin) in units.items():
        scale, offset = _convert_one(name, unit, source, where.column(name))
        if (scale, offset) != (1.0, 0.0):
            arrays[name] = arrays[name] * scale + offset
        done.append(f"{name} from {unit}")
    if done:
        meta["converted_to_si"] = ", ".join(done)
    return names, {c: arrays[c] for c in names}, meta


def check_plausible(data: Mapping[str, np.ndarray], metadata: Mapping[str, str],
                    source: str, where: Where) -> None:
    """Refuse what is not a servodrive recording in SI units (plant-free checks).

    See the module docstring and the constants :data:`MAX_SAMPLE_STEP`,
    :data:`GAP_FACTOR`, :data:`JITTER_TOLERANCE`, :data:`MAX_COMMAND`,
    :data:`MAX_POSITION`.

    Raises
    ------
    InputError
        Naming the file, the line or column, and the likely cause.
    """
    t = data["t"]
    steps = np.diff(t)
    step = float(np.median(steps))
    convert = _declare("t", "ms")
    if step > MAX_SAMPLE_STEP:
        raise InputError(f"the median sample step is {step:.6g} s (duration "
                         f"{float(t[-1] - t[0]):.6g} s); a servodrive recording samples at "
                         f"10 Hz or faster (step <= {MAX_SAMPLE_STEP:g} s): is the time in "
                         f"ms? {convert}", source=source, location=where.column("t"))
    big = steps > GAP_FACTOR * step
    if big.any():
        i = int(np.flatnonzero(big)[0])
        raise InputError(
            f"a gap of {float(steps[i]):.6g} s ({float(steps[i]) / step:.3g} sample steps "
            f"of {step:.6g} s) between t = {float(t[i])!r} s and t = {float(t[i + 1])!r} s; "
            f"steps up to {GAP_FACTOR:g} times the median (jitter, dropped samples) are "
            "accepted, a longer gap means the file is not one continuous run: split it at "
            "the gap (workbench diagnose takes the pieces together, as several recordings "
            "of one rig), or load a time window on one side of the gap", source=source,
            location=where.cell("t", i + 1))
    if "sample_time" in metadata:
        declared = float(metadata["sample_time"])
        if abs(declared / step - 1.0) > JITTER_TOLERANCE:
            raise InputError(
                f"sample_time {declared:g} s contradicts the time column, whose median step "
                f"is {step:.6g} s (jitter of {JITTER_TOLERANCE:.0%} is accepted); correct "
                "the header or the time unit (a controller period is not the sample time "
                "of the recording)", source=source, location=where.meta("sample_time"))
    if "u" in data:
        _bound(data["u"], MAX_COMMAND, "u", "V", "valve commands are a few volts: mV? "
               + _declare("u", "mV"), source, where)
    for name in ("x", "r"):
        if name in data:
            _bound(data[name], MAX_POSITION, name, "m", "mm? " + _declare(name, "mm"),
                   source, where)


def unit_suspects(data: Mapping[str, np.ndarray], p_range: tuple[float, float]
                  ) -> dict[str, str]:
    """Columns whose values look like another unit, by the plant-free bounds of
    :func:`check_plausible` (time step, |u|, |x|, |r|) and the absolute pressure range
    ``p_range`` (Pa): column -> the unit they look like. A logger that writes one column
    in rig units usually writes the others so too; one error names them all
    (:func:`also_suspect`)."""
    out: dict[str, str] = {}

    def finite(y):
        y = np.asarray(y, dtype=float)
        return y[np.isfinite(y)]
    t = finite(data["t"]) if "t" in data else np.empty(0)
    if t.size > 1 and float(np.median(np.diff(t))) > MAX_SAMPLE_STEP:
        out["t"] = "ms"
    u = finite(data["u"]) if "u" in data else np.empty(0)
    if u.size and float(np.max(np.abs(u))) > MAX_COMMAND:
        out["u"] = "mV"
    for name in ("x", "r"):
        y = finite(data[name]) if name in data else np.empty(0)
        if y.size and float(np.max(np.abs(y))) > MAX_POSITION:
            out[name] = "mm"
    for name in ("p_a", "p_b", "p_s"):
        y = finite(data[name]) if name in data else np.empty(0)
        if y.size and float(np.max(y)) < 20.0:        # a pneumatic drive runs at <= ~10 bar
            out[name] = "bar_g"
        elif y.size and float(np.max(y)) < p_range[0]:
            out[name] = "kPa_g"
    return out


def also_suspect(exc: InputError, data: Mapping[str, np.ndarray],
                 p_range: tuple[float, float]) -> InputError:
    """``exc`` (a check of one column's unit) with every other column that looks like
    another unit named too, and the one units line that declares them all; ``exc``
    itself when no other column does."""
    sus = unit_suspects(data, p_range)
    others = {k: v for k, v in sus.items() if f"'{k}'" not in str(exc.location or "")}
    if not others or not sus:
        return exc
    prefix = f"{exc.source}, {exc.location}: " if exc.source and exc.location else \
        f"{exc.source}: " if exc.source else ""
    text = str(exc)[len(prefix):] if str(exc).startswith(prefix) else str(exc)
    line = ", ".join(f"{k}={v}" for k, v in sus.items())
    listed = ", ".join(f"'{k}' ({v}?)" for k, v in others.items())
    return InputError(f"{text}. Other columns look like rig units too: {listed}; if so, "
                      f"declare them all in one line: '# units: {line}' (bar_g: gauge bar; "
                      "check each guess against the logger's manual)",
                      source=exc.source, location=exc.location)


def _declare(name: str, unit: str) -> str:
    """How to say that column ``name`` is in ``unit``."""
    return (f"declare it: '# units: {name}={unit}' in the file, or --columns "
            f"{name}={name}:{unit}")


def _bound(y: np.ndarray, limit: float, name: str, unit: str, hint: str, source: str,
           where: Where) -> None:
    bad = np.abs(y) > limit
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"{float(y[i]):.6g} {unit} is implausible (|{name}| <= {limit:g} "
                         f"{unit}); {hint}", source=source, location=where.cell(name, i))


def check_against_plant(data: Mapping[str, np.ndarray], params: Any, source: str,
                        where: Where) -> None:
    """Position within the stroke and command within the valve's range.

    Parameters
    ----------
    data : mapping of str to array
        The recording's columns (SI).
    params : PlantParams
        The plant the recording is used with.

    Raises
    ------
    InputError
        Naming the first sample outside the range (by :data:`STROKE_MARGIN` and
        :data:`COMMAND_MARGIN`), the range, and a unit hint when a factor of 1000
        would bring the column into range.
    """
    stroke = float(params["cylinder.stroke"])
    lo_u, hi_u = float(params["valve.command_min"]), float(params["valve.command_max"])
    checks = [(n, -STROKE_MARGIN * stroke, (1 + STROKE_MARGIN) * stroke, "m",
               f"the stroke [0, {stroke:g}] m", "mm") for n in ("x", "r")]
    span = hi_u - lo_u
    checks.append(("u", lo_u - COMMAND_MARGIN * span, hi_u + COMMAND_MARGIN * span, "V",
                   f"the valve's command range [{lo_u:g}, {hi_u:g}] V", "mV"))
    for name, low, high, unit, what, small in checks:
        if name not in data:
            continue
        y = data[name]
        bad = (y < low) | (y > high)
        if not bad.any():
            continue
        i = int(np.flatnonzero(bad)[0])
        lo, hi = float(y.min()), float(y.max())
        hint = ""                # a factor-1000 slip: the values fit when divided by 1000
        reach = max(abs(low), abs(high))     # and lie far beyond the range (x = 0.6 m on
        if (low <= lo * 1e-3 and hi * 1e-3 <= high     # a 0.5 m stroke is no mm slip)
                and max(abs(lo), abs(hi)) > 10.0 * reach):
            hint = f"; in {small}? {_declare(name, small)}"
        raise InputError(f"{float(y[i]):.6g} {unit} is outside {what} (the column spans "
                         f"{lo:.6g}..{hi:.6g} {unit}, {int(bad.sum())} of {y.size} samples "
                         f"outside){hint}", source=source, location=where.cell(name, i))


class _Shifted(Where):
    """Locations of a window: sample k of the window is sample k + offset of the file."""

    def __init__(self, inner: Where, offset: int) -> None:
        self.inner, self.offset = inner, offset

    def header(self) -> str | None:
        return self.inner.header()

    def column(self, name: str) -> str:
        return self.inner.column(name)

    def sample(self, index: int) -> str:
        return self.inner.sample(index + self.offset)

    def cell(self, name: str, index: int) -> str:
        return self.inner.cell(name, index + self.offset)

    def meta(self, key: str) -> str:
        return self.inner.meta(key)


def time_window(data: dict[str, np.ndarray], window: Any, source: str, where: Where
            ) -> tuple[dict[str, np.ndarray], Where]:
    """Samples with t0 <= t <= t1 (s; None is open), and locations that still name the
    file's lines.

    Raises
    ------
    InputError
        For a malformed or empty window, or one holding fewer than 2 samples.
    """
    try:
        t0, t1 = window
        lo = -math.inf if t0 is None else float(t0)
        hi = math.inf if t1 is None else float(t1)
    except (TypeError, ValueError):
        raise InputError(f"time window {window!r} is not (t0, t1) in s",
                         source=source) from None
    if math.isnan(lo) or math.isnan(hi) or lo >= hi:
        raise InputError(f"time window [{lo:g}, {hi:g}] s is empty: t0 < t1 is needed",
                         source=source)
    t = data["t"]
    keep = np.flatnonzero((t >= lo) & (t <= hi))
    if keep.size < 2:
        raise InputError(f"time window [{lo:g}, {hi:g}] s holds {keep.size} sample(s); the "
                         f"recording spans {float(t[0]):.6g}..{float(t[-1]):.6g} s",
                         source=source, location=where.column("t"))
    first, last = int(keep[0]), int(keep[-1]) + 1
    return {k: v[first:last] for k, v in data.items()}, _Shifted(where, first)


def time_hint(steps: np.ndarray) -> str:
    """Why a time column is not increasing, when its steps say it: stamps written with
    too few digits repeat (many zero steps), a logger that restarts its clock for each
    run steps back far (several experiments in one file)."""
    zero, back = int(np.sum(steps == 0)), steps < 0
    if zero > max(2, 0.01 * len(steps)):
        pos = steps[steps > 0]
        res = f" (resolution {float(np.min(pos)):.3g} s)" if len(pos) else ""
        return (f"; {zero} of {len(steps)} steps repeat a time stamp: the time is written "
                f"with too few digits{res}: write more digits")
    if back.any():
        k = int(np.argmax(back))
        typical = float(np.median(steps[steps > 0])) if (steps > 0).any() else 0.0
        if -steps[k] > 100 * typical > 0:
            return (f"; the time steps back by {-float(steps[k]):.4g} s: several runs in "
                    "one file? give each run as its own file (workbench diagnose takes "
                    "several recordings of the same rig)")
    return ""
