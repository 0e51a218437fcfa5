"""The composed plant: signals, the symbolic parameter vector, and its equilibria."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from workbench import Plant, linearize
from workbench.params import PlantParams

from conftest import EFFECT_KEYS, PLANTS, SPEC_EFFECTS, plant_dict, write_plant
from conftest import state_scale as _scale

BASIC_STATES = (("x", "m"), ("v", "m/s"), ("p_a", "Pa"), ("p_b", "Pa"))

#: States each effect adds (formats.md section 2 / the brief), with units.
ADDED_STATES = {
    "dry_friction": (),
    "valve_deadband": (),
    "valve_offset": (),
    "valve_dynamics": (("spool", "V"), ("spool_rate", "V/s")),
    "line_dynamics": None,   # 4 * segments, checked separately
    "leakage": (),
    "supply_droop": (("p_s", "Pa"),),
    "heat_transfer": (("T_a", "K"), ("T_b", "K")),
}


def _signals(plant):
    return tuple((s.name, s.unit) for s in plant.states)


# ====================================================================== signals
def test_basic_plant_states_and_units(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml"))
    assert _signals(plant) == BASIC_STATES
    assert plant.input_names == ("u",)
    assert plant.inputs[0].unit == "V"
    assert plant.f.size1_out(0) == 4
    assert plant.h.size1_out(0) == len(plant.outputs)


@pytest.mark.parametrize("effect", [e for e in SPEC_EFFECTS if e != "line_dynamics"])
def test_each_effect_adds_its_states(tmp_path, effect):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", [effect]))
    assert _signals(plant) == BASIC_STATES + ADDED_STATES[effect]
    assert plant.f.size1_out(0) == len(plant.states)


def test_lines_add_four_states_per_segment(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", ["line_dynamics"],
                                        {"lines.segments": 3}))
    extra = _signals(plant)[4:]
    # Two lines (a and b), each with a node pressure and a segment flow per segment.
    assert len(extra) == 4 * 3
    assert sorted(n for n, _ in extra) == sorted(
        [f"line_{side}_{kind}{j}" for side in "ab" for kind in "pq" for j in range(3)])
    assert {u for n, u in extra if "_p" in n} == {"Pa"}
    assert {u for n, u in extra if "_q" in n} == {"kg/s"}
    # Without a segment count the plant chooses one from the length (formats.md).
    plant = Plant.from_toml(write_plant(tmp_path / "q.toml", ["line_dynamics"],
                                        {"lines.length": 10.0}))
    assert plant.segments >= 1
    assert len(plant.states) == 4 + 4 * plant.segments


def test_all_effects_together(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", SPEC_EFFECTS, {"lines.segments": 2}))
    names = plant.state_names
    assert names[:4] == ("x", "v", "p_a", "p_b")
    assert len(names) == 4 + 2 + 2 + 4 * 2 + 1
    assert {"spool", "spool_rate", "T_a", "T_b", "p_s"} <= set(names)
    assert plant.effects == SPEC_EFFECTS


@pytest.mark.parametrize("effect", SPEC_EFFECTS)
def test_param_names_follow_the_effects_and_p0_the_file(tmp_path, effect):
    data = plant_dict([effect])
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", [effect]))
    effect_keys = {f"{sec}.{k}" for sec, keys in EFFECT_KEYS[effect].items() for k in keys}
    assert effect_keys <= set(plant.param_names)
    other = {f"{sec}.{k}" for e, tab in EFFECT_KEYS.items() if e != effect
             for sec, keys in tab.items() for k in keys}
    assert not other & set(plant.param_names)
    # Keys that do not enter the dynamics are not parameters.
    assert not {"valve.command_min", "valve.command_max", "lines.segments"} & set(plant.param_names)
    # p0 holds the file's values (external_force defaults to 0 N when absent).
    for name, value in zip(plant.param_names, plant.p0):
        sec, key = name.split(".")
        assert value == data[sec].get(key, 0.0 if name == "load.external_force" else None), name


@pytest.mark.parametrize("path", sorted(PLANTS.glob("*.toml")), ids=lambda p: p.name)
def test_reference_plants_have_the_basic_states(path):
    plant = Plant.from_toml(path)
    assert _signals(plant) == BASIC_STATES
    assert plant.effects == ()
    assert "controller.kp" not in plant.param_names


# ====================================================================== equilibria
@pytest.mark.parametrize("path", sorted(PLANTS.glob("*.toml")), ids=lambda p: p.name)
@pytest.mark.parametrize("x", [0.05, 0.25, 0.45])
def test_f_vanishes_at_the_operating_point_of_reference_plants(path, x):
    plant = Plant.from_toml(path)
    op = linearize.operating_point(plant, x)
    assert op.x == x and op.state[plant.state_index("x")] == x
    f = np.asarray(plant.f(op.state, op.u, plant.p0)).ravel()
    scales = np.array([_scale(n) for n in plant.state_names])
    # A closed-centre valve at its centre passes exactly no flow, and the piston
    # with equal pressures on equal areas feels no force: f is zero up to the
    # roundoff in the solved command (~1e-15 of the span). In one 10 ms sample no
    # state may drift by more than 1e-9 of its scale.
    assert np.max(np.abs(f) * 0.01 / scales) <= 1e-9
    # The pressures are physical: between atmosphere and supply.
    p_atm, p_s = plant.params["gas.atmospheric_pressure"], plant.params["supply.pressure"]
    assert p_atm < op.p_a < p_s and p_atm < op.p_b < p_s


def _distance_to_equilibrium(plant, op):
    """Scaled Newton step from ``op`` to a root of the real model's f (x and u held).

    A rate residual alone is no measure: a 1 Pa error in a line node of 3 cm^3
    gives a rate of ~1e4 Pa/s. The Newton step J^+ f converts the residual into the
    state error it implies (min-norm, so a closed-centre valve's undetermined
    pressures count as zero distance). Returns (largest |step| / scale, state name).
    """
    names = plant.state_names
    idx = [i for i, n in enumerate(names) if n != "x"]
    xs = ca.SX.sym("xs", len(names))
    jac = ca.Function("jac_x", [xs], [ca.jacobian(plant.f(xs, op.u, plant.p0), xs)])
    J = np.asarray(jac(op.state))[np.ix_(idx, idx)]
    f = np.asarray(plant.f(op.state, op.u, plant.p0)).ravel()[idx]
    s = np.array([_scale(names[i]) for i in idx])
    step = np.linalg.lstsq(J * s, -f, rcond=None)[0]
    k = int(np.argmax(np.abs(step)))
    return float(abs(step[k])), names[idx[k]]


_EQ_CASES = {
    "lines": (["line_dynamics"], {}),
    "supply_droop": (["supply_droop"], {}),
    "spool_heat_offset": (["valve_dynamics", "heat_transfer", "valve_offset"], {}),
    "leakage": (["leakage"], {}),
    "leakage_droop_lines": (["leakage", "supply_droop", "line_dynamics"], {}),
}


@pytest.mark.parametrize("case", list(_EQ_CASES))
def test_operating_point_is_an_equilibrium_of_the_real_model(tmp_path, case):
    """f(x_e, u_e) = 0 for plants with effects, measured as a distance in the states.

    Tolerance 1e-4 of each state's scale (10 Pa in a pressure): operating_point
    solves a model whose every valve edge leaks PIN_UNDERLAP = 1e-4 of a full
    opening, to pin the pressures a closed-centre valve leaves undetermined. That
    pinning flow, not the solver (ftol 1e-15), limits the agreement with the real
    model, and it is at most of that relative size (its docstring promises ~1e-6
    in the pressures). A missing or wrong flow term gives O(1e-2..1).
    """
    effects, overrides = _EQ_CASES[case]
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", effects, overrides))
    op = linearize.operating_point(plant, 0.25)
    dist, where = _distance_to_equilibrium(plant, op)
    assert dist <= 1e-4, (f"{where} is {dist:.2g} (of its scale) away from an equilibrium "
                          f"of the real model; p_a = {op.p_a:.6g} Pa, u = {op.u:.6g} V, "
                          f"op.residual = {op.residual:.2g}")


# ====================================================================== symbolic p
def _moving_state(plant, v=0.012):
    """Mid-stroke, moving at about the Stribeck velocity, valve open, every state off its rest."""
    vals = {"x": 0.2, "v": v, "p_a": 3.4e5, "p_b": 2.1e5, "spool": 6.5, "spool_rate": 40.0,
            "T_a": 301.0, "T_b": 287.0, "p_s": 5.7e5}
    out = []
    for n in plant.state_names:
        if n in vals:
            out.append(vals[n])
        elif "_p" in n:
            out.append((3.6e5 if "_a_" in n else 1.9e5) + 1e3 * int(n[-1]))
        else:
            out.append(4e-4 if "_a_" in n else -3e-4)
    return np.array(out)


_SYM_EFFECTS = list(SPEC_EFFECTS)
_SYM_OVERRIDES = {"lines.segments": 3, "cylinder.rod_diameter": 0.01,
                  "load.external_force": 15.0}


def test_every_parameter_enters_f(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", _SYM_EFFECTS, _SYM_OVERRIDES),
                            friction="smooth")
    ps = ca.SX.sym("ps", len(plant.p0))
    jp = ca.Function("jac_p", [ps], [ca.jacobian(plant.f(_moving_state(plant), 6.0, ps), ps)])
    J = np.asarray(jp(plant.p0))
    unused = [n for n, col in zip(plant.param_names, J.T) if not np.any(col != 0.0)]
    assert unused == []
    # The mass enters only the acceleration.
    col = J[:, plant.param_index("load.mass")]
    assert np.flatnonzero(col).tolist() == [plant.state_index("v")]


@pytest.mark.parametrize("name", ["load.mass", "valve.sonic_conductance", "supply.pressure",
                                  "cylinder.bore", "lines.length", "friction.static",
                                  "gas.heat_transfer_coefficient", "valve.null_offset",
                                  "leakage.cross_piston", "supply.reservoir_volume",
                                  "gas.temperature", "valve.damping"])
def test_changing_p_equals_rebuilding_from_the_file(tmp_path, name):
    """No file value is baked into f as a constant: changing p[name] gives exactly
    the f of a plant rebuilt from a file with that value."""
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", _SYM_EFFECTS, _SYM_OVERRIDES),
                            friction="smooth")
    x, u = _moving_state(plant), 6.0
    new = plant.p0[plant.param_index(name)] * 1.05
    p = plant.pvec(**{name.replace(".", "__"): new})
    rebuilt = plant.with_params(**{name: new})
    f_sym = np.asarray(plant.f(x, u, p)).ravel()
    f_file = np.asarray(rebuilt.f(x, u, rebuilt.p0)).ravel()
    # The same expression graph evaluated at the same numbers: equal to roundoff.
    np.testing.assert_allclose(f_sym, f_file, rtol=1e-13, atol=0)
    # ... and the change did something.
    assert np.any(f_sym != np.asarray(plant.f(x, u, plant.p0)).ravel())


def test_doubling_the_mass_halves_the_acceleration(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml"))
    x = np.array([0.2, 0.15, 3.5e5, 2.2e5])
    u = 7.0
    f1 = np.asarray(plant.f(x, u, plant.p0)).ravel()
    i_m = plant.param_index("load.mass")
    f2 = np.asarray(plant.f(x, u, plant.pvec(load__mass=2 * plant.p0[i_m]))).ravel()
    # Independent acceleration: rodless piston, m a = A (p_a - p_b) - beta v.
    area = math.pi / 4 * 0.025 ** 2
    acc = (area * (x[2] - x[3]) - 40.0 * x[1]) / 1.2
    # A handful of floating-point operations: 1e-12 relative.
    assert f1[1] == pytest.approx(acc, rel=1e-12)
    assert f2[1] == pytest.approx(f1[1] / 2, rel=1e-15)   # one exact division by 2
    # Nothing else depends on the mass.
    np.testing.assert_array_equal(np.delete(f1, 1), np.delete(f2, 1))


def test_params_of_a_replaced_plant_are_validated(tmp_path):
    from workbench.errors import InputError
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml"))
    with pytest.raises(InputError, match=r"\[load\] mass: expected a number > 0"):
        plant.with_params(**{"load.mass": 0.0})
    assert isinstance(plant.with_friction("smooth").params, PlantParams)
