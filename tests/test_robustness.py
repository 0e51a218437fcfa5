"""Monte Carlo robustness: seeded, reproducible, and it can tell controllers apart."""

from __future__ import annotations

import pytest

from workbench import Plant
from workbench.controllers import PID
from workbench.errors import InputError
from workbench.robustness import DEFAULT_UNCERTAINTY, Uncertainty, draw_plants, monte_carlo
from workbench.simulate import steps

PLANT = "designs/plants/situm_rodless.toml"


def test_draws_are_seeded_and_within_ranges():
    plant = Plant.from_toml(PLANT)
    a = draw_plants(plant, 5, seed=7)
    b = draw_plants(plant, 5, seed=7)
    assert [d for d, _ in a] == [d for d, _ in b]              # reproducible
    for d, p in a:
        assert 1.0 <= d["gas.polytropic_index"] <= 1.4
        assert 0.5 * 0.91 <= d["load.mass"] <= 2.0 * 0.91
        assert abs(d["supply.pressure"] - 5e5) <= 1e5
        assert p.params["load.mass"] == d["load.mass"]
    with pytest.raises(InputError):
        Uncertainty("load.mass", 2.0, 1.0)
    assert len(DEFAULT_UNCERTAINTY) == 4


def test_pass_rates_separate_a_sound_and_an_unstable_controller():
    plant = Plant.from_toml(PLANT)
    ref = steps([0.25, 0.30, 0.25], hold=2.5)          # long enough to settle (~1 s)
    ok = lambda p: PID(kp=10.0, sample_time=0.01, u_center=5.0, u_min=0.0, u_max=10.0)  # noqa: E731
    # K0 = 200 x 0.7 = 140 1/s: far beyond every limit (~54 1/s) for any draw
    bad = lambda p: PID(kp=200.0, sample_time=0.01, u_center=5.0, u_min=0.0, u_max=10.0)  # noqa: E731
    from workbench.validate import Specification
    spec = Specification(max_overshoot=float("inf"))   # judge settling and steadiness only
    res = monte_carlo(plant, {"P kp=10": ok, "P kp=200": bad}, n=3, seed=1, spec=spec,
                      reference=ref)
    again = monte_carlo(plant, {"P kp=10": ok}, n=3, seed=1, spec=spec, reference=ref)
    assert res.passed["P kp=10"] == again.passed["P kp=10"]     # reproducible
    assert res.pass_rate("P kp=10") == 1.0
    assert res.pass_rate("P kp=200") == 0.0
    rows = {r[0]: r for r in res.table()}
    assert rows["P kp=200"][3] != ""                           # names what failed
