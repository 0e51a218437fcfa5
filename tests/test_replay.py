"""workbench.replay: the one replay of a recording, its strategies checked against
simulate's own closed- and open-loop simulations (independent entry points)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench import Plant, controllers, simulate
from workbench import replay as rp
from workbench.errors import InputError, WorkbenchError
from workbench.recording import Recording

from conftest import PLANTS


@pytest.fixture(scope="module")
def plant() -> Plant:
    return Plant.from_toml(PLANTS / "rig25_mpye.toml")


@pytest.fixture(scope="module")
def closed_run(plant):
    """0.6 s of the plant file's PD loop on two steps, sampled at 1 ms."""
    t = np.arange(601) * 1e-3
    return simulate.closed_loop(plant, controllers.from_plant(plant),
                                simulate.steps([0.2, 0.3], hold=0.3), t_end=0.6, x0=0.25,
                                output_times=t, progress=False)


@pytest.fixture(scope="module")
def rec(closed_run):
    return Recording.from_arrays(closed_run.time, u=closed_run["u"], r=closed_run.reference,
                                 x=closed_run["x"], p_a=closed_run["p_a"], p_b=closed_run["p_b"])


def test_closed_loop_reproduces_the_loop_that_made_the_recording(plant, closed_run, rec):
    # same model, controller, reference and initial state: only the reference's
    # sampling (held at 1 ms vs the step function) differs, and the steps fall on
    # samples, so the replay is the same CVODES run to its tolerance (rtol 1e-7);
    # 1 um is 100x the expected difference on a 0.1 m step
    run = rp.run(plant, rec, rp.ClosedLoop(), x0=closed_run.states[0])
    assert np.max(np.abs(run["x"] - closed_run["x"])) < 1e-6


def test_open_loop_strategies_agree(plant, rec):
    # per sample (simulate.open_loop) and per run of equal commands (Simulator.hold)
    # are the same integrator at the same tolerances: ~1e-5 of full scale apart
    x0 = rp.initial_state(plant, rec)
    a = rp.run(plant, rec, rp.OpenLoop(steps="sample"), x0=x0)
    b = rp.run(plant, rec, rp.OpenLoop(steps="run"), x0=x0)
    assert np.max(np.abs(a["x"] - b["x"])) < 1e-6
    assert np.max(np.abs(a["p_a"] - b["p_a"])) < 10.0


def test_anchored_open_loop_restarts_on_the_anchors(plant, rec):
    # anchors taken from a free replay: re-anchoring on them changes nothing beyond the
    # integrator's tolerance; anchors shifted by 1 mm show up exactly at the anchor
    free = rp.run(plant, rec, rp.OpenLoop(steps="run"))
    every = 100
    anchors = free.states[::every].copy()
    same = rp.run(plant, rec, rp.OpenLoop(steps="run", anchor_every=every), x0=anchors)
    assert np.max(np.abs(same["x"] - free["x"])) < 1e-6
    ix = plant.state_names.index("x")
    anchors[:, ix] += 1e-3
    moved = rp.run(plant, rec, rp.OpenLoop(steps="run", anchor_every=every), x0=anchors)
    # (an anchor on the last sample starts no interval, so it is not applied)
    np.testing.assert_allclose(moved["x"][:-1:every], free["x"][:-1:every] + 1e-3, atol=1e-12)


def test_initial_state_takes_the_recorded_or_given_pressures(plant, rec):
    st = rp.initial_state(plant, rec)
    names = plant.state_names
    assert st[names.index("p_a")] == rec["p_a"][0]
    given = rp.initial_state(plant, rec, p_a=4e5, p_b=3e5)
    assert given[names.index("p_a")] == 4e5 and given[names.index("p_b")] == 3e5
    # without recorded pressures: the equilibrium of plant.initial_state
    eq = rp.initial_state(plant, rec, recorded_pressures=False)
    np.testing.assert_array_equal(eq, plant.initial_state(float(rec["x"][0])))


def test_fallback_and_bad_options(plant, rec):
    def failing(*args):
        raise WorkbenchError("CVODES failed")

    def second(plant, recording, x0, params, progress):
        return {"x": np.zeros(3)}

    assert rp.run(plant, rec, rp.Fallback(failing, second))["x"].shape == (3,)
    with pytest.raises(InputError):
        rp.OpenLoop(steps="per-sample")
    with pytest.raises(InputError):
        rp.OpenLoop(steps="sample", anchor_every=10)
    with pytest.raises(InputError, match="replay mode"):
        rp.is_closed(plant, rec, "sometimes")
    assert rp.is_closed(plant, rec, "auto") and not rp.is_closed(plant, rec, "open")


@pytest.mark.parametrize("scale, hint", [(1e3, "mm"), (2.4, "stroke"), (1.0, None)])
def test_library_replay_checks_the_recording_against_the_plant(plant, scale, hint):
    # issue 15: the CLI checked recordings, the library entry point did not -- a position
    # in mm (x = 250 on a 0.5 m stroke) was clipped to the stroke and replayed silently
    t = np.arange(0.0, 0.2, 0.01)
    x = np.full_like(t, 0.25) * scale
    rec = Recording.from_arrays(t, u=np.full_like(t, plant.params["valve.command_center"]),
                                x=x)
    if hint is None:                                   # SI: replays
        assert rp.replay(plant, rec, mode="open", progress=False).recording.has("x")
        return
    with pytest.raises(InputError, match=hint):
        rp.replay(plant, rec, mode="open", progress=False)
