"""The NMPC's whole sample as one compiled C call (modes ``rti`` and ``sqp``).

:class:`CompiledNMPC` runs exactly what :func:`.update.advance` does: scale the
measurement, extrapolate the reference to the nodes (with a ``preview``: the node
reference made in Python by :func:`.nodes.node_reference`, ~10 us) and project it onto
the admissible stroke, shift the previous plan, update the
force estimate, linearise and condense, solve the QP, update the plan, fall back to
a cold start and then to the shifted previous plan on failure. Of the Gauss-Newton
step (:func:`.qp.sqp_step`: prep, QP, post) the linearisation (:func:`.qp.intervals`)
and post (:func:`.qp.apply_step`) are generated as C by CasADi; a hand-written C
driver (:mod:`.fast_c`) does the rest of the sample: the condensing (what
:func:`.qp.condense` computes, by the block recursion, with the rows of the limits
between the nodes), and the QP, by DAQP's own C library (the
static ``libdaqpstat.a`` shipped with CasADi, linked in) on the rows that may be
active: the previous sample's working set, and the rows its solution violates (the
same optimum as on all rows; see :mod:`.fast_c`).
With lumped lines (:mod:`.lines`) the line states' Kalman step is generated as C
too and called by the driver at the start of the sample (its covariance kept in the
memory): one C call per sample for the filter and the SQP (with the filter a separate
CasADi call from Python, two segments per line took 1.03 ms CPU per sample).
Python does per sample: four numbers into a preallocated buffer, one ctypes call,
the command returned as a float; no array or memory object is made after the first
sample.

The step is built on the Problem's CasADi functions (:func:`.qp.intervals`,
:func:`.qp.apply_step`), so a change of the model flows in; the driver replicates
:mod:`.update`'s sample logic and :func:`.qp.condense`'s QP (its settings layout and
soft limits read from the problem, checked at build), and tests hold the two to the
same plans on closed loops (to 1e-8: the QP's optimum is the same, its rounding not).

The memory (:class:`CompiledMemory`) is one float buffer, updated **in place** by
each ``update`` (the returned state is the one passed in): a memory must not be
used for two runs at once, and one controller must not run in two threads at once.
"""

from __future__ import annotations

import ctypes
import os
from math import isfinite
import sys
import tempfile
import weakref
from pathlib import Path

import casadi as ca
import numpy as np

from ...errors import InputError
from ...integrate.jit import (MINMAX, CompileError, cache_dir, have_compiler,
                              inline_minmax, shared_library, source_digest)
from .model import NMPC_STATES, V_SCALE
from .nodes import admissible, node_reference
from .fast_c import DRIVER, config
from .lines import line_filter, line_start
from .qp import SQP_CONTRACTION, SQP_DAMPING, apply_step, daqp_primal_tol, intervals
from .results import StepInfo

__all__ = ["CompiledNMPC", "CompiledMemory", "compiled_unavailable"]

#: compiled NMPCs of one horizon alive at once in a process (the generated functions'
#: memory pool)
_MAX_LIVE = 64
#: C compiler flags of the step (no -ffast-math: the step tests for NaN; -fno-math-errno
#: lets sqrt be one instruction: nothing reads errno; -fno-semantic-interposition lets
#: the compiler inline CasADi's runtime helpers (casadi_sq, casadi_sign, ...) into the
#: interval maps of a shared library: 22 -> 15 us of linearisation a sample at N = 20,
#: with fmax / fmin inlined too, :func:`_inline_minmax`); without it if the compiler
#: refuses it
_FLAGS = tuple(os.environ.get("WB_FAST_FLAGS",
                              "-O2 -fno-math-errno -fno-semantic-interposition").split())
_FLAGS_FALLBACK = tuple(f for f in _FLAGS if f != "-fno-semantic-interposition")
#: scaled units: a row left out of DAQP's QP is added when violated by more (fast_c)
QP_TOL = 1e-9
#: rounds of constraint generation before the full QP is solved cold (fast_c)
QP_ROUNDS = 8
#: DAQP started from the working set (its ``sense`` warm start), cold if that fails
QP_WARM = True


def compiled_unavailable() -> str | None:
    """None when the compiled step can be built here, else why not."""
    if not have_compiler():
        return "no C compiler found (set CC)"
    if not _daqp_paths():
        return "this CasADi installation lacks DAQP's headers or static library"
    return None


def _daqp_paths() -> tuple[str, str] | None:
    """(include directory, libdaqpstat.a) shipped with CasADi, or None."""
    root = Path(ca.__file__).resolve().parent
    inc, lib = root / "include", root / "libdaqpstat.a"
    if (inc / "daqp" / "api.h").is_file() and lib.is_file():
        return str(inc), str(lib)
    return None


def _source(pb) -> str:
    """The generated interval linearisation and post followed by the driver (which
    condenses and calls DAQP)."""
    nz, nc = pb.N + pb.ns, pb.n_rows
    funs = [intervals(pb), apply_step(pb)]
    _check_layout(pb, *funs)
    if pb.lines:                    # the lumped lines' filter, called by the driver
        funs.append(line_filter(pb, pb.c.pressure_noise))
    with tempfile.TemporaryDirectory(prefix="wb_fast_") as tmp:
        gen = ca.CodeGenerator("wb_fast.c", {"with_header": False})
        for f in funs:
            gen.add(f)
        gen.generate(tmp + os.sep)
        generated = Path(tmp, "wb_fast.c").read_text()
    generated = _inline_minmax(generated)
    names = config(pb.nx)
    cfg = "\n".join(f"#define C_{k} {i}" for i, k in enumerate(names))
    return generated + DRIVER % {
        "N": pb.N, "NX": pb.nx, "NP": pb.P.size, "CFG": cfg, "NCFG": len(names), "NZ": nz,
        "NC": nc,
        "NRN": 2 * pb.N * len(pb.soft), "MINT": pb.m_int,
        "KI0": pb.first_interior, "PRIMAL_TOL": daqp_primal_tol(pb) or 0.0, "QP_TOL": QP_TOL,
        "QP_ROUNDS": QP_ROUNDS, "QP_WARM": int(QP_WARM), "SQP_CONTRACTION": SQP_CONTRACTION,
        "SQP_DAMPING": SQP_DAMPING, **_settings_layout(pb),
        "NSOFT": len(pb.soft), "SOFT_I": ", ".join(str(i) for i, _ in pb.soft),
        "SOFT_J": ", ".join(str(j) for _, j in pb.soft), "W_LO": float(pb.w_lo),
        "W_HI": float(pb.w_hi), "LSTART": _line_start_sources(pb.nx)}


def _line_start_sources(nx: int) -> str:
    """The driver's LSTART: per lumped line state, the index of the scaled measurement
    it starts at (2 p_a, 3 p_b) or -1 (zero), read from :func:`.lines.line_start`."""
    if nx <= len(NMPC_STATES):
        return ""
    z, _ = line_start(np.array([0.0, 0.0, 2.0, 3.0]), nx)
    return ", ".join(str(int(v)) if v else "-1" for v in z[len(NMPC_STATES):])


#: fmax / fmin inlined (~230 calls per interval map at N = 20), from the JIT module
_MINMAX, _inline_minmax = MINMAX, inline_minmax


def _settings_layout(pb) -> dict[str, int]:
    """Offsets of the cost weights and limits in the settings vector P, read from
    :meth:`Problem.unpack` (the driver's condensing indexes P by them)."""
    idx = pb.unpack(np.arange(pb.P.size))
    names = ("P_WX", "P_WV", "P_WDU", "P_RHO1", "P_RHO2", "P_LO", "P_HI")
    sizes = (pb.N, pb.N, 1, 1, 1, pb.nx, pb.nx)
    out = {}
    for name, part, n in zip(names, idx, sizes):
        part = np.atleast_1d(part)
        if part.size != n or np.any(np.diff(part) != 1):
            raise CompileError("the NMPC's settings vector changed its layout; the compiled "
                               "sample's condensing (controllers.mpc.fast_c) must follow")
        out[name] = int(part[0])
    return out


def _check_layout(pb, lin, post) -> None:
    """The driver passes the linearisation's outputs to its condensing and to post as
    dense buffers of the condensed QP's sizes: refuse a problem whose functions no
    longer fit that (rather than compute nonsense)."""
    N, nx, m = pb.N, pb.nx, pb.m_int
    shapes = [(nx, N + 1), (1, N), (1, 1), (nx, nx * N), (nx, N), (nx, N), (nx, 1)]
    shapes += [(nx, N * m), (nx, nx * N * m), (nx, N * m)] if m else []
    post_in = [(nx, N + 1), (1, N), (nx, N + 1), (nx * (N + 1), N), (N + pb.ns, 1)]
    dense = [lin.sparsity_out(i) for i in range(lin.n_out())]
    dense += [post.sparsity_out(i) for i in range(post.n_out())]
    if (lin.n_out() != len(shapes) or post.n_out() != 6
            or any(lin.sparsity_out(i).shape != s for i, s in enumerate(shapes))
            or any(post.sparsity_in(i).shape != s for i, s in enumerate(post_in))
            or not all(sp.is_dense() for sp in dense)):
        raise CompileError("the NMPC's linearisation / post functions changed their layout; "
                           "the compiled sample's driver (controllers.mpc.fast) must follow")


class CompiledMemory:
    """The memory of :class:`CompiledNMPC` between samples: one float buffer.

    Attributes (views, SI where stated): ``X`` (nx, N + 1) and ``U`` (N,) the plan,
    scaled as in :class:`~.results.NMPCState`; ``u_prev`` scaled command applied;
    ``r_prev`` m; ``z`` (nx,) scaled measured state (and lumped lines' estimate); ``d`` N
    force estimate; ``t`` s; ``line_cov`` (nl^2,) covariance of the lumped lines'
    estimate (:mod:`.lines`; None before the first sample or without lines);
    :attr:`info` the last update's :class:`~.results.StepInfo`; ``working_set``
    (N + ns bounds, then the QP's rows: +1 upper, -1 lower, 0 inactive) the last QP's
    active constraints, the warm start of the next.
    """

    def __init__(self, N: int, size: int, nx: int = 4) -> None:
        self.buf = np.zeros(size)
        self.ptr = self.buf.ctypes.data
        self.N, self.nx = N, nx
        n = nx * (N + 1) + N
        it = n + 5 + nx
        nl = nx - len(NMPC_STATES)
        pl = size - 1 - nl * nl                        # the driver's M_PL, M_PLOK after it
        self._off = {"u_prev": n, "r_prev": n + 1, "z": n + 2, "d": n + 2 + nx,
                     "t": n + 3 + nx, "it": it, "qps": it + 9 + nx, "ws": it + 12 + nx,
                     "pl": pl}

    @property
    def line_cov(self) -> np.ndarray | None:
        if self.nx == len(NMPC_STATES) or self.buf[-1] == 0.0:
            return None
        return self.buf[self._off["pl"]:-1]

    @line_cov.setter
    def line_cov(self, cov) -> None:
        if self.nx == len(NMPC_STATES):
            return
        if cov is None:
            self.buf[-1] = 0.0
        else:
            self.buf[self._off["pl"]:-1] = np.asarray(cov, dtype=float).ravel()
            self.buf[-1] = 1.0

    def _at(self, name: str) -> int:
        return self._off[name]

    @property
    def X(self) -> np.ndarray:
        nx = self.nx
        return self.buf[:nx * (self.N + 1)].reshape(self.N + 1, nx).T

    @property
    def U(self) -> np.ndarray:
        n = self.nx * (self.N + 1)
        return self.buf[n:n + self.N]

    u_prev = property(lambda self: float(self.buf[self._at("u_prev")]))
    r_prev = property(lambda self: float(self.buf[self._at("r_prev")]))
    z = property(lambda self: self.buf[self._at("z"):self._at("z") + self.nx])
    d = property(lambda self: float(self.buf[self._at("d")]))
    t = property(lambda self: float(self.buf[self._at("t")]))

    def phase_times(self) -> tuple[float, float, float, float, float]:
        """s (wall) of the last sample: the linearisation (shift, estimate, interval
        maps), the condensing, the QP (DAQP), post (plan update), each summed over the
        sample's Gauss-Newton steps, and the whole sample in C."""
        i = self._at("it") + 4 + self.nx
        t = self.buf[i:i + 4]
        return float(t[0]), float(t[1]), float(t[2]), float(t[3]), float(self.buf[i - 1])

    @property
    def working_set(self) -> np.ndarray:
        return self.buf[self._at("ws"):self._off["pl"]]

    def qp_counts(self) -> tuple[int, int, int]:
        """The last sample's DAQP calls, rows given to DAQP in all (of the QP's rows,
        the rest checked; see :mod:`.fast_c`) and full QPs solved cold (fallbacks)."""
        q = self.buf[self._at("qps"):self._at("qps") + 3]
        return int(q[0]), int(q[1]), int(q[2])

    def step_info(self, pb, solve_time: float | None = None) -> StepInfo:
        """The last update's report, violations in SI units; its solve time the C
        sample's, or ``solve_time`` (s) if given."""
        i = self._off["it"]
        it, ok, restarted = self.buf[i:i + 3]
        v = self.buf[i + 3:i + 7].tolist()
        ts = float(self.buf[i + 3 + self.nx])
        return StepInfo(iterations=int(it), success=bool(ok),
                        solve_time=ts if solve_time is None else solve_time,
                        restarted=bool(restarted), slack_stroke=max(v[0], 0.0) * pb.L,
                        slack_pressure=max(v[2], v[3]) * pb.p_sup,
                        slack_speed=v[1] * V_SCALE if pb.c.max_speed is not None else 0.0)


class CompiledNMPC:
    """An :class:`~.controller.NMPC` (mode rti or sqp) whose every sample
    is one compiled C call; same plans as the NMPC itself (see the module text).

    Parameters
    ----------
    nmpc : NMPC
        The controller to run; its settings and problem are used as they are.

    Raises
    ------
    InputError
        Mode ipopt, or a QP solver other than DAQP (the only one whose C
        library is linked into the step).
    workbench.integrate.jit.CompileError
        No C compiler, or CasADi without DAQP's C library (:func:`compiled_unavailable`).
    """

    needs = NMPC_STATES

    def __init__(self, nmpc) -> None:
        if nmpc.mode not in ("rti", "sqp"):
            raise InputError(f"the compiled NMPC step runs modes rti and sqp, not {nmpc.mode!r}")
        if nmpc.qp_solver != "daqp":
            raise InputError(f"the compiled NMPC step links DAQP; qp_solver is {nmpc.qp_solver!r}")
        why = compiled_unavailable()
        if why:
            raise CompileError(f"the compiled NMPC step cannot be built: {why}")
        self.nmpc, self.sample_time = nmpc, nmpc.sample_time
        self.pb = pb = nmpc._problem
        inc, lib = _daqp_paths()
        more = (f"-I{inc}", f"-DCASADI_MAX_NUM_THREADS={_MAX_LIVE}")
        flags, fallback = (*_FLAGS, *more), (*_FLAGS_FALLBACK, *more)
        src = _source(pb)
        name = f"wb_fast_n{pb.N}"
        if not (cache_dir() / f"{name}_{source_digest(src.encode(), [*flags, lib])}.so").exists():
            print(f"NMPC: compiling its sample to C (N = {pb.N}; once, then cached in "
                  f"{cache_dir()}) ...", file=sys.stderr, flush=True)
        path, _ = shared_library(name, src, (flags, fallback), libs=(lib,))
        self._lib = so = ctypes.CDLL(str(path))
        so.wb_fast_new.restype = ctypes.c_void_p
        so.wb_fast_new.argtypes = [ctypes.c_void_p]
        so.wb_fast_free.argtypes = [ctypes.c_void_p]
        so.wb_fast_sample.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                      ctypes.c_double, ctypes.c_void_p]
        so.wb_fast_sample.restype = ctypes.c_int
        so.wb_fast_sample_ref.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                          ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p]
        so.wb_fast_sample_ref.restype = ctypes.c_int
        self._msize = int(so.wb_fast_memory_size())
        c = nmpc
        vals = {**{f"sx{i}": pb.sx[i] for i in range(pb.nx)}, "L": pb.L,
                "T": pb.T, "rate_limit": c.reference_rate_limit, "r_lo": c.stroke_margin,
                "r_hi": pb.L - c.stroke_margin, "max_it": c.max_iterations,
                "tol": c.tolerance, "rti": float(c.mode == "rti"),
                "warm": float(c.warm_start), "u_c": pb.u_c, "u_s": pb.u_s, "v_scale": V_SCALE}
        self._cfg = np.concatenate([[float(vals[k]) for k in config(pb.nx)], pb.P])
        if self._cfg.size != so.wb_fast_config_size():
            raise CompileError("the compiled NMPC step does not match its settings")
        self._h = so.wb_fast_new(self._cfg.ctypes.data)
        if not self._h:
            raise MemoryError(f"the compiled NMPC step could not allocate its work (at most "
                              f"{_MAX_LIVE} compiled NMPCs of one horizon alive at once)")
        weakref.finalize(self, so.wb_fast_free, self._h)
        self._y = np.zeros(len(NMPC_STATES))
        self._u = np.zeros(1)
        self._yp, self._up = self._y.ctypes.data, self._u.ctypes.data
        self._call = so.wb_fast_sample
        self._call_ref = so.wb_fast_sample_ref
        self._rv = np.zeros(2 * (pb.N + 1))

    @property
    def kind(self) -> str:
        return f"NMPC ({self.nmpc.mode}, N = {self.nmpc.horizon}, compiled sample)"

    def memory(self, plan=None) -> CompiledMemory:
        """A fresh memory: before the first sample (``plan`` None), or holding ``plan``
        = (X (4, N + 1), U (1, N), u_prev, r_prev, z (4,), d, t[, working set]) of an
        :class:`~.results.NMPCState` (scaled as there; r_prev m, d N, t s; the QP's
        working set, :attr:`CompiledMemory.working_set`, or None: none active)."""
        mem = CompiledMemory(self.pb.N, self._msize, self.pb.nx)
        if plan is not None:
            X, U, u_prev, r_prev, z, d, t, *ws = plan
            if ws and ws[0] is not None:                 # only a warm start: else none
                ws = np.asarray(ws[0], dtype=float).ravel()
                if ws.size == mem.working_set.size:
                    mem.working_set[:] = ws
            n, b = self.pb.nx * (self.pb.N + 1), mem.buf
            b[:n] = np.asarray(X, dtype=float).ravel(order="F")
            b[n:n + self.pb.N] = np.asarray(U, dtype=float).ravel()
            b[mem._at("u_prev")], b[mem._at("r_prev")] = u_prev, r_prev
            b[mem._at("z"):mem._at("z") + self.pb.nx] = z
            b[mem._at("d")], b[mem._at("t")] = d, t
            b[mem._at("t") + 1] = 1.0                  # started
        return mem

    def reset(self) -> None:
        """No memory before the first sample (it starts from rest at the measured state)."""
        return None

    def update(self, state: CompiledMemory | None, r: float, y: dict):
        """(memory, command in V) from the reference (m) and measured x, v, p_a, p_b (SI).

        The memory passed in is updated in place and returned (a new one at the first
        sample).
        """
        if state is None:
            state = CompiledMemory(self.pb.N, self._msize, self.pb.nx)
        yy = self._y
        try:
            yy[0], yy[1], yy[2], yy[3] = y["x"], y["v"], y["p_a"], y["p_b"]
        except KeyError as exc:
            raise InputError(f"the NMPC needs the measured {exc} (it measures x, v, p_a, p_b)") from None
        if not (isfinite(yy[0]) and isfinite(yy[1]) and isfinite(yy[2]) and isfinite(yy[3])
                and isfinite(r)):
            bad = [k for k, v in (*zip(NMPC_STATES, yy), ("reference", r)) if not isfinite(v)]
            raise InputError(f"the NMPC got a measurement or reference that is not a finite "
                             f"number: {', '.join(bad)}")
        if self.nmpc.preview is None:
            self._call(self._h, state.ptr, self._yp, r, self._up)
        else:
            self._node_reference(state, r)
            self._call_ref(self._h, state.ptr, self._yp, r, self._rv.ctypes.data, self._up)
        if self.pb.valve is not None:                  # planned in the compensated command
            return state, self.pb.valve(self._u[0])
        return state, self._u[0]

    def _node_reference(self, state: CompiledMemory, r: float) -> None:
        """The previewed node reference (scaled) into the buffer the C sample reads."""
        pb, N = self.pb, self.pb.N
        started = state.buf[state._at("t") + 1] != 0.0
        t = state.t + pb.T if started else 0.0
        R, VR = admissible(pb, *node_reference(pb, r, state.r_prev if started else None, t))
        self._rv[:N + 1] = R / pb.L
        self._rv[N + 1:] = VR / V_SCALE

    def info(self, state: CompiledMemory) -> StepInfo:
        """The last update's report (:class:`~.results.StepInfo`)."""
        return state.step_info(self.pb)
