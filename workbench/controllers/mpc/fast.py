"""The NMPC's whole sample as one compiled C call (modes ``rti`` and ``sqp``).

:class:`CompiledNMPC` runs exactly what :func:`.update.advance` does: scale the
measurement, extrapolate the reference to the nodes (with a ``preview``: the node
reference made in Python by :func:`.nodes.node_reference`, ~10 us) and project it onto
the admissible stroke, shift the previous plan, update the
force estimate, linearise and condense, solve the QP, update the plan, fall back to
a cold start and then to the shifted previous plan on failure. The Gauss-Newton step
(:func:`.qp.sqp_step`: prep, DAQP, post) is generated as C by CasADi with the QP
solver inside (DAQP's own C library, the static ``libdaqpstat.a`` shipped with
CasADi, linked in); a hand-written C driver around it does the rest of the sample.
Python does per sample: four numbers into a preallocated buffer, one ctypes call,
the command returned as a float; no array or memory object is made after the first
sample.

The step is built on the Problem's CasADi functions (:func:`.qp.prepare`,
:func:`.qp.apply_step`), so a change of the problem (constraints, model) flows in;
the driver replicates :mod:`.update`'s sample logic, and a test holds the two to
the same plans on a closed loop.

The memory (:class:`CompiledMemory`) is one float buffer, updated **in place** by
each ``update`` (the returned state is the one passed in): a memory must not be
used for two runs at once, and one controller must not run in two threads at once.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
import weakref
from pathlib import Path

import casadi as ca
import numpy as np

from ...errors import InputError
from ...integrate.jit import (CompileError, cache_dir, have_compiler, shared_library,
                              source_digest)
from .model import NMPC_STATES, V_SCALE
from .nodes import admissible, node_reference
from .qp import apply_step, prepare, qp_solver
from .results import StepInfo

__all__ = ["CompiledNMPC", "CompiledMemory", "compiled_unavailable"]

#: offsets in the configuration vector of the driver (after them: the settings P)
_CFG = ("sx0", "sx1", "sx2", "sx3", "L", "T", "rate_limit", "r_lo", "r_hi", "max_it",
        "tol", "rti", "warm", "u_c", "u_s", "v_scale")

#: compiled NMPCs of one horizon alive at once in a process (the QP's memory pool)
_MAX_LIVE = 64
#: C compiler flags of the step (no -ffast-math: the step tests for NaN; -fno-math-errno
#: lets sqrt be one instruction: nothing reads errno; 10 % off the interval maps)
_FLAGS = tuple(os.environ.get("WB_FAST_FLAGS", "-O2 -fno-math-errno").split())

_DRIVER = r"""
/* ---- driver: one NMPC sample around the generated step (workbench.controllers.mpc.fast) */
#include <stdlib.h>
#include <string.h>
#include <time.h>
#define NX 4
#define NN %(N)d
#define NP %(NP)d
#define NXN (NX * (NN + 1))
#define NZ %(NZ)d
#define NC %(NC)d
%(CFG)s
#define C_P %(NCFG)d
/* memory layout */
#define M_X 0
#define M_U (M_X + NXN)
#define M_UPREV (M_U + NN)
#define M_RPREV (M_UPREV + 1)
#define M_Z (M_RPREV + 1)
#define M_D (M_Z + NX)
#define M_T (M_D + 1)
#define M_STARTED (M_T + 1)
#define M_IT (M_STARTED + 1)
#define M_OK (M_IT + 1)
#define M_RESTARTED (M_OK + 1)
#define M_VIOL (M_RESTARTED + 1)
#define M_TIME (M_VIOL + NX)
#define M_TPHASE (M_TIME + 1)   /* s, of the last sample: prep, QP, post; then samples */
#define M_SIZE (M_TPHASE + 4)

typedef struct {
  const casadi_real **arg; casadi_real **res; casadi_int *iw; casadi_real *w;
  int mem[3];
  double cfg[C_P + NP];
  double X[NXN], U[NN], Xn[NXN], Un[NN], u0, viol[NX], ok, stp, dd;
  double R[NN + 1], VR[NN + 1], zm[NX], zp[NX];
  /* the QP between prep and post */
  double H[NZ * NZ], g[NZ], A[NC * NZ], lba[NC], uba[NC], lbx[NZ], ubx[NZ];
  double hh[NXN], G[NXN * NN], Xs[NXN], Us[NN], dw[NZ];
  double tphase[3];
} wb_fast_t;

static double now(void) {
  struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int wb_fast_memory_size(void) { return M_SIZE; }
int wb_fast_config_size(void) { return C_P + NP; }

void wb_fast_free(wb_fast_t *h) {
  if (!h) return;
  if (h->mem[0] >= 0) { wb_nmpc_prep_release(h->mem[0]); wb_nmpc_prep_decref(); }
  if (h->mem[1] >= 0) { wb_nmpc_qp_release(h->mem[1]); wb_nmpc_qp_decref(); }
  if (h->mem[2] >= 0) { wb_nmpc_post_release(h->mem[2]); wb_nmpc_post_decref(); }
  free(h->arg); free(h->res); free(h->iw); free(h->w); free(h);
}

#define WB_MAX(a, b) ((a) > (b) ? (a) : (b))
wb_fast_t *wb_fast_new(const double *cfg) {
  casadi_int sz[3][4], na = 12, nr = 12, ni = 1, nw = 1; int k;
  wb_fast_t *h = (wb_fast_t *)calloc(1, sizeof(wb_fast_t));
  if (!h) return 0;
  h->mem[0] = h->mem[1] = h->mem[2] = -1;
  wb_nmpc_prep_work(&sz[0][0], &sz[0][1], &sz[0][2], &sz[0][3]);
  wb_nmpc_qp_work(&sz[1][0], &sz[1][1], &sz[1][2], &sz[1][3]);
  wb_nmpc_post_work(&sz[2][0], &sz[2][1], &sz[2][2], &sz[2][3]);
  for (k = 0; k < 3; ++k) {
    na = WB_MAX(na, sz[k][0]); nr = WB_MAX(nr, sz[k][1]);
    ni = WB_MAX(ni, sz[k][2]); nw = WB_MAX(nw, sz[k][3]);
  }
  h->arg = (const casadi_real **)malloc(sizeof(casadi_real *) * na);
  h->res = (casadi_real **)malloc(sizeof(casadi_real *) * nr);
  h->iw = (casadi_int *)malloc(sizeof(casadi_int) * ni);
  h->w = (casadi_real *)malloc(sizeof(casadi_real) * nw);
  wb_nmpc_prep_incref(); h->mem[0] = wb_nmpc_prep_checkout();
  wb_nmpc_qp_incref(); h->mem[1] = wb_nmpc_qp_checkout();
  wb_nmpc_post_incref(); h->mem[2] = wb_nmpc_post_checkout();
  if (!h->arg || !h->res || !h->iw || !h->w || h->mem[0] < 0 || h->mem[1] < 0
      || h->mem[2] < 0) { wb_fast_free(h); return 0; }
  memcpy(h->cfg, cfg, sizeof(double) * (C_P + NP));
  return h;
}

/* one Gauss-Newton step from h->X, h->U (qp.sqp_step: prep, QP, post, each timed);
   1 on success (then h->Xn, h->Un are the plan) */
static int step(wb_fast_t *h, double sh, double up, double dprev, double est) {
  int i; double t0 = now(), t1, t2;
  const double *a[11];
  a[0] = h->X; a[1] = h->U; a[2] = &sh; a[3] = h->zm; a[4] = h->R; a[5] = h->VR; a[6] = &up;
  a[7] = h->zp; a[8] = &dprev; a[9] = &est; a[10] = h->cfg + C_P;
  for (i = 0; i < 11; ++i) h->arg[i] = a[i];
  h->res[0] = h->H; h->res[1] = h->g; h->res[2] = h->A; h->res[3] = h->lba;
  h->res[4] = h->uba; h->res[5] = h->lbx; h->res[6] = h->ubx; h->res[7] = h->hh;
  h->res[8] = h->G; h->res[9] = h->Xs; h->res[10] = h->Us; h->res[11] = &h->dd;
  if (wb_nmpc_prep(h->arg, h->res, h->iw, h->w, h->mem[0])) return 0;
  t1 = now();
  h->arg[0] = h->H; h->arg[1] = h->g; h->arg[2] = h->A; h->arg[3] = h->lba;
  h->arg[4] = h->uba; h->arg[5] = h->lbx; h->arg[6] = h->ubx;
  for (i = 7; i < 12; ++i) h->arg[i] = 0;          /* no initial guess, no q, p */
  h->res[0] = h->dw;
  for (i = 1; i < 4; ++i) h->res[i] = 0;
  if (wb_nmpc_qp(h->arg, h->res, h->iw, h->w, h->mem[1])) return 0;
  t2 = now();
  h->arg[0] = h->Xs; h->arg[1] = h->Us; h->arg[2] = h->hh; h->arg[3] = h->G;
  h->arg[4] = h->dw; h->arg[5] = h->cfg + C_P;
  h->res[0] = h->Xn; h->res[1] = h->Un; h->res[2] = &h->u0; h->res[3] = h->viol;
  h->res[4] = &h->ok; h->res[5] = &h->stp;
  if (wb_nmpc_post(h->arg, h->res, h->iw, h->w, h->mem[2])) return 0;
  h->tphase[0] += t1 - t0; h->tphase[1] += t2 - t1; h->tphase[2] += now() - t2;
  return h->ok != 0.0;
}

/* up to iters steps (update.py's _sqp): the estimate is updated in the first only */
static int sqp(wb_fast_t *h, int shift, double up, double *dprev, double *est, int iters,
               double *d, int *ok) {
  int it; double sh = shift ? 1.0 : 0.0;
  *ok = 0; *d = *dprev;
  for (it = 1; it <= iters; ++it) {
    *ok = step(h, sh, up, *dprev, *est);
    if (it == 1) { *d = *dprev = h->dd; *est = 0.0; }
    if (!*ok) break;
    memcpy(h->X, h->Xn, sizeof(double) * NXN); memcpy(h->U, h->Un, sizeof(double) * NN);
    sh = 0.0;
    if (h->stp < h->cfg[C_tol]) break;
  }
  return it > iters ? iters : it;
}

static void cold(wb_fast_t *h) {
  int k, i;
  for (k = 0; k <= NN; ++k) for (i = 0; i < NX; ++i) h->X[i + NX * k] = h->zm[i];
  for (k = 0; k < NN; ++k) h->U[k] = 0.0;
}

/* the node reference (update.node_reference without preview, then admissible) */
static void reference(wb_fast_t *h, double r, int started, double r_prev) {
  const double *c = h->cfg; int k;
  double T = c[C_T], rate = started ? (r - r_prev) / T : 0.0;
  if (!(fabs(rate) <= c[C_rate_limit])) rate = 0.0;
  for (k = 0; k <= NN; ++k) {
    double R = r + rate * T * (double)k, VR = rate;
    if (R < c[C_r_lo] || R > c[C_r_hi]) VR = 0.0;
    R = R < c[C_r_lo] ? c[C_r_lo] : R;
    R = R > c[C_r_hi] ? c[C_r_hi] : R;
    h->R[k] = R / c[C_L]; h->VR[k] = VR / c[C_v_scale];
  }
}

/* one sample: memory m updated in place, command (V) in *u; returns 1 on success.
   RV: the node reference given (scaled position, then velocity, N + 1 each: the
   preview, made by the caller) or 0 (extrapolated from r here) */
int wb_fast_sample_ref(wb_fast_t *h, double *m, const double *y, double r, const double *RV,
                       double *u) {
  const double *c = h->cfg; struct timespec t0, t1;
  int started = m[M_STARTED] != 0.0, warm, ok = 0, restarted = 0, it = 0, i, k, iters;
  double up, dprev, est, d;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (i = 0; i < NX; ++i) h->zm[i] = y[i] / c[C_sx0 + i];
  if (RV) {
    memcpy(h->R, RV, sizeof(double) * (NN + 1)); memcpy(h->VR, RV + NN + 1, sizeof(double) * (NN + 1));
  } else reference(h, r, started, m[M_RPREV]);
  if (started) {
    up = m[M_UPREV]; dprev = m[M_D]; est = 1.0;
    for (i = 0; i < NX; ++i) h->zp[i] = m[M_Z + i];
  } else {
    up = 0.0; dprev = 0.0; est = 0.0;
    for (i = 0; i < NX; ++i) h->zp[i] = h->zm[i];
  }
  d = dprev;
  warm = started && c[C_warm] != 0.0;
  if (warm) {
    memcpy(h->X, m + M_X, sizeof(double) * NXN); memcpy(h->U, m + M_U, sizeof(double) * NN);
    it = sqp(h, 1, up, &dprev, &est, c[C_rti] != 0.0 ? 1 : (int)c[C_max_it], &d, &ok);
  }
  if (!ok) {
    restarted = warm;
    iters = (!started || c[C_rti] == 0.0 || restarted) ? (int)c[C_max_it] : 1;
    cold(h);
    it = sqp(h, 0, up, &dprev, &est, iters, &d, &ok);
  }
  if (!ok) {                              /* the previous plan, shifted (or rest) */
    if (!started) cold(h);
    else {
      for (k = 0; k < NN; ++k) for (i = 0; i < NX; ++i) h->X[i + NX * k] = m[M_X + i + NX * (k + 1)];
      for (i = 0; i < NX; ++i) h->X[i + NX * NN] = m[M_X + i + NX * NN];
      for (k = 0; k < NN - 1; ++k) h->U[k] = m[M_U + k + 1];
      h->U[NN - 1] = m[M_U + NN - 1];
    }
  }
  memcpy(m + M_X, h->X, sizeof(double) * NXN); memcpy(m + M_U, h->U, sizeof(double) * NN);
  m[M_UPREV] = h->U[0]; m[M_RPREV] = r; m[M_D] = d;
  m[M_T] = started ? m[M_T] + c[C_T] : 0.0;
  for (i = 0; i < NX; ++i) { m[M_Z + i] = h->zm[i]; m[M_VIOL + i] = ok ? h->viol[i] : 0.0; }
  m[M_STARTED] = 1.0; m[M_IT] = it; m[M_OK] = ok; m[M_RESTARTED] = restarted;
  *u = c[C_u_c] + c[C_u_s] * h->U[0];
  clock_gettime(CLOCK_MONOTONIC, &t1);
  m[M_TIME] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  for (i = 0; i < 3; ++i) { m[M_TPHASE + i] = h->tphase[i]; h->tphase[i] = 0.0; }
  m[M_TPHASE + 3] += 1.0;
  return ok;
}

int wb_fast_sample(wb_fast_t *h, double *m, const double *y, double r, double *u) {
  return wb_fast_sample_ref(h, m, y, r, 0, u);
}
"""


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
    """The generated step (prep, DAQP, post) followed by the driver."""
    nz, nc = pb.N + pb.ns, pb.n_rows
    funs = (prepare(pb), qp_solver("daqp", nz, nc), apply_step(pb))
    _check_layout(*funs)
    with tempfile.TemporaryDirectory(prefix="wb_fast_") as tmp:
        gen = ca.CodeGenerator("wb_fast.c", {"with_header": False})
        for f in funs:
            gen.add(f)
        gen.generate(tmp + os.sep)
        generated = Path(tmp, "wb_fast.c").read_text()
    cfg = "\n".join(f"#define C_{k} {i}" for i, k in enumerate(_CFG))
    return generated + _DRIVER % {"N": pb.N, "NP": pb.P.size, "CFG": cfg, "NCFG": len(_CFG),
                                  "NZ": nz, "NC": nc}


def _check_layout(prep, qp, post) -> None:
    """The driver passes prep's outputs to the QP and to post as dense buffers: refuse
    a problem whose functions no longer fit that (rather than compute nonsense)."""
    pairs = [(prep.sparsity_out(i), qp.sparsity_in(i)) for i in range(7)]
    pairs += [(prep.sparsity_out(a), post.sparsity_in(b))
              for a, b in ((9, 0), (10, 1), (7, 2), (8, 3))]
    pairs.append((qp.sparsity_out(0), post.sparsity_in(4)))
    dense = [prep.sparsity_out(i) for i in range(prep.n_out())]
    dense += [post.sparsity_out(i) for i in range(post.n_out())]
    if (prep.n_out() != 12 or post.n_out() != 6 or any(a != b for a, b in pairs)
            or not all(sp.is_dense() for sp in dense)):
        raise CompileError("the NMPC's prep / QP / post functions changed their layout; "
                           "the compiled sample's driver (controllers.mpc.fast) must follow")


class CompiledMemory:
    """The memory of :class:`CompiledNMPC` between samples: one float buffer.

    Attributes (views, SI where stated): ``X`` (4, N + 1) and ``U`` (N,) the plan,
    scaled as in :class:`~.results.NMPCState`; ``u_prev`` scaled command applied;
    ``r_prev`` m; ``z`` (4,) scaled measured state; ``d`` N force estimate; ``t`` s;
    :attr:`info` the last update's :class:`~.results.StepInfo`.
    """

    def __init__(self, N: int, size: int) -> None:
        self.buf = np.zeros(size)
        self.ptr = self.buf.ctypes.data
        self.N = N

    def _at(self, name: str) -> int:
        n = 4 * (self.N + 1)
        return {"u_prev": n + self.N, "r_prev": n + self.N + 1, "z": n + self.N + 2,
                "d": n + self.N + 6, "t": n + self.N + 7, "it": n + self.N + 9}[name]

    @property
    def X(self) -> np.ndarray:
        return self.buf[:4 * (self.N + 1)].reshape(self.N + 1, 4).T

    @property
    def U(self) -> np.ndarray:
        n = 4 * (self.N + 1)
        return self.buf[n:n + self.N]

    u_prev = property(lambda self: float(self.buf[self._at("u_prev")]))
    r_prev = property(lambda self: float(self.buf[self._at("r_prev")]))
    z = property(lambda self: self.buf[self._at("z"):self._at("z") + 4])
    d = property(lambda self: float(self.buf[self._at("d")]))
    t = property(lambda self: float(self.buf[self._at("t")]))

    def phase_times(self) -> tuple[float, float, float, float]:
        """s (wall) of the last sample: the compiled prep (shift, estimate, interval
        maps, condensing), the QP (DAQP), post (plan update), each summed over the
        sample's Gauss-Newton steps, and the whole sample in C."""
        i = self._at("it") + 8
        t = self.buf[i:i + 3]
        return float(t[0]), float(t[1]), float(t[2]), float(self.buf[i - 1])

    def step_info(self, pb) -> StepInfo:
        """The last update's report, violations in SI units."""
        i = self._at("it")
        it, ok, restarted = self.buf[i:i + 3]
        v = self.buf[i + 3:i + 7]
        return StepInfo(iterations=int(it), success=bool(ok), solve_time=float(self.buf[i + 7]),
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
        flags = (*_FLAGS, f"-I{inc}", f"-DCASADI_MAX_NUM_THREADS={_MAX_LIVE}")
        src = _source(pb)
        name = f"wb_fast_n{pb.N}"
        if not (cache_dir() / f"{name}_{source_digest(src.encode(), [*flags, lib])}.so").exists():
            print(f"NMPC: compiling its sample to C (N = {pb.N}; once, then cached in "
                  f"{cache_dir()}) ...", file=sys.stderr, flush=True)
        path, _ = shared_library(name, src, (flags,), libs=(lib,))
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
        vals = {"sx0": pb.sx[0], "sx1": pb.sx[1], "sx2": pb.sx[2], "sx3": pb.sx[3], "L": pb.L,
                "T": pb.T, "rate_limit": c.reference_rate_limit, "r_lo": c.stroke_margin,
                "r_hi": pb.L - c.stroke_margin, "max_it": c.max_iterations,
                "tol": c.tolerance, "rti": float(c.mode == "rti"),
                "warm": float(c.warm_start), "u_c": pb.u_c, "u_s": pb.u_s, "v_scale": V_SCALE}
        self._cfg = np.concatenate([[float(vals[k]) for k in _CFG], pb.P])
        if self._cfg.size != so.wb_fast_config_size():
            raise CompileError("the compiled NMPC step does not match its settings")
        self._h = so.wb_fast_new(self._cfg.ctypes.data)
        if not self._h:
            raise MemoryError(f"the compiled NMPC step could not allocate its work (at most "
                              f"{_MAX_LIVE} compiled NMPCs of one horizon alive at once)")
        weakref.finalize(self, so.wb_fast_free, self._h)
        self._y = np.zeros(4)
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
        = (X (4, N + 1), U (1, N), u_prev, r_prev, z (4,), d, t) of an
        :class:`~.results.NMPCState` (scaled as there; r_prev m, d N, t s)."""
        mem = CompiledMemory(self.pb.N, self._msize)
        if plan is not None:
            X, U, u_prev, r_prev, z, d, t = plan
            n, b = 4 * (self.pb.N + 1), mem.buf
            b[:n] = np.asarray(X, dtype=float).ravel(order="F")
            b[n:n + self.pb.N] = np.asarray(U, dtype=float).ravel()
            b[mem._at("u_prev")], b[mem._at("r_prev")] = u_prev, r_prev
            b[mem._at("z"):mem._at("z") + 4] = z
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
            state = CompiledMemory(self.pb.N, self._msize)
        yy = self._y
        try:
            yy[0], yy[1], yy[2], yy[3] = y["x"], y["v"], y["p_a"], y["p_b"]
        except KeyError as exc:
            raise InputError(f"the NMPC needs the measured {exc} (it measures x, v, p_a, p_b)") from None
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
