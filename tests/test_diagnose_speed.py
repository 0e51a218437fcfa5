"""``workbench bench diagnose`` reports CPU seconds that include the worker processes.

The candidate refits run in worker processes, so the CPU time of a diagnosis is mostly
theirs; on a loaded machine it is the steadier figure than wall time. Checked against
a child process that burns a known amount of CPU (measured by itself, independently).
"""

from __future__ import annotations

import subprocess
import sys

from workbench.bench.diagnose import _cpu

BURN = ("import time\n"
        "t0 = time.process_time()\n"
        "while time.process_time() - t0 < 0.4:\n"
        "    pass\n"
        "print(time.process_time() - t0)\n")


def test_cpu_seconds_include_finished_child_processes():
    """A child that burns 0.4 s of CPU (by its own clock) raises _cpu() by at least
    that (plus the interpreter's start-up, so no upper bound that load could break
    other than a generous 5 s)."""
    before = _cpu()
    out = subprocess.run([sys.executable, "-c", BURN], capture_output=True, text=True,
                         check=True)
    burned = float(out.stdout)
    grown = _cpu() - before
    assert burned >= 0.4
    assert burned - 0.02 <= grown < burned + 5.0


# ---------------------------------------------------------------- the refits' Jacobian
# The engine's forward sensitivities (Engine.run_sensitivity, used by the refits with
# refit.EXACT_JACOBIAN) against central differences of plain replays, on a 2 s
# recording of the synthetic rig without dry friction (no stick-slip, no deadband
# edge), evaluated by CasADi's virtual machine (jit=False: no C compiler run in the
# suite). Compared on the first 0.8 s of short-horizon predictions (four windows):
# later in this recording (0.91 s) one 2 ms ROS2 step moves x by -36 um where eight
# sub-steps give +15 um (the piston starting to move under a 1.4e7 Pa/s pressure
# rise: a local error of the coarse step that the engine's guard does not catch), and
# the next step returns; there central differences read slopes of 0.9 m per unit at a
# step of 1e-7 (a jump of 0.2 um in the replay, cause not found) -- not a derivative
# to compare with.

import numpy as np
import pytest


@pytest.fixture(scope="module")
def smooth_model():
    from workbench.diagnose import synth
    from workbench.diagnose.candidates import candidates
    from workbench.diagnose.data import prepare
    from workbench.diagnose.nominal import predictors
    from workbench.diagnose.refit import CandidateModel
    from workbench.diagnose.sets import combine
    from workbench.plant import Plant
    case = synth.concealed_case("leakage", seed=3)
    rec = synth.record(case, seed=3, duration=2.0)
    plant = Plant(case.nominal).with_friction("stick")
    prep = prepare(plant, rec)
    shpe, _ = predictors(prep)
    by = {c.name: c for c in candidates(plant.params)}
    cand = combine([by["leakage"], by["parameter_error:load.mass"]])
    model = CandidateModel(prep, plant.params, cand, jit=False)
    from workbench.diagnose.engine import EngineInputs
    shpe.index = shpe.index[:400]
    shpe.inputs = EngineInputs(shpe.inputs.data[:, :400])
    shpe.starts = shpe.starts[shpe.starts < 400]
    return prep, shpe, cand, model


def test_engine_sensitivities_are_the_derivative_of_the_replay(smooth_model):
    """dY/dz of x, p_a, p_b from one sensitivity pass equals central differences of
    two plain passes per direction, within 1e-3 relative in the norm. The step, 1e-3
    in z, is where the difference's own error is smallest: it grows as the step
    shrinks (measured 1.7e-4 at 1e-3, 1.6e-2 at 1e-5, 0.15 at 1e-6 for the cross-piston
    leak, whose slopes are small against the replay's round-off), so it is round-off,
    not the sensitivities; a wiring error (seed order, chunking, a missed parameter)
    is of order 1. The values of the pass are those of a plain pass (the same
    arithmetic, 1e-9 relative)."""
    from workbench.diagnose.refit import directions
    prep, shpe, cand, model = smooth_model
    z = cand.z0() + np.array([0.3, 0.1, 0.05])        # off the bounds, not at the start
    vals = cand.values(z)
    D = directions(cand, model.plant, vals)
    Y, dY = model.engine.run_sensitivity(model.z0, shpe.inputs, model.pvec(vals), D)
    Y0 = model.run(shpe, vals)
    assert np.allclose(Y[:3], Y0[:3], rtol=1e-9, atol=1e-9)
    h = 1e-3
    for j in range(cand.k):
        zp, zm = z.copy(), z.copy()
        zp[j] += h
        zm[j] -= h
        fd = (model.run(shpe, cand.values(zp))[:3] - model.run(shpe, cand.values(zm))[:3]) / (2 * h)
        for row in range(3):
            ref = np.linalg.norm(fd[row])
            assert ref > 0, (j, row)
            assert np.linalg.norm(dY[row, j] - fd[row]) <= 1e-3 * ref, (cand.free[j].key, row)


def test_exact_objective_jacobian_matches_its_residuals(smooth_model):
    """The refit objective's exact Jacobian (residual weights, decimation, transforms)
    against central differences of its own residual vector, same step and bound."""
    from workbench.diagnose.refit import _Objective
    prep, shpe, cand, model = smooth_model
    obj = _Objective(model, cand, shpe, exact=True)
    z = cand.z0() + np.array([0.3, 0.1, 0.05])
    J = obj.jacobian(z)
    h = 1e-3
    fd = np.column_stack([(obj(z + h * e) - obj(z - h * e)) / (2 * h) for e in np.eye(cand.k)])
    assert J.shape == fd.shape == (len(obj(z)), cand.k)
    assert np.linalg.norm(J - fd) <= 1e-3 * np.linalg.norm(fd)


def test_parameter_directions_are_the_chain_rule(smooth_model):
    """d(parameter vector)/dz, analytic (log and scaled values, the static friction
    derived as coulomb (1 + excess)), against central differences of the candidate's
    own mapping z -> plant values -> parameter vector (bilinear after the transforms:
    differences of 1e-6 are exact to round-off, 1e-8 relative)."""
    from workbench.diagnose.candidates import candidates
    from workbench.diagnose.refit import CandidateModel, directions
    from workbench.diagnose.sets import combine
    prep, _, _, _ = smooth_model
    by = {c.name: c for c in candidates(prep.plant.params)}
    for cand in (by["dry_friction"], combine([by["dry_friction"], by["leakage"]]),
                 by["parameter_error:supply.pressure"]):
        model = CandidateModel(prep, prep.plant.params, cand, jit=False)
        z = cand.z0() + 0.2
        D = directions(cand, model.plant, cand.values(z))
        h = 1e-6
        for j in range(cand.k):
            zp, zm = z.copy(), z.copy()
            zp[j] += h
            zm[j] -= h
            fd = (model.pvec(cand.values(zp)) - model.pvec(cand.values(zm))) / (2 * h)
            assert np.allclose(D[:, j], fd, rtol=1e-6, atol=1e-8 * np.abs(fd).max()), \
                (cand.name, cand.free[j].key)


def test_one_blas_thread_within_a_diagnosis():
    """diagnose() runs with one OpenBLAS thread (blas.single_thread): every OpenBLAS
    numpy and scipy ship reports 1 inside, its former count after (no BLAS found, e.g.
    another platform: nothing to check, nothing changed)."""
    from workbench.diagnose.blas import _libraries, single_thread
    libs = _libraries()
    before = [int(get()) for get, _ in libs]
    with single_thread():
        assert all(int(get()) == 1 for get, _ in libs)
    assert [int(get()) for get, _ in libs] == before


# ---------------------------------------------------------------- one C source per structure
# The replay's C source is compiled once per plant structure and kept by its hash
# (workbench.integrate.jit). A parameter value written into it as a literal makes
# every value of it a new source and a new gcc run: the guards' supply pressure was
# one (a fitted supply pressure's start values). It is an input now (Engine.guard).

def _guard_engines(scales):
    from workbench.diagnose import synth
    from workbench.diagnose.engine import Engine
    from workbench.plant import Plant
    base = synth.nominal_params()
    p_s = float(base["supply.pressure"])
    return [Engine(Plant(base.replace(**{"supply.pressure": p_s * s})), 1e-3, None, jit=False,
                   chunk=100) for s in scales]


def _c_source(fun) -> str:
    import os
    import tempfile
    import casadi as ca
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator("f.c", {"with_header": False})
        gen.add(fun)
        gen.generate(tmp + os.sep)
        with open(os.path.join(tmp, "f.c")) as fh:
            return fh.read()


def test_engine_source_does_not_depend_on_the_supply_pressure():
    """Plants that differ only in their supply pressure (by the last bit, as a log
    transform's round trip moves it, and by 10 %) give the same C source; planted bug:
    the guards' literal ``prm["supply.pressure"]`` back in ``_error_too_large`` -> red."""
    a, b, c = _guard_engines((1.0, 1.0 - 2.0 ** -52, 0.9))
    assert _c_source(a._fun) == _c_source(b._fun) == _c_source(c._fun)
    assert a.guard != b.guard != c.guard


def test_engine_guard_is_the_only_supply_pressure_it_keeps():
    """Two engines built at supply pressures 10 % apart replay the same parameter vector
    bit-identically once the guard is the same, and differently with their own guards
    where a guard decides (the ``inexact`` row: the local error measured against
    1e-4 of the supply pressure): the guard is an input that counts, and the plant's
    supply pressure is kept nowhere else. The command swings the valve fully open both
    ways, so the pressures move fast and the local error crosses the thresholds."""
    from workbench.diagnose.engine import EngineInputs, INPUT_ROWS
    a, b = _guard_engines((1.0, 0.9))
    t = np.arange(300) * 1e-3
    u = np.where((t // 0.05) % 2 == 0, 9.5, 0.5)
    d = np.zeros((len(INPUT_ROWS), len(t)))
    d[INPUT_ROWS.index("u_rec")] = u
    z0 = a.plant.initial_state(0.5 * a.plant.stroke)
    ya = a.run(z0, EngineInputs(d), a.plant.p0)
    yb = b.run(z0, EngineInputs(d), a.plant.p0)
    inexact = a.rows.index("inexact")
    assert np.all(np.isfinite(ya[:4]))
    b_own = b.guard
    b.guard = a.guard
    try:
        yb_a = b.run(z0, EngineInputs(d), a.plant.p0)
        b.guard = 1e-3 * b_own           # thresholds 1000x tighter: every moving step flags
        tight = b.run(z0, EngineInputs(d), a.plant.p0)
    finally:
        b.guard = b_own
    assert np.array_equal(ya, yb_a, equal_nan=True)
    assert tight[inexact].sum() > ya[inexact].sum()
    assert not np.array_equal(yb[inexact], tight[inexact])


def test_engine_input_chunks_are_the_padded_columns():
    """The inputs laid out once per chunk size (EngineInputs.chunks, each chunk's
    columns one after the other) are the columns in order, the last chunk padded with
    the last column without its anchoring; neither the data nor a chunk can be changed
    under the cache (read-only). Planted: a chunk offset by one column, or the padding
    left anchored -> red."""
    from workbench.diagnose.engine import EngineInputs, INPUT_ROWS
    rng = np.random.default_rng(1)
    d = rng.uniform(0.5, 1.5, (len(INPUT_ROWS), 23))
    inp = EngineInputs(d)
    chunks = inp.chunks(10)
    assert len(chunks) == 3 and inp.chunks(10) is chunks          # made once
    got = np.hstack([c.reshape(len(INPUT_ROWS), 10, order="F") for c in chunks])
    assert np.array_equal(got[:, :23], d)
    anchors = [INPUT_ROWS.index(r) for r in ("anchor", "anchor_hidden", "anchor_p")]
    others = [i for i in range(len(INPUT_ROWS)) if i not in anchors]
    assert np.all(got[anchors, 23:] == 0.0)
    assert np.array_equal(got[others, 23:], np.repeat(d[others, -1:], 7, axis=1))
    for a in (inp.data, chunks[0]):
        with pytest.raises(ValueError):
            a[0] = 2.0
