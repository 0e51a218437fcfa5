"""One serialisation name and one meaning of ``summary()`` (issue 11).

Every class of the package serialises with ``to_dict()`` (a JSON-ready dict: plain
numbers, strings, lists and dicts; non-finite floats become JSON null through
:func:`workbench.params.json_safe` where JSON is written) and ``summary()`` is a short
human-readable ``str``. The walk imports every module of ``workbench`` and looks at the
classes each defines, so a new ``as_dict`` or a dict-returning ``summary`` fails here.
"""

from __future__ import annotations

import importlib
import inspect
import json
import math
import pkgutil
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench import Plant, linearize, simulate, stability
from workbench import validate as V
from workbench.controllers.force import DriveModel, pressure_plan
from workbench.identify.arx import fit_arx
from workbench.identify.arx import validate as arx_validate
from workbench.params import json_safe

PLANTS = Path(__file__).resolve().parents[1] / "designs" / "plants"

FORBIDDEN = ("as_dict", "as_json", "to_json")

# Exceptions to the naming rule, keyed (module, class, method), each with its reason.
# Empty: every class follows it. (The re-layout used this list while files moved.)
ALLOWED: dict[tuple[str, str, str], str] = {}


def _modules():
    """Every module of the package, imported (a module that fails to import fails here)."""
    mods = [workbench]
    for info in pkgutil.walk_packages(workbench.__path__, prefix="workbench."):
        if info.name.rsplit(".", 1)[-1] == "__main__":
            continue
        mods.append(importlib.import_module(info.name))
    return mods


def _classes():
    """(module name, class) for each public class a module of the package defines."""
    for mod in _modules():
        for name, cls in vars(mod).items():
            if inspect.isclass(cls) and not name.startswith("_") and cls.__module__ == mod.__name__:
                yield mod.__name__, cls


def _violations():
    """(module, class, method) of every old serialisation name or non-str summary."""
    found = set()
    for mod, cls in _classes():
        for meth in FORBIDDEN:
            if meth in vars(cls):
                found.add((mod, cls.__name__, meth))
        summary = vars(cls).get("summary")
        if summary is not None:
            ret = inspect.signature(summary).return_annotation if callable(summary) else None
            if ret not in (str, "str"):
                found.add((mod, cls.__name__, "summary"))
    return found


def test_walk_finds_the_serialising_classes():
    # guards the walk itself: classes known to have to_dict / summary are seen
    seen = {(m, c.__name__) for m, c in _classes()}
    assert {("workbench.linearize", "TangentModel"), ("workbench.equilibrium", "OperatingPoint"),
            ("workbench.stability.limits", "GainLimits"),
            ("workbench.controllers.force", "PressurePlan")} <= seen


def test_one_serialisation_name_and_str_summaries():
    found = _violations()
    new = sorted(found - set(ALLOWED))
    assert not new, ("rename to to_dict() (JSON-ready dict) or make summary() return a str "
                     f"annotated '-> str': {new}")
    stale = sorted(set(ALLOWED) - found)
    assert not stale, f"renamed already: delete from ALLOWED in {__file__}: {stale}"


def _assert_plain(value, where="to_dict()"):
    """Only dicts with str keys, lists, str, bool, int, float and None (what ``json``
    writes without a ``default``; NumPy ints and bools are not among them)."""
    if isinstance(value, dict):
        for k, v in value.items():
            assert isinstance(k, str), f"{where}: key {k!r} is not a str"
            _assert_plain(v, f"{where}[{k!r}]")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _assert_plain(v, f"{where}[{i}]")
    else:
        assert value is None or isinstance(value, (str, bool, int, float)), (
            f"{where}: {type(value).__name__} is not plain JSON")


def _round_trip(obj) -> dict:
    """``obj.to_dict()``: plain, strict-JSON after json_safe, and read back unchanged."""
    d = obj.to_dict()
    _assert_plain(d, f"{type(obj).__name__}.to_dict()")
    safe = json_safe(d)
    assert json.loads(json.dumps(safe, allow_nan=False)) == safe
    return d


@pytest.fixture(scope="module")
def situm():
    return Plant.from_toml(PLANTS / "situm_rodless_nominal.toml")


def test_linear_models_and_gain_limits_to_dict(situm):
    op = linearize.operating_point(situm, 0.25)
    lin = linearize.tangent(situm, op)
    d = _round_trip(lin)
    assert d["equilibrium"] == _round_trip(op)
    assert np.array_equal(np.array(d["A"]), lin.A) and d["states"] == list(lin.state_names)
    red = _round_trip(linearize.reduced_position_model(lin))
    lim = stability.gain_limits(red["w0"], red["zeta"], 0.01, k0=0.5)
    ld = _round_trip(lim)
    assert ld["k0"] == 0.5 and ld["sampled"] == lim.sampled


def test_arx_model_and_validation_to_dict():
    rng = np.random.default_rng(3)
    u = rng.standard_normal(400)
    y = np.zeros(400)
    for k in range(2, 400):                    # y_k = 0.5 y_(k-1) + 0.2 u_(k-2) + noise
        y[k] = 0.5 * y[k - 1] + 0.2 * u[k - 2] + 0.01 * rng.standard_normal()
    m = fit_arx(y[:200], u[:200], (1, 1, 2), sample_time=0.01)
    _round_trip(m)
    _round_trip(arx_validate(m, y[200:], u[200:]))


def test_validation_with_inf_settling_time_is_strict_json(situm):
    # a response that rings for ever (10 mm at 3 Hz): settling time inf, written as null
    ref = simulate.profile([(0.0, 0.2), (0.5, 0.2), (0.5, 0.3), (3.0, 0.3)])
    t = np.arange(0.0, 3.0 + 1e-12, 1e-3)
    x = np.where(t < 0.5, 0.2, 0.3 + 0.01 * np.sin(2 * np.pi * 3.0 * t))
    p = np.full_like(t, 3.5e5)
    states = np.column_stack([x, np.gradient(x, t), p, p])
    names = ("x", "v", "p_a", "p_b")
    traj = simulate.Trajectory(time=t, states=states, inputs=np.full((t.size, 1), 5.0),
                               outputs=states, state_names=names, output_names=names,
                               reference=ref(t))
    v = V.evaluate(traj, ref, V.Specification(), situm)
    seg = [i for i, s in enumerate(v.segments) if s.segment.kind == "step"][0]
    assert math.isinf(v.segments[seg].settling_time)
    d = json_safe(_round_trip(v))
    assert d["segments"][seg]["settling_time"] is None
    assert isinstance(v.summary(), str) and "FAILED" in v.summary()


def test_pressure_plan_to_dict_and_summary():
    affine = Plant.from_toml(Path(__file__).resolve().parent / "data" / "plants"
                             / "input_affine.toml")
    m = DriveModel.from_plant(affine)
    t = np.arange(0.0, 1.0 + 1e-9, 1e-2)
    force = 100.0 * np.sin(2 * np.pi * t)                    # N, well inside the range
    plan = pressure_plan(m, t, force, x=0.25, rule="mean")
    d = _round_trip(plan)
    assert d["p_min"] == float(min(plan.p_a.min(), plan.p_b.min())) and d["feasible"] is True
    text = plan.summary()
    assert isinstance(text, str) and "'mean'" in text and text.endswith("feasible")
    bad = pressure_plan(m, t, 2 * m.force_range[1] * np.ones_like(t), x=0.25, rule="mean")
    assert not bad.feasible and "infeasible: " + bad.problems[0] in bad.summary()
