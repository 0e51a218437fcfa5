"""Shared fixtures: plant files written into ``tmp_path`` with chosen effects.

The base plant is the 25 mm rodless rig of ``designs/plants/rig25_mpye.toml``
without its controller; the effect keys are those of formats.md section 2, with
values in the range a rig engineer would write.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import shutil
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np
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


_DESIGN_CONSOLE: dict[tuple[str, ...], tuple[str, str]] = {}


class _Tee:
    """A text stream that keeps what is written (``text``) and passes it on."""

    def __init__(self, stream) -> None:
        self.stream, self.text = stream, io.StringIO()

    def write(self, s: str) -> int:
        self.text.write(s)
        return self.stream.write(s)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return False


def design_console(name: str, *args: str) -> tuple[str, str]:
    """(stdout, stderr) of :func:`run_design`'s one run of ``name`` with ``args``."""
    return _DESIGN_CONSOLE[(name, *args)]


def run_design(name: str, out: Path, *args: str) -> tuple[int, dict | None]:
    """Run ``designs/<name>.py``'s ``main(["--quick", *args, "--out", out])`` in-process.

    Returns its exit code and its ``summary.json`` (None when it wrote none). The run
    is made once per session for the same name and arguments (the quick designs are
    deterministic: fixed seeds) into a private folder; each caller gets a copy of its
    files in ``out``, so a test that edits them does not affect another.
    """
    import json
    import runpy
    import tempfile
    key = (name, *args)
    current = _plain_nodeid(os.environ.get("PYTEST_CURRENT_TEST", "").rsplit(" ", 1)[0])
    if _ITEM_GROUPS.get(current, f"design:{name}") != f"design:{name}":
        # a reader outside the design's group would make the run again on another worker
        raise RuntimeError(f"{current} reads the run of designs/{name}.py: mark it "
                           f"@pytest.mark.design({name!r}) (tests/conftest.py, scheduling)")
    if key not in _DESIGN_RUNS:
        root = Path(__file__).resolve().parents[1]
        mod = runpy.run_path(str(root / "designs" / f"{name}.py"), run_name="design")
        import atexit
        first = Path(tempfile.mkdtemp(prefix=f"wb_design_{name}_")) / "out"
        atexit.register(shutil.rmtree, first.parent, True)
        out_tee, err_tee = _Tee(sys.stdout), _Tee(sys.stderr)
        with contextlib.redirect_stdout(out_tee), contextlib.redirect_stderr(err_tee):
            rc = mod["main"](["--quick", *args, "--out", str(first)])
        _DESIGN_RUNS[key] = (rc, first)
        _DESIGN_CONSOLE[key] = (out_tee.text.getvalue(), err_tee.text.getvalue())
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


# ------------------------------------------------ design summaries (issue 17, test_designs)
# The validations and whole-run figures the designs write (workbench.validate /
# workbench.compare), recomputed here from the CSV each design writes of the same run
# (t, u, x, p_a, p_b, r[, q_supply] at the output grid, printed to the last digit) by
# the definitions of the docstrings, written out independently. Tolerance 1e-9
# relative (+1e-12 absolute): the same arithmetic on the same numbers.

#: validate.Specification's documented defaults (its docstring; formats.md).
SPEC_DEFAULTS = {"max_overshoot": 10.0, "max_settling_time": 1.5, "settling_band": 0.02,
                 "band_floor": 1e-3, "max_steady_state_error": 1e-3, "steady_state_window": 0.5,
                 "max_saturation": 0.1, "max_ramp_error": 0.02, "pressure_tolerance": 2e4,
                 # no sine limit by default: inf, which strict JSON writes as null
                 "max_sine_error": None, "name": ""}
RHO_ANR_KG_M3 = 1.185          # physics.md: ISO 6358 / ANR reference density


def close_value(a, b, what, rel=1e-9, abs_=1e-12):
    """a == b to rounding, NaN == NaN and inf == inf; ``a`` None (strict JSON writes a
    non-finite number as null) matches a non-finite ``b`` only."""
    if a is None:
        assert b is None or not math.isfinite(float(b)), (what, a, b)
        return
    a, b = float(a), float(b)
    if math.isnan(b) or math.isinf(b):
        assert (math.isnan(a) and math.isnan(b)) or a == b, (what, a, b)
    else:
        assert a == pytest.approx(b, rel=rel, abs=abs_), (what, a, b)


def trapezoid(y, t):
    """Trapezoid rule over samples y at instants t (written out)."""
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def _seg_values(seg, t, x, r, spec):
    """One segment's metrics by the definitions of workbench.metrics' docstrings."""
    sel = (t >= seg["start"] - 1e-9) & (t <= seg["end"] + 1e-9)
    tt, xx = t[sel], x[sel]
    rr = r[sel] if seg["kind"] == "ramp" else np.full(len(tt), seg["r_end"])
    e = np.abs(rr - xx)
    out = {"tracking_error": float(np.max(e)), "iae": trapezoid(e, tt)}
    w = min(spec["steady_state_window"], 0.5 * (seg["end"] - seg["start"]))
    if seg["kind"] in ("step", "hold"):
        win = tt >= seg["end"] - w - 1e-9
        out["steady_state_error"] = trapezoid(e[win], tt[win]) / (tt[win][-1] - tt[win][0])
    if seg["kind"] == "step":
        size = seg["r_end"] - seg["r_start"]
        sgn = math.copysign(1.0, size)
        band = max(spec["settling_band"] * abs(size), spec["band_floor"])
        over = max(float(np.max(sgn * (xx - seg["r_end"]))), 0.0)
        out.update(overshoot=100.0 * over / abs(size), overshoot_abs=over, band=band)
        # settling: from the last sample outside the band, interpolated; inf when that
        # is within the last window of the segment (still moving at its end)
        outside = np.flatnonzero(np.abs(xx - seg["r_end"]) > band)
        if len(outside) == 0:
            st = 0.0
        else:
            k = int(outside[-1])
            if k == len(tt) - 1 or tt[k] >= tt[-1] - w:
                st = math.inf
            else:
                a_, b_ = abs(xx[k] - seg["r_end"]), abs(xx[k + 1] - seg["r_end"])
                st = tt[k] + (a_ - band) / (a_ - b_) * (tt[k + 1] - tt[k]) - seg["start"]
        out["settling_time"] = st
        prog = sgn * (xx - seg["r_start"]) / abs(size)

        def cross(level):
            k = np.flatnonzero(prog >= level)
            if len(k) == 0:
                return math.inf
            k = int(k[0])
            return tt[k] if k == 0 else tt[k - 1] + (level - prog[k - 1]) / (
                prog[k] - prog[k - 1]) * (tt[k] - tt[k - 1])
        out["rise_time"] = cross(0.9) - cross(0.1) if math.isfinite(cross(0.9)) else math.inf
    return out


def check_validation(v, df, u_limits=(0.0, 10.0), p_atm=101325.0, p_s=6e5):
    """A ``Validation.to_dict()`` against the CSV of the same run (see above)."""
    t, x, u, r = (df[c].to_numpy() for c in ("t", "x", "u", "r"))
    p_all = np.concatenate([df["p_a"].to_numpy(), df["p_b"].to_numpy()])
    spec = v["spec"]
    assert spec == SPEC_DEFAULTS
    assert isinstance(v["label"], str) and v["label"] and v["error"] is None
    assert isinstance(v["wall_time"], float) and v["wall_time"] > 0.0
    segs = v["segments"]
    # the segments tile the profile, and the CSV's r is their reference
    assert segs[0]["start"] == 0.0 and all(a["end"] == b["start"] for a, b in zip(segs, segs[1:]))
    for s in segs:
        sel = (t > s["start"] + 1e-9) & (t < s["end"] - 1e-9)
        ref = (s["r_start"] + (t[sel] - s["start"]) / (s["end"] - s["start"])
               * (s["r_end"] - s["r_start"])) if s["kind"] == "ramp" else s["r_end"]
        np.testing.assert_allclose(r[sel], ref, atol=1e-12)
        assert s["complete"] is True
        mine = _seg_values(s, t, x, r, spec)
        for k in ("overshoot", "overshoot_abs", "settling_time", "rise_time", "band",
                  "steady_state_error", "tracking_error", "iae"):
            close_value(s[k], mine.get(k, math.nan), (s["kind"], s["start"], k))
    m = v["metrics"]
    close_value(m["iae"], trapezoid(np.abs(r - x), t), "iae")
    lo, hi = u_limits
    sat = (u <= lo + 1e-9 * (hi - lo)) | (u >= hi - 1e-9 * (hi - lo))
    close_value(m["saturation_fraction"], np.sum(np.diff(t) * sat[:-1]) / (t[-1] - t[0]), "sat")
    close_value(m["p_min"], p_all.min(), "p_min")
    close_value(m["p_max"], p_all.max(), "p_max")
    ramps = [_seg_values(s, t, x, r, spec)["tracking_error"] for s in segs if s["kind"] == "ramp"]
    close_value(m["ramp_error_max"], max(ramps), "ramp_error_max")
    close_value(m["simulated_time"], t[-1], "simulated_time")
    close_value(m["duration"], segs[-1]["end"], "duration")
    assert m["sine_error_max"] is None      # no sine section: NaN, which strict JSON writes null
    assert m["simulated_time"] >= m["duration"] - 1e-9
    # the checks: each value, its limit, and pass = value within the limit
    checks = {c["name"]: c for c in v["checks"]}
    assert list(checks) == ["simulation", "overshoot", "settling time", "steady-state error",
                            "ramp tracking error", "command saturation",
                            "min chamber pressure", "max chamber pressure"]
    for c in v["checks"]:
        if c["value"] is None:          # non-finite (e.g. never settled) as strict JSON null
            assert c["passed"] is False, c
            continue
        ok = c["value"] <= c["limit"] if c["bound"] == "max" else c["value"] >= c["limit"]
        assert c["passed"] is bool(ok), c
    steps = [s for s in segs if s["kind"] == "step"]
    close_value(checks["simulation"]["value"], m["duration"], "simulation")
    close_value(checks["overshoot"]["value"], max(
        steps, key=lambda s: s["overshoot"] / max(spec["max_overshoot"], 100 * spec["band_floor"]
                                                   / abs(s["r_end"] - s["r_start"])))["overshoot"],
        "worst overshoot")
    close_value(checks["settling time"]["value"], max(
        math.inf if s["settling_time"] is None else s["settling_time"] for s in steps), "settling")
    close_value(checks["settling time"]["limit"], spec["max_settling_time"], "settling limit")
    close_value(checks["steady-state error"]["value"], max(
        s["steady_state_error"] for s in segs if s["kind"] in ("step", "hold")), "sse")
    close_value(checks["ramp tracking error"]["value"], m["ramp_error_max"], "ramp")
    close_value(checks["command saturation"]["value"], 100 * m["saturation_fraction"], "sat %")
    close_value(checks["command saturation"]["limit"], 100 * spec["max_saturation"], "sat limit")
    close_value(checks["min chamber pressure"]["value"], m["p_min"], "p_min check")
    close_value(checks["min chamber pressure"]["limit"], p_atm - spec["pressure_tolerance"], "p lo")
    close_value(checks["max chamber pressure"]["value"], m["p_max"], "p_max check")
    close_value(checks["max chamber pressure"]["limit"], p_s + spec["pressure_tolerance"], "p hi")
    assert v["passed"] is all(c["passed"] for c in v["checks"])
    return v


def check_figures(f, v, df, air_bound=None):
    """A ``compare.run_figures`` dict against the CSV and the validation ``v`` of the same
    run. Without ``q_supply`` in the CSV the air is bounded instead (``air_bound``, kg)."""
    t, x, u, r = (df[c].to_numpy() for c in ("t", "x", "u", "r"))
    e = np.abs(r - x)
    segs = v["segments"]
    settled = np.ones(len(t), dtype=bool)
    for s in segs:
        if s["kind"] == "step":
            settled &= ~((t >= s["start"]) & (t < s["start"] + 0.5))
    steps = [s for s in segs if s["kind"] == "step"]
    # strict JSON writes non-finite numbers as null: a step that never settles has an
    # infinite settling time (null = inf); its other figures are NaN when undefined (null =
    # NaN, skipped like NaN by compare.run_figures)
    def fin(vals, none=math.nan):
        vals = [none if q is None else q for q in vals]
        return max((q for q in vals if not math.isnan(q)), default=math.nan)
    close_value(f["iae"], v["metrics"]["iae"], "iae")
    close_value(f["max_error"], e.max(), "max_error")
    close_value(f["max_error_settled"], e[settled].max(), "max_error_settled")
    close_value(f["settling_time"], fin((s["settling_time"] for s in steps), math.inf),
                "settling_time")
    close_value(f["overshoot"], fin(s["overshoot"] for s in steps), "overshoot")
    close_value(f["overshoot_abs"], fin(s["overshoot_abs"] for s in steps), "overshoot_abs")
    close_value(f["steady_state_error"], fin(s["steady_state_error"] for s in segs
                                        if s["kind"] in ("step", "hold")), "sse")
    close_value(f["ramp_error"], v["metrics"]["ramp_error_max"], "ramp_error")
    if "q_supply" in df:
        close_value(f["air_kg"], trapezoid(df["q_supply"].to_numpy(), t), "air_kg")
    else:
        assert 0.0 < f["air_kg"] < air_bound
    close_value(f["air_l_anr"], f["air_kg"] / RHO_ANR_KG_M3 * 1e3, "air_l_anr")
    # u is held between control samples: its total variation over the output grid is
    # that over the control samples
    close_value(f["command_activity"], np.sum(np.abs(np.diff(u))) / (t[-1] - t[0]), "activity",
           rel=1e-6)
    close_value(f["saturation"], v["metrics"]["saturation_fraction"], "saturation")
    for k, arr in (("u", u), ("x", x)):
        close_value(f[f"{k}_min"], arr.min(), k + "_min")
        close_value(f[f"{k}_max"], arr.max(), k + "_max")
    close_value(f["p_min"], v["metrics"]["p_min"], "p_min")
    close_value(f["p_max"], v["metrics"]["p_max"], "p_max")
    assert f["passed"] is v["passed"]
    assert f["failed"] == [c["name"] for c in v["checks"] if not c["passed"]]


# ------------------------------------------------------------------ scheduling on workers
#
# CI runs ``pytest -n 2 --dist loadgroup`` (README). Every test is put in a group here,
# and a group runs whole on one worker:
#
# * ``@pytest.mark.design("name")``: every test that reads a quick design's run (its own
#   file's fixture, ``test_designs.py``, ``test_report_designs.py``) is in the group
#   ``design:name``, so the run (:func:`run_design`, cached in the worker's process) is
#   made once in the suite, not once on each worker that needs it;
# * ``@pytest.mark.independent``: a test that shares no fixture with its neighbours is a
#   group of its own (the concealed-effect diagnoses: each makes its own recording), so
#   one heavy file does not pin a worker for a third of the suite;
# * any other test: its file (as ``--dist loadfile``: module fixtures built once).
#
# The groups are ordered heaviest first (longest-processing-time-first: the light groups
# fill in at the end, so the two workers finish together), by the measured times in
# ``tests/durations.json`` (per test, seconds; a test not listed counts
# :data:`_UNTIMED_S`). The order decides only where and when a test runs, never what it
# checks. Refresh the times with ``WB_DURATIONS_OUT=tests/durations.json pytest ...``.
#
# xdist's own ``loadgroup`` renames a marked item's node id (``id@group``), which pytest 9.2
# no longer lets a plugin do (measured: pytest 9.2.0 with xdist 3.8.0, every test became
# its own unit), so the workers write the groups to a file the controller's scheduler
# reads (:class:`_GroupScheduling`): the same rule, through documented hooks.

DURATIONS = Path(__file__).resolve().parent / "durations.json"
#: Seconds assumed for a test without a measured time (most tests take well under 1 s).
_UNTIMED_S = 0.3
#: Tests shorter than this are not written to the durations file (they count as untimed).
_TIMED_FROM_S = 1.0


def _plain_nodeid(nodeid: str) -> str:
    """A node id without an xdist ``@group`` suffix."""
    at, bracket = nodeid.rfind("@"), nodeid.rfind("]")
    return nodeid[:at] if at > bracket else nodeid


def _group(item) -> str:
    mark = item.get_closest_marker("design")
    if mark is not None:
        return f"design:{mark.args[0]}"
    if item.get_closest_marker("independent") is not None:
        return item.nodeid
    return item.nodeid.split("::", 1)[0]


def _grouping(config) -> bool:
    """True when the run is ``--dist loadgroup`` (on a worker xdist sets ``dist`` to "no"
    and keeps ``loadgroup``)."""
    return bool(getattr(config.option, "loadgroup", False)
                or getattr(config.option, "dist", "no") == "loadgroup")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    if not _grouping(config):
        return
    import json
    try:
        times = json.loads(DURATIONS.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        times = {}
    items[:], groups = schedule(items, times)
    _ITEM_GROUPS.update(groups)
    path = getattr(config, "workerinput", {}).get("wb_groups")
    if path:
        from workbench.params import atomic_write_text
        atomic_write_text(f"{path}.{config.workerinput['workerid']}", json.dumps(groups))


#: node id -> group, filled when the run is grouped (read by :func:`run_design`'s check).
_ITEM_GROUPS: dict[str, str] = {}


def schedule(items: list, times: Mapping[str, float]) -> tuple[list, dict[str, str]]:
    """``items`` in groups (:func:`_group`), heaviest group first by ``times`` (node id ->
    s; :data:`_UNTIMED_S` if absent), each group's items in their order; and node id ->
    group. The sort is stable, so every worker gets the same order (xdist checks it)."""
    groups: dict[str, list] = {}
    for item in items:
        groups.setdefault(_group(item), []).append(item)
    weight = {g: sum(times.get(i.nodeid, _UNTIMED_S) for i in its) for g, its in groups.items()}
    order = sorted(groups, key=lambda g: (-weight[g], g))
    return ([i for g in order for i in groups[g]],
            {i.nodeid: g for g in order for i in groups[g]})


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """Controller: tell each worker where to write its groups (:class:`_GroupScheduling`)."""
    config = node.config
    if _grouping(config):
        if not hasattr(config, "_wb_groups"):
            import tempfile
            folder = Path(tempfile.mkdtemp(prefix="wb_xdist_groups_"))
            config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
            config._wb_groups = folder / "groups.json"
        node.workerinput["wb_groups"] = str(config._wb_groups)


@pytest.hookimpl(optionalhook=True, tryfirst=True)
def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class _GroupScheduling(LoadScopeScheduling):
        """xdist's scope scheduling with the scopes the workers wrote (module docstring
        above) and in their order (heaviest first, not xdist's largest-count first)."""

        _groups: dict[str, str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self._groups is None:
                import json
                self._groups = {}
                where = getattr(config, "_wb_groups", None)
                for f in sorted(where.parent.glob("groups.json.*")) if where else ():
                    self._groups = json.loads(f.read_text(encoding="utf-8"))
                    break
            plain = _plain_nodeid(nodeid)
            return self._groups.get(plain, plain.split("::", 1)[0])

    config.option.loadscopereorder = False
    return _GroupScheduling(config, log)


_MEASURED: dict[str, float] = {}


def pytest_runtest_logreport(report):
    if os.environ.get("WB_DURATIONS_OUT"):
        key = _plain_nodeid(report.nodeid)
        _MEASURED[key] = _MEASURED.get(key, 0.0) + report.duration


def pytest_sessionfinish(session):
    out = os.environ.get("WB_DURATIONS_OUT")
    if not out or hasattr(session.config, "workerinput"):   # the controller writes
        return
    import json
    from workbench.params import atomic_write_text
    timed = {k: round(v, 1) for k, v in sorted(_MEASURED.items()) if v >= _TIMED_FROM_S}
    atomic_write_text(out, json.dumps(timed, indent=0) + "\n")
