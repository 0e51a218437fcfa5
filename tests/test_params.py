"""Plant files (formats.md sections 1 and 2): round trip, effects, and bad input.

Every bad-input test checks that the message starts with ``<file>, <key>: `` and
says what was expected, since formats.md requires errors that name the file, the
key and what was expected.
"""

from __future__ import annotations

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
