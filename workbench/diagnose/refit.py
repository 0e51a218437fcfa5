"""Refit a candidate: scan its signature grid, then least squares on short-horizon predictions.

For one :class:`~.candidates.Candidate` on the nominal plant:

1. the augmented plant structure is compiled once (:class:`.engine.Engine`);
2. its *signature scan*: the short-horizon prediction cost (:func:`.predict.horizons`)
   on the candidate's grid, which says whether the effect can explain the
   mismatch at all and where to start;
3. bounded least squares (scipy ``trf``) on the weighted prediction residuals in
   transformed coordinates (log for positive quantities), with secant slopes over
   steps large enough to see through stick-slip as its Jacobian (or, with
   :data:`EXACT_JACOBIAN`, the replay's exact forward sensitivities);
4. standard deviations and 95 % intervals from the Gauss-Newton covariance, the
   residual variance inflated by the correlation of the residuals within a window; an
   interval is widened to every value the fit evaluated whose cost lies inside the
   likelihood-ratio region (:func:`_evaluated_span`: a flat or rough cost);
5. the cost of the re-anchored closed-loop replay (:func:`.predict.segments`) at the
   fitted values, an independent check of the gain.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy.optimize import least_squares

from ..params import PlantParams
from ..plant import Plant
from .candidates import Candidate, Free
from .data import Prepared
from .engine import Engine
from .predict import Predictor

__all__ = ["FitResult", "CandidateModel", "fit_candidate", "substeps_for", "directions",
           "refit_set", "MAX_STEP", "EXACT_JACOBIAN"]

#: s: largest ROS2 step (the chambers' fastest time constants are a few ms).
MAX_STEP = 0.0025
#: The refits' Jacobian: exact forward sensitivities (True) or secant slopes over a few
#: percent (False, the default; why: :class:`_Objective`).
EXACT_JACOBIAN = False


def substeps_for(h: float) -> int:
    """ROS2 steps per engine sample so that no step exceeds :data:`MAX_STEP`."""
    return max(int(math.ceil(h / MAX_STEP - 1e-9)), 1)


@dataclass
class FitResult:
    """What refitting one candidate gave.

    Attributes
    ----------
    name, effect : of the candidate. k : number of fitted values.
    values : fitted values (candidate keys). std, ci95 : their uncertainty.
    cost : short-horizon prediction cost at the fitted values (noise units).
    signal_costs : the same per signal.
    seg_cost : re-anchored closed-loop cost at the fitted values (or None).
    grid : (values, cost) of the signature scan.
    fits : short-horizon prediction fit (%) per signal.
    plant_values : dotted plant keys to add.
    """

    name: str
    effect: str
    k: int
    values: dict[str, float]
    std: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    cost: float
    signal_costs: dict[str, float]
    seg_cost: float | None
    grid: list[tuple[dict[str, float], float]]
    fits: dict[str, float]
    plant_values: dict[str, Any]
    nfev: int = 0
    wall_s: float = 0.0
    message: str = ""
    at_bound: list[str] = field(default_factory=list)
    error: str | None = None
    err: np.ndarray | None = field(default=None, repr=False)
    corr: dict[tuple[str, str], float] = field(default_factory=dict)


class CandidateModel:
    """A candidate on the nominal plant: structure, engine, parameter vector."""

    def __init__(self, prep: Prepared, params: PlantParams, cand: Candidate | None,
                 start: Mapping[str, float] | None = None, jit: bool = True,
                 base: Mapping[str, float] | None = None) -> None:
        self.cand = cand
        self.base = dict(base or {})
        vals = cand.values(cand.z0(start)) if cand is not None else {}
        p_struct = params.replace(**self.base) if self.base else params
        self.params = cand.apply(p_struct, vals) if cand is not None else p_struct
        self.plant = Plant(self.params)
        from .predict import default_step
        self.step = default_step(prep)
        h = prep.dt * self.step
        self.engine = Engine(self.plant, h, prep.controller if prep.closed else None, jit=jit,
                             substeps=substeps_for(h))
        self.p0 = self.plant.p0.copy()
        x0 = float(np.clip(prep.xs[0], 0.0, self.plant.stroke))
        if prep.pressures:
            self.z0 = self.plant.initial_state(x0, **prep.first_pressures(),
                                               u0=float(prep.rec["u"][0]))
        else:
            self.z0 = self.plant.initial_state(x0)

    def pvec(self, values: Mapping[str, float]) -> np.ndarray:
        p = self.p0.copy()
        if self.cand is None:
            return p
        for k, v in self.cand.plant_values(values).items():
            if k in self.plant.param_names:
                p[self.plant.param_index(k)] = v
        return p

    def run(self, pred: Predictor, values: Mapping[str, float]) -> np.ndarray:
        if pred.step != self.step:
            raise ValueError(f"predictor step {pred.step} != engine step {self.step}")
        return self.engine.run(self.z0, pred.inputs, self.pvec(values))


def _secant_jacobian(fun, z: np.ndarray, r0: np.ndarray, steps: np.ndarray,
                     bounds: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Secant slopes of ``fun`` over steps of a few percent in ``z`` (see
    :class:`_Objective`)."""
    J = np.empty((len(r0), len(z)))
    for i in range(len(z)):
        h = steps[i]
        zi = z.copy()
        if zi[i] + h > bounds[1][i]:
            h = -h
        zi[i] += h
        J[:, i] = (fun(zi) - r0) / h
    return J


def directions(cand: Candidate, plant: Plant, values: Mapping[str, float]) -> np.ndarray:
    """d(parameter vector)/d(optimiser coordinates) at ``values``: (npar, k).

    Each fitted value is its plant key (d value / d z = value for a log transform,
    ``scale`` otherwise), except ``friction.static_excess``, which sets
    ``friction.static = coulomb (1 + excess)``; keys that are not parameters of the
    structure (segment counts) have no column entry.
    """
    D = np.zeros((len(plant.p0), cand.k))
    free = [f.key for f in cand.free]
    for i, f in enumerate(cand.free):
        dv = values[f.key] if f.log else f.scale
        if f.key in plant.param_names:
            D[plant.param_index(f.key), i] = dv
        if "friction.static" in plant.param_names and "friction.static_excess" in free:
            if f.key == "friction.coulomb":
                D[plant.param_index("friction.static"), i] = \
                    dv * (1.0 + values["friction.static_excess"])
            elif f.key == "friction.static_excess":
                D[plant.param_index("friction.static"), i] = dv * values["friction.coulomb"]
    return D


def fit_candidate(prep: Prepared, params: PlantParams, cand: Candidate, shpe: Predictor,
                  seg: Predictor | None = None, max_nfev: int = 12, jit: bool = True,
                  base: Mapping[str, float] | None = None,
                  start: Mapping[str, float] | None = None) -> FitResult:
    """Scan and refit one candidate (see the module docstring).

    Parameters
    ----------
    prep : prepared recording. params : nominal plant parameters.
    cand : the candidate. shpe : the short-horizon predictor (objective).
    seg : the closed-loop segment predictor (check), or None.
    max_nfev : least-squares iterations (each costs k + 1 replays).
    base : dotted plant keys already added (an earlier finding) under this candidate.
    start : start values instead of the grid scan's best point.
    """
    t0 = time.perf_counter()
    model = CandidateModel(prep, params, cand, start, jit=jit, base=base)
    obj = _Objective(model, cand, shpe)
    z0, grid = _start_point(obj, start)
    z, J, message = _least_squares(obj, z0, max_nfev)
    vals = cand.values(z)
    Y = obj.outputs(z)                  # the solution's replay, kept by the objective
    r = shpe.residuals(Y)
    std, ci, corr = _uncertainty(cand.free, vals, J, r, shpe.n_eff)
    ci = _evaluated_span(obj, r, ci)
    seg_cost = seg.cost(model.run(seg, vals)) if seg is not None else None
    return FitResult(name=cand.name, effect=cand.effect, k=cand.k, values=vals, std=std, ci95=ci,
                     cost=shpe.cost(Y), signal_costs=shpe.signal_costs(Y), seg_cost=seg_cost,
                     grid=grid, fits=shpe.fits(Y), plant_values=cand.plant_values(vals),
                     nfev=obj.nfev, wall_s=time.perf_counter() - t0, message=str(message),
                     at_bound=_at_bound(cand.free, z, obj.lo, obj.hi),
                     err=shpe.error_by_sample(Y).astype(np.float32), corr=corr)


def refit_set(prep: Prepared, params: PlantParams, members: Sequence[Candidate],
              values: Mapping[str, float], pred: Predictor, max_nfev: int = 12,
              jit: bool = True) -> FitResult | None:
    """The set ``members`` refitted jointly on the predictor ``pred`` from ``values``
    (candidate keys), or None when the members cannot be joined.

    Two uses (:mod:`.core`): on the long replay (the re-anchored closed-loop segments,
    :func:`.predict.segments`) when the short-horizon values make the whole
    recording's replay worse than a subset of the set does -- the set search fits on
    0.2 s horizons, which see each member's fast signature but not what accumulates:
    values that trade off there (a supply pressure and a droop's regulator conductance
    both set the pressure a transient reaches) are told apart by the level the loop
    settles to over seconds; and on the short horizons when a negligible member is
    left out, the others having been fitted beside it.
    """
    from .combined import combine
    joint = combine(list(members), dict(values)) if len(members) > 1 else members[0]
    if joint is None:
        return None
    return fit_candidate(prep, params, joint, pred, None, max_nfev=max_nfev, jit=jit,
                         start=dict(values))


class _Objective:
    """The weighted short-horizon residuals of a candidate as a function of its values
    in optimiser coordinates ``z`` (clipped to the bounds), cached per ``z``; counts the
    replays (``nfev``).

    Its Jacobian (:meth:`jacobian`), with ``exact`` (:data:`EXACT_JACOBIAN`), is the
    exact derivative of the discrete replay: forward sensitivities computed by CasADi
    alongside it in one compiled pass (:meth:`.engine.Engine.run_sensitivity`).
    Otherwise, the default, it is the secant over steps of a few percent in ``z``
    (3 % of a log value, 0.05 of a scaled one), which sees through the non-smooth parts
    of the model: a stuck piston's break-away falls on one sample or the next, so the
    local derivative of a stick-slip replay is a poor guide over a Gauss-Newton step
    (measured on the dry-friction case: the exact derivative differs from the 3 %
    secant by 130-240 % (norm), from a 1e-4 difference by 1-18 %). Measured on the
    single-effect bench case (loaded 2-core machine), the exact Jacobian found the
    same friction within 0.1-1.5 % but one sensitivity pass costs 2.9 plain replays
    for 3 directions (the secant: 3), and its C code takes 4-12x as long to compile
    per candidate structure (40-185 s against 9-15 s), which a fresh machine pays for
    every candidate: not the default.
    """

    def __init__(self, model: CandidateModel, cand: Candidate, shpe: Predictor,
                 exact: bool | None = None) -> None:
        self.model, self.cand, self.shpe = model, cand, shpe
        self.lo = np.array([f.z_bounds[0] for f in cand.free])
        self.hi = np.array([f.z_bounds[1] for f in cand.free])
        self.steps = np.array([0.03 if f.log else 0.05 for f in cand.free])
        self.exact = EXACT_JACOBIAN if exact is None else bool(exact)
        self.nfev = 0
        self._cache: dict[bytes, np.ndarray] = {}
        self._outputs: dict[bytes, np.ndarray] = {}

    def cost(self, values: Mapping[str, float]) -> float:
        """Short-horizon prediction cost at ``values`` (candidate keys), replayed at their
        optimiser coordinates and kept: the least squares starting from the best grid
        point does not replay it again."""
        return self.shpe.cost(self.outputs(self.cand.z0(values)))

    def __call__(self, z: np.ndarray) -> np.ndarray:
        z = np.asarray(z, dtype=float)
        key = z.tobytes()
        if key not in self._cache:
            self.nfev += 1
            vals = self.cand.values(np.clip(z, self.lo, self.hi))
            Y = self.model.run(self.shpe, vals)
            self._cache[key], self._outputs[key] = self.shpe.residuals(Y), Y
        return self._cache[key]

    def outputs(self, z: np.ndarray) -> np.ndarray:
        """The engine's outputs at ``z`` (replayed once: kept from :meth:`__call__`)."""
        z = np.asarray(z, dtype=float)
        if z.tobytes() not in self._outputs:
            self(z)
        return self._outputs[z.tobytes()]

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """Jacobian of the residuals at ``z``: the secant, or (``exact``) the exact one
        from one sensitivity pass of the engine, zero in a direction whose bound clips
        ``z``."""
        z = np.asarray(z, dtype=float)
        if not self.exact:
            return _secant_jacobian(self, z, self(z), self.steps, (self.lo, self.hi))
        zc = np.clip(z, self.lo, self.hi)
        vals = self.cand.values(zc)
        m = self.model
        D = directions(self.cand, m.plant, vals)
        D[:, (z < self.lo) | (z > self.hi)] = 0.0
        Y, dY = m.engine.run_sensitivity(m.z0, self.shpe.inputs, m.pvec(vals), D)
        self.nfev += 1
        key = z.tobytes()
        if key not in self._cache:
            self._cache[key], self._outputs[key] = self.shpe.residuals(Y), Y
        return self.shpe.residual_jacobian(Y, dY)


def _start_point(obj: _Objective, start: Mapping[str, float] | None
                 ) -> tuple[np.ndarray, list[tuple[dict[str, float], float]]]:
    """Where the least squares starts (optimiser coordinates, just inside the bounds):
    ``start`` when given, else the best point of the signature scan; and the scan
    ((values, cost) per grid point; empty when ``start`` is given)."""
    cand = obj.cand
    grid: list[tuple[dict[str, float], float]] = []
    if start is None:
        # each point on top of the best so far: a joint candidate's members' grids are
        # scanned one after the other (a grid point sets all of its candidate's scanned
        # values, so a single candidate's scan is unchanged)
        best = cand.values(cand.z0())
        for point in cand.grid_points():
            vals = {**(min(grid, key=lambda g: g[1])[0] if grid else best), **point}
            grid.append((vals, obj.cost(vals)))
        best = min(grid, key=lambda g: g[1])[0] if grid else best
        if obj.shpe.kind == "segments" and grid:
            best = _pattern_search(obj, grid)
    else:
        best = {**cand.values(cand.z0()), **start}
    return np.clip(cand.z0(best), obj.lo + 1e-9, obj.hi - 1e-9), grid


#: Grid points a rough cost's pattern search starts from (:func:`_pattern_search`).
PATTERN_STARTS = 3
#: Stencils evaluated per start at most (measured: 9-17 reach the secant steps).
PATTERN_MOVES = 40


def _pattern_search(obj: _Objective, grid: Sequence[tuple[dict[str, float], float]]
                    ) -> dict[str, float]:
    """The lowest cost a pattern search over the scanned values reaches from the
    :data:`PATTERN_STARTS` best grid points (values, candidate keys).

    Why: a closed-loop segment predictor (``kind == "segments"``, the objective when no
    pressure is recorded) runs the loop for a whole second from each anchor, so a
    stick-slip event one sample earlier or later changes the rest of the segment: the
    cost is rough on the scale of the least squares' secant steps, and a descent from
    the best grid point stops in the first dent of it. The search compares costs only:
    every point of the 3^k stencil (diagonals included: dry friction's valley runs
    along F_s - F_c = const, across both of its scanned coordinates) at half the
    grid's spacing, moving to the best lower one, halving the step when none is lower,
    down to the secant steps. Measured, 8 s position-only recordings at 200 Hz with
    jitter of the foreign rig (smooth Stribeck friction) in its PD loop, (F_c, F_s):
    18/26 N: 12.9/14.5 -> 19.5/25.9 N (cost 2038 -> 278); 25/30 N: 18.4/18.4 ->
    25.3/30.3 N (2894 -> 1425); 12/15.5 N: 10.3/14.8 -> 11.6/14.7 N (269 -> 55); another
    18/26 N recording stays at 12.9/12.9 N (cost 3148; the lowest scanned 2950 at
    18/23 N and 22/29 N: x alone barely tells them apart there).
    """
    cand = obj.cand
    keys = [i for i, f in enumerate(cand.free) if len(set(cand.grid.get(f.key, ()))) > 1]
    if not keys:
        return min(grid, key=lambda g: g[1])[0]
    lo, hi = obj.lo + 1e-9, obj.hi - 1e-9
    spacing = np.array([np.min(np.diff(sorted({cand.free[i].to_z(v)
                                               for v in cand.grid[cand.free[i].key]})))
                        for i in keys])
    moves = [np.array(d) for d in itertools.product((-1, 0, 1), repeat=len(keys)) if any(d)]

    def cost(z: np.ndarray) -> float:
        return obj.cost(cand.values(z))

    ends = []
    for start, c0 in sorted(grid, key=lambda g: g[1])[:PATTERN_STARTS]:
        z, f, step = np.clip(cand.z0(start), lo, hi), c0, spacing / 2.0
        for _ in range(PATTERN_MOVES):        # a bound on the replays: each move lowers f
            if not np.any(step >= obj.steps[keys]):
                break
            trial = []
            for d in moves:
                zt = z.copy()
                zt[keys] = np.clip(zt[keys] + d * step, lo[keys], hi[keys])
                trial.append((cost(zt), zt))
            ft, zt = min(trial, key=lambda t: t[0])
            if ft < f:
                z, f = zt, ft
            else:
                step = step / 2.0
        ends.append((f, z))
    return cand.values(min(ends, key=lambda e: e[0])[1])


def _least_squares(obj: _Objective, z0: np.ndarray, max_nfev: int
                   ) -> tuple[np.ndarray, np.ndarray, str]:
    """Bounded least squares (scipy ``trf``) from ``z0``: the solution, the Jacobian
    there and the solver's message (``z0`` and its Jacobian when it fails)."""
    try:
        sol = least_squares(obj, z0, jac=obj.jacobian, bounds=(obj.lo, obj.hi), method="trf",
                            x_scale=1.0, max_nfev=max_nfev, xtol=1e-4, ftol=1e-5, gtol=1e-8)
        return sol.x, sol.jac, sol.message
    except (ValueError, np.linalg.LinAlgError) as exc:     # pragma: no cover - defensive
        return z0, obj.jacobian(z0), f"least squares failed: {exc}"


def _uncertainty(free: Sequence[Free], vals: Mapping[str, float], J: np.ndarray,
                 r: np.ndarray, n_eff: float
                 ) -> tuple[dict[str, float], dict[str, tuple[float, float]],
                            dict[tuple[str, str], float]]:
    """Standard deviations, 95 % intervals (their units) and pairwise correlations of
    the fitted values.

    Gauss-Newton covariance ``pinv(J' J) s2`` in optimiser coordinates, the residual
    variance ``s2`` inflated by the correlation of the residuals within a window
    (``len(r) / n_eff``, at least 1), mapped back through each value's transform.
    """
    s2 = _residual_variance(r, len(free), n_eff)
    std: dict[str, float] = {}
    ci: dict[str, tuple[float, float]] = {}
    try:
        cov = np.linalg.pinv(J.T @ J) * s2
    except np.linalg.LinAlgError:                           # pragma: no cover
        return std, ci, {}
    for i, f in enumerate(free):
        sz = math.sqrt(max(cov[i, i], 0.0))
        v = vals[f.key]
        if f.log:
            std[f.key] = v * sz
            e = min(1.96 * sz, 700.0)     # an unidentified value: (0, inf), not a crash
            ci[f.key] = (v * math.exp(-e), v * math.exp(e) if e < 700.0 else math.inf)
        else:
            std[f.key] = f.scale * sz
            ci[f.key] = (v - 1.96 * f.scale * sz, v + 1.96 * f.scale * sz)
    corr: dict[tuple[str, str], float] = {}
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    for i, j in itertools.combinations(range(len(free)), 2):
        if d[i] > 0 and d[j] > 0:
            corr[(free[i].key, free[j].key)] = float(cov[i, j] / (d[i] * d[j]))
    return std, ci, corr


def _residual_variance(r: np.ndarray, k: int, n_eff: float) -> float:
    """Variance of one weighted residual with ``k`` fitted values, inflated by the
    correlation of the residuals within a window (``len(r) / n_eff``, at least 1)."""
    m = len(r)
    return float(r @ r) / max(m - k, 1) * max(m / n_eff, 1.0)


#: 95 % quantile of chi-square with one degree of freedom: a value lies inside its
#: profile-likelihood interval when the best fit holding it costs at most this many
#: residual variances more than the best fit overall.
CHI2_95_1 = 3.841458820694124


def _evaluated_span(obj: "_Objective", r: np.ndarray, ci: Mapping[str, tuple[float, float]]
                    ) -> dict[str, tuple[float, float]]:
    """The 95 % intervals ``ci`` widened to each value of every point the fit evaluated
    (grid scan, pattern search, least-squares steps) whose residual sum of squares lies
    within :data:`CHI2_95_1` residual variances of the lowest evaluated.

    Why: the Gauss-Newton interval is the curvature at the solution, which a flat or
    rough cost does not have: on a position-only recording (the closed-loop segment
    objective) the friction cost is flat along a valley and rough across it, and the
    interval came out 25.6-26.2 N where values of 13-29 N fit within a few percent. A
    point inside the likelihood-ratio region is a witness: the profile likelihood at
    its value of any one parameter (the best over the others) is at least as good, so
    that value belongs to the profile interval. The span of witnesses is therefore a
    lower bound on the profile interval, computed from replays already made.
    """
    cand = obj.cand
    s2 = _residual_variance(r, cand.k, obj.shpe.n_eff)
    pts = [(float(res @ res), key) for key, res in obj._cache.items()]
    if not pts or not (s2 > 0.0 and math.isfinite(s2)):
        return dict(ci)
    floor = min(min(c for c, _ in pts), float(r @ r))
    out = dict(ci)
    for c, key in pts:
        if not c <= floor + CHI2_95_1 * s2:
            continue
        z = np.clip(np.frombuffer(key, dtype=float), obj.lo, obj.hi)
        for f, v in cand.values(z).items():
            if f in out:
                a, b = out[f]
                out[f] = (min(a, float(v)), max(b, float(v)))
    return out


def _at_bound(free: Sequence[Free], z: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[str]:
    """Keys whose fitted value lies within 0.1 % of its range from a bound (a lower bound
    of zero on a linear scale -- no leak, no offset -- does not count)."""
    return [f.key for f, zi, a, b in zip(free, z, lo, hi)
            if (zi - a) < 1e-3 * (b - a) and not (f.low == 0.0 and not f.log)
            or (b - zi) < 1e-3 * (b - a)]
