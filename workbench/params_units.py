"""Reading a plant file safely, and catching unit slips in its values.

:func:`read_toml` turns a file into the nested mapping :class:`~workbench.params.
PlantParams` validates: UTF-8 with or without a byte-order mark, a regular file of a
sane size, TOML nested no deeper than a plant file can be. Every failure is an
:class:`~workbench.errors.InputError` naming the file.

:func:`check_units` refuses values that are a unit slip rather than a physical value:
20 K is 20 degrees Celsius, a bore of 25 m is 25 mm, a sonic conductance of 0.7
m^3/(s Pa) is 0.7 l/(s bar). The bounds are far outside every pneumatic servodrive
(the smallest and largest valves, cylinders and lab climates) and far inside the value
the slip produces (a factor of 1000, or an offset of 273 K), so a real plant never
meets them and a slip always does. The message names the key and suggests the
conversion.
"""

from __future__ import annotations

import re
import stat
import tomllib
from pathlib import Path
from typing import Any, Mapping

from .errors import InputError

__all__ = ["MAX_PLANT_FILE_BYTES", "PLAUSIBLE", "read_toml", "check_units", "slip_hint",
           "quoted_number_hint"]

#: Largest plant file read, bytes: a plant file is a few kB of keys (a fitted valve
#: polynomial included); anything this large is not one.
MAX_PLANT_FILE_BYTES = 1_000_000

_KELVIN = 273.15

#: Plausible range (low, high) per key in SI, and the slip each side suggests.
PLAUSIBLE: dict[str, tuple[float, float, str, str]] = {
    # key: (low, high, hint when below, hint when above)
    "gas.temperature": (
        200.0, 500.0, "temperatures are in kelvin: Celsius? {v:g} degC = {k:.2f} K", ""),
    "gas.atmospheric_pressure": (
        3.0e4, 1.5e5, "pressures are in Pa absolute: bar? {v:g} bar = {pa:.6g} Pa",
        "an ambient pressure above 1.5 bar: check the unit (Pa, absolute)"),
    "supply.pressure": (
        0.0, 5.0e6, "", "above 50 bar is beyond any pneumatic supply: check the unit (Pa, "
                        "absolute; bar needs * 1e5)"),
    "valve.sonic_conductance": (
        0.0, 1.0e-5, "", "above 1000 l/(s bar), larger than any servo valve: l/(s bar)? "
                         "{v:g} l/(s bar) = {c:.4g} m^3/(s Pa)"),
    "cylinder.bore": (0.0, 1.0, "", "a bore above 1 m: mm? {v:g} mm = {m:g} m"),
    "cylinder.stroke": (0.0, 20.0, "", "a stroke above 20 m: mm? {v:g} mm = {m:g} m"),
    "cylinder.dead_volume_a": (
        0.0, 0.1, "", "a dead volume above 100 l: cm^3? {v:g} cm^3 = {cc:.4g} m^3"),
    "cylinder.dead_volume_b": (
        0.0, 0.1, "", "a dead volume above 100 l: cm^3? {v:g} cm^3 = {cc:.4g} m^3"),
    "lines.length": (0.0, 100.0, "", "a line longer than 100 m: mm? {v:g} mm = {m:g} m"),
    "lines.diameter": (0.0, 0.1, "", "a line diameter above 100 mm: mm? {v:g} mm = {m:g} m"),
    "controller.sample_time": (
        1.0e-6, 10.0, "faster than 1 MHz, which no servo controller samples at (a 24 s "
                      "run would take {steps:.3g} steps): a typo? s expected",
        "a controller period above 10 s: ms? {v:g} ms = {m:g} s"),
}


#: Keys whose "below" hint is about a tiny positive value (a sample time of 1e-9 s); for
#: zero or a negative value it would be nonsense ("a 24 s run would take inf steps").
#: Temperatures are not here: -20 is a plausible Celsius slip.
_POSITIVE_ONLY = frozenset({"controller.sample_time"})


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a plant file into nested dicts.

    Parameters
    ----------
    path : str or path-like
        The TOML file: UTF-8 (a leading byte-order mark is accepted), a regular file.

    Returns
    -------
    dict
        The parsed TOML.

    Raises
    ------
    InputError
        Naming the file: not found, not a regular file (a directory, FIFO or device),
        larger than :data:`MAX_PLANT_FILE_BYTES`, not UTF-8 (with the line of the bad
        byte), not TOML, or nested deeper than Python can parse.
    """
    path = Path(path)
    src = str(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        raise InputError("file not found", source=src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", source=src) from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError("is a directory, expected a plant file (.toml)", source=src)
    if not stat.S_ISREG(info.st_mode):
        raise InputError("is not a regular file (a FIFO, socket or device?); a plant file "
                         "is a TOML text file", source=src)
    if info.st_size > MAX_PLANT_FILE_BYTES:
        raise InputError(f"is {info.st_size} bytes; a plant file is a few kB of keys "
                         f"(limit {MAX_PLANT_FILE_BYTES} bytes): is this the right file?",
                         source=src)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the file: {exc.strerror or exc}", source=src) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise InputError(f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset "
                         f"{exc.start} cannot be decoded); save the plant file as UTF-8"
                         + _not_a_plant_hint(path, ""),
                         source=src, location=f"line {line}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}{_toml_line(text, str(exc))}"
                         + _not_a_plant_hint(path, text), source=src) from None
    except RecursionError:
        raise InputError("not a plant file: tables or arrays are nested too deeply to "
                         "parse (a plant file has one level of [sections])",
                         source=src) from None
    if not data:
        raise InputError("the file holds no keys (it is empty, or only blank and '#' "
                         "comment lines); a plant file has the sections [gas], [supply], "
                         "[valve], [cylinder] and [load] (formats.md section 1)", source=src)
    return data


#: tomllib's position in its messages: "... (at line 29, column 11)".
_TOML_AT = re.compile(r"\(at line (\d+), column (\d+)\)")
#: Suffixes of the recordings the workbench reads (formats.md section 3).
_RECORDING_SUFFIXES = (".csv", ".txt", ".mat")


def _toml_line(text: str, message: str) -> str:
    """``": 'mass = 1.2.3'"``, the line tomllib's ``message`` points at, or ``""``.

    The message gives line and column; the line itself is what the user looks for
    (a duplicated key, a missing quote or bracket)."""
    match = _TOML_AT.search(message)
    if not match:
        return ""
    lines = text.splitlines()
    k = int(match.group(1))
    if not 1 <= k <= len(lines) or not lines[k - 1].strip():
        return ""
    shown = lines[k - 1].strip()
    shown = shown if len(shown) <= 80 else shown[:77] + "..."
    return f"; the line reads {shown!r}"


def _not_a_plant_hint(path: Path, text: str) -> str:
    """A hint when the file given as the plant is plainly a recording: a recording's
    suffix, or a first line that is a CSV header naming the recording's columns
    (t, u, x: formats.md section 3). Swapped arguments are the usual cause."""
    first = ""
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            first = line.strip()
            break
    cells = {c.strip().strip('"').strip() for c in re.split(r"[,;\t]", first)}
    if path.suffix.lower() not in _RECORDING_SUFFIXES and not {"t", "x"} <= cells:
        return ""
    return ("; this looks like a recording (formats.md section 3), not a plant file: the "
            "plant file (.toml) comes first, e.g. workbench diagnose PLANT.toml "
            "RECORDING.csv --out DIR")


def check_units(values: Mapping[str, Any], source: str) -> None:
    """Refuse values that are unit slips (see :data:`PLAUSIBLE`).

    Parameters
    ----------
    values : mapping of str to value
        Dotted key -> value in SI units, already type- and range-checked.
    source : str
        The file, named in the error.

    Raises
    ------
    InputError
        Naming the key, the value, the plausible range and the likely conversion.
    """
    for path, (low, high, _, _) in PLAUSIBLE.items():
        if path not in values:
            continue
        v = float(values[path])
        if low <= v <= high:
            continue
        section, _, name = path.partition(".")
        text = f"{v:g} is implausible (expected {low:g} to {high:g})"
        raise InputError(text + slip_hint(path, v), source=source,
                         location=f"[{section}] {name}")


def slip_hint(path: str, value: float) -> str:
    """``": <hint>"`` naming the likely unit slip of ``value`` at key ``path``, or ``""``."""
    if path not in PLAUSIBLE:
        return ""
    low, high, below, above = PLAUSIBLE[path]
    v = float(value)
    hint = below if v < low else above if v > high else ""
    if v <= 0.0 and path in _POSITIVE_ONLY:
        return ""           # a sign or a zero, not a tiny value: the range says it all
    if not hint:
        return ""
    fill = {"v": v, "k": v + _KELVIN, "pa": v * 1e5, "c": v * 1e-8, "m": v * 1e-3,
            "cc": v * 1e-6, "steps": 24.0 / v if v > 0 else float("inf")}
    return ": " + hint.format(**fill)


#: A number written as text, with an optional unit: "1.2", "25 mm", "6 bar", "-3e-6 m^3".
_QUOTED = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([^\s\d].*?)?\s*$")
#: Quantity of a plant key's SI unit, for the conversions of recording_units.UNIT_SCALES.
_QUANTITY_OF_UNIT = {"m": "length", "Pa": "pressure", "s": "time", "V": "voltage",
                     "m/s": "velocity"}


def quoted_number_hint(name: str, unit: str, raw: str) -> str:
    """``": <hint>"`` for a number given as text (``mass = "1.2"``, ``bore = "25 mm"``).

    A plant file holds plain SI numbers (formats.md section 1), so the text is never
    converted; the hint shows the line to write instead. A unit the workbench knows for
    the key's quantity (the recording units of :mod:`workbench.recording_units`) is
    converted in the hint; a pressure in a unit without ``_g`` is shown both as
    absolute and as gauge, since datasheets quote supply pressures as gauge.
    """
    match = _QUOTED.match(raw)
    if not match:
        return ""
    number, text_unit = float(match.group(1)), (match.group(2) or "").strip()
    if not text_unit or text_unit == unit:
        return f": write the number without quotes, {name} = {number:g} ({unit or '-'})"
    from .recording_units import UNIT_SCALES
    scales = UNIT_SCALES.get(_QUANTITY_OF_UNIT.get(unit, ""), {})
    if text_unit not in scales:
        return (f": values are plain numbers in SI units ({unit or '-'}), without quotes "
                f"or a unit name")
    scale, offset = scales[text_unit]
    si = number * scale + offset
    hint = f": values are plain numbers in {unit}: {name} = {si:.6g}"
    if unit == "Pa" and offset == 0.0 and f"{text_unit}_g" in scales:
        gauge = number * scales[f"{text_unit}_g"][0] + scales[f"{text_unit}_g"][1]
        hint += f" if {raw.strip()!r} is absolute, {name} = {gauge:.6g} if it is gauge"
    return hint
