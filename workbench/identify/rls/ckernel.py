"""The RLS recursion as a plain C loop, built by the package's JIT cache (``method="c"``).

The same arithmetic as :func:`.kernels._run_numpy` (forget first, Joseph-form
covariance update, trace-bounded forgetting, the information matrix ``M``, ``V`` and
the effective sample count for the standard deviations), written as a C loop over the
samples with the number of parameters fixed when the library is built (one library
per number of parameters, compiled once and kept in :func:`workbench.integrate.jit.cache_dir`).

Where it differs from the numpy reference, only by rounding:

* The Joseph form is evaluated expanded, entry by entry of the upper triangle,
  ``P(k) = P~ - K a' - a K' + den K K'`` with ``a = P~ phi``, ``den = 1 + phi' a``,
  ``K = a / den``. This is the Joseph form ``(I - K phi') P~ (I - K phi')' + K K'``
  multiplied out, not the short form ``P~ - K a'``: an error ``dK`` in the gain enters
  it only to second order (the first-order terms ``-dK a' - a dK' + den (K dK' +
  dK K')`` cancel since ``a = den K``), which is the Joseph form's point. Each entry is
  computed once for ``i <= j`` and mirrored, so ``P`` is symmetric exactly (the
  reference symmetrises ``(P + P') / 2``).
* ``trace(P M)`` and ``diag(P M P)`` (the sandwich's diagonal) are summed directly
  instead of forming ``B = P M``.

The regressors are formed in the loop from ``y`` and ``u`` (no regressor matrix), and
the outputs are written straight into the result's arrays (theta, std, errors,
lambda_k, sigma^2: no strided copies afterwards). The loop runs in chunks of
``CHUNK`` samples (a few milliseconds each), so a progress bar can advance and
Ctrl-C is answered between chunks.
"""

from __future__ import annotations

import ctypes
from typing import Callable

import numpy as np

__all__ = ["c_kernel", "run_c", "CHUNK", "FLAGS", "MAX_PARAMETERS"]

#: samples per C call: ~2 ms at 4 parameters (Ctrl-C and the progress bar between calls)
CHUNK = 1 << 15
#: -O3: the loops over the (compile-time) parameters are unrolled and partly vectorised
#: (52 vs 64 ms per 10^6 samples at -O2, 4 parameters); no -ffast-math: the variance is
#: NaN by design until a degree of freedom is left, and the trace bound's min / max must
#: keep IEEE semantics; -fno-math-errno lets sqrt be one instruction (nothing reads errno)
FLAGS = ("-O3", "-fno-math-errno")

_SOURCE = r"""
/* workbench.identify.rls.ckernel: RLS with forgetting, NP parameters */
#include <math.h>
#define NP %(NP)d
#define NT (NP * (NP + 1) / 2)
int wb_rls_np(void) { return NP; }
/* x: the packed state [theta (NP), triu(P) (NT, column by column), triu(M) (NT), V, ne],
   read at the start and written back at the end */
/* N samples from y[0], u[0] (the caller's pointers: sample k of the record, k >= the
   first full regressor); the regressor of sample k is
   [-y(k-1) .. -y(k-na), u(k-nk) .. u(k-nk-nb+1)], nb = NP - na */
int wb_rls_run(long N, const double *y, const double *u, int na, int nk, double *x,
               double lam, double p_max, double *theta_out, double *std_out,
               double *eps_out, double *lk_out, double *s2_out)
{
    double th[NP], P[NP][NP], M[NP][NP], a[NP], K[NP], f[NP], V, ne;
    const double lam_pmax = lam * p_max, il_lam = 1.0 / lam;
    int i, j, q, t;
    long k;
    for (i = 0; i < NP; ++i) th[i] = x[i];
    t = NP;
    for (j = 0; j < NP; ++j)
        for (i = 0; i <= j; ++i, ++t) {
            P[i][j] = P[j][i] = x[t];
            M[i][j] = M[j][i] = x[t + NT];
        }
    V = x[NP + 2 * NT];
    ne = x[NP + 2 * NT + 1];
    for (k = 0; k < N; ++k) {
        double tr = 0.0, lk, il, den = 1.0, eps = y[k], trB = 0.0, dof, s2;
        for (i = 0; i < na; ++i) f[i] = -y[k - 1 - i];
        for (i = na; i < NP; ++i) f[i] = u[k - nk - (i - na)];
        for (i = 0; i < NP; ++i) tr += P[i][i];
        /* lambda_k = min(1, max(lambda, trace(P) / p_max)); a NaN trace gives lambda.
           While the bound does not act (almost always) the two divisions stay off
           the recursion's critical path: 50 -> 41 ms per 10^6 samples */
        if (tr > lam_pmax) {
            lk = tr / p_max;
            lk = lk > lam ? lk : lam;
            lk = lk < 1.0 ? lk : 1.0;
            il = 1.0 / lk;
        } else {
            lk = lam;
            il = il_lam;
        }
        for (i = 0; i < NP; ++i) {            /* a = P~ phi, P~ = P / lambda_k */
            double s = 0.0;
            for (j = 0; j < NP; ++j) s += P[i][j] * f[j];
            a[i] = s * il;
        }
        for (i = 0; i < NP; ++i) {
            den += f[i] * a[i];
            eps -= f[i] * th[i];
        }
        for (i = 0; i < NP; ++i) {
            K[i] = a[i] / den;
            th[i] += K[i] * eps;
        }
        /* Joseph form multiplied out: P~ - K a' - a K' + den K K' (upper, mirrored) */
        for (j = 0; j < NP; ++j)
            for (i = 0; i <= j; ++i) {
                double v = P[i][j] * il - (K[i] * a[j] + a[i] * K[j]) + den * (K[i] * K[j]);
                P[i][j] = P[j][i] = v;
                v = lk * lk * M[i][j] + f[i] * f[j];
                M[i][j] = M[j][i] = v;
            }
        V = lk * V + eps * eps / den;
        ne = lk * ne + 1.0;
        for (i = 0; i < NP; ++i)
            for (j = 0; j < NP; ++j) trB += P[i][j] * M[j][i];
        dof = ne - trB;
        s2 = dof > 0.5 ? V / dof : NAN;
        for (i = 0; i < NP; ++i) {            /* diag(P M P)_i = p_i' M p_i */
            double s = 0.0;
            for (j = 0; j < NP; ++j) {
                double mp = 0.0;
                for (q = 0; q < NP; ++q) mp += M[j][q] * P[q][i];
                s += P[i][j] * mp;
            }
            theta_out[k * NP + i] = th[i];
            std_out[k * NP + i] = sqrt(s2 * s);
        }
        eps_out[k] = eps;
        lk_out[k] = lk;
        s2_out[k] = s2;
    }
    for (i = 0; i < NP; ++i) x[i] = th[i];
    t = NP;
    for (j = 0; j < NP; ++j)
        for (i = 0; i <= j; ++i, ++t) {
            x[t] = P[i][j];
            x[t + NT] = M[i][j];
        }
    x[NP + 2 * NT] = V;
    x[NP + 2 * NT + 1] = ne;
    return 0;
}
"""

#: largest number of parameters the C loop takes: its matrices live on the stack
#: (3 n^2 doubles: 98 kB at 64); beyond it the numpy loop runs
MAX_PARAMETERS = 64

_KERNELS: dict[int, Callable | None] = {}


def source(n: int) -> str:
    """The C source of the loop for ``n`` parameters."""
    return _SOURCE % {"NP": int(n)}


def c_kernel(n: int) -> Callable | None:
    """The compiled loop for ``n`` parameters (built once, cached on disk and here),
    or None without a C compiler, when the source does not compile, or above
    :data:`MAX_PARAMETERS`."""
    if n > MAX_PARAMETERS:
        return None
    if n in _KERNELS:
        return _KERNELS[n]
    from ...integrate.jit import CompileError, have_compiler, shared_library
    fn = None
    if have_compiler():
        try:
            path, _ = shared_library(f"wb_rls{n}", source(n), (FLAGS, ("-O2",)))
        except CompileError:
            path = None
        if path is not None:
            lib = ctypes.CDLL(str(path))
            if lib.wb_rls_np() == n:
                fn = lib.wb_rls_run
                vp = ctypes.c_void_p
                fn.argtypes = [ctypes.c_long, vp, vp, ctypes.c_int, ctypes.c_int, vp,
                               ctypes.c_double, ctypes.c_double, vp, vp, vp, vp, vp]
                fn.restype = ctypes.c_int
                fn._keep = lib                         # the library lives with the function
    _KERNELS[n] = fn
    return fn


def run_c(fn: Callable, y: np.ndarray, u: np.ndarray, orders: tuple[int, int, int], k0: int,
          x0: np.ndarray, lam: float, p_max: float,
          progress: bool = False) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Run the compiled loop over samples ``k0 .. len(y) - 1``.

    Parameters
    ----------
    fn : the function from :func:`c_kernel` for ``na + nb`` parameters.
    y, u : ndarray, shape (n,)
        Output and input samples; the regressors are formed in the loop
        (:func:`.estimator.regressors`' convention).
    orders : (na, nb, nk)
        ARX orders.
    k0 : int
        First sample with a full regressor, ``max(na, nk + nb - 1)``.
    x0 : ndarray
        Packed initial state (:func:`.kernels._pack`).
    lam, p_max : float
        Forgetting factor (-) and bound on ``trace(P)``.
    progress : bool
        Show a progress bar.

    Returns
    -------
    (outputs, final packed state): ``outputs`` has ``theta`` and ``std`` (N, na + nb)
    and ``errors``, ``effective_forgetting``, ``noise_variance`` (N,), N = n - k0,
    each a fresh array.
    """
    na, nb, nk = orders
    n = na + nb
    y = np.ascontiguousarray(y, dtype=float)
    u = np.ascontiguousarray(u, dtype=float)
    N = y.size - k0
    x = np.array(x0, dtype=float)
    out = {"theta": np.empty((N, n)), "std": np.empty((N, n)), "errors": np.empty(N),
           "effective_forgetting": np.empty(N), "noise_variance": np.empty(N)}
    ptr = {k: v.ctypes.data for k, v in out.items()}
    py, pu, px = y.ctypes.data, u.ctypes.data, x.ctypes.data
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=N, desc="rls", unit="sample", leave=False)
    d = 8                                   # bytes per double
    try:
        for i0 in range(0, N, CHUNK):
            m = min(CHUNK, N - i0)
            fn(m, py + d * (k0 + i0), pu + d * (k0 + i0), na, nk, px, float(lam),
               float(p_max), ptr["theta"] + d * n * i0, ptr["std"] + d * n * i0,
               ptr["errors"] + d * i0, ptr["effective_forgetting"] + d * i0,
               ptr["noise_variance"] + d * i0)
            if bar is not None:
                bar.update(m)
    finally:
        if bar is not None:
            bar.close()
    return out, x
