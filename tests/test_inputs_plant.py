"""Plant files as a user writes them by hand (issues 12 and 14, session 12): each slip
is refused with a message naming the file, the line or key, and the line to write.

The cases edit one line of designs/plants/rig25_mpye.toml. Expected conversions in the
hints are computed here from the unit definitions (1 mm = 1e-3 m, 1 bar = 1e5 Pa, gauge
= absolute - 101325 Pa), not taken from the code under test.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from workbench.errors import InputError
from workbench.params import PlantParams

ROOT = Path(__file__).resolve().parents[1]
PLANT = ROOT / "designs" / "plants" / "rig25_mpye.toml"
RECORDING = ROOT / "tests" / "data" / "recordings" / "step_small.csv"
P_ATM = 101325.0


def _edited(tmp_path: Path, old: str, new: str, name: str = "plant.toml") -> Path:
    text = PLANT.read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


def _refused(path: Path, *patterns: str) -> str:
    with pytest.raises(InputError) as info:
        PlantParams.from_toml(path)
    text = str(info.value)
    assert text.startswith(str(path)), text
    for p in patterns:
        assert re.search(p, text), (p, text)
    return text


@pytest.mark.parametrize("content", ["", "\n\n", "# a plant file, to be written\n"],
                         ids=["empty", "blank lines", "comment only"])
def test_empty_plant_file_says_it_is_empty(tmp_path, content):
    path = tmp_path / "plant.toml"
    path.write_text(content)
    _refused(path, r"holds no keys", r"\[gas\]")


def test_syntax_error_quotes_the_line(tmp_path):
    path = _edited(tmp_path, "mass = 1.2", "mass = 1.2.3")
    line = PLANT.read_text().splitlines().index("mass = 1.2") + 1
    _refused(path, rf"at line {line}\b", r"the line reads 'mass = 1\.2\.3'")


def test_duplicated_key_quotes_the_second_line(tmp_path):
    path = _edited(tmp_path, "mass = 1.2", "mass = 1.2\nmass = 1.3")
    _refused(path, r"the line reads 'mass = 1\.3'")


@pytest.mark.parametrize("name", ["swapped.csv", "swapped.toml"])
def test_recording_given_as_the_plant_file_says_so(tmp_path, name):
    """Swapped arguments: by suffix, and by content (a CSV header with t and x)."""
    path = tmp_path / name
    path.write_text(RECORDING.read_text())
    _refused(path, r"looks like a recording", r"plant file \(\.toml\) comes first")


def test_valid_plant_has_no_recording_hint():
    """The hint needs a recording's suffix or header: a plant file never gets it."""
    assert PlantParams.from_toml(PLANT).name == "rig25-mpye"


@pytest.mark.parametrize("old, new, pattern", [
    ("mass = 1.2", 'mass = "1.2"', r"without quotes, mass = 1\.2 \(kg\)"),
    ("bore = 0.025", 'bore = "25 mm"', rf"bore = {25 * 1e-3:g}$"),
    ("bore = 0.025", 'bore = "2.5cm"', rf"bore = {2.5 * 1e-2:g}$"),
    ("pressure = 6.0e5", 'pressure = "6 bar"',
     rf"pressure = {6 * 1e5:g} if '6 bar' is absolute, pressure = {6 * 1e5 + P_ATM:g} if "
     r"it is gauge"),
    ("pressure = 6.0e5", 'pressure = "7 bar_g"', rf"pressure = {7 * 1e5 + P_ATM:g}$"),
    ("mass = 1.2", 'mass = "1.2 kilo"', r"plain numbers in SI units \(kg\)"),
])
def test_number_written_as_text_gets_the_line_to_write(tmp_path, old, new, pattern):
    """A quoted number is never converted (formats.md: SI numbers, nothing guessed):
    it is refused, and the hint shows the SI value to write."""
    key = old.split(" = ")[0]
    _refused(_edited(tmp_path, old, new), rf"\] {key}: expected a number", pattern)


def test_text_that_is_no_number_gets_no_conversion(tmp_path):
    text = _refused(_edited(tmp_path, "mass = 1.2", 'mass = "heavy"'),
                    r"expected a number > 0 \(kg\), got 'heavy'")
    assert "without quotes" not in text and "plain numbers" not in text


def test_negative_sample_time_gets_no_tiny_value_hint(tmp_path):
    """'-0.01 s' is a sign slip; the hint for a tiny positive period ("faster than
    1 MHz ... inf steps") was appended to it before."""
    text = _refused(_edited(tmp_path, "sample_time = 0.01", "sample_time = -0.01"),
                    r"\[controller\] sample_time: expected a number > 0 \(s\), got -0\.01$")
    assert "MHz" not in text and "inf" not in text


def test_tiny_sample_time_keeps_its_hint(tmp_path):
    _refused(_edited(tmp_path, "sample_time = 0.01", "sample_time = 1e-9"),
             r"faster than 1 MHz")


def test_section_named_after_an_effect_says_where_its_keys_go(tmp_path):
    path = tmp_path / "plant.toml"
    path.write_text(PLANT.read_text() + "\n[valve_deadband]\ndeadband = 0.02\n")
    _refused(path, r"section \[valve_deadband\]", r"'valve_deadband' is an effect",
             r"\[valve\] deadband")


def test_unknown_effect_lists_the_modelled_ones(tmp_path):
    path = tmp_path / "plant.toml"
    path.write_text(PLANT.read_text() + "\n[backlash]\nwidth = 0.001\n")
    text = _refused(path, r"unknown section \[backlash\]", r"effects the workbench models: "
                    r"dry_friction, .*heat_transfer")
    typo = _edited(tmp_path, "[cylinder]", "[cylindre]", "typo.toml")
    assert "effects the workbench models" not in _refused(typo, r"did you mean \[cylinder\]")
    assert "did you mean" not in text
