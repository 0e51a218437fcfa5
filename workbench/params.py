"""Plant parameters: the TOML contract of ``formats.md`` sections 1 and 2.

Every parameter is declared once, in :data:`SCHEMA`, with its unit, whether it is
required, the range it must lie in and, for optional keys, the *effect* it belongs
to. Loading, validation, saving and the symbolic parameter vector of the plant are
all driven by that table, so a key cannot be known to one and unknown to another.

Examples
--------
>>> from workbench.params import PlantParams
>>> params = PlantParams.from_toml("designs/plants/situm_rodless.toml")
>>> params.effects                 # paper 000's rig as calibrated (designs/paper_000.py)
('dry_friction', 'valve_deadband')

Valve law (extra optional keys; formats.md defines none, so files without them load
unchanged and describe the four-edge ISO 6358 valve)::

    [valve]
    law = "input_affine"          # or "iso6358" (the default)
    underlap_law = "linear"       # or "rounded" (iso6358 law only), see physics.valve
    affine_phi = [0.0]            # kg/s: phi(p), leakage at every command
    affine_psi_in = [...]         # kg/s per unit Gamma: psi(p) while Gamma > 0 (inlet)
    affine_psi_out = [...]        # kg/s per unit Gamma: psi(p) while Gamma < 0 (exhaust)
    affine_gamma = [1.0, 0.0]     # -: Gamma(s) = g1 s + g2 s|s| + ..., s normalised opening

The polynomials are in the port pressure in bar, p / 1e5 Pa (absolute), lowest power
first; s is the valve's signed effective opening in [-1, 1] ((u - command_center -
null_offset) / command_span, clipped, after the deadband). Port a follows
q_a = phi(p_a) + psi(p_a, sgn Gamma) Gamma(s), port b the same law with Gamma(-s)
(paper 003's approximation II, see :func:`workbench.physics.valve.affine_port_flows`).
With the input-affine law, ``sonic_conductance`` and ``critical_pressure_ratio`` are
still required (they describe the datasheet valve) but do not enter the dynamics.
"""

from __future__ import annotations

import difflib
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import tomli_w

from .errors import InputError
from .params_units import check_units, quoted_number_hint, read_toml, slip_hint

__all__ = [
    "Key",
    "SCHEMA",
    "EFFECTS",
    "EFFECT_NAMES",
    "CONTROLLER_KINDS",
    "VALVE_LAWS",
    "AFFINE_KEYS",
    "PlantParams",
]


@dataclass(frozen=True)
class Key:
    """Declaration of one plant-file key.

    Parameters
    ----------
    section, name : str
        Where the key lives: ``[section] name = ...``.
    unit : str
        SI unit (``"-"`` when dimensionless).
    kind : {"float", "int", "str", "floats"}
        Expected TOML type (integers are accepted for floats); ``"floats"`` is an
        array of finite numbers (stored as a tuple of floats).
    required : bool
        Must be present in every plant file.
    low, high : float or None
        Admissible range.
    low_open, high_open : bool
        Whether the bounds are excluded.
    effect : str or None
        Name of the effect (formats.md section 2) the key switches on.
    physical : bool
        Enters the dynamics, so it is part of the symbolic parameter vector.
    default : Any
        Value used when an optional non-effect key is absent.
    doc : str
        One line of explanation, used in error messages and ``check``.
    min_items, max_items : int
        Admissible array length (``kind = "floats"`` only).
    law : str or None
        Valve law (:data:`VALVE_LAWS`) the key belongs to: it enters the dynamics
        only under that law, and ``None`` means under every law.
    """

    section: str
    name: str
    unit: str
    kind: str = "float"
    required: bool = True
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    effect: str | None = None
    physical: bool = True
    default: Any = None
    doc: str = ""
    min_items: int = 1
    max_items: int = 16
    law: str | None = None

    @property
    def path(self) -> str:
        """Dotted name, e.g. ``"load.mass"``."""
        return f"{self.section}.{self.name}"

    def expected(self) -> str:
        """Human description of an admissible value."""
        if self.kind == "str":
            return "a string"
        if self.kind == "floats":
            what = f"an array of {self.min_items} to {self.max_items} finite numbers"
            if self.unit and self.unit != "-":
                what += f" ({self.unit})"
            return what
        if self.kind == "int":
            what = "an integer"
        else:
            what = "a number"
        lo = "" if self.low is None else f"{self.low:g}"
        hi = "" if self.high is None else f"{self.high:g}"
        if self.low is not None and self.high is not None:
            left = "(" if self.low_open else "["
            right = ")" if self.high_open else "]"
            what += f" in {left}{lo}, {hi}{right}"
        elif self.low is not None:
            what += f" {'>' if self.low_open else '>='} {lo}"
        elif self.high is not None:
            what += f" {'<' if self.high_open else '<='} {hi}"
        if self.unit and self.unit != "-":
            what += f" ({self.unit})"
        return what


def _k(section: str, name: str, unit: str, **kw: Any) -> Key:
    return Key(section, name, unit, **kw)


_POS = dict(low=0.0, low_open=True)
_NONNEG = dict(low=0.0)

#: Every key a plant file may contain, in the order ``to_toml`` writes them.
SCHEMA: tuple[Key, ...] = (
    _k("gas", "temperature", "K", **_POS, doc="supply air temperature"),
    _k("gas", "polytropic_index", "-", low=1.0, high=1.4,
       doc="chamber process exponent k (1 isothermal .. 1.4 adiabatic)"),
    _k("gas", "atmospheric_pressure", "Pa", **_POS, doc="ambient pressure, absolute"),
    _k("gas", "heat_transfer_coefficient", "W/K", required=False, effect="heat_transfer",
       **_NONNEG, doc="wall heat transfer h*A of each chamber"),
    _k("supply", "pressure", "Pa", **_POS, doc="supply pressure, absolute"),
    _k("supply", "reservoir_volume", "m^3", required=False, effect="supply_droop", **_POS,
       doc="volume of the reservoir between regulator and valve"),
    _k("supply", "regulator_conductance", "m^3/(s Pa)", required=False,
       effect="supply_droop", **_POS, doc="sonic conductance of the regulator"),
    _k("valve", "sonic_conductance", "m^3/(s Pa)", **_POS, law="iso6358",
       doc="ISO 6358 sonic conductance C of one fully open edge"),
    _k("valve", "critical_pressure_ratio", "-", low=0.0, high=1.0, low_open=True,
       high_open=True, law="iso6358", doc="ISO 6358 critical pressure ratio b"),
    _k("valve", "command_center", "V", doc="command that centres the spool"),
    _k("valve", "command_span", "V", **_POS, doc="|u - centre| that opens an edge fully"),
    _k("valve", "command_min", "V", physical=False, doc="lowest command the drive accepts"),
    _k("valve", "command_max", "V", physical=False, doc="highest command the drive accepts"),
    _k("valve", "law", "", kind="str", required=False, physical=False, default="iso6358",
       doc="valve flow law: 'iso6358' (four ISO 6358 edges) or 'input_affine' "
           "(paper 003: q = phi(p) + psi(p, sgn Gamma) Gamma(s))"),
    _k("valve", "underlap_law", "", kind="str", required=False, physical=False,
       default="linear",
       doc="underlap law of the four ISO 6358 edges wherever the plant applies an "
           "underlap (the equilibrium pin): 'linear' (every edge u more open) or "
           "'rounded' ((sqrt(o^2 + u^2) +- o)/2, as the valve-table generator)"),
    _k("valve", "affine_phi", "kg/s", kind="floats", required=False, law="input_affine",
       doc="phi(p): port flow at every command, ascending powers of p/1e5 Pa"),
    _k("valve", "affine_psi_in", "kg/s", kind="floats", required=False, law="input_affine",
       doc="psi(p) while Gamma > 0 (inlet), kg/s per unit Gamma, powers of p/1e5 Pa"),
    _k("valve", "affine_psi_out", "kg/s", kind="floats", required=False, law="input_affine",
       doc="psi(p) while Gamma < 0 (exhaust), kg/s per unit Gamma, powers of p/1e5 Pa"),
    _k("valve", "affine_gamma", "-", kind="floats", required=False, law="input_affine",
       max_items=8, doc="Gamma(s) = sum g_k s|s|^(k-1) of the normalised opening s"),
    _k("valve", "deadband", "-", required=False, effect="valve_deadband", low=0.0,
       high=1.0, high_open=True, doc="spool overlap as a fraction of the span"),
    _k("valve", "null_offset", "V", required=False, effect="valve_offset",
       doc="the spool is centred at command_center + null_offset"),
    _k("valve", "bandwidth", "Hz", required=False, effect="valve_dynamics", **_POS,
       doc="natural frequency of the spool's 2nd-order lag"),
    _k("valve", "damping", "-", required=False, effect="valve_dynamics", **_POS,
       doc="damping ratio of the spool's 2nd-order lag"),
    _k("cylinder", "bore", "m", **_POS, doc="piston diameter"),
    _k("cylinder", "rod_diameter", "m", **_NONNEG, doc="rod diameter, 0 for rodless"),
    _k("cylinder", "stroke", "m", **_POS, doc="usable stroke L; x = 0 where chamber a is smallest"),
    _k("cylinder", "dead_volume_a", "m^3", **_POS, doc="volume of chamber a at x = 0"),
    _k("cylinder", "dead_volume_b", "m^3", **_POS, doc="volume of chamber b at x = L"),
    _k("load", "mass", "kg", **_POS, doc="piston + payload"),
    _k("load", "viscous_friction", "N s/m", **_NONNEG, doc="viscous friction coefficient"),
    _k("load", "external_force", "N", required=False, default=0.0,
       doc="constant force opposing positive x (e.g. gravity on a vertical axis)"),
    _k("friction", "coulomb", "N", required=False, effect="dry_friction", **_NONNEG,
       doc="sliding (Coulomb) friction"),
    _k("friction", "static", "N", required=False, effect="dry_friction", **_NONNEG,
       doc="break-away (static) friction"),
    _k("friction", "stribeck_velocity", "m/s", required=False, effect="dry_friction",
       **_POS, doc="velocity scale of the Stribeck decay"),
    _k("lines", "length", "m", required=False, effect="line_dynamics", **_POS,
       doc="length of each valve-chamber line"),
    _k("lines", "diameter", "m", required=False, effect="line_dynamics", **_POS,
       doc="inner diameter of the lines"),
    _k("lines", "segments", "-", kind="int", required=False, physical=False, low=1,
       high=200, doc="lumped segments per line (default from the length)"),
    _k("leakage", "conductance_to_atmosphere", "m^3/(s Pa)", required=False,
       effect="leakage", **_NONNEG, doc="ISO 6358 conductance from each chamber to atmosphere"),
    _k("leakage", "cross_piston", "kg/(s Pa)", required=False, effect="leakage",
       **_NONNEG, doc="laminar leak conductance across the piston"),
    _k("controller", "kind", "", kind="str", required=False, physical=False,
       doc="controller law: 'p', 'pd' or 'pid'"),
    _k("controller", "sample_time", "s", required=False, physical=False, **_POS,
       doc="controller period; u is held between samples"),
    _k("controller", "kp", "V/m", required=False, physical=False, doc="proportional gain"),
    _k("controller", "kd", "V s/m", required=False, physical=False, default=0.0,
       doc="derivative gain"),
    _k("controller", "ki", "V/(m s)", required=False, physical=False, default=0.0,
       doc="integral gain (kind = 'pid')"),
    _k("controller", "position_resolution", "m", required=False, physical=False,
       **_POS, doc="ADC quantisation step of the measured position"),
    _k("controller", "command_resolution", "V", required=False, physical=False,
       **_POS, doc="DAC quantisation step of the command"),
)

#: Top-level keys (outside any section).
TOP_LEVEL: tuple[Key, ...] = (
    _k("", "name", "", kind="str", required=False, physical=False, doc="plant name"),
)

REQUIRED_SECTIONS = ("gas", "supply", "valve", "cylinder", "load")
OPTIONAL_SECTIONS = ("friction", "lines", "leakage", "controller")
CONTROLLER_KINDS = ("p", "pd", "pid")
#: Valve flow laws a plant file may select with ``[valve] law``.
VALVE_LAWS = ("iso6358", "input_affine")

#: Effect name -> keys that describe it (formats.md section 2).
EFFECTS: dict[str, tuple[Key, ...]] = {}
for _key in SCHEMA:
    if _key.effect:
        EFFECTS.setdefault(_key.effect, ())
        EFFECTS[_key.effect] = EFFECTS[_key.effect] + (_key,)
EFFECT_NAMES: tuple[str, ...] = (
    "dry_friction", "valve_deadband", "valve_offset", "valve_dynamics",
    "line_dynamics", "leakage", "supply_droop", "heat_transfer",
)
#: Effects for which any one of the keys is enough (the others default to zero).
_ANY_KEY_EFFECTS = {"leakage"}

_BY_PATH = {k.path: k for k in SCHEMA}
#: Keys of the input-affine valve law, all required when it is selected.
AFFINE_KEYS: tuple[Key, ...] = tuple(k for k in SCHEMA if k.law == "input_affine")


def _split_index(path: str) -> tuple[str, int | None]:
    """``"valve.affine_phi[2]"`` -> ``("valve.affine_phi", 2)``; plain paths -> (path, None)."""
    if path.endswith("]") and "[" in path:
        base, _, idx = path[:-1].rpartition("[")
        if idx.isdigit():
            return base, int(idx)
    return path, None


def _fmt_path(path: str) -> str:
    section, _, name = path.rpartition(".")
    return f"[{section}] {name}" if section else name


@dataclass(frozen=True)
class PlantParams:
    """Validated, immutable contents of a plant file.

    Parameters
    ----------
    values : Mapping[str, float | int | str]
        Dotted key -> value, SI units, only keys that were given (or defaulted).
    name : str
        Plant name.
    source : str
        File the parameters came from (for messages).
    """

    values: Mapping[str, Any]
    name: str = "plant"
    source: str = "<memory>"

    # ---------------------------------------------------------------- creation
    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "<memory>") -> "PlantParams":
        """Validate a nested mapping as parsed from TOML.

        Raises
        ------
        InputError
            Naming the file, the key and what was expected.
        """
        if not isinstance(data, Mapping):
            raise InputError("expected a table of sections", source=source)
        values: dict[str, Any] = {}
        name = "plant"
        for top, content in data.items():
            if top == "name":
                if not isinstance(content, str):
                    raise InputError(f"expected a string, got {content!r}", source=source,
                                     location="key 'name'")
                name = content
                continue
            if top not in REQUIRED_SECTIONS + OPTIONAL_SECTIONS:
                if not isinstance(content, Mapping):
                    raise InputError(_top_level_key_message(top, content), source=source,
                                     location=f"key '{top}'")
                hint = difflib.get_close_matches(top, REQUIRED_SECTIONS + OPTIONAL_SECTIONS, 1)
                known = ", ".join(f"[{s}]" for s in REQUIRED_SECTIONS + OPTIONAL_SECTIONS)
                raise InputError(
                    f"unknown section [{top}]"
                    + (f" (did you mean [{hint[0]}]?)" if hint else "")
                    + _effect_section_hint(top, bool(hint)) + f"; known sections: {known}",
                    source=source, location=f"section [{top}]")
            if not isinstance(content, Mapping):
                raise InputError(f"expected a section [{top}] with keys, got a value {content!r}",
                                 source=source, location=f"key '{top}'")
            known_keys = [k.name for k in SCHEMA if k.section == top]
            for name_, raw in content.items():
                path = f"{top}.{name_}"
                key = _BY_PATH.get(path)
                if key is None:
                    hint = difflib.get_close_matches(name_, known_keys, 1)
                    raise InputError(
                        f"unknown key '{name_}'"
                        + (f" (did you mean '{hint[0]}'?)" if hint else "")
                        + f"; keys of [{top}]: {', '.join(known_keys)}",
                        source=source, location=f"[{top}] {name_}")
                values[path] = _check_value(key, raw, source)
        for section in REQUIRED_SECTIONS:
            if section not in data:
                raise InputError(f"missing required section [{section}]", source=source,
                                 location=f"section [{section}]")
        for key in SCHEMA:
            if key.required and key.path not in values:
                raise InputError(f"missing required key; expected {key.expected()}: {key.doc}",
                                 source=source, location=_fmt_path(key.path))
        _check_effects(values, source)
        _check_consistency(values, source)
        check_units(values, source)
        return cls(values=dict(values), name=name, source=source)

    @classmethod
    def from_toml(cls, path: str | os.PathLike) -> "PlantParams":
        """Read and validate a plant file (UTF-8, with or without a byte-order mark).

        Raises
        ------
        InputError
            Naming the file (and key) for a missing, unreadable, non-UTF-8 or invalid
            TOML file and for everything :meth:`from_dict` rejects.
        """
        path = Path(path)
        src = str(path)
        return cls.from_dict(read_toml(path), source=src)

    # ---------------------------------------------------------------- access
    def __getitem__(self, path: str) -> Any:
        """Value of a dotted key; ``"valve.affine_phi[2]"`` picks one array entry."""
        if path in self.values:
            return self.values[path]
        base, idx = _split_index(path)
        if idx is not None and base in self.values and _BY_PATH[base].kind == "floats":
            arr = self.values[base]
            if idx >= len(arr):
                raise KeyError(f"plant parameter '{base}' has {len(arr)} entries, "
                               f"no index {idx}")
            return arr[idx]
        key = _BY_PATH.get(path)
        if key is None:
            raise KeyError(f"no plant parameter '{path}'")
        if key.default is not None:
            return key.default
        raise KeyError(f"plant parameter '{path}' is not set in {self.source}")

    def get(self, path: str, default: Any = None) -> Any:
        """Value of a dotted key, or ``default`` when absent."""
        try:
            return self[path]
        except KeyError:
            return default

    def __contains__(self, path: str) -> bool:
        return path in self.values

    @property
    def effects(self) -> tuple[str, ...]:
        """Names of the effects this plant has, in formats.md order."""
        return tuple(e for e in EFFECT_NAMES
                     if any(k.path in self.values for k in EFFECTS[e]))

    def has_effect(self, effect: str) -> bool:
        """Whether the named effect is present."""
        if effect not in EFFECTS:
            raise KeyError(f"unknown effect '{effect}'; known: {', '.join(EFFECT_NAMES)}")
        return effect in self.effects

    @property
    def has_controller(self) -> bool:
        """Whether the plant file describes a controller."""
        return "controller.kind" in self.values

    def replace(self, **changes: Any) -> "PlantParams":
        """A copy with dotted keys changed (``None`` removes an optional key).

        The result is validated like a file, so an effect can be switched on by
        giving all its keys, and off by removing them. One entry of an array key
        is changed by its indexed name, e.g. ``"valve.affine_psi_in[2]"`` (the names
        of :attr:`workbench.Plant.param_names`).

        Examples
        --------
        >>> params = PlantParams.from_toml("designs/plants/situm_rodless.toml")
        >>> p2 = params.replace(**{"load.mass": 2.0})
        >>> p2["load.mass"], params["load.mass"]      # kg; the original is unchanged
        (2.0, 0.91)
        """
        new = dict(self.values)
        for path, val in changes.items():
            base, idx = _split_index(path)
            if idx is not None and base in _BY_PATH and _BY_PATH[base].kind == "floats":
                if base not in new or idx >= len(new[base]):
                    raise InputError(f"no entry {idx} to change (the array has "
                                     f"{len(new.get(base, ()))})", source=self.source,
                                     location=_fmt_path(base))
                arr = list(new[base])
                arr[idx] = val
                new[base] = arr
            elif val is None:
                new.pop(path, None)
            else:
                new[path] = val
        return PlantParams.from_dict(_nest(new, self.name), source=self.source)

    def without_effect(self, effect: str) -> "PlantParams":
        """A copy with every key of ``effect`` removed (with ``[lines] segments`` for
        ``line_dynamics``: the number of segments of lines that are gone)."""
        companions = ("lines.segments",) if effect == "line_dynamics" else ()
        return self.replace(**{k.path: None for k in EFFECTS[effect]},
                            **{path: None for path in companions})

    # ---------------------------------------------------------------- output
    def to_dict(self) -> dict[str, Any]:
        """Nested mapping in schema order, ready for TOML."""
        return _nest(self.values, self.name)

    def to_toml(self, path: str | os.PathLike) -> None:
        """Write the plant file atomically (a temporary file renamed into place)."""
        atomic_write_text(path, tomli_w.dumps(self.to_dict()))


def _nest(values: Mapping[str, Any], name: str) -> dict[str, Any]:
    out: dict[str, Any] = {"name": name}
    for key in SCHEMA:
        if key.path in values:
            val = values[key.path]
            out.setdefault(key.section, {})[key.name] = list(val) if key.kind == "floats" else val
    return out


def _effect_section_hint(top: str, near_section: bool) -> str:
    """For a section named after an effect ([dry_friction]): where its keys go
    (formats.md section 2: an effect is switched on by its keys, not by a section);
    for another name that is no typo of a section (``near_section`` False): the
    effects the workbench models."""
    name = difflib.get_close_matches(top, EFFECT_NAMES, 1, 0.8)
    if name:
        keys = ", ".join(f"[{k.section}] {k.name}" for k in EFFECTS[name[0]])
        return (f"; '{name[0]}' is an effect: it is switched on by its keys, {keys}, "
                f"not by a section of its name")
    if near_section:
        return ""
    return (f"; effects the workbench models: {', '.join(EFFECT_NAMES)} (formats.md "
            f"section 2), each switched on by its keys in a known section")


def _top_level_key_message(top: str, content: Any) -> str:
    """Explain a key outside every section (``title = ...``): not a section."""
    owners = [k.section for k in SCHEMA if k.name == top]
    where = (f"; '{top}' is a key of [{owners[0]}]: move it under that section"
             if owners else "")
    return (f"unknown top-level key '{top}' (= {content!r}); outside the sections a plant "
            f"file may only have 'name' (a string){where}")


def _check_value(key: Key, raw: Any, source: str) -> Any:
    loc = _fmt_path(key.path)
    if key.kind == "floats":
        return _check_array(key, raw, source, loc)
    if key.kind == "str":
        if not isinstance(raw, str):
            raise InputError(f"expected {key.expected()}, got {raw!r}", source=source, location=loc)
        return raw
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        hint = quoted_number_hint(key.name, key.unit, raw) if isinstance(raw, str) else ""
        raise InputError(f"expected {key.expected()}, got {raw!r} ({type(raw).__name__})"
                         + hint, source=source, location=loc)
    if key.kind == "int":
        if not isinstance(raw, int):
            raise InputError(f"expected {key.expected()}, got {raw!r}", source=source, location=loc)
        val: Any = int(raw)
    else:
        try:
            val = float(raw)
        except OverflowError:  # an integer beyond the float range
            val = math.inf
    if not math.isfinite(val):
        raise InputError(f"expected {key.expected()}, got {raw!r}", source=source, location=loc)
    bad = False
    if key.low is not None and (val < key.low or (key.low_open and val == key.low)):
        bad = True
    if key.high is not None and (val > key.high or (key.high_open and val == key.high)):
        bad = True
    if bad:
        raise InputError(f"expected {key.expected()}, got {raw!r}"
                         + slip_hint(key.path, val), source=source, location=loc)
    return val


def _check_array(key: Key, raw: Any, source: str, loc: str) -> tuple[float, ...]:
    if isinstance(raw, (str, bytes)) or not isinstance(raw, (list, tuple)):
        raise InputError(f"expected {key.expected()}, got {raw!r} ({type(raw).__name__})",
                         source=source, location=loc)
    if not key.min_items <= len(raw) <= key.max_items:
        raise InputError(f"expected {key.expected()}, got {len(raw)} entries",
                         source=source, location=loc)
    out = []
    for i, item in enumerate(raw):
        if isinstance(item, bool) or not isinstance(item, (int, float)):
            raise InputError(f"expected {key.expected()}, got {item!r} "
                             f"({type(item).__name__}) at index {i}", source=source,
                             location=loc)
        try:
            val = float(item)
        except OverflowError:  # an integer beyond the float range
            val = math.inf
        if not math.isfinite(val):
            raise InputError(f"expected {key.expected()}, got {item!r} at index {i}",
                             source=source, location=loc)
        out.append(val)
    return tuple(out)


def _check_effects(values: Mapping[str, Any], source: str) -> None:
    if "lines.segments" in values and not any(k.path in values
                                              for k in EFFECTS["line_dynamics"]):
        raise InputError("segments alone describes no lines: [lines] needs length and "
                         "diameter (m) for the line_dynamics effect; give both, or remove "
                         "[lines]", source=source, location="[lines] length, diameter")
    for effect, keys in EFFECTS.items():
        given = [k for k in keys if k.path in values]
        if not given or effect in _ANY_KEY_EFFECTS:
            continue
        missing = [k for k in keys if k.path not in values]
        if missing:
            names = ", ".join(_fmt_path(k.path) for k in missing)
            raise InputError(
                f"effect '{effect}' is switched on by {_fmt_path(given[0].path)} but "
                f"{names} is missing; give all of "
                + ", ".join(k.name for k in keys) + " or none",
                source=source, location=_fmt_path(missing[0].path))


def _check_consistency(values: Mapping[str, Any], source: str) -> None:
    if values["valve.command_min"] >= values["valve.command_max"]:
        raise InputError("expected command_min < command_max", source=source,
                         location="[valve] command_min")
    center = values["valve.command_center"]
    if not values["valve.command_min"] <= center <= values["valve.command_max"]:
        raise InputError("expected command_center within [command_min, command_max]",
                         source=source, location="[valve] command_center")
    if values["cylinder.rod_diameter"] >= values["cylinder.bore"]:
        raise InputError("expected rod_diameter < bore", source=source,
                         location="[cylinder] rod_diameter")
    p_atm = values["gas.atmospheric_pressure"]
    if values["supply.pressure"] <= p_atm:
        raise InputError(
            f"expected an absolute supply pressure above atmospheric ({p_atm:g} Pa), got "
            f"{values['supply.pressure']:g} Pa; a gauge value needs + {p_atm:g} Pa, "
            "a value in bar needs * 1e5", source=source, location="[supply] pressure")
    if "friction.static" in values and values["friction.static"] < values["friction.coulomb"]:
        raise InputError("expected static >= coulomb (break-away friction is not lower "
                         "than sliding friction)", source=source, location="[friction] static")
    _check_valve_law(values, source)
    ctrl = [k for k in values if k.startswith("controller.")]
    if ctrl:
        for need in ("controller.kind", "controller.sample_time", "controller.kp"):
            if need not in values:
                raise InputError(f"a [controller] needs '{need.split('.')[1]}'", source=source,
                                 location=_fmt_path(need))
        if values["controller.kind"] not in CONTROLLER_KINDS:
            raise InputError(f"expected one of {', '.join(repr(k) for k in CONTROLLER_KINDS)}, "
                             f"got {values['controller.kind']!r}", source=source,
                             location="[controller] kind")


def _check_valve_law(values: Mapping[str, Any], source: str) -> None:
    """``[valve] law`` is known; the input-affine law has all its coefficients, the
    ISO law none of them (a stray coefficient would be silently ignored otherwise)."""
    law = values.get("valve.law", "iso6358")
    if law not in VALVE_LAWS:
        hint = difflib.get_close_matches(law, VALVE_LAWS, 1)
        raise InputError(f"expected one of {', '.join(repr(v) for v in VALVE_LAWS)}, got {law!r}"
                         + (f" (did you mean {hint[0]!r}?)" if hint else ""),
                         source=source, location="[valve] law")
    _check_underlap_law(values, law, source)
    names = ", ".join(k.name for k in AFFINE_KEYS)
    if law == "input_affine":
        for key in AFFINE_KEYS:
            if key.path not in values:
                raise InputError(
                    f"missing; law = 'input_affine' needs all of {names}; expected "
                    f"{key.expected()}: {key.doc}", source=source, location=_fmt_path(key.path))
        if not any(values["valve.affine_gamma"]):
            raise InputError("expected at least one nonzero coefficient: with Gamma = 0 "
                             "the command would not move the valve", source=source,
                             location="[valve] affine_gamma")
    else:
        for key in AFFINE_KEYS:
            if key.path in values:
                raise InputError(
                    f"applies only with law = 'input_affine', but this valve's law is "
                    f"{law!r}{'' if 'valve.law' in values else ' (the default)'}; "
                    f"set [valve] law = \"input_affine\" or remove {names}",
                    source=source, location=_fmt_path(key.path))


def _check_underlap_law(values: Mapping[str, Any], law: str, source: str) -> None:
    """``[valve] underlap_law`` is known, and 'rounded' only with the four-edge law
    (the input-affine law's underlap leak is the linear one, see
    :func:`workbench.physics.valve.affine_port_flows`)."""
    under = values.get("valve.underlap_law", "linear")
    from .physics.valve import UNDERLAP_LAWS    # lazy: casadi not needed to parse
    if under not in UNDERLAP_LAWS:
        hint = difflib.get_close_matches(under, UNDERLAP_LAWS, 1)
        raise InputError(f"expected one of {', '.join(repr(v) for v in UNDERLAP_LAWS)}, "
                         f"got {under!r}" + (f" (did you mean {hint[0]!r}?)" if hint else ""),
                         source=source, location="[valve] underlap_law")
    if under != "linear" and law == "input_affine":
        raise InputError(f"underlap_law = {under!r} applies only to the four-edge valve "
                         "(law = 'iso6358'); the input-affine law's underlap is 'linear'",
                         source=source, location="[valve] underlap_law")


def usual_permissions(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """mkstemp makes files private (0600); give ``tmp`` the mode of the file it
    replaces, or 0644 less the umask for a new one."""
    try:
        if os.path.exists(path):
            mode = os.stat(path).st_mode & 0o777
        else:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o644 & ~umask
        os.chmod(tmp, mode)
    except OSError:
        pass


def json_safe(value: Any) -> Any:
    """``value`` with non-finite floats (inf, NaN) as None, recursively through dicts,
    lists and tuples: JSON has no such tokens, and strict readers reject them."""
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never half."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        usual_permissions(tmp, path)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
