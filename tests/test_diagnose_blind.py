"""Blind check: a rig simulated by other code than the workbench's.

The recording comes from the small independent simulator :mod:`foreign_rig` (numpy
and scipy ``solve_ivp``, LSODA, one call per 10 ms controller period): its own ISO
6358 four-edge valve with a linear (laminar) patch near equal pressures, the
polytropic chambers, and a *different friction law*: a smooth Stribeck curve times
tanh(v / 2 mm/s) plus viscous friction, where the workbench uses Karnopp stick-slip.
The diagnosis must still name dry friction and find the Coulomb level within 30 %.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

import foreign_rig
from workbench.diagnose import synth


def test_foreign_friction_law_is_diagnosed(tmp_path):
    from workbench.diagnose import diagnose
    plant_file = synth.concealed_case("none", seed=0).write_nominal(tmp_path / "plant.toml")
    coulomb, static = 22.0, 31.0
    rec = foreign_rig.record(plant_file, synth.rich_reference(21, 20.0), 20.0, seed=21,
                             friction={"coulomb": coulomb, "static": static, "stribeck": 0.012})
    d = diagnose(plant_file, rec)
    res = d.to_dict()
    assert res["findings"], d.summary()
    f = res["findings"][0]
    assert f["effect"] == "dry_friction", d.summary()
    assert f["parameters"]["coulomb"] == pytest.approx(coulomb, rel=0.3)
    assert np.mean(list(res["fit_after"].values())) > np.mean(list(res["fit_before"].values()))


def test_foreign_rig_is_independent_of_the_workbench_model():
    """The simulator imports nothing of the workbench's model (only its Recording class)."""
    tree = ast.parse(Path(foreign_rig.__file__).read_text(encoding="utf-8"))
    mods = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    mods |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert {m for m in mods if m and m.startswith("workbench")} == {"workbench.recording"}


def test_foreign_rig_converges(tmp_path):
    """The recordings' integration error is far below the logger's resolution: 1.6 s of
    the stiffest rig (lines of 4 m x 3 mm, spool, supply droop, heat transfer and leaks
    all on) at the recordings' rtol = 1e-6 against rtol = 1e-9 differs by less than 1 um
    and 2 Pa, 1 % of an LSB (position 122 um, pressure 244 Pa). Measured: 0.09 um and
    0.18 Pa; rtol = 1e-4 gives 21 um and 132 Pa, rtol = 1e-3 4 um and 13 Pa (fail)."""
    plant_file = synth.concealed_case("none", seed=0).write_nominal(tmp_path / "plant.toml")
    every = {"lines.length": 4.0, "lines.diameter": 0.003, "valve.bandwidth": 30.0,
             "valve.damping": 0.7, "supply.reservoir_volume": 5e-4,
             "supply.regulator_conductance": 5e-9, "gas.heat_transfer_coefficient": 0.5,
             "leakage.conductance_to_atmosphere": 3e-10, "leakage.cross_piston": 3e-9}
    ref = synth.rich_reference(4, 1.6)
    runs = [foreign_rig.simulate(plant_file, ref, 1.6, overrides=every, rtol=rtol)[1]
            for rtol in (1e-6, 1e-9)]
    assert np.ptp(runs[1][:, 0]) > 0.05                          # it moved
    assert np.max(np.abs(runs[0][:, 0] - runs[1][:, 0])) < 1e-6
    assert np.max(np.abs(runs[0][:, 2:] - runs[1][:, 2:])) < 2.0


def test_foreign_rig_lugre_converges(tmp_path):
    """The LuGre friction law (stiff bristles, 0.1 mm pre-sliding) integrates as finely
    as the rest: rtol 1e-6 against 1e-9 within 1 um and 2 Pa (1 % of an LSB)."""
    plant_file = synth.concealed_case("none", seed=0).write_nominal(tmp_path / "plant.toml")
    ref = synth.rich_reference(4, 1.6)
    fr = {"coulomb": 22.0, "static": 31.0, "stribeck": 0.012, "law": "lugre"}
    runs = [foreign_rig.simulate(plant_file, ref, 1.6, friction=fr, rtol=rtol)[1]
            for rtol in (1e-6, 1e-9)]
    assert np.ptp(runs[1][:, 0]) > 0.05
    assert np.max(np.abs(runs[0][:, 0] - runs[1][:, 0])) < 1e-6
    assert np.max(np.abs(runs[0][:, 2:] - runs[1][:, 2:])) < 2.0
