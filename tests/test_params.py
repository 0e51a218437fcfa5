"""Plant files (formats.md sections 1 and 2): round trip, effects, and bad input.

Every bad-input test checks that the message starts with ``<file>, <key>: `` and
says what was expected, since formats.md requires errors that name the file, the
key and what was expected.
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import pytest
import tomli_w

from workbench.errors import InputError
from workbench.params import PlantParams

from conftest import DATA, DELETE, PLANTS, SPEC_EFFECTS, plant_dict, write_plant

ALL_EFFECTS_FILE = DATA / "all_effects.toml"


def _flatten(nested: dict) -> dict:
    """{"load": {"mass": 1.2}} -> {"load.mass": 1.2} (top-level 'name' dropped)."""
    return {f"{sec}.{key}": val for sec, table in nested.items() if isinstance(table, dict)
            for key, val in table.items()}


def _prefix(path: Path, location: str) -> str:
    """Regex for the start of a message: '<file>, <location>: '."""
    return "^" + re.escape(f"{path}, {location}: ")


# ---------------------------------------------------------------------- round trip
def test_round_trip_with_every_effect_key(tmp_path):
    written = tomllib.loads(ALL_EFFECTS_FILE.read_text(encoding="utf-8"))
    first = PlantParams.from_toml(ALL_EFFECTS_FILE)
    # What was loaded is what the file says (not only self-consistent): every key, same value.
    assert dict(first.values) == _flatten(written)
    assert first.name == "all-effects"

    out = tmp_path / "again.toml"
    first.to_toml(out)
    second = PlantParams.from_toml(out)
    assert dict(second.values) == dict(first.values)   # exact: TOML floats round-trip
    assert second.name == first.name
    # All 8 effects of formats.md section 2, in its order.
    assert first.effects == SPEC_EFFECTS
    assert second.effects == SPEC_EFFECTS
    assert second.has_controller


def test_effect_keys_in_the_file_cover_formats_md_section_2():
    # The fixture file must really contain every key the spec lists, or the round
    # trip above proves less than it claims.
    spec_keys = {
        "friction.coulomb", "friction.static", "friction.stribeck_velocity",
        "valve.deadband", "valve.null_offset", "valve.bandwidth", "valve.damping",
        "lines.length", "lines.diameter",
        "leakage.conductance_to_atmosphere", "leakage.cross_piston",
        "supply.reservoir_volume", "supply.regulator_conductance",
        "gas.heat_transfer_coefficient",
    }
    loaded = PlantParams.from_toml(ALL_EFFECTS_FILE)
    assert spec_keys <= set(loaded.values)


def test_plant_without_effect_keys_has_no_effects(tmp_path):
    params = PlantParams.from_toml(write_plant(tmp_path / "basic.toml"))
    assert params.effects == ()
    for eff in SPEC_EFFECTS:
        assert not params.has_effect(eff)


@pytest.mark.parametrize("effect", SPEC_EFFECTS)
def test_each_effect_alone_is_detected(tmp_path, effect):
    params = PlantParams.from_toml(write_plant(tmp_path / "p.toml", effects=[effect]))
    assert params.effects == (effect,)


@pytest.mark.parametrize("path", sorted(PLANTS.glob("*.toml")), ids=lambda p: p.name)
def test_reference_plants_load_and_round_trip(tmp_path, path):
    first = PlantParams.from_toml(path)
    first.to_toml(tmp_path / "copy.toml")
    assert dict(PlantParams.from_toml(tmp_path / "copy.toml").values) == dict(first.values)


# ---------------------------------------------------------------------- bad input
def test_missing_required_key(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"load.mass": DELETE})
    with pytest.raises(InputError, match=_prefix(path, "[load] mass")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "missing" in msg and "expected a number > 0 (kg)" in msg


def test_missing_required_section(tmp_path):
    data = plant_dict()
    del data["load"]
    path = tmp_path / "p.toml"
    path.write_text(tomli_w.dumps(data))
    with pytest.raises(InputError, match=_prefix(path, "section [load]")) as exc:
        PlantParams.from_toml(path)
    assert "missing required section" in str(exc.value)


def test_unknown_section_with_hint(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"frction.coulomb": 20.0})
    with pytest.raises(InputError, match=_prefix(path, "section [frction]")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "unknown section [frction]" in msg
    assert "did you mean [friction]?" in msg
    assert "known sections:" in msg and "[load]" in msg


def test_unknown_key_with_did_you_mean(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"load.mas": 1.2})
    with pytest.raises(InputError, match=_prefix(path, "[load] mas")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "unknown key 'mas'" in msg and "did you mean 'mass'?" in msg


@pytest.mark.parametrize("key, value, expected", [
    ("cylinder.bore", -0.025, "expected a number > 0 (m), got -0.025"),
    ("load.mass", -1.2, "expected a number > 0 (kg), got -1.2"),
    ("cylinder.dead_volume_a", -5e-6, "expected a number > 0 (m^3)"),
    ("load.viscous_friction", -40.0, "expected a number >= 0 (N s/m), got -40.0"),
])
def test_negative_size(tmp_path, key, value, expected):
    path = write_plant(tmp_path / "p.toml", overrides={key: value})
    section, name = key.split(".")
    with pytest.raises(InputError, match=_prefix(path, f"[{section}] {name}")) as exc:
        PlantParams.from_toml(path)
    assert expected in str(exc.value)


@pytest.mark.parametrize("key, unit", [
    ("cylinder.stroke", "m"), ("cylinder.bore", "m"), ("load.mass", "kg"),
    ("valve.sonic_conductance", "m^3/(s Pa)"), ("valve.command_span", "V"),
])
def test_zero_size(tmp_path, key, unit):
    path = write_plant(tmp_path / "p.toml", overrides={key: 0.0})
    section, name = key.split(".")
    with pytest.raises(InputError, match=_prefix(path, f"[{section}] {name}")) as exc:
        PlantParams.from_toml(path)
    assert f"expected a number > 0 ({unit}), got 0.0" in str(exc.value)


@pytest.mark.parametrize("ratio", [0.0, 1.0, 1.2])
def test_critical_ratio_outside_open_unit_interval(tmp_path, ratio):
    path = write_plant(tmp_path / "p.toml", overrides={"valve.critical_pressure_ratio": ratio})
    with pytest.raises(InputError, match=_prefix(path, "[valve] critical_pressure_ratio")) as exc:
        PlantParams.from_toml(path)
    assert f"expected a number in (0, 1), got {ratio!r}" in str(exc.value)


@pytest.mark.parametrize("value, typename", [("1.2", "str"), (True, "bool")])
def test_wrong_type_for_a_number(tmp_path, value, typename):
    path = write_plant(tmp_path / "p.toml", overrides={"load.mass": value})
    with pytest.raises(InputError, match=_prefix(path, "[load] mass")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "expected a number > 0 (kg)" in msg and f"({typename})" in msg


def test_wrong_type_string_expected(tmp_path):
    path = write_plant(tmp_path / "p.toml", controller=True,
                       overrides={"controller.kind": 3})
    with pytest.raises(InputError, match=_prefix(path, "[controller] kind")) as exc:
        PlantParams.from_toml(path)
    assert "expected a string, got 3" in str(exc.value)


def test_invalid_toml_syntax(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('name = "x"\n[load]\nmass = = 1.2\n', encoding="utf-8")
    with pytest.raises(InputError, match="^" + re.escape(f"{path}: not valid TOML")) as exc:
        PlantParams.from_toml(path)
    # tomllib reports where: line 3 is the bad one.
    assert "line 3" in str(exc.value)


def test_file_not_found(tmp_path):
    path = tmp_path / "nowhere" / "plant.toml"
    with pytest.raises(InputError, match="^" + re.escape(f"{path}: file not found")):
        PlantParams.from_toml(path)


def test_partial_effect_names_the_missing_keys(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"friction.coulomb": 20.0})
    with pytest.raises(InputError, match=_prefix(path, "[friction] static")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "effect 'dry_friction'" in msg
    assert "[friction] static" in msg and "[friction] stribeck_velocity" in msg
    assert "give all of coulomb, static, stribeck_velocity or none" in msg


@pytest.mark.parametrize("cmin, cmax", [(10.0, 0.0), (5.0, 5.0)])
def test_command_min_not_below_max(tmp_path, cmin, cmax):
    path = write_plant(tmp_path / "p.toml",
                       overrides={"valve.command_min": cmin, "valve.command_max": cmax})
    with pytest.raises(InputError, match=_prefix(path, "[valve] command_min")) as exc:
        PlantParams.from_toml(path)
    assert "expected command_min < command_max" in str(exc.value)


def test_supply_pressure_in_bar_suggests_conversion(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"supply.pressure": 6.0})
    with pytest.raises(InputError, match=_prefix(path, "[supply] pressure")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "absolute supply pressure above atmospheric" in msg
    assert "bar needs * 1e5" in msg


def test_static_below_coulomb(tmp_path):
    path = write_plant(tmp_path / "p.toml", effects=["dry_friction"],
                       overrides={"friction.coulomb": 30.0, "friction.static": 20.0})
    with pytest.raises(InputError, match=_prefix(path, "[friction] static")) as exc:
        PlantParams.from_toml(path)
    assert "expected static >= coulomb" in str(exc.value)


def test_controller_with_unknown_kind(tmp_path):
    path = write_plant(tmp_path / "p.toml", controller=True,
                       overrides={"controller.kind": "lqr"})
    with pytest.raises(InputError, match=_prefix(path, "[controller] kind")) as exc:
        PlantParams.from_toml(path)
    assert "expected one of 'p', 'pd', 'pid', got 'lqr'" in str(exc.value)


def test_replace_validates_like_a_file():
    params = PlantParams.from_toml(ALL_EFFECTS_FILE)
    with pytest.raises(InputError, match=re.escape("[load] mass: expected a number > 0")):
        params.replace(**{"load.mass": -1.0})
    # Removing one key of a multi-key effect is a partial effect, so an error.
    with pytest.raises(InputError, match="effect 'valve_dynamics'"):
        params.replace(**{"valve.damping": None})
    assert "valve_dynamics" not in params.without_effect("valve_dynamics").effects


# ---------------------------------------------------------------------- valve law
AFFINE_FILE = DATA / "input_affine.toml"
#: Keys selecting the input-affine law, as written in the test data file.
AFFINE = {f"valve.{k}": v for k, v in tomllib.loads(AFFINE_FILE.read_text(encoding="utf-8"))
          ["valve"].items() if k == "law" or k.startswith("affine_")}


def test_valve_law_defaults_to_iso6358_and_is_not_written():
    params = PlantParams.from_toml(PLANTS / "rig25_mpye.toml")
    assert params["valve.law"] == "iso6358"
    # An existing file gains no key on a round trip: the default is not written.
    assert "valve.law" not in params.values
    assert "law" not in params.to_dict()["valve"]


def test_round_trip_of_the_input_affine_keys(tmp_path):
    written = tomllib.loads(AFFINE_FILE.read_text(encoding="utf-8"))
    first = PlantParams.from_toml(AFFINE_FILE)
    assert first["valve.law"] == "input_affine"
    for name in ("affine_phi", "affine_psi_in", "affine_psi_out", "affine_gamma"):
        # Stored as a tuple of floats, entry for entry what the file says.
        assert first[f"valve.{name}"] == tuple(written["valve"][name])
        assert all(type(c) is float for c in first[f"valve.{name}"])
    out = tmp_path / "again.toml"
    first.to_toml(out)
    second = PlantParams.from_toml(out)
    assert dict(second.values) == dict(first.values)   # exact: TOML floats round-trip
    assert tomllib.loads(out.read_text())["valve"]["affine_psi_in"] == written["valve"]["affine_psi_in"]


def test_integer_coefficients_are_accepted_as_floats(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, "valve.affine_gamma": [1, 0]})
    assert PlantParams.from_toml(path)["valve.affine_gamma"] == (1.0, 0.0)


def test_indexed_access_and_replace_of_one_coefficient():
    params = PlantParams.from_toml(AFFINE_FILE)
    assert params["valve.affine_psi_in[2]"] == params["valve.affine_psi_in"][2]
    new = params.replace(**{"valve.affine_psi_in[2]": 0.5})
    assert new["valve.affine_psi_in"][2] == 0.5
    assert new["valve.affine_psi_in"][:2] == params["valve.affine_psi_in"][:2]
    with pytest.raises(KeyError, match="has 6 entries, no index 6"):
        params["valve.affine_psi_in[6]"]
    with pytest.raises(InputError, match=re.escape("[valve] affine_phi: no entry 3 to change")):
        params.replace(**{"valve.affine_phi[3]": 1e-5})


def test_switching_the_law_back_needs_the_coefficients_removed():
    params = PlantParams.from_toml(AFFINE_FILE)
    with pytest.raises(InputError, match="applies only with law = 'input_affine'"):
        params.replace(**{"valve.law": "iso6358"})
    iso = params.replace(**{k: None for k in AFFINE})
    assert iso["valve.law"] == "iso6358"


def test_unknown_valve_law_with_hint(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, "valve.law": "input-affine"})
    with pytest.raises(InputError, match=_prefix(path, "[valve] law")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "expected one of 'iso6358', 'input_affine', got 'input-affine'" in msg
    assert "(did you mean 'input_affine'?)" in msg


def test_valve_law_must_be_a_string(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"valve.law": 2})
    with pytest.raises(InputError, match=_prefix(path, "[valve] law")) as exc:
        PlantParams.from_toml(path)
    assert "expected a string, got 2" in str(exc.value)


def test_unknown_affine_key_with_did_you_mean(tmp_path):
    overrides = {**AFFINE, "valve.affine_psi_in": DELETE, "valve.affine_psi_inn": [1.0]}
    path = write_plant(tmp_path / "p.toml", overrides=overrides)
    with pytest.raises(InputError, match=_prefix(path, "[valve] affine_psi_inn")) as exc:
        PlantParams.from_toml(path)
    assert "did you mean 'affine_psi_in'?" in str(exc.value)


@pytest.mark.parametrize("value, expected", [
    ([0.08, "a", 0.01], "got 'a' (str) at index 1"),
    ([0.08, True], "got True (bool) at index 1"),
    ([0.08, float("nan")], "got nan at index 1"),
    ([float("inf")], "got inf at index 0"),
    (0.08, "got 0.08 (float)"),
    ("0.08, 0.01", "got '0.08, 0.01' (str)"),
    ([], "got 0 entries"),
    ([0.01] * 17, "got 17 entries"),
    ([[0.08], [0.01]], "got [0.08] (list) at index 0"),
])
def test_bad_coefficient_arrays(tmp_path, value, expected):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, "valve.affine_psi_in": value})
    with pytest.raises(InputError, match=_prefix(path, "[valve] affine_psi_in")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "expected an array of 1 to 16 finite numbers (kg/s)" in msg
    assert expected in msg


def test_gamma_has_a_shorter_length_limit(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, "valve.affine_gamma": [1.0] * 9})
    with pytest.raises(InputError, match=_prefix(path, "[valve] affine_gamma")) as exc:
        PlantParams.from_toml(path)
    assert "expected an array of 1 to 8 finite numbers, got 9 entries" in str(exc.value)


@pytest.mark.parametrize("missing", ["affine_phi", "affine_psi_in", "affine_psi_out",
                                     "affine_gamma"])
def test_input_affine_law_needs_every_coefficient(tmp_path, missing):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, f"valve.{missing}": DELETE})
    with pytest.raises(InputError, match=_prefix(path, f"[valve] {missing}")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "missing; law = 'input_affine' needs all of affine_phi, affine_psi_in, " \
           "affine_psi_out, affine_gamma" in msg
    assert "expected an array of" in msg


@pytest.mark.parametrize("law", ["iso6358", None])
def test_coefficients_without_the_input_affine_law_are_an_error(tmp_path, law):
    # Decided: an error, not a warning. A coefficient the ISO law would ignore is
    # most likely a forgotten `law = "input_affine"`, and nothing is guessed silently.
    overrides = {"valve.affine_gamma": [1.0, 0.0]}
    if law is not None:
        overrides["valve.law"] = law
    path = write_plant(tmp_path / "p.toml", overrides=overrides)
    with pytest.raises(InputError, match=_prefix(path, "[valve] affine_gamma")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "applies only with law = 'input_affine', but this valve's law is 'iso6358'" in msg
    assert ("(the default)" in msg) == (law is None)
    assert 'set [valve] law = "input_affine" or remove' in msg


def test_gamma_identically_zero_is_an_error(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={**AFFINE, "valve.affine_gamma": [0.0, 0]})
    with pytest.raises(InputError, match=_prefix(path, "[valve] affine_gamma")) as exc:
        PlantParams.from_toml(path)
    assert "at least one nonzero coefficient" in str(exc.value)


# ---------------------------------------------------------------------- issue 15: abuse
def test_non_utf8_plant_file_is_an_input_error_with_the_line(tmp_path):
    path = write_plant(tmp_path / "p.toml")
    text = path.read_bytes().replace(b'name = "', b'name = "caf\xe9 ')  # Latin-1 e-acute
    path.write_bytes(text)
    with pytest.raises(InputError, match=_prefix(path, "line 1")) as exc:
        PlantParams.from_toml(path)
    assert "not UTF-8" in str(exc.value) and "0xe9" in str(exc.value)


def test_deeply_nested_toml_is_an_input_error_not_a_recursion_error(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("x = " + "[" * 100_000 + "]" * 100_000 + "\n", encoding="utf-8")
    with pytest.raises(InputError, match="^" + re.escape(f"{path}: ")) as exc:
        PlantParams.from_toml(path)
    assert "nested too deeply" in str(exc.value)


def test_byte_order_mark_is_accepted_as_for_recordings(tmp_path):
    plain = write_plant(tmp_path / "p.toml")
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert dict(PlantParams.from_toml(bom).values) == dict(PlantParams.from_toml(plain).values)


def test_top_level_key_is_not_called_a_section(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text('title = "rig"\n' + tomli_w.dumps(plant_dict()), encoding="utf-8")
    with pytest.raises(InputError, match=_prefix(path, "key 'title'")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "unknown top-level key 'title'" in msg and "section" not in msg.split(";")[0]
    assert "'name'" in msg


def test_top_level_key_of_a_section_says_where_it_belongs(tmp_path):
    path = tmp_path / "p.toml"
    path.write_text("mass = 1.2\n" + tomli_w.dumps(plant_dict()), encoding="utf-8")
    with pytest.raises(InputError, match="a key of \\[load\\]"):
        PlantParams.from_toml(path)


@pytest.mark.parametrize("celsius", [20, 20.0, -10.0, 0.0])
def test_temperature_in_celsius_is_refused_with_the_kelvin_value(tmp_path, celsius):
    path = write_plant(tmp_path / "p.toml", overrides={"gas.temperature": celsius})
    with pytest.raises(InputError, match=_prefix(path, "[gas] temperature")) as exc:
        PlantParams.from_toml(path)
    msg = str(exc.value)
    assert "Celsius" in msg and f"{celsius + 273.15:.2f} K" in msg


@pytest.mark.parametrize("key, value, hint", [
    ("cylinder.bore", 25.0, "mm?"),
    ("cylinder.stroke", 500.0, "mm?"),
    ("valve.sonic_conductance", 0.7, "l/(s bar)?"),
    ("cylinder.dead_volume_a", 3.0, "cm^3?"),
    ("gas.atmospheric_pressure", 1.01325, "bar?"),
])
def test_unit_slips_in_sizes_are_refused_with_the_conversion(tmp_path, key, value, hint):
    # Each value is 1000x (or 1e5x) away from any real servodrive, the bounds a
    # factor >= 10 away from the largest real one (see params_units.PLAUSIBLE).
    path = write_plant(tmp_path / "p.toml", overrides={key: value})
    section, name = key.split(".")
    with pytest.raises(InputError, match=_prefix(path, f"[{section}] {name}")) as exc:
        PlantParams.from_toml(path)
    assert hint in str(exc.value)


def test_lines_segments_alone_names_the_missing_keys(tmp_path):
    path = write_plant(tmp_path / "p.toml", overrides={"lines.segments": 4})
    with pytest.raises(InputError, match=_prefix(path, "[lines] length, diameter")) as exc:
        PlantParams.from_toml(path)
    assert "needs length and diameter" in str(exc.value)


def test_controller_sample_time_of_a_nanosecond_is_refused(tmp_path):
    path = write_plant(tmp_path / "p.toml", controller=True,
                       overrides={"controller.sample_time": 1e-9})
    with pytest.raises(InputError, match=_prefix(path, "[controller] sample_time")) as exc:
        PlantParams.from_toml(path)
    assert "2.4e+10 steps" in str(exc.value)   # 24 s / 1e-9 s


@pytest.mark.parametrize("make", ["dir", "fifo"])
def test_plant_path_that_is_not_a_regular_file(tmp_path, make):
    path = tmp_path / "p.toml"
    if make == "dir":
        path.mkdir()
    else:
        os.mkfifo(path)   # reading it would block forever
    with pytest.raises(InputError, match="^" + re.escape(f"{path}: ")):
        PlantParams.from_toml(path)


def test_without_line_dynamics_also_drops_the_segments(tmp_path):
    path = write_plant(tmp_path / "p.toml", effects=("line_dynamics",),
                       overrides={"lines.segments": 2})
    params = PlantParams.from_toml(path).without_effect("line_dynamics")
    assert "line_dynamics" not in params.effects and "lines.segments" not in params
