"""The C driver of :mod:`.fast`: one NMPC sample around the generated linearisation
and post, with the condensing done here and the QP solved by DAQP on the rows that
may be active.

The driver follows :mod:`.update`'s sample logic (scale, the lumped lines' estimate
by the generated filter step ``wb_nmpc_lines`` of :func:`.lines.line_filter`, node
reference, shift, force estimate, Gauss-Newton steps, cold-start and previous-plan
fallbacks).

*Condensing by the block recursion.* The QP is :func:`.qp.condense`'s, built here
from the interval Jacobians: the node corrections' sensitivities to the moves by
G_{k+1} = [A_k G_k, B_k] (nx^2 k per node, ~N^2 nx^2 / 2 in all), the Hessian
S0' Wx S0 + S1' Wv S1 + wdu D'D and the gradient over the lower-triangular S (node
k + 1 depends on moves 0..k only: ~N^3 / 3), the rows from the same S. The generated
MX loop computed the same in ~15 us at N = 20, this in ~3.5 us (the same numbers up
to rounding; tests compare the closed loops). The rows of the limits between the
nodes (:func:`.limits.interior_rows`) come from the same G_k: the state at a point
inside interval k moves by Ai (G_k dw) + Bi dw_k (the generated MX condensing took
60 us of a 115 us sample with them at N = 20, two substeps, loaded machine).

The QP is then solved exactly, but not on all its rows at once:

*Constraint generation from the previous working set.* Of the 2 x N x (soft limits)
rows (160 at N = 20 with a speed limit) only a few are ever active; DAQP's cost is
its set-up (the Cholesky factor of H and every row times its inverse, ~n^2 / 2 per
row; 23 us of the 29 us a sample took on all rows) and a feasibility pass over every
row per iteration. The driver passes DAQP the command and slack bounds and only the
rows active at the previous QP: the last sample's working set moved on by one node
when the plan was shifted (as an RTI shifts its primal guess), the last step's within
a sample. It then checks every row left out at DAQP's solution; the violated ones are
added and the QP solved again. The result is the optimum of the full QP: the reduced
QP's optimum satisfies every row, so it is feasible for the full QP and no feasible
point has a lower cost (the reduced QP's feasible set contains the full one's); the
QP is strictly convex, so that optimum is unique. Rows are only left out, never
relaxed. DAQP starts from the working set (the rows and bounds active at the previous
QP marked active in its ``sense``: its warm start; ~10 % off its time), from cold when
that fails. After ``QP_ROUNDS`` rounds, or when DAQP fails on the reduced QP, the full
QP is solved cold, as CasADi's DAQP plugin does.

A left-out row counts as violated beyond ``QP_TOL`` (scaled units: position / stroke,
pressure / supply); DAQP's own tolerance on the rows it holds is its ``primal_tol``,
:func:`.qp.daqp_primal_tol` (on rows normalised by the factor of H: 1e-9 with the
limits between the nodes, else DAQP's default 1e-6; CasADi's plugin gets the same).
The two solutions (this one and DAQP's on all rows) differ by rounding where their
final working sets agree, and by at most a violation DAQP accepts where they do not
(tests: <= 1e-8 in the plan; at DAQP's default 1e-6 they were 3e-7 apart with the
limits between the nodes).

The rows are ordered as :func:`.qp.condense` stacks them: per soft limit a lower and
an upper block of N node rows, then per soft limit a lower and an upper block of
(N - KI0) x MINT interior rows (:func:`.limits.interior_rows`, intervals KI0 .. N - 1,
:data:`.limits.FIRST_INTERVAL`), which the shift of the working set follows.
"""

from __future__ import annotations

__all__ = ["DRIVER", "CONFIG", "config"]

#: offsets in the configuration vector of the driver (after them: the settings P), for
#: the 4-state model (:func:`config` for nx states)
CONFIG = ("sx0", "sx1", "sx2", "sx3", "L", "T", "rate_limit", "r_lo", "r_hi", "max_it",
          "tol", "rti", "warm", "u_c", "u_s", "v_scale")


def config(nx: int) -> tuple[str, ...]:
    """:data:`CONFIG` for a model of ``nx`` states (their scales sx0 .. sx{nx-1} first:
    with lumped lines the driver is given their estimate with the measurement)."""
    return tuple(f"sx{i}" for i in range(nx)) + CONFIG[4:]

DRIVER = r"""
/* ---- driver: one NMPC sample around the generated step (workbench.controllers.mpc.fast) */
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <daqp/api.h>
#define NX %(NX)d
#define NN %(N)d
#define NP %(NP)d
#define NXN (NX * (NN + 1))
#define NZ %(NZ)d
#define NC %(NC)d
#define NRN %(NRN)d      /* node rows: NRN / NN blocks of NN rows, node by node */
#define MINT %(MINT)d    /* then interior rows: MINT points per interval, */
#define KI0 %(KI0)d      /* ... from interval KI0 on (limits.FIRST_INTERVAL): */
#define NRI ((NN - KI0) * MINT)                 /* blocks of NRI rows, interval by interval */
#define NRI_B (NRI > 0 ? (NC - NRN) / NRI : 0)  /* (lower, upper per soft limit) */
#define NW (NZ + NC)     /* working set: the bounds, then the rows */
#define NZI (NX * NN * MINT + 1)  /* interior points' states (+1: never empty) */
#define QP_TOL %(QP_TOL)r
#define PRIMAL_TOL %(PRIMAL_TOL)r  /* DAQP's primal_tol (qp.daqp_primal_tol; 0: its default) */
#define QP_ROUNDS %(QP_ROUNDS)d
#define QP_WARM %(QP_WARM)d
#define SQP_CONTRACTION %(SQP_CONTRACTION)r
#define SQP_DAMPING %(SQP_DAMPING)r
%(CFG)s
#define C_P %(NCFG)d
/* the condensed QP (qp.condense): settings P's layout (Problem.unpack), soft limits
   (state index, slack index), the scaled command range */
#define P_WX %(P_WX)d
#define P_WV %(P_WV)d
#define P_WDU %(P_WDU)d
#define P_RHO1 %(P_RHO1)d
#define P_RHO2 %(P_RHO2)d
#define P_LO %(P_LO)d
#define P_HI %(P_HI)d
#define NSOFT %(NSOFT)d
static const int SOFT_I[NSOFT] = {%(SOFT_I)s}, SOFT_J[NSOFT] = {%(SOFT_J)s};
#define W_LO %(W_LO)r
#define W_HI %(W_HI)r
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
#define M_TPHASE (M_TIME + 1)   /* s, last sample: lin, condense, QP, post; then samples */
#define M_QPS (M_TPHASE + 5)    /* DAQP calls, rows given to DAQP, cold fallbacks: last sample */
#define M_WS (M_QPS + 3)        /* working set of the last QP: +1 upper, -1 lower, 0 */
#define NL (NX - 4)             /* lumped lines' states (mpc.lines), estimated here */
#define M_PL (M_WS + NW)        /* their covariance (NL x NL, column-major) */
#define M_PLOK (M_PL + NL * NL) /* 1: it holds the last sample's (else: start at rest) */
#define M_SIZE (M_PLOK + 1)
#if NL > 0
/* a line state at rest (lines.line_start): its chamber's pressure (2, 3) or 0 (-1) */
static const int LSTART[NL] = {%(LSTART)s};
#endif

typedef struct {
  const casadi_real **arg; casadi_real **res; casadi_int *iw; casadi_real *w;
  int mem[3];
  double cfg[C_P + NP];
  double X[NXN], U[NN], Xn[NXN], Un[NN], u0, viol[NX], ok, stp, dd;
  double R[NN + 1], VR[NN + 1], zm[NX], zp[NX], Pl[NL * NL + 1];
  /* the condensed QP */
  double H[NZ * NZ], g[NZ], A[NC * NZ], lba[NC], uba[NC], lbx[NZ], ubx[NZ];
  double hh[NXN], G[NXN * NN], Xs[NXN], Us[NN], dw[NZ];
  /* the plan linearised (qp.intervals) */
  double Aj[NX * NX * NN], Bj[NX * NN], cdef[NX * NN], dz0[NX];
  double Zi[NZI], Ai[NZI * NX], Bi[NZI];
  /* DAQP's reduced QP: rows given (row-major), bounds, multipliers, sense */
  double Ar[NC * NZ], bl[NW], bu[NW], lam[NW], ws[NW], Av[NC];
  int sense[NW], sub[NC], in[NC];
  double tphase[4], qps[3];
  DAQPWorkspace work;
} wb_fast_t;

static double now(void) {
  struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int wb_fast_memory_size(void) { return M_SIZE; }
int wb_fast_config_size(void) { return C_P + NP; }

void wb_fast_free(wb_fast_t *h) {
  if (!h) return;
  if (h->mem[0] >= 0) { wb_nmpc_lin_release(h->mem[0]); wb_nmpc_lin_decref(); }
  if (h->mem[1] >= 0) { wb_nmpc_post_release(h->mem[1]); wb_nmpc_post_decref(); }
#if NL > 0
  if (h->mem[2] >= 0) { wb_nmpc_lines_release(h->mem[2]); wb_nmpc_lines_decref(); }
#endif
  free(h->arg); free(h->res); free(h->iw); free(h->w); free(h);
}

#define WB_MAX(a, b) ((a) > (b) ? (a) : (b))
wb_fast_t *wb_fast_new(const double *cfg) {
  casadi_int sz[3][4] = {{0}}, na = 13, nr = 12, ni = 1, nw = 1; int k;
  wb_fast_t *h = (wb_fast_t *)calloc(1, sizeof(wb_fast_t));
  if (!h) return 0;
  h->mem[0] = h->mem[1] = h->mem[2] = -1;
  wb_nmpc_lin_work(&sz[0][0], &sz[0][1], &sz[0][2], &sz[0][3]);
  wb_nmpc_post_work(&sz[1][0], &sz[1][1], &sz[1][2], &sz[1][3]);
#if NL > 0
  wb_nmpc_lines_work(&sz[2][0], &sz[2][1], &sz[2][2], &sz[2][3]);
#endif
  for (k = 0; k < 3; ++k) {
    na = WB_MAX(na, sz[k][0]); nr = WB_MAX(nr, sz[k][1]);
    ni = WB_MAX(ni, sz[k][2]); nw = WB_MAX(nw, sz[k][3]);
  }
  h->arg = (const casadi_real **)malloc(sizeof(casadi_real *) * na);
  h->res = (casadi_real **)malloc(sizeof(casadi_real *) * nr);
  h->iw = (casadi_int *)malloc(sizeof(casadi_int) * ni);
  h->w = (casadi_real *)malloc(sizeof(casadi_real) * nw);
  wb_nmpc_lin_incref(); h->mem[0] = wb_nmpc_lin_checkout();
  wb_nmpc_post_incref(); h->mem[1] = wb_nmpc_post_checkout();
#if NL > 0
  wb_nmpc_lines_incref(); h->mem[2] = wb_nmpc_lines_checkout();
  if (h->mem[2] < 0) { wb_fast_free(h); return 0; }
#endif
  if (!h->arg || !h->res || !h->iw || !h->w || h->mem[0] < 0 || h->mem[1] < 0) {
    wb_fast_free(h); return 0;
  }
  memcpy(h->cfg, cfg, sizeof(double) * (C_P + NP));
  return h;
}

/* ---- the QP (see workbench.controllers.mpc.fast_c) */

/* the working set moved on by one node (the plan was shifted): the last node's kept */
static void ws_shift(double *ws) {
  int b, k, j;
  for (k = 0; k < NN - 1; ++k) ws[k] = ws[k + 1];                /* the moves' bounds */
  for (b = 0; b < NRN / NN; ++b) {
    double *r = ws + NZ + b * NN;
    for (k = 0; k < NN - 1; ++k) r[k] = r[k + 1];
  }
  for (b = 0; b < NRI_B; ++b) {       /* interior rows: intervals KI0 .. NN - 1 */
    double *r = ws + NZ + NRN + b * NRI;
    for (k = 0; k + 1 < NN - KI0; ++k)
      for (j = 0; j < MINT; ++j) r[k * MINT + j] = r[(k + 1) * MINT + j];
  }
}

/* DAQP's sense of a constraint marked sg in a working set (+1 upper, -1 lower
   active): active only at a finite bound (a mark at an infinite one, from a working
   set of another QP, would pin the step at infinity) */
static int ws_sense(double sg, double lo, double up) {
  if (sg > 0.0 && up < INFINITY) return 1;
  if (sg < 0.0 && lo > -INFINITY) return 3;
  return 0;
}

/* DAQP on the bounds and the rows h->sub[0..nsub), the working set h->ws marked active
   (warm) or not; its exit flag (1: optimal), the step in h->dw, its working set in h->ws */
static int qp_daqp(wb_fast_t *h, int nsub, int warm) {
  DAQPProblem p; DAQPResult r; int i, j; c_float t;
  for (i = 0; i < NZ; ++i) {
    h->bl[i] = h->lbx[i]; h->bu[i] = h->ubx[i];
    h->sense[i] = h->lbx[i] == h->ubx[i] ? 5 : warm ? ws_sense(h->ws[i], h->lbx[i], h->ubx[i]) : 0;
  }
  for (j = 0; j < nsub; ++j) {
    int row = h->sub[j]; double sg = h->ws[NZ + row];
    for (i = 0; i < NZ; ++i) h->Ar[j * NZ + i] = h->A[row + NC * i];
    h->bl[NZ + j] = h->lba[row]; h->bu[NZ + j] = h->uba[row];
    h->sense[NZ + j] = h->lba[row] == h->uba[row] ? 5 : warm ? ws_sense(sg, h->lba[row], h->uba[row]) : 0;
  }
  p.n = NZ; p.m = NZ + nsub; p.ms = NZ; p.H = h->H; p.f = h->g; p.A = h->Ar;
  p.bupper = h->bu; p.blower = h->bl; p.sense = h->sense;
  r.x = h->dw; r.lam = h->lam;
  /* as CasADi's DAQP plugin calls it, on a zeroed workspace, with DAQP's own
     default settings but primal_tol (allocated by the set-up, freed with the workspace:
     a set-up that fails frees the settings it holds) */
  memset(&h->work, 0, sizeof(h->work));
  if (setup_daqp(&p, &h->work, &t) < 0) r.exitflag = -1;
  else {
    if (PRIMAL_TOL > 0.0) h->work.settings->primal_tol = PRIMAL_TOL;
    daqp_solve(&r, &h->work);
  }
  free_daqp_workspace(&h->work);
  free_daqp_ldp(&h->work);
  h->qps[0] += 1.0; h->qps[1] += nsub;
  for (i = 0; i < NZ && r.exitflag == 1; ++i)
    if (!(fabs(h->dw[i]) < INFINITY)) r.exitflag = -1;   /* NaN or inf: failed */
  if (r.exitflag == 1) {                 /* the working set of this solution */
    for (i = 0; i < NZ; ++i) h->ws[i] = h->lam[i] > 0.0 ? 1.0 : h->lam[i] < 0.0 ? -1.0 : 0.0;
    for (j = 0; j < NC; ++j) h->ws[NZ + j] = 0.0;
    for (j = 0; j < nsub; ++j) {
      double l = h->lam[NZ + j];
      h->ws[NZ + h->sub[j]] = l > 0.0 ? 1.0 : l < 0.0 ? -1.0 : 0.0;
    }
  }
  return r.exitflag;
}

/* the rows left out that the step h->dw violates join the rows given; how many joined */
static int qp_violated(wb_fast_t *h, int *nsub) {
  int i, j, added = 0;
  for (j = 0; j < NC; ++j) h->Av[j] = 0.0;
  for (i = 0; i < NZ; ++i) {
    const double *a = h->A + NC * i; double x = h->dw[i];
    for (j = 0; j < NC; ++j) h->Av[j] += a[j] * x;
  }
  for (j = 0; j < NC; ++j) {
    if (h->in[j]) continue;
    if (h->Av[j] < h->lba[j] - QP_TOL) h->ws[NZ + j] = -1.0;
    else if (h->Av[j] > h->uba[j] + QP_TOL) h->ws[NZ + j] = 1.0;
    else continue;
    h->in[j] = 1; h->sub[(*nsub)++] = j; ++added;
  }
  return added;
}

/* the condensed QP from the working set h->ws (see the module text): 1 on success */
static int qp(wb_fast_t *h) {
  int j, nsub = 0, round;
  for (j = 0; j < NC; ++j) {
    h->in[j] = h->ws[NZ + j] != 0.0;
    if (h->in[j]) h->sub[nsub++] = j;
  }
  for (round = 0; round < QP_ROUNDS; ++round) {
    if (qp_daqp(h, nsub, QP_WARM) != 1 && qp_daqp(h, nsub, 0) != 1) break;
    if (!qp_violated(h, &nsub)) return 1;
  }
  /* the full QP, cold */
  h->qps[2] += 1.0;
  for (j = 0; j < NC; ++j) { h->sub[j] = j; h->in[j] = 1; }
  return qp_daqp(h, NC, 0) == 1;
}

/* ---- the condensed QP (qp.condense) */
#define NG NXN    /* rows of G: the node corrections' sensitivities, node by node */
/* S_i(k, j): node k + 1's state i by move j (zero for j > k) */
#define S_(i, k, j) h->G[NX * ((k) + 1) + (i) + NG * (j)]

/* node corrections at zero moves h_k and their sensitivities G_k to the moves, by the
   linearised dynamics dz_{k+1} = A_k dz_k + B_k dw_k + c_k from dz_0 */
static void condense_nodes(wb_fast_t *h) {
  int k, i, j, l;
  memset(h->G, 0, sizeof(h->G));
  for (i = 0; i < NX; ++i) h->hh[i] = h->dz0[i];
  for (k = 0; k < NN; ++k) {
    const double *Ak = h->Aj + NX * NX * k, *hk = h->hh + NX * k;
    for (i = 0; i < NX; ++i) {
      double s = 0.0;
      for (l = 0; l < NX; ++l) s += Ak[i + NX * l] * hk[l];
      h->hh[NX * (k + 1) + i] = s + h->cdef[i + NX * k];
    }
    for (j = 0; j < k; ++j) {
      const double *gk = h->G + NX * k + NG * j; double *gn = h->G + NX * (k + 1) + NG * j;
      for (i = 0; i < NX; ++i) {
        double s = 0.0;
        for (l = 0; l < NX; ++l) s += Ak[i + NX * l] * gk[l];
        gn[i] = s;
      }
    }
    for (i = 0; i < NX; ++i) h->G[NX * (k + 1) + i + NG * k] = h->Bj[i + NX * k];
  }
}

/* the cost: H = diag(S0' Wx S0 + S1' Wv S1 + wdu D'D, rho2 I), g (S: lower triangular,
   so node k + 1 sums only over moves up to k) */
static void condense_cost(wb_fast_t *h, double up) {
  const double *P = h->cfg + C_P, *wx = P + P_WX, *wv = P + P_WV;
  double wdu = P[P_WDU], ex[NN], ev[NN], m[NN];
  int k, j, l;
  memset(h->H, 0, sizeof(h->H));
  for (k = 0; k < NN; ++k) {
    ex[k] = wx[k] * (h->Xs[NX * (k + 1)] + h->hh[NX * (k + 1)] - h->R[k + 1]);
    ev[k] = wv[k] * (h->Xs[NX * (k + 1) + 1] + h->hh[NX * (k + 1) + 1] - h->VR[k + 1]);
    m[k] = h->Us[k] - (k ? h->Us[k - 1] : up);
  }
  for (j = 0; j < NN; ++j) {
    double gj = 0.0;
    for (l = j; l < NN; ++l) {
      double s = 0.0;
      for (k = l; k < NN; ++k) s += wx[k] * S_(0, k, j) * S_(0, k, l) + wv[k] * S_(1, k, j) * S_(1, k, l);
      h->H[j + NZ * l] = h->H[l + NZ * j] = s;
    }
    for (k = j; k < NN; ++k) gj += S_(0, k, j) * ex[k] + S_(1, k, j) * ev[k];
    h->g[j] = gj + wdu * (m[j] - (j + 1 < NN ? m[j + 1] : 0.0));
    h->H[j + NZ * j] += wdu * (j + 1 < NN ? 2.0 : 1.0);
    if (j + 1 < NN) { h->H[j + NZ * (j + 1)] -= wdu; h->H[j + 1 + NZ * j] -= wdu; }
  }
  for (j = NN; j < NZ; ++j) { h->H[j + NZ * j] = P[P_RHO2]; h->g[j] = P[P_RHO1]; }
}

/* the rows: per soft limit (i, slack j) lo_i - x_i <= S_i dw + s_j and
   S_i dw - s_j <= hi_i - x_i at nodes 1..N; the bounds of the moves and slacks */
static void condense_rows(wb_fast_t *h) {
  const double *P = h->cfg + C_P;
  int b, k, j, c;
  for (b = 0; b < NSOFT; ++b) {
    int i = SOFT_I[b], r0 = 2 * b * NN, r1 = (2 * b + 1) * NN;
    for (k = 0; k < NN; ++k) {
      double x = h->Xs[NX * (k + 1) + i] + h->hh[NX * (k + 1) + i];
      for (j = 0; j < NN; ++j) h->A[r0 + k + NC * j] = h->A[r1 + k + NC * j] = S_(i, k, j);
      for (c = 0; c < NZ - NN; ++c) {
        h->A[r0 + k + NC * (NN + c)] = c == SOFT_J[b] ? 1.0 : 0.0;
        h->A[r1 + k + NC * (NN + c)] = c == SOFT_J[b] ? -1.0 : 0.0;
      }
      h->lba[r0 + k] = P[P_LO + i] - x; h->uba[r0 + k] = INFINITY;
      h->lba[r1 + k] = -INFINITY; h->uba[r1 + k] = P[P_HI + i] - x;
    }
  }
  for (j = 0; j < NN; ++j) { h->lbx[j] = W_LO - h->Us[j]; h->ubx[j] = W_HI - h->Us[j]; }
  for (j = NN; j < NZ; ++j) { h->lbx[j] = 0.0; h->ubx[j] = INFINITY; }
}

/* the rows at the points between the nodes (limits.interior_rows): the state at point
   p of interval k >= KI0 is Zi_c + Ai_c (h_k + G_k dw) + Bi_c dw_k (c = k MINT + p;
   G_k: node k's sensitivities, moves 0 .. k - 1); per soft limit (i, slack j) a lower
   row block lo_i - x <= . + s_j, then an upper one . - s_j <= hi_i - x */
static void condense_interior(wb_fast_t *h) {
#if MINT > 0
  const double *P = h->cfg + C_P;
  int b, k, p, l, jj, c;
  for (b = 0; b < NSOFT; ++b) {
    int i = SOFT_I[b], r0 = NRN + 2 * b * NRI, r1 = NRN + (2 * b + 1) * NRI;
    for (k = KI0; k < NN; ++k) for (p = 0; p < MINT; ++p) {
      int col = k * MINT + p, q = (k - KI0) * MINT + p;
      const double *Ac = h->Ai + NX * NX * col;         /* Ai_c(i, l) = Ac[i + NX l] */
      double x = h->Zi[i + NX * col];
      for (l = 0; l < NX; ++l) x += Ac[i + NX * l] * h->hh[NX * k + l];
      for (jj = 0; jj < NN; ++jj) {
        double a = 0.0;
        if (jj < k) for (l = 0; l < NX; ++l) a += Ac[i + NX * l] * h->G[NX * k + l + NG * jj];
        else if (jj == k) a = h->Bi[i + NX * col];
        h->A[r0 + q + NC * jj] = h->A[r1 + q + NC * jj] = a;
      }
      for (c = 0; c < NZ - NN; ++c) {
        h->A[r0 + q + NC * (NN + c)] = c == SOFT_J[b] ? 1.0 : 0.0;
        h->A[r1 + q + NC * (NN + c)] = c == SOFT_J[b] ? -1.0 : 0.0;
      }
      h->lba[r0 + q] = P[P_LO + i] - x; h->uba[r0 + q] = INFINITY;
      h->lba[r1 + q] = -INFINITY; h->uba[r1 + q] = P[P_HI + i] - x;
    }
  }
#else
  (void)h;
#endif
}

/* the condensed QP of the linearised plan; 0 on success */
static int condense(wb_fast_t *h, double up) {
  condense_nodes(h); condense_cost(h, up); condense_rows(h); condense_interior(h);
  return 0;
}

/* one Gauss-Newton step from h->X, h->U (qp.sqp_step: linearise, condense, QP, post,
   each timed); 1 on success (then h->Xn, h->Un are the plan) */
static int step(wb_fast_t *h, double sh, double up, double dprev, double est) {
  int i; double t0 = now(), t1, t2, t3;
  const double *a[9];
  a[0] = h->X; a[1] = h->U; a[2] = &sh; a[3] = h->zm; a[4] = &up; a[5] = h->zp;
  a[6] = &dprev; a[7] = &est; a[8] = h->cfg + C_P;
  for (i = 0; i < 9; ++i) h->arg[i] = a[i];
  h->res[0] = h->Xs; h->res[1] = h->Us; h->res[2] = &h->dd; h->res[3] = h->Aj;
  h->res[4] = h->Bj; h->res[5] = h->cdef; h->res[6] = h->dz0; h->res[7] = h->Zi;
  h->res[8] = h->Ai; h->res[9] = h->Bi;
  if (wb_nmpc_lin(h->arg, h->res, h->iw, h->w, h->mem[0])) return 0;
  t1 = now();
  if (condense(h, up)) return 0;
  t2 = now();
  if (sh != 0.0) ws_shift(h->ws);
  if (!qp(h)) { memset(h->ws, 0, sizeof(h->ws)); return 0; }
  t3 = now();
  h->arg[0] = h->Xs; h->arg[1] = h->Us; h->arg[2] = h->hh; h->arg[3] = h->G;
  h->arg[4] = h->dw; h->arg[5] = h->cfg + C_P;
  h->res[0] = h->Xn; h->res[1] = h->Un; h->res[2] = &h->u0; h->res[3] = h->viol;
  h->res[4] = &h->ok; h->res[5] = &h->stp;
  if (wb_nmpc_post(h->arg, h->res, h->iw, h->w, h->mem[1])) return 0;
  h->tphase[0] += t1 - t0; h->tphase[1] += t2 - t1; h->tphase[2] += t3 - t2;
  h->tphase[3] += now() - t3;
  return h->ok != 0.0;
}

/* up to iters steps (update.py's _sqp): the estimate is updated in the first only */
static int sqp(wb_fast_t *h, int shift, double up, double *dprev, double *est, int iters,
               double *d, int *ok) {
  int it, i, damp = h->cfg[C_rti] == 0.0;
  double sh = shift ? 1.0 : 0.0, a = 1.0, prev = INFINITY, back, dup[NN];
  *ok = 0; *d = *dprev;
  for (it = 1; it <= iters; ++it) {
    *ok = step(h, sh, up, *dprev, *est);
    if (it == 1) { *d = *dprev = h->dd; *est = 0.0; }
    if (!*ok) break;
    /* mode sqp: halve the step taken at each step that does not contract and turns
       the commands back (update.py's _sqp) */
    back = 0.0;
    for (i = 0; i < NN; ++i) {
      double du = h->Un[i] - h->U[i];
      if (it > 1) back += du * dup[i];
      dup[i] = du;
    }
    if (damp && it > 1 && h->stp >= SQP_CONTRACTION * prev && back < 0.0) a *= SQP_DAMPING;
    prev = h->stp;
    if (a == 1.0) {
      memcpy(h->X, h->Xn, sizeof(double) * NXN); memcpy(h->U, h->Un, sizeof(double) * NN);
    } else {
      for (i = 0; i < NXN; ++i) h->X[i] += a * (h->Xn[i] - h->X[i]);
      for (i = 0; i < NN; ++i) h->U[i] += a * (h->Un[i] - h->U[i]);
    }
    sh = 0.0;
    if (h->stp < h->cfg[C_tol]) break;
  }
  return it > iters ? iters : it;
}

static void cold(wb_fast_t *h) {
  int k, i;
  for (k = 0; k <= NN; ++k) for (i = 0; i < NX; ++i) h->X[i + NX * k] = h->zm[i];
  for (k = 0; k < NN; ++k) h->U[k] = 0.0;
  memset(h->ws, 0, sizeof(h->ws));
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

/* the lumped lines' estimate into h->zm[4..] (lines.line_filter: one step of the Kalman
   filter from the last sample's state, command and force estimate; at rest,
   lines.line_start, at the first sample, without the last sample's covariance, or when
   the step fails or is not finite: Problem.measured_state) */
static void lines(wb_fast_t *h, double *m, int started) {
#if NL > 0
  int i, ok = started && m[M_PLOK] != 0.0;
  if (ok) {
    h->arg[0] = m + M_Z; h->arg[1] = m + M_UPREV; h->arg[2] = m + M_D; h->arg[3] = h->zm;
    h->arg[4] = m + M_PL;
    h->res[0] = h->zp; h->res[1] = h->Pl;
    ok = !wb_nmpc_lines(h->arg, h->res, h->iw, h->w, h->mem[2]);
    for (i = 0; i < NX && ok; ++i) ok = fabs(h->zp[i]) < INFINITY;
    for (i = 0; i < NL * NL && ok; ++i) ok = fabs(h->Pl[i]) < INFINITY;
  }
  if (ok) {
    for (i = 0; i < NL; ++i) h->zm[4 + i] = h->zp[4 + i];
    memcpy(m + M_PL, h->Pl, sizeof(double) * NL * NL);
  } else {
    for (i = 0; i < NL; ++i) h->zm[4 + i] = LSTART[i] < 0 ? 0.0 : h->zm[LSTART[i]];
    for (i = 0; i < NL * NL; ++i) m[M_PL + i] = 0.0;
  }
  m[M_PLOK] = 1.0;
#else
  (void)h; (void)m; (void)started;
#endif
}

/* one sample: memory m updated in place, command (V) in *u; returns 1 on success.
   y: the measured x, v, p_a, p_b (SI; the lumped lines' states are estimated here);
   RV: the node reference given (scaled position, then velocity, N + 1 each: the
   preview, made by the caller) or 0 (extrapolated from r here) */
int wb_fast_sample_ref(wb_fast_t *h, double *m, const double *y, double r, const double *RV,
                       double *u) {
  const double *c = h->cfg; struct timespec t0, t1;
  int started = m[M_STARTED] != 0.0, warm, ok = 0, restarted = 0, it = 0, i, k, iters;
  double up, dprev, est, d;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  h->qps[0] = h->qps[1] = h->qps[2] = 0.0;
  for (i = 0; i < 4; ++i) h->zm[i] = y[i] / c[C_sx0 + i];
  lines(h, m, started);
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
    memcpy(h->ws, m + M_WS, sizeof(double) * NW);
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
    memset(h->ws, 0, sizeof(h->ws));
  }
  memcpy(m + M_X, h->X, sizeof(double) * NXN); memcpy(m + M_U, h->U, sizeof(double) * NN);
  memcpy(m + M_WS, h->ws, sizeof(double) * NW);
  m[M_UPREV] = h->U[0]; m[M_RPREV] = r; m[M_D] = d;
  m[M_T] = started ? m[M_T] + c[C_T] : 0.0;
  for (i = 0; i < NX; ++i) { m[M_Z + i] = h->zm[i]; m[M_VIOL + i] = ok ? h->viol[i] : 0.0; }
  m[M_STARTED] = 1.0; m[M_IT] = it; m[M_OK] = ok; m[M_RESTARTED] = restarted;
  *u = c[C_u_c] + c[C_u_s] * h->U[0];
  clock_gettime(CLOCK_MONOTONIC, &t1);
  m[M_TIME] = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  for (i = 0; i < 4; ++i) { m[M_TPHASE + i] = h->tphase[i]; h->tphase[i] = 0.0; }
  m[M_TPHASE + 4] += 1.0;
  for (i = 0; i < 3; ++i) m[M_QPS + i] = h->qps[i];
  return ok;
}

int wb_fast_sample(wb_fast_t *h, double *m, const double *y, double r, double *u) {
  return wb_fast_sample_ref(h, m, y, r, 0, u);
}
"""
