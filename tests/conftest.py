"""Shared fixtures: plant files written into ``tmp_path`` with chosen effects.

The base plant is the 25 mm rodless rig of ``designs/plants/rig25_mpye.toml``
without its controller; the effect keys are those of formats.md section 2, with
values in the range a rig engineer would write.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import pytest
import tomli_w

REPO = Path(__file__).resolve().parents[1]
PLANTS = REPO / "designs" / "plants"
DATA = Path(__file__).resolve().parent / "data" / "plants"

#: The basic plant (formats.md section 1), SI units, no effects and no controller.
BASE: dict[str, Any] = {
    "name": "test-rig",
    "gas": {"temperature": 293.15, "polytropic_index": 1.2, "atmospheric_pressure": 101325.0},
    "supply": {"pressure": 6.0e5},
    "valve": {"sonic_conductance": 6.25e-8, "critical_pressure_ratio": 0.23,
              "command_center": 5.0, "command_span": 5.0,
              "command_min": 0.0, "command_max": 10.0},
    "cylinder": {"bore": 0.025, "rod_diameter": 0.0, "stroke": 0.5,
                 "dead_volume_a": 5.0e-6, "dead_volume_b": 5.0e-6},
    "load": {"mass": 1.2, "viscous_friction": 40.0},
}

#: Effect name (formats.md section 2) -> {section: {key: value}} switching it on.
EFFECT_KEYS: dict[str, dict[str, dict[str, Any]]] = {
    "dry_friction": {"friction": {"coulomb": 20.0, "static": 30.0, "stribeck_velocity": 0.01}},
    "valve_deadband": {"valve": {"deadband": 0.05}},
    "valve_offset": {"valve": {"null_offset": 0.1}},
    "valve_dynamics": {"valve": {"bandwidth": 100.0, "damping": 0.7}},
    "line_dynamics": {"lines": {"length": 1.0, "diameter": 0.004}},
    "leakage": {"leakage": {"conductance_to_atmosphere": 1.0e-10, "cross_piston": 1.0e-9}},
    "supply_droop": {"supply": {"reservoir_volume": 1.0e-3, "regulator_conductance": 1.0e-7}},
    "heat_transfer": {"gas": {"heat_transfer_coefficient": 0.5}},
}

#: The effect names of formats.md section 2, in its order (written out here, not
#: taken from the package, so the test checks the package against the spec).
SPEC_EFFECTS = ("dry_friction", "valve_deadband", "valve_offset", "valve_dynamics",
                "line_dynamics", "leakage", "supply_droop", "heat_transfer")

#: Typical size of a state by its kind, for scaled comparisons and finite-difference
#: steps: m, m/s, Pa, kg/s, K, V, V/s. Written here, not taken from the plant, so that
#: the tolerances of the tests do not move with the code under test.
_KIND_SCALE = {"position": 0.5, "velocity": 1.0, "pressure": 1e5, "mass_flow": 1e-3,
               "temperature": 300.0, "spool": 5.0, "spool_rate": 100.0}


def state_scales(plant) -> "np.ndarray":
    """Typical size of each state of ``plant`` (SI), from its kind (:data:`_KIND_SCALE`)."""
    import numpy as np
    return np.array([_KIND_SCALE[sig.kind] for sig in plant.states])


CONTROLLER = {"kind": "pd", "sample_time": 0.01, "kp": 20.0, "kd": 1.0}


def plant_dict(effects: Iterable[str] = (), overrides: Mapping[str, Any] | None = None,
               controller: bool = False) -> dict[str, Any]:
    """Nested plant mapping: the base plant, the named effects, then dotted overrides.

    ``overrides`` maps dotted keys (``"load.mass"``) to values; the value
    :data:`DELETE` removes the key.
    """
    data = copy.deepcopy(BASE)
    for eff in effects:
        for section, keys in EFFECT_KEYS[eff].items():
            data.setdefault(section, {}).update(keys)
    if controller:
        data["controller"] = dict(CONTROLLER)
    for path, value in (overrides or {}).items():
        section, _, key = path.rpartition(".")
        table = data.setdefault(section, {}) if section else data
        if value is DELETE:
            table.pop(key, None)
        else:
            table[key] = value
    return data


DELETE = object()


def write_plant(path: Path, effects: Iterable[str] = (), overrides: Mapping[str, Any] | None = None,
                controller: bool = False) -> Path:
    """Write a plant TOML file and return its path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(tomli_w.dumps(plant_dict(effects, overrides, controller)), encoding="utf-8")
    return path


@pytest.fixture
def make_plant_file(tmp_path: Path) -> Callable[..., Path]:
    """Factory: ``make_plant_file(effects=(...), overrides={...}, controller=False, name=...)``."""
    counter = [0]

    def make(effects: Iterable[str] = (), overrides: Mapping[str, Any] | None = None,
             controller: bool = False, name: str | None = None) -> Path:
        counter[0] += 1
        fname = name or f"plant_{counter[0]}.toml"
        return write_plant(tmp_path / fname, effects, overrides, controller)

    return make


@pytest.fixture
def make_plant(make_plant_file) -> Callable[..., Any]:
    """Factory returning a :class:`workbench.Plant` (``friction=`` passed through)."""
    from workbench import Plant

    def make(effects: Iterable[str] = (), overrides: Mapping[str, Any] | None = None,
             friction: str = "stick") -> Any:
        return Plant.from_toml(make_plant_file(effects, overrides), friction=friction)

    return make


#: (design, arguments) -> (exit code, folder of the one run): :func:`run_design` runs
#: each quick design once per session and hands every later caller a copy.
_DESIGN_RUNS: dict[tuple[str, ...], tuple[int, Path]] = {}


def run_design(name: str, out: Path, *args: str) -> tuple[int, dict | None]:
    """Run ``designs/<name>.py``'s ``main(["--quick", *args, "--out", out])`` in-process.

    Returns its exit code and its ``summary.json`` (None when it wrote none). The run
    is made once per session for the same name and arguments (the quick designs are
    deterministic: fixed seeds) into a private folder; each caller gets a copy of its
    files in ``out``, so a test that edits them does not affect another.
    """
    import json
    import runpy
    import shutil
    import tempfile
    key = (name, *args)
    if key not in _DESIGN_RUNS:
        root = Path(__file__).resolve().parents[1]
        mod = runpy.run_path(str(root / "designs" / f"{name}.py"), run_name="design")
        import atexit
        first = Path(tempfile.mkdtemp(prefix=f"wb_design_{name}_")) / "out"
        atexit.register(shutil.rmtree, first.parent, True)
        rc = mod["main"](["--quick", *args, "--out", str(first)])
        _DESIGN_RUNS[key] = (rc, first)
    rc, first = _DESIGN_RUNS[key]
    if first.exists():
        shutil.copytree(first, out, dirs_exist_ok=True)
    summary = out / "summary.json"
    return rc, (json.loads(summary.read_text()) if summary.exists() else None)


def central_jacobian(fun, x, u: float, x_scales, u_step: float):
    """Central differences of ``fun(x, u)`` (a vector) in x and u: steps of 1e-6 of each
    state's scale and ``u_step`` in u, truncation error O(h^2) ~ 1e-10 relative."""
    import numpy as np
    x = np.asarray(x, dtype=float)
    cols = []
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = 1e-6 * x_scales[j]
        cols.append((fun(x + e, u) - fun(x - e, u)) / (2 * e[j]))
    return np.column_stack(cols), (fun(x, u + u_step) - fun(x, u - u_step)) / (2 * u_step)
