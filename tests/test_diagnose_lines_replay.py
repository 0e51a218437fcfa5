"""The diagnosis engine's replay of a plant with long pneumatic lines (issue 12).

With the concealed structure valve_offset + line_dynamics the engine's short-horizon
replay of the *exact* model missed the position by tenths of a millimetre, which the
set search then explained with a spurious valve lag. The causes, measured on a
noise-free closed-loop recording of 4 m of 3 mm tubing made by
:func:`workbench.simulate.closed_loop` (CVODES, 16 segments; x rms over 0.2 s windows,
``/tmp/h12g/exp14.py``):

* not a model difference: from the true full state the engine converges on CVODES
  (3.3 um rms at 16 sub-steps of the 2 ms step in this file's test window);
* the 2 ms ROS2 step at command steps: the line's segment modes (0.25 m of tube:
  ~0.7 ms acoustic time) are far faster than the step, and a window that starts a
  reference step misses by 0.45 mm rms at one step per sample, 0.09 mm at four;
* the first window of a recording starts its hidden states at rest (line flows 0) while
  the piston moves: 2.3 mm rms in that window, 37 um from the true state.
Carrying the line states over from one window to the next is not a cause: at the window
starts they are within 0.5 kPa and a few % of the flow of the true ones.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench import Plant, controllers, simulate
from workbench.diagnose import synth
from workbench.diagnose.engine import INPUT_ROWS, Engine, EngineInputs

R = {n: i for i, n in enumerate(INPUT_ROWS)}
H = 0.002         # s: the refits' engine step at 1 kHz


def _line_run(length, diameter, segments=None):
    """1.2 s of the 25 mm rig with ``length`` m of ``diameter`` m tubing per side and a
    0.15 V valve offset, in closed loop on a step at 0.5 s, simulated by CVODES (all
    states kept)."""
    vals = {"valve.null_offset": 0.15, "lines.length": length, "lines.diameter": diameter}
    if segments:
        vals["lines.segments"] = segments
    plant = synth.concealed_case("none", seed=3, values=vals).plant
    pid = controllers.from_plant(plant)
    t = np.arange(1201) * 1e-3

    def ref(tt):
        return np.where(np.asarray(tt) < 0.5, 0.15, 0.3)
    run = simulate.closed_loop(plant, pid, ref, t_end=t[-1], x0=plant.initial_state(0.15),
                               output_times=t, progress=False)
    return plant, t, np.asarray(run.states), np.asarray(run["u"])


@pytest.fixture(scope="module")
def line_run():
    """4 m of 3 mm tubing, 16 segments (the plant file's default: one per 0.25 m)."""
    return _line_run(4.0, 0.003)


def _window(plant, S, u, k0, n, substeps):
    """x over n engine steps of H from the true full state at sample k0, open loop on the
    recorded command (held over each 2-sample step: it changes every 10 samples)."""
    d = np.zeros((len(INPUT_ROWS), n))
    d[R["u_rec"]] = u[k0:k0 + 2 * n:2]
    eng = Engine(plant, H, None, substeps=substeps, jit=False, chunk=n)
    return eng.run(S[k0], EngineInputs(d), plant.p0)[0]


def test_engine_converges_on_cvodes_with_lines(line_run):
    """The window from 0.46 s (the reference step at 0.5 s: the valve opens fully) from
    the true state: at 16 ROS2 steps per sample the engine is within 10 um of
    CVODES over 0.2 s (measured 5.6 um max, 3.3 um rms), so the engine and
    ``workbench.simulate`` integrate the same line model. At one ROS2 step per sample
    the same window missed by 0.81 mm max (0.50 mm rms): the step, not the model, is
    what the replay got wrong there."""
    plant, t, S, u = line_run
    k0, n = 460, 100
    x_ref = S[k0:k0 + 2 * n:2, plant.state_index("x")]
    from workbench.diagnose.engine import LINE_SUBSTEPS
    sub = max(16 // LINE_SUBSTEPS, 1)
    assert np.max(np.abs(_window(plant, S, u, k0, n, sub) - x_ref)) < 10e-6


def test_candidate_line_structure_needs_four_steps_per_sample():
    """The diagnosis's line candidate (3 segments per line), 3 m of 4 mm tubing, the same
    window from the true state: four ROS2 steps per 2 ms sample are within 60 um rms of
    CVODES (measured 36.8 um), one step per sample is not within 0.3 mm (measured
    615 um: the mismatch the set search explained with a valve lag). The engine takes
    :data:`~workbench.diagnose.engine.LINE_SUBSTEPS` steps per sample for a line
    structure; the test asks for four in all (and one) whatever that default is."""
    from workbench.diagnose.engine import LINE_SUBSTEPS
    plant, t, S, u = _line_run(3.0, 0.004, segments=3)
    k0, n = 460, 100
    x_ref = S[k0:k0 + 2 * n:2, plant.state_index("x")]

    def rms(total):
        if total % LINE_SUBSTEPS:
            pytest.skip(f"LINE_SUBSTEPS = {LINE_SUBSTEPS} does not divide {total}")
        e = _window(plant, S, u, k0, n, total // LINE_SUBSTEPS) - x_ref
        return float(np.sqrt(np.mean(e ** 2)))
    assert rms(4) < 60e-6
    if LINE_SUBSTEPS == 1:
        assert rms(1) > 300e-6
