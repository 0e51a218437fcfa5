"""The composed plant: signals, the symbolic parameter vector, and its equilibria."""

from __future__ import annotations

import itertools
import math

import casadi as ca
import numpy as np
import pytest
from scipy import optimize

from workbench import Plant, linearize
from workbench.params import PlantParams
from workbench.physics import gas, valve

from conftest import DATA, EFFECT_KEYS, PLANTS, SPEC_EFFECTS, plant_dict, write_plant
from conftest import central_jacobian, state_scales

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
    kinds = {sig.name: sig.kind for sig in plant.states}
    assert {n for n, _ in extra if kinds[n] == "pressure"} == {
        f"line_{side}_p{j}" for side in "ab" for j in range(3)}
    assert {u for n, u in extra if kinds[n] == "pressure"} == {"Pa"}
    assert {u for n, u in extra if kinds[n] == "mass_flow"} == {"kg/s"}
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


#: Effects a plant calibrated from measurements may keep in designs/plants/: the static
#: ones a calibration can find (spool overlap, dry friction, null offset), none that adds
#: states (the reference plants keep the basic states).
CALIBRATED_EFFECTS = {"valve_deadband", "dry_friction", "valve_offset"}


@pytest.mark.parametrize("path", sorted(PLANTS.glob("*.toml")), ids=lambda p: p.name)
def test_reference_plants_have_the_basic_states(path):
    """The reference plants of designs/plants/ are effect-free, except a plant whose name
    says it is calibrated (e.g. situm_rodless.toml, paper 000's rig calibrated by
    designs/paper_000.py): hiding the effects its calibration found would misstate the
    rig, so it keeps them, each value's line saying where it comes from (a comment)."""
    plant = Plant.from_toml(path)
    assert _signals(plant) == BASIC_STATES
    if plant.name.endswith("-calibrated"):
        assert set(plant.effects) <= CALIBRATED_EFFECTS
        lines = path.read_text().splitlines()
        for name in plant.param_names:
            sec, key = name.split(".")
            if sec in ("valve", "friction", "cylinder", "supply") and any(
                    ln.startswith(f"{key} ") for ln in lines):
                line = next(ln for ln in lines if ln.startswith(f"{key} "))
                assert "#" in line, f"{path.name}: {name} does not say where it comes from"
    else:
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
    scales = state_scales(plant)
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
    s = state_scales(plant)[idx]
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
    seen = {"pressure": 0, "mass_flow": 0}   # line states: side a's segments, then side b's
    n_seg = plant.segments
    for sig in plant.states:
        if sig.name in vals:
            out.append(vals[sig.name])
            continue
        k = seen[sig.kind]
        seen[sig.kind] += 1
        side_a, j = k < n_seg, k % n_seg
        if sig.kind == "pressure":
            out.append((3.6e5 if side_a else 1.9e5) + 1e3 * j)
        else:
            out.append(4e-4 if side_a else -3e-4)
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


# ====================================================================== valve law
AFFINE_FILE = DATA / "input_affine.toml"


def _iso_hand(c, b, p1, p2, t1=293.15):
    """ISO 6358-1 mass flow for p1 >= p2 (physics.md), with plain math: rho0 = 1.185
    kg/m^3 at T0 = 293.15 K. Zero at equal pressures; the ratios used here stay
    below the package's laminar patch (0.995) otherwise."""
    x = p2 / p1
    if x == 1.0:
        return 0.0
    assert x < 0.995
    psi = 1.0 if x <= b else math.sqrt(1.0 - ((x - b) / (1.0 - b)) ** 2)
    return c * p1 * 1.185 * math.sqrt(293.15 / t1) * psi


def _affine_plant(friction="stick"):
    return Plant.from_toml(AFFINE_FILE, friction=friction)


def _chamber_flows(plant, p, u, x=0.25):
    """(q_a, q_b) in kg/s at rest at ``x``, both chambers at ``p``, from f itself:
    with v = 0, dp_i/dt = k r T q_i / V_i (physics.md), so q_i = V_i dp_i/dt / (k r T)."""
    prm = plant.params
    k, T = prm["gas.polytropic_index"], prm["gas.temperature"]
    v_a = prm["cylinder.dead_volume_a"] + plant.area_a * x
    v_b = prm["cylinder.dead_volume_b"] + plant.area_b * (plant.stroke - x)
    f = np.asarray(plant.f([x, 0.0, p, p], u, plant.p0)).ravel()
    return v_a * f[2] / (k * gas.R_AIR * T), v_b * f[3] / (k * gas.R_AIR * T)


def test_affine_plant_parameters_are_its_coefficients():
    plant = _affine_plant()
    prm = plant.params
    assert plant.valve_law == "input_affine"
    for key in ("affine_phi", "affine_psi_in", "affine_psi_out", "affine_gamma"):
        coeffs = prm[f"valve.{key}"]
        names = [f"valve.{key}[{j}]" for j in range(len(coeffs))]
        assert [n for n in plant.param_names if n.startswith(f"valve.{key}[")] == names
        assert [plant.p0[plant.param_index(n)] for n in names] == list(coeffs)
    # The ISO keys stay in the file but are no parameters: they do not enter f.
    assert "valve.sonic_conductance" not in plant.param_names
    assert "valve.critical_pressure_ratio" not in plant.param_names
    iso = Plant.from_toml(PLANTS / "rig25_mpye.toml")
    assert iso.valve_law == "iso6358"
    assert not any("affine" in n for n in iso.param_names)


def test_every_parameter_of_the_affine_plant_enters_f(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", _SYM_EFFECTS,
                                        {**_SYM_OVERRIDES, **_affine_keys()}),
                            friction="smooth")
    ps = ca.SX.sym("ps", len(plant.p0))
    jp = ca.Function("jac_p", [ps], [ca.jacobian(plant.f(_moving_state(plant), 6.0, ps), ps)])
    J = np.asarray(jp(plant.p0))
    unused = [n for n, col in zip(plant.param_names, J.T) if not np.any(col != 0.0)]
    # phi[0] = 0 still enters (additively); every coefficient can be estimated.
    assert unused == []


def _affine_keys():
    prm = PlantParams.from_toml(AFFINE_FILE)
    return {k: list(v) if isinstance(v, tuple) else v for k, v in prm.values.items()
            if k == "valve.law" or k.startswith("valve.affine_")}


@pytest.mark.parametrize("name", ["valve.affine_psi_in[2]", "valve.affine_psi_out[0]",
                                  "valve.affine_gamma[0]", "valve.command_span"])
def test_changing_an_affine_coefficient_equals_rebuilding_from_the_file(name):
    plant = _affine_plant()
    x = np.array([0.2, 0.1, 3.4e5, 2.1e5])
    new = plant.p0[plant.param_index(name)] * 1.05
    p = plant.pvec(**{name: new})
    rebuilt = plant.with_params(**{name: new})
    f_sym = np.asarray(plant.f(x, 6.5, p)).ravel()
    f_file = np.asarray(rebuilt.f(x, 6.5, rebuilt.p0)).ravel()
    # Same graph, same numbers: equal to roundoff.
    np.testing.assert_allclose(f_sym, f_file, rtol=1e-13, atol=0)
    assert np.any(f_sym != np.asarray(plant.f(x, 6.5, plant.p0)).ravel())


def test_affine_plant_flows_match_the_iso_plant_they_were_fitted_to():
    """The data file's coefficients were fitted to rig25_mpye's four-edge valve.

    Grid: 23 chamber pressures in [p_atm, p_s] x 21 commands over 0..10 V, both
    ports (not the fit's own 60 x 41 grid). Measured here: RMS 0.37 g/s, largest
    2.8 g/s (on the fit's grid 0.42 and 3.9 g/s; the largest errors are at full
    opening with the chamber near supply pressure, where the ISO inflow has its
    steep end). Bounds: RMS < 0.5 g/s, paper 003's figure for approximation II of
    its valve; largest < 4.5 g/s, about 10 % of the 44 g/s full-opening flow and
    above the fit's own-grid maximum.
    """
    aff, iso = _affine_plant(), Plant.from_toml(PLANTS / "rig25_mpye.toml")
    p_atm, p_s, C, b = 101325.0, 6.0e5, 6.25e-8, 0.23
    errs = []
    for p in np.linspace(p_atm, p_s, 23):
        for u in np.linspace(0.0, 10.0, 21):
            qa_aff, qb_aff = _chamber_flows(aff, p, u)
            qa_iso, qb_iso = _chamber_flows(iso, p, u)
            # The ISO plant's flows are the four-edge law of physics.md, written out:
            # S->A and B->E open with max(o, 0), A->E and S->B with max(-o, 0). The
            # round trip through dp/dt costs a few ulp: 1e-11 relative.
            o = (u - 5.0) / 5.0
            fill, vent = _iso_hand(C, b, p_s, p), _iso_hand(C, b, p, p_atm)
            qa_hand = max(o, 0.0) * fill - max(-o, 0.0) * vent
            qb_hand = max(-o, 0.0) * fill - max(o, 0.0) * vent
            assert (qa_iso, qb_iso) == pytest.approx((qa_hand, qb_hand), rel=1e-11, abs=1e-15)
            errs += [qa_aff - qa_hand, qb_aff - qb_hand]
    errs = np.array(errs)
    rms, worst = float(np.sqrt(np.mean(errs ** 2))), float(np.max(np.abs(errs)))
    assert rms < 0.5e-3, f"RMS {rms * 1e3:.3f} g/s"
    assert worst < 4.5e-3, f"largest {worst * 1e3:.3f} g/s"


def test_affine_plant_mirrors_the_ports_and_keeps_the_sign_convention():
    plant = _affine_plant()
    for p in (1.5e5, 3.0e5, 5.0e5):
        for du in (0.3, 2.0, 5.0):
            qa_up, qb_up = _chamber_flows(plant, p, 5.0 + du)
            qa_dn, qb_dn = _chamber_flows(plant, p, 5.0 - du)
            # Positive command fills a and exhausts b (physics.md, four_edge_flows).
            assert qa_up > 0 > qb_up
            # Port b with the mirrored command is port a: same law, same numbers.
            assert qb_dn == pytest.approx(qa_up, rel=1e-12)
            assert qa_dn == pytest.approx(qb_up, rel=1e-12)
    # Centre: phi = 0 in the fitted file, so no flow at all.
    assert _chamber_flows(plant, 3.0e5, 5.0) == (0.0, 0.0)


def test_affine_plant_supply_flow_is_the_inflow_part():
    plant = _affine_plant()
    i_q = plant.output_index("q_supply")
    prm = plant.params
    k, T = prm["gas.polytropic_index"], prm["gas.temperature"]
    v_a = prm["cylinder.dead_volume_a"] + plant.area_a * 0.25
    v_b = prm["cylinder.dead_volume_b"] + plant.area_b * 0.25
    x = np.array([0.25, 0.0, 3.0e5, 4.0e5])
    for u in (2.0, 5.0, 7.5):
        y = plant.evaluate_h(x, u)
        f = plant.evaluate_f(x, u)
        q_a, q_b = v_a * f[2] / (k * gas.R_AIR * T), v_b * f[3] / (k * gas.R_AIR * T)
        # max(q_a, 0) + max(q_b, 0); v = 0 so the volumes do not change. 1e-12 relative
        # covers the round trip through dp/dt.
        assert y[i_q] == pytest.approx(max(q_a, 0.0) + max(q_b, 0.0), rel=1e-12, abs=1e-18)
        assert y[i_q] >= 0.0


def test_inflow_part_equals_the_four_edge_supply_flow():
    """The choice for q_supply agrees with the four-edge valve wherever that valve
    has no path from supply to an exhausting port (exhausting chamber above atmosphere)."""
    C, b, p_s, p_atm = 6.25e-8, 0.23, 6.0e5, 101325.0
    for s in np.linspace(-1.0, 1.0, 11):
        for p_a in (1.2e5, 3.0e5, 5.5e5):
            for p_b in (1.1e5, 4.0e5):
                q_a, q_b, q_sup = valve.four_edge_flows(s, p_s, p_a, p_b, p_atm, C, b)
                assert float(q_sup) == pytest.approx(max(float(q_a), 0.0) + max(float(q_b), 0.0),
                                                     rel=1e-14, abs=1e-18)


def test_affine_plant_jacobian_matches_central_differences():
    """CasADi's Jacobian of f in (x, u) against central differences, rel 1e-6.

    The state is away from every kink (valve open, v != 0, pressures inside the
    range). Steps: 1e-6 of each state's scale (and of the 5 V span); the truncation
    error of a central difference is O(h^2 f''') ~ 1e-12 relative, roundoff
    eps |f| / h ~ 1e-10 relative, so 1e-6 leaves room without hiding a wrong term.
    """
    plant = _affine_plant()
    x0 = np.array([0.2, 0.1, 3.4e5, 2.1e5])
    u0 = 6.5
    xs, us = ca.SX.sym("xs", 4), ca.SX.sym("us")
    fx = plant.f(xs, us, plant.p0)
    jac = ca.Function("j", [xs, us], [ca.jacobian(fx, xs), ca.jacobian(fx, us)])
    jx, ju = (np.asarray(m) for m in jac(x0, u0))
    scales = state_scales(plant)
    fd, fdu = central_jacobian(plant.evaluate_f, x0, u0, scales, 1e-6 * 5.0)
    # Compare each column relative to its largest entry (entries that are exactly
    # zero, e.g. dx'/dp_a, are zero in both).
    for i in range(4):
        np.testing.assert_allclose(fd[:, i], jx[:, i], rtol=1e-6,
                                   atol=1e-6 * np.max(np.abs(jx[:, i])))
    np.testing.assert_allclose(fdu, ju.ravel(), rtol=1e-6, atol=1e-6 * np.max(np.abs(ju)))


def test_affine_plant_operating_point_and_tangent_model_at_mid_stroke():
    aff, iso = _affine_plant(), Plant.from_toml(PLANTS / "rig25_mpye.toml")
    op = linearize.operating_point(aff, 0.25)
    f = aff.evaluate_f(op.state, op.u)
    # phi = 0: at the centre no flow at all, equal pressures on equal areas; as for
    # the four-edge plant, no state may drift by 1e-9 of its scale in 10 ms.
    scales = state_scales(aff)
    assert np.max(np.abs(f) * 0.01 / scales) <= 1e-9
    assert op.u == pytest.approx(5.0, abs=1e-9)
    # The pin holds the chambers where the fitted inlet and exhaust gains agree,
    # psi_in(p) = psi_out(p): measured 4.4552 bar against the ISO valve's centre
    # balance 4.4656 bar (0.23 %, the fit's error near that pressure); bound 1 %.
    prm = aff.params
    pn = op.p_a / 1e5
    psi_in = valve.polyval(prm["valve.affine_psi_in"], pn)
    psi_out = valve.polyval(prm["valve.affine_psi_out"], pn)
    assert psi_in == pytest.approx(psi_out, rel=1e-6)
    p_e = linearize.centre_balance_pressure(6.0e5, 101325.0, 0.23)
    # Independent balance: equal edges pass equal flow, ISO 6358-1 by hand, brentq.
    p_hand = optimize.brentq(lambda p: _iso_hand(1.0, 0.23, 6.0e5, p) - _iso_hand(1.0, 0.23, p,
                                                                                 101325.0),
                             1.2e5, 5.9e5, xtol=1e-9, rtol=1e-14)
    # both roots to ~1e-9 Pa, flow functions equal to ~1e-13: 1e-12 relative
    assert p_e == pytest.approx(p_hand, rel=1e-12)
    assert op.p_a == pytest.approx(p_e, rel=0.01) and op.p_b == pytest.approx(op.p_a, rel=1e-9)
    # Tangent model: the same drive as the four-edge plant to the fit's accuracy.
    # Bounds 1 % (the fit's error near p_e).
    lin_aff, lin_iso = linearize.tangent(aff, op), linearize.tangent(iso, x=0.25)
    assert lin_aff.A.shape == (4, 4) and np.all(np.isfinite(lin_aff.A))
    assert np.all(lin_aff.eigenvalues.real <= 1e-9)
    red_aff = linearize.reduced_position_model(lin_aff)
    red_iso = linearize.reduced_position_model(lin_iso)
    # The four-edge plant's reduced model by hand (paper 000's third-order form is exact
    # for the basic drive): closed chambers are air springs K = k p_e A^2 (1/V_a + 1/V_b),
    # m s^2 + beta s + K gives w0 = sqrt(K/m) and zeta = beta / (2 sqrt(K m)); the valve
    # gain dq/du = q_ISO(p_s -> p_e)/span into a and out of b gives Kv = r T dq/du / (p_e A).
    # (rig25: k 1.2, A = pi/4 0.025^2, V = 5e-6 + A 0.25, m 1.2 kg, beta 40 N s/m, span 5 V.)
    area = math.pi / 4 * 0.025 ** 2
    vol = 5e-6 + area * 0.25
    stiff = 1.2 * p_hand * area ** 2 * 2.0 / vol
    gq = _iso_hand(6.25e-8, 0.23, 6.0e5, p_hand) / 5.0
    # The fit is exact up to the optimiser's tolerance (xtol 1e-14): 1e-9 relative.
    assert red_iso.w0 == pytest.approx(math.sqrt(stiff / 1.2), rel=1e-9)
    assert red_iso.zeta == pytest.approx(40.0 / (2 * math.sqrt(stiff * 1.2)), rel=1e-9)
    assert red_iso.kv == pytest.approx(287.0 * 293.15 * gq / (p_hand * area), rel=1e-9)
    assert red_aff.w0 == pytest.approx(red_iso.w0, rel=0.01)
    assert red_aff.kv == pytest.approx(red_iso.kv, rel=0.01)


def test_gamma_odd_is_odd_for_any_coefficients():
    rng = np.random.default_rng(3)
    du_sym = ca.SX.sym("du")
    for _ in range(5):
        g = rng.normal(size=rng.integers(1, 5))
        gam = ca.Function("gam", [du_sym], [valve.gamma_odd(du_sym, g)])
        for du in (0.0, 1e-3, 0.3, 0.99, 1.0):
            # Exactly odd: |du| and du * power are computed from the same magnitude.
            assert valve.gamma_odd(-du, g) == -valve.gamma_odd(du, g)
            assert float(gam(-du)) == -float(gam(du))
        assert valve.gamma_odd(0.0, g) == 0.0
    # ... also with symbolic coefficients, as the plant builds it.
    gs = ca.SX.sym("g", 3)
    fun = ca.Function("gam", [du_sym, gs], [valve.gamma_odd(du_sym, ca.vertsplit(gs))])
    assert float(fun(-0.4, [1.0, 0.3, -0.2])) == -float(fun(0.4, [1.0, 0.3, -0.2]))


def test_regularised_f_of_the_affine_plant_pins_the_centre():
    plant = _affine_plant()
    f_reg = plant.regularised_f(1e-4)
    p = 3.0e5   # below the balance pressure: the pinning leak fills the chamber
    x = [0.25, 0.0, p, p]
    assert float(f_reg(x, 5.0, plant.p0)[2]) > 0.0
    assert float(plant.f(x, 5.0, plant.p0)[2]) == 0.0   # the real valve is closed
    # Away from the centre the leak is a 1e-4 correction of a full-opening flow.
    d_real = float(plant.f(x, 7.0, plant.p0)[2])
    assert float(f_reg(x, 7.0, plant.p0)[2]) == pytest.approx(d_real, rel=1e-3)


def test_data_file_coefficients_are_reproduced_by_its_command():
    """The stored coefficients come from the command in the file's header."""
    rig = PlantParams.from_toml(PLANTS / "rig25_mpye.toml")
    fit = valve.fit_affine_to_four_edge(
        rig["valve.sonic_conductance"], rig["valve.critical_pressure_ratio"],
        rig["supply.pressure"], rig["gas.atmospheric_pressure"], rig["gas.temperature"])
    stored = PlantParams.from_toml(AFFINE_FILE)
    for key, val in fit.plant_values().items():
        if key == "valve.law":
            assert stored[key] == val
        else:
            # A least-squares solve: LAPACK builds may differ in the last bits; the
            # coefficients span ~1e-4..1e-1 with a condition number ~1e5, so 1e-8.
            np.testing.assert_allclose(stored[key], val, rtol=1e-8, atol=1e-12)
    # The fit's error, recomputed here: the stored coefficients evaluated with numpy
    # against the four-edge valve's port-A flow written from ISO 6358-1 by hand
    # (:func:`_iso_hand`), on the fit's grid (60 pressures in [p_atm, p_s] x 41
    # openings in [-1, 1], both chamber pressures equal, one temperature).
    C, b = rig["valve.sonic_conductance"], rig["valve.critical_pressure_ratio"]
    p_s, p_atm = rig["supply.pressure"], rig["gas.atmospheric_pressure"]
    P = np.polynomial.polynomial
    g1, g2 = stored["valve.affine_gamma"]
    errs = []
    for p in np.linspace(p_atm, p_s, 60):
        for o in np.linspace(-1.0, 1.0, 41):
            q_hand = (max(o, 0.0) * _iso_hand(C, b, p_s, p)
                      - max(-o, 0.0) * _iso_hand(C, b, p, p_atm))
            gam = g1 * o + g2 * o * abs(o)
            psi = P.polyval(p / 1e5, stored["valve.affine_psi_in" if gam >= 0
                                           else "valve.affine_psi_out"])
            errs.append(P.polyval(p / 1e5, stored["valve.affine_phi"]) + psi * gam - q_hand)
    errs = np.abs(errs)
    rms, worst = float(np.sqrt(np.mean(errs ** 2))), float(errs.max())
    # The same sums in another order, with coefficients equal to 1e-8: 1e-7 relative.
    assert fit.rms == pytest.approx(rms, rel=1e-7)
    assert fit.max_error == pytest.approx(worst, rel=1e-7)
    # ... what the file's header says (0.42 / 3.9 g/s, to its digits), and within
    # paper 003's bound for approximation II (RMS < 0.5 g/s).
    assert round(rms * 1e3, 2) == 0.42 and round(worst * 1e3, 1) == 3.9
    assert rms < 0.5e-3
    # pin_ends: a chamber at supply pressure takes no more air, one at atmosphere
    # gives no more.
    assert valve.polyval(fit.psi_in, 6.0) == pytest.approx(0.0, abs=1e-15)
    assert valve.polyval(fit.psi_out, 1.01325) == pytest.approx(0.0, abs=1e-15)


def test_summary_reports_the_valve_law():
    aff, iso = _affine_plant(), Plant.from_toml(PLANTS / "rig25_mpye.toml")
    assert aff.to_dict()["valve_law"] == "input_affine"
    assert iso.to_dict()["valve_law"] == "iso6358"
    # Full-opening flow from the law in use: 45.4 g/s fitted vs 44.4 g/s ISO
    # (the fit's error at p_atm, fully open); within 5 %.
    assert aff.full_opening_flow() == pytest.approx(iso.full_opening_flow(), rel=0.05)
    assert "input_affine" in repr(aff)



def test_summary_chamber_volumes_are_the_full_stroke_volumes(tmp_path):
    """V_max of each chamber: its dead volume plus its piston area times the stroke,
    written out from the file's numbers (bore 25 mm, rod 10 mm, stroke 0.5 m,
    dead 5 cm^3). A handful of roundings in each: 1e-14 relative."""
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", (), {"cylinder.rod_diameter": 0.01}))
    s = plant.to_dict()
    assert s["volume_a_max_m3"] == pytest.approx(5e-6 + math.pi / 4 * 0.025 ** 2 * 0.5, rel=1e-14)
    assert s["volume_b_max_m3"] == pytest.approx(
        5e-6 + math.pi / 4 * (0.025 ** 2 - 0.01 ** 2) * 0.5, rel=1e-14)
    # The chambers at the ends of the stroke, seen through chamber_masses: the
    # full chamber holds p V / (r T) of gas.
    m_a, _ = plant.chamber_masses([0.5, 0.0, 3e5, 3e5])
    assert m_a == pytest.approx(3e5 * s["volume_a_max_m3"] / (gas.R_AIR * 293.15), rel=1e-14)


# ====================================================================== signal semantics
#: Unit of each kind of signal (SI), written out here so the test checks the package.
_KIND_UNITS = {"position": "m", "velocity": "m/s", "pressure": "Pa", "temperature": "K",
               "mass_flow": "kg/s", "force": "N", "command": "V", "spool": "V",
               "spool_rate": "V/s"}
_STATE_EFFECTS = ("line_dynamics", "valve_dynamics", "heat_transfer", "supply_droop")
_COMBOS = [c for r in range(len(_STATE_EFFECTS) + 1)
           for c in itertools.combinations(_STATE_EFFECTS, r)]


def _combo_plant(tmp_path, combo):
    if combo == "affine":
        return _affine_plant()
    segments = {"lines.segments": 2} if "line_dynamics" in combo else {}  # alone: refused
    return Plant.from_toml(write_plant(tmp_path / "p.toml", combo, segments))


@pytest.mark.parametrize("combo", _COMBOS, ids=lambda c: "+".join(c) or "basic")
def test_every_signal_has_kind_unit_scale_and_rest(tmp_path, combo):
    plant = _combo_plant(tmp_path, combo)
    for sig in plant.states + plant.outputs + plant.inputs:
        assert sig.kind in _KIND_UNITS, sig
        assert sig.unit == _KIND_UNITS[sig.kind], sig
        assert math.isfinite(sig.scale) and sig.scale > 0, sig
        assert math.isfinite(sig.rest), sig
    # Each state has exactly one kind; the helpers agree with the signals.
    n = len(plant.states)
    by_kind = sorted(i for k in _KIND_UNITS for i in plant.states_of_kind(k))
    assert by_kind == list(range(n))
    assert np.array_equal(plant.state_scales(), [s.scale for s in plant.states])
    assert all(plant.signal(s.name) is s for s in plant.states)
    assert plant.signal("q_supply").kind == "mass_flow" and plant.signal("u").kind == "command"
    with pytest.raises(KeyError, match="no signal"):
        plant.signal("p_c")
    # The scales and rests come from the plant file (conftest.BASE: stroke 0.5 m,
    # span 5 V around 5 V, 293.15 K, supply 6 bar; valve_dynamics: 100 Hz).
    expect = {"x": (0.5, 0.25), "v": (1.0, 0.0), "u": (5.0, 5.0), "spool": (5.0, 5.0),
              "spool_rate": (5.0 * 2 * math.pi * 100.0, 0.0), "T_a": (293.15, 293.15),
              "q_supply": (1e-3, 0.0)}
    if "supply_droop" in combo:
        expect["p_s"] = (1e5, 6.0e5)
    for name, (scale, rest) in expect.items():
        if name in plant.state_names + plant.output_names + plant.input_names:
            assert (plant.signal(name).scale, plant.signal(name).rest) == pytest.approx(
                (scale, rest), rel=1e-15), name
    # Chambers and line nodes rest at one pressure between atmosphere and supply.
    held = plant.states_of_kind("pressure", parts=("chamber", "line"))
    rests = {plant.states[i].rest for i in held}
    assert len(rests) == 1 and 101325.0 < rests.pop() < 6.0e5


@pytest.mark.parametrize("combo", _COMBOS + ["affine"],
                         ids=lambda c: c if isinstance(c, str) else "+".join(c) or "basic")
def test_rest_is_the_closed_centre_equilibrium(tmp_path, combo):
    """A closed-centre valve at its centre, equal pressures on equal areas (rodless,
    no external force, no leakage): physics says the rest state is an equilibrium."""
    plant = _combo_plant(tmp_path, combo)
    rest, u_c = plant.rest_state(), plant.inputs[0].rest
    scales = plant.state_scales()
    # Real f: no flow at all at the centre, no force; every row zero up to roundoff.
    # Criterion as for the operating points above: no state drifts by 1e-9 of its
    # scale in one 10 ms sample.
    drift = np.abs(plant.evaluate_f(rest, u_c)) * 0.01 / scales
    assert np.max(drift) <= 1e-9, plant.state_names[int(np.argmax(drift))]
    # The pinned valve (every edge leaking PIN_UNDERLAP) holds a chamber only at the
    # centre balance pressure: the rows of the chamber and line pressures vanish at
    # rest (brentq solves the balance to 1e-9 Pa, i.e. ~1e-18 of drift) ...
    f_pin = plant.regularised_f(linearize.PIN_UNDERLAP)
    held = list(plant.states_of_kind("pressure", parts=("chamber", "line")))

    def pinned_drift(state):
        f = np.asarray(f_pin(state, u_c, plant.p0)).ravel()
        return np.max(np.abs(f[held]) * 0.01 / scales[held])

    assert pinned_drift(rest) <= 1e-9
    # ... and not 0.1 % away from it (measured ~5e-7 there), so the check can fail.
    off = rest.copy()
    off[held] *= 1.001
    assert pinned_drift(plant.rest_state(off, u_c)) >= 1e-7
    # The solved operating point at the rest position is the rest state. With a
    # drooping supply the pin's leak lowers the reservoir and with it the pinned
    # pressures by ~1e-5 of their scale (measured 9.5e-6); else they agree to roundoff.
    op = linearize.operating_point(plant, rest[plant.state_index("x")])
    tol = 1e-4 if "supply_droop" in plant.effects else 1e-12
    assert np.max(np.abs(op.state - rest) / scales) <= tol
    assert op.u == pytest.approx(u_c, abs=1e-9 * plant.inputs[0].scale)


def test_rest_state_takes_followed_signals_and_parameters(tmp_path):
    plant = Plant.from_toml(write_plant(tmp_path / "p.toml", _STATE_EFFECTS, {"lines.segments": 2}))
    names = plant.state_names
    state = np.arange(1.0, len(names) + 1.0) * 1e3          # every state off its rest
    p = plant.pvec(**{"gas.temperature": 310.0, "supply.pressure": 5.5e5})
    z = plant.rest_state(state, 6.1, p)
    expect = dict(zip(names, state[:4]))                      # x, v, p_a, p_b kept
    expect.update(spool=6.1, spool_rate=0.0, T_a=310.0, T_b=310.0, p_s=5.5e5,
                  line_a_p0=state[2], line_a_p1=state[2], line_b_p0=state[3],
                  line_b_p1=state[3], line_a_q0=0.0, line_a_q1=0.0, line_b_q0=0.0,
                  line_b_q1=0.0)
    assert dict(zip(names, z)) == pytest.approx(expect, rel=1e-15)
    # The same on CasADi symbols (the diagnosis engine's quiescent states).
    zs, us, ps = ca.SX.sym("z", len(names)), ca.SX.sym("u"), ca.SX.sym("p", len(p))
    fun = ca.Function("rest", [zs, us, ps], [plant.rest_state(zs, us, ps)])
    assert np.array_equal(np.asarray(fun(state, 6.1, p)).ravel(), z)
    # Defaults: nominal parameters and the valve centre.
    z0 = plant.rest_state()
    assert z0[names.index("spool")] == 5.0 and z0[names.index("T_a")] == 293.15


def test_plant_and_equilibrium_form_no_import_circle():
    """equilibrium.py imports plant for type hints only; plant.py never imports linearize."""
    import ast
    import workbench.equilibrium as eq_mod
    import workbench.plant as plant_mod

    def runtime_imports(module):
        tree = ast.parse(open(module.__file__, encoding="utf-8").read())
        skip = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                skip |= {id(n) for n in ast.walk(node)}
        return {(getattr(n, "module", None) or "") + ":" + ",".join(a.name for a in n.names)
                for n in ast.walk(tree)
                if isinstance(n, (ast.Import, ast.ImportFrom)) and id(n) not in skip}

    eq_imports = runtime_imports(eq_mod)
    assert not any("plant" in i or "linearize" in i for i in eq_imports), eq_imports
    assert not any("linearize" in i for i in runtime_imports(plant_mod))
