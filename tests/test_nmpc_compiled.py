"""The NMPC sample as one compiled C call (workbench.controllers.mpc.fast) against the
NMPC itself (workbench.controllers.mpc.update): same plans on a closed loop.

Speed is measured by ``workbench bench mpc``, not here. A short horizon (N = 5) keeps
the C source small (compiled once per cache, ~10 s on a loaded machine).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench import Plant
from workbench.controllers.mpc import NMPC
from workbench.controllers.mpc.fast import CompiledNMPC, compiled_unavailable
from workbench.errors import InputError
from workbench.simulate import Simulator

from nmpc_loop import NAMES, loop_difference

ROOT = Path(__file__).resolve().parents[1]
RIG25 = ROOT / "designs" / "plants" / "rig25_mpye.toml"

pytestmark = pytest.mark.skipif(compiled_unavailable() is not None,
                                reason=f"compiled NMPC step: {compiled_unavailable()}")


@pytest.fixture(scope="module")
def rig25():
    return Plant.from_toml(RIG25)


@pytest.fixture(scope="module")
def nmpc(rig25):
    # the force observer on (its estimate is part of the memory compared), N = 5; the
    # defaults otherwise (limits between the nodes too: 3 points per interval)
    return NMPC.for_plant(rig25, horizon=5, sample_time=0.01, jit=False)


@pytest.fixture(scope="module")
def fast(nmpc):
    return CompiledNMPC(nmpc)


def _reference(k: int) -> float:
    """m on the 0.5 m stroke: hold, a 100 mm step (a jump: held over the horizon), a
    0.1 m/s ramp (extrapolated), then a step to 0.47 m and a 0.3 m/s ramp through the
    stroke margin (0.49 m) to beyond the stroke (projected onto the margin, velocity 0)."""
    if k < 5:
        return 0.10
    if k < 50:
        return 0.20
    if k < 90:
        return 0.20 + 0.1 * 0.01 * (k - 50)
    if k < 120:
        return 0.47
    return 0.47 + 0.3 * 0.01 * (k - 120)


def _compare(rig25, ours, ref, samples: int, counts: list | None = None) -> float:
    """Largest difference of plan, command, force estimate and iterations over a closed
    loop driven by the reference NMPC, both fed the same measurements (``counts``: the
    compiled sample's QP counts per sample appended)."""
    def extra(sa, sf):
        info = ours.info(sf) if isinstance(ours, CompiledNMPC) else sf.info
        if counts is not None:
            counts.append(sf.qp_counts())
        assert info.iterations == sa.info.iterations and info.success == sa.info.success
        assert info.restarted == sa.info.restarted
        return abs(sa.u_prev - sf.u_prev)
    return loop_difference(rig25, ref, ours, samples, _reference, extra)


def test_compiled_rti_gives_the_same_plans(rig25, nmpc, fast):
    # Same arithmetic in the same order (the step is the same CasADi graph, DAQP the
    # same C library): equal to rounding; 1e-8 (scaled units, force / 100 N) leaves
    # room for a compiler that contracts multiply-adds, and a wrong node reference,
    # shift or estimate differs by > 1e-3.
    assert _compare(rig25, fast, nmpc, 140) <= 1e-8


def test_compiled_sqp_gives_the_same_plans(rig25, nmpc, fast):
    # mode and iteration limit are settings of the same library (no second compile)
    sqp = nmpc.with_settings(mode="sqp", max_iterations=4)
    assert _compare(rig25, CompiledNMPC(sqp), sqp, 60) <= 1e-8


def test_compiled_sample_follows_a_preview(rig25, nmpc):
    # with the whole reference known (the reference _reference(k) at t = k T, its
    # jumps and ramps previewed over the horizon) the node reference comes from Python
    def preview(t):
        k = np.floor(np.asarray(t, dtype=float) / 0.01 + 1e-9).astype(int)
        return np.array([_reference(int(i)) for i in np.ravel(k)]).reshape(np.shape(t))
    pv = nmpc.with_settings(preview=preview)
    counts = []
    assert _compare(rig25, CompiledNMPC(pv), pv, 140, counts) <= 1e-8
    # the same plans although DAQP saw only the rows of the last working set and those
    # its solution violated (fast_c): on this loop limits were active (rows given),
    # rows were added (a second DAQP call in an RTI sample), and the QP was never
    # solved on all its rows (136: 2 x 4 limits x (5 nodes + 4 x 3 points between
    # them); the rows given: a sum over a sample's DAQP calls)
    calls, rows, full = np.array(counts).T
    assert pv._problem.n_rows == 136
    assert rows.sum() > 0 and calls[5:].max() >= 2 and full.sum() == 0
    assert np.all(rows < 136 * calls)


def test_compiled_sample_with_limits_between_the_nodes(rig25, nmpc):
    # limits also at the RK4 substep between two nodes (two substeps: one point each;
    # the fixture's default has three), the rows condensed by the driver
    il = nmpc.with_settings(interior_limits=True, substeps=2)
    counts = []
    assert _compare(rig25, CompiledNMPC(il), il, 140, counts) <= 1e-8
    assert np.array(counts)[:, 1].sum() > 0                 # limits were active


def test_full_qp_fallback_without_a_speed_limit(rig25, nmpc, monkeypatch):
    # three soft limits (stroke, p_a, p_b) instead of four: the driver's condensing
    # reads the soft limits and the settings' layout from the problem. And no round of
    # constraint generation allowed: every QP is the full one, solved cold (the
    # driver's fallback when the reduced QPs do not settle or DAQP fails on them).
    # One build for both (each build costs seconds).
    from workbench.controllers.mpc import fast as fast_mod
    monkeypatch.setattr(fast_mod, "QP_ROUNDS", 0)
    free = nmpc.with_settings(max_speed=None)
    assert free._problem.ns == 2 and len(free._problem.soft) == 3
    counts = []
    assert _compare(rig25, CompiledNMPC(free), free, 140, counts) <= 1e-8
    calls, rows, full = np.array(counts).T
    n_rows = free._problem.n_rows                  # 2 x 3 limits x (5 nodes + 4 x 3 points)
    assert n_rows == 102 and np.all(full == calls) and np.all(rows == n_rows * calls)


def test_plans_stay_inside_the_command_range(rig25, nmpc, fast):
    # the model clips the spool at the command limits (sensitivity 1 inside, 0.5 at
    # the limit): a plan at the limit is kept INSIDE it, so that its linearisation does
    # not depend on the rounding of the QP's step. The 100 mm step saturates the valve.
    from workbench.controllers.mpc.qp import INSIDE
    pb, sim = fast.pb, Simulator(rig25)
    x, mem, lo = rig25.initial_state(0.10), None, []
    for k in range(30):
        y = {n: float(x[rig25.state_index(n)]) for n in NAMES}
        mem, u = fast.update(mem, 0.10 if k < 5 else 0.30, y)
        lo.append(mem.U.min())
        x = sim.step(x, float(np.clip(u, 0.0, 10.0)), 0.01)[-1]
    assert min(lo) == pytest.approx(pb.w_lo + INSIDE, abs=1e-15)   # saturated ...
    assert min(lo) > pb.w_lo                                         # ... inside


def test_compiled_memory_reports_the_last_sample(rig25, fast):
    y = {"x": 0.2, "v": 0.0, "p_a": 4e5, "p_b": 4e5}
    mem, u = fast.update(None, 0.25, y)
    assert fast.info(mem).success and fast.info(mem).iterations >= 1
    # the plan starts at the measured state, its first command is the one applied
    assert np.allclose(mem.X[:, 0] * fast.pb.sx, [0.2, 0.0, 4e5, 4e5], rtol=1e-12)
    assert u == pytest.approx(fast.pb.u_c + fast.pb.u_s * mem.U[0], rel=1e-14)
    assert mem.r_prev == 0.25 and mem.t == 0.0
    # the phases are timed inside the sample: each > 0, together within the sample
    lin, cond, qp, post, whole = mem.phase_times()
    assert min(lin, cond, qp, post) > 0.0 and lin + cond + qp + post <= whole
    mem2, _ = fast.update(mem, 0.25, y)
    assert mem2 is mem and mem.t == pytest.approx(0.01)
    with pytest.raises(InputError, match="p_b"):
        fast.update(mem, 0.25, {"x": 0.2, "v": 0.0, "p_a": 4e5})
    with pytest.raises(InputError, match="p_a"):
        fast.update(mem, 0.25, {"x": 0.2, "v": 0.0, "p_a": float("nan"), "p_b": 4e5})
    with pytest.raises(InputError, match="reference"):
        fast.update(mem, float("inf"), y)


def test_compiled_step_refuses_what_it_does_not_run(nmpc):
    with pytest.raises(InputError, match="ipopt"):
        CompiledNMPC(nmpc.with_settings(mode="ipopt"))
    with pytest.raises(InputError, match="DAQP"):
        CompiledNMPC(nmpc.with_settings(qp_solver="qrqp"))


def test_nmpc_update_runs_the_compiled_sample(rig25, nmpc):
    # NMPC itself (jit on, the default compiled_sample) runs each update as one C call
    # and gives the plans of the Python update (jit off: CasADi's virtual machine);
    # the memory goes through an NMPCState every sample (copied in and out)
    on = nmpc.with_settings(jit=True)
    assert on.compiled_reason is None
    assert on.kind == nmpc.kind
    assert _compare(rig25, on, nmpc, 140) <= 1e-8
    y = {"x": 0.2, "v": 0.0, "p_a": 4e5, "p_b": 4e5}
    s1, _ = on.update(None, 0.25, y)
    X1 = np.asarray(s1.X).copy()
    s2, _ = on.update(s1, 0.30, y)
    assert np.array_equal(np.asarray(s1.X), X1)           # the state passed in is kept
    assert s2.t == pytest.approx(0.01) and s2.r_prev == 0.30 and s2.info.success
    # the QP's working set travels in the state: the next sample's QP starts from it
    pb = on._problem
    assert s2.working_set.shape == (pb.N + pb.ns + pb.n_rows,)
    assert np.all(np.isin(s2.working_set, (-1.0, 0.0, 1.0)))
    # the buffer behind the last state is updated in place (update.py), so a state
    # used twice (a branch) must give the same sample both times
    s3, u3 = on.update(s2, 0.35, y)
    s3b, u3b = on.update(s2, 0.35, y)                      # s2 is no longer the last
    assert u3 == u3b and np.array_equal(s3.X, s3b.X) and np.array_equal(s3.U, s3b.U)
    s4, _ = on.update(s3, 0.40, y)                         # back on the first branch
    s4b, _ = on.update(s3b, 0.40, y)
    assert np.array_equal(s4.X, s4b.X) and s4.t == s4b.t == pytest.approx(0.03)
    with pytest.raises(ValueError):                        # read-only: not read back
        s4.X[0, 0] = 0.3


@pytest.mark.parametrize("jit", [False, True])
def test_nmpc_update_names_a_bad_measurement(nmpc, jit):
    # the Python update (jit off) as the compiled sample: an InputError naming the
    # input, not CasADi's assertion on a NaN
    c = nmpc.with_settings(jit=jit)
    y = {"x": 0.2, "v": 0.0, "p_a": 4e5, "p_b": 4e5}
    s, _ = c.update(None, 0.25, y)
    with pytest.raises(InputError, match="p_a"):
        c.update(s, 0.25, {**y, "p_a": float("nan")})
    with pytest.raises(InputError, match="x"):
        c.update(s, 0.25, {**y, "x": float("-inf")})
    with pytest.raises(InputError, match="reference"):
        c.update(s, float("nan"), y)
    with pytest.raises(InputError, match="v"):
        c.update(s, 0.25, {k: y[k] for k in ("x", "p_a", "p_b")})
    s2, _ = c.update(s, 0.25, y)                           # the memory is intact
    assert s2.info.success and s2.t == pytest.approx(0.01)


def test_nmpc_says_why_it_runs_in_python(nmpc):
    assert "jit" in nmpc.compiled_reason
    assert "compiled_sample" in nmpc.with_settings(jit=True, compiled_sample=False).compiled_reason
    assert "ipopt" in nmpc.with_settings(jit=True, mode="ipopt").compiled_reason


def test_inlined_fmax_fmin_match_libm():
    # the compiled sample replaces CasADi's calls of libm's fmax / fmin by the macros of
    # fast._MINMAX (inlined: 7 us a sample at N = 20); on finite values, infinities and
    # NaN (either side: the other operand) they must give libm's result exactly
    import ctypes
    from workbench.controllers.mpc.fast import _MINMAX, _inline_minmax
    from workbench.integrate.jit import shared_library
    src = ("#include <math.h>\n" + _MINMAX
           + "int wb_check(const double *v, int n) { int i, j, bad = 0;\n"
           "  for (i = 0; i < n; ++i) for (j = 0; j < n; ++j) {\n"
           "    double a = WB_FMAX(v[i], v[j]), b = fmax(v[i], v[j]);\n"
           "    double c = WB_FMIN(v[i], v[j]), d = fmin(v[i], v[j]);\n"
           "    if (!((a == b) || (a != a && b != b)) || !((c == d) || (c != c && d != d))) ++bad;\n"
           "  } return bad; }\n")
    path, _ = shared_library("wb_test_minmax", src)
    v = np.array([-np.inf, -2.5, -1e-300, 0.0, 3.0, 7.0, np.inf, np.nan])
    assert ctypes.CDLL(str(path)).wb_check(v.ctypes.data_as(ctypes.c_void_p), len(v)) == 0
    # and the replacement is made where CasADi's runtime calls them
    out = _inline_minmax("x\n  return fmax(x, y);\n  return fmin(x, y);\n")
    assert "WB_FMAX(x, y)" in out and "WB_FMIN(x, y)" in out and "return fmax" not in out



def test_any_warm_start_gives_the_same_plan(rig25, nmpc, fast):
    # the working set is only DAQP's starting guess: the QP solved is the full one
    # (rows left out are checked and added), so a working set of another QP gives the
    # plan of no working set: rows marked active on their infinite side (a lower row
    # as upper; what a working set shifted by the wrong rows once gave: DAQP then
    # returned a NaN step as optimal, the sample failed and restarted cold), and
    # random marks
    pb = fast.pb
    x = rig25.initial_state(0.30)
    y = {n: float(x[rig25.state_index(n)]) for n in NAMES}
    y["v"] = 0.4                                       # a limit active over the plan
    ref, _ = fast.update(fast.memory(None), 0.47, y)
    plan = (ref.X.copy(), ref.U[None, :].copy(), ref.u_prev, 0.47, ref.z.copy(), ref.d, ref.t)
    base, _ = fast.update(fast.memory(plan + (None,)), 0.47, y)
    assert base.qp_counts()[1] > 0                      # rows were active
    nz, n = pb.N + pb.ns, pb.N
    wrong = []
    for row in range(2 * n * len(pb.soft)):             # blocks: lower, upper, ...
        ws = base.working_set.copy()
        ws[nz + row] = 1.0 if (row // n) % 2 == 0 else -1.0    # marked at its infinite side
        wrong.append(ws)
    rng = np.random.default_rng(0)
    for ws in wrong + [rng.choice([-1.0, 0.0, 1.0], size=wrong[0].size) for _ in range(4)]:
        got, _ = fast.update(fast.memory(plan + (ws,)), 0.47, y)
        assert fast.info(got).success and not fast.info(got).restarted
        assert np.max(np.abs(got.U - base.U)) <= 1e-8
        assert np.max(np.abs(got.X - base.X)) <= 1e-8
