"""Stability maps: sweep two parameters, colour the plane by the largest closed-loop pole.

Every point of a map is the *exact* sampled-data loop: the plant's equilibrium at
the swept parameters, its tangent model from CasADi, ZOH discretisation at the
controller's sample time, the discrete PID (and any computation delay) closed
around the position, and the eigenvalues of the closed loop. The colour is the
largest pole magnitude |z|max; |z|max < 1 is stable.

Over the map the classical boundaries are drawn for a P controller: the
continuous Hurwitz limit K0 = 2 zeta w0 and the PCT limit K0 = 2 zeta / Ts,
Ts = T/2 + 1/w0, with w0, zeta and Kv of the dominant mode pair of the tangent
model at each point.

Speed comes from doing all points of a block in one call: the equilibria by a
fixed Gauss-Newton iteration and the Jacobians there in one compiled CasADi function
mapped over the block (zero-copy into NumPy), the discretisation (batched Pade expm)
and eigenvalues in batched NumPy (:mod:`.kernel`). Blocks run on all local cores (forked worker
processes) or on a Dask cluster (``scheduler="tcp://..."``; :mod:`.parallel`).
The axes are in :mod:`.axes`; this module holds the result and the driver.

Examples
--------
>>> from workbench import Plant
>>> from workbench.stability import maps
>>> plant = Plant.from_toml("designs/plants/situm_rodless_nominal.toml")
>>> m = maps.stability_map(plant, maps.Axis.linspace("kp", 1, 40, 100),
...                        maps.Axis.linspace("load.mass", 0.5, 5, 100))
>>> round(float(m.stable.mean()), 2)             # share of the (kp, mass) grid that is stable
0.75
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..plant import Plant
from .axes import AXIS_ALIASES, CONTROLLER_AXES, Axis, parse_axis
from .kernel import expm_batched
from .parallel import run_blocks, sweeper_for

__all__ = ["Axis", "StabilityMap", "stability_map", "parse_axis", "expm_batched",
           "AXIS_ALIASES", "CONTROLLER_AXES"]

#: Map size (points) from which the CasADi functions are compiled to C.
_COMPILE_ABOVE = 4000

#: How long to wait for a Dask scheduler before giving up.
DASK_CONNECT_TIMEOUT = "10s"


# ------------------------------------------------------------------------ result
@dataclass(frozen=True)
class StabilityMap:
    """Largest closed-loop pole magnitude over a plane of two parameters.

    Arrays are indexed ``[iy, ix]`` (rows follow the y axis, as in images).

    Attributes
    ----------
    x, y : the two axes. rho : |z|max of the visible closed-loop modes (-).
    kv : velocity gain of the tangent model at each point, m/(V s).
    kp : proportional gain at each point, V/m. k0 : loop gain kp*Kv, 1/s.
    hidden_modes : closed-loop modes hidden from the position loop (count).
    boundary : coarse-grid w0 (rad/s), zeta (-), k0 ratios to the continuous and PCT
        limits (None unless the controller is a P controller).
    fallbacks : equilibria solved one by one after the batched solve missed.
    """

    x: Axis
    y: Axis
    rho: np.ndarray
    kv: np.ndarray
    kp: np.ndarray
    hidden_modes: np.ndarray
    plant_name: str
    position: float
    controller: dict
    delay_samples: int
    boundary: dict | None
    fallbacks: int
    elapsed_s: float
    notes: tuple[str, ...] = ()

    @property
    def stable(self) -> np.ndarray:
        return self.rho < 1.0

    @property
    def k0(self) -> np.ndarray:
        return self.kp * self.kv

    @property
    def points_per_s(self) -> float:
        return self.rho.size / self.elapsed_s if self.elapsed_s > 0 else float("inf")

    def to_dict(self) -> dict:
        def arr(a):
            return [[None if not np.isfinite(v) else float(v) for v in row] for row in a]
        out = {"plant": self.plant_name, "position_m": self.position,
               "controller": self.controller, "delay_samples": self.delay_samples,
               "x": {"name": self.x.name, "unit": self.x.unit, "values": self.x.values.tolist()},
               "y": {"name": self.y.name, "unit": self.y.unit, "values": self.y.values.tolist()},
               "rho": arr(self.rho), "stable_fraction": float(np.mean(self.stable)),
               "fallbacks": self.fallbacks, "elapsed_s": self.elapsed_s,
               "points_per_s": self.points_per_s, "notes": list(self.notes)}
        return out

    def to_csv(self, path) -> None:
        """Long format: one row per point (x, y, rho, stable, kp, kv, k0)."""
        import pandas as pd
        from ..params import atomic_write_text
        X, Y = np.meshgrid(self.x.values, self.y.values)
        df = pd.DataFrame({self.x.name: X.ravel(), self.y.name: Y.ravel(),
                           "rho": self.rho.ravel(), "stable": self.stable.ravel(),
                           "kp_V_per_m": self.kp.ravel(), "kv_m_per_Vs": self.kv.ravel(),
                           "k0_per_s": self.k0.ravel()})
        atomic_write_text(path, df.to_csv(index=False, float_format="%.9g"))


# ------------------------------------------------------------------------ driver
def stability_map(plant: Plant, x: Axis, y: Axis, *, position: float | None = None,
                  controller=None, delay_samples: int = 0, scheduler: str | None = None,
                  workers: int | None = None, block_size: int = 2500,
                  boundary_points: int = 40, progress: bool | None = None,
                  compile_c: bool = True) -> StabilityMap:
    """Stability map of the sampled position loop over the plane ``x`` by ``y``.

    Parameters
    ----------
    plant : the plant (its effects included; dry friction is left out of the
        tangent models, as in :func:`workbench.linearize.tangent`).
    x, y : the axes (:class:`Axis`); plant parameters by dotted name, ``position``
        (m), or controller quantities ``kp`` (V/m), ``kd``, ``ki``, ``k0`` (1/s, the
        loop gain kp*Kv), ``sample_time`` (s).
    position : piston position of the equilibrium, m (default mid-stroke), unless an
        axis sweeps it.
    controller : a :class:`~workbench.controllers.PID` (or dict with kp, kd, ki,
        sample_time); default the plant file's controller.
    delay_samples : samples of computation delay between measuring and applying.
    scheduler : Dask scheduler address (``tcp://host:8786``) or a
        ``distributed.Client``; default: local worker processes on all cores.
    workers : local worker processes (default all cores; 1 = in this process).
    block_size : points per task.
    boundary_points : points per axis of the coarse grid on which the classical
        (continuous, PCT) boundaries are computed.
    progress : show a progress bar (default: when on a terminal).
    """
    t_start = time.perf_counter()
    _check_axes(plant, x, y)
    ctrl = _controller_spec(plant, controller)
    if delay_samples < 0 or int(delay_samples) != delay_samples:
        raise InputError("delay_samples must be a non-negative integer")
    pos = plant.stroke / 2 if position is None else float(position)
    if not 0 <= pos <= plant.stroke:
        raise InputError(f"position {pos:g} m is outside the stroke [0, {plant.stroke:g}] m")
    ny, nx = len(y), len(x)
    compile_c = bool(compile_c) and nx * ny >= _COMPILE_ABOVE
    spec = (plant.params.to_dict(), plant.friction, pos, ctrl, int(delay_samples), compile_c)
    sweeper = sweeper_for(spec)
    flat, P, positions, gains, T, k0 = _point_inputs(sweeper, x, y, ctrl, pos)
    tasks = _blocks(positions, P, gains, T, k0, block_size)
    results = run_blocks(spec, tasks, scheduler, workers, progress, nx * ny,
                         connect_timeout=DASK_CONNECT_TIMEOUT)
    cat = {k: np.concatenate([r[k] for r in results]) for k in ("rho", "kv", "kp", "hidden")}
    fallbacks = int(sum(r["fallbacks"] for r in results))

    boundary = None
    if ctrl["kd"] == 0 and ctrl["ki"] == 0 and not {x.name, y.name} & {"kd", "ki"}:
        boundary = _boundaries(sweeper, x, y, flat, P, positions, gains, T, k0, boundary_points)
    elapsed = time.perf_counter() - t_start
    return StabilityMap(x=x, y=y, rho=cat["rho"].reshape(ny, nx), kv=cat["kv"].reshape(ny, nx),
                        kp=cat["kp"].reshape(ny, nx), hidden_modes=cat["hidden"].reshape(ny, nx),
                        plant_name=str(plant.name or ""),
                        position=pos, controller=ctrl, delay_samples=int(delay_samples),
                        boundary=boundary, fallbacks=fallbacks, elapsed_s=elapsed,
                        notes=_notes(plant, cat, fallbacks))


def _check_axes(plant: Plant, x: Axis, y: Axis) -> None:
    """Both axes sweep something this plant has, within its valid range."""
    if x.name == y.name:
        raise InputError(f"both axes sweep {x.name!r}")
    pnames = Plant(plant.params.without_effect("dry_friction")).param_names \
        if plant.params.has_effect("dry_friction") else plant.param_names
    for ax in (x, y):
        if ax.kind == "plant" and ax.name not in pnames:
            from difflib import get_close_matches
            near = get_close_matches(ax.name, list(pnames) + list(CONTROLLER_AXES) + ["position"], 1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise InputError(f"cannot sweep {ax.name!r}: not a parameter of this plant{hint}; "
                             f"plant parameters: {', '.join(pnames)}; also position, "
                             f"{', '.join(CONTROLLER_AXES)}")
        if ax.kind == "position" and (ax.values.min() < 0 or ax.values.max() > plant.stroke):
            raise InputError(f"position axis must lie within the stroke [0, {plant.stroke:g}] m")
        if ax.name in ("sample_time",) and ax.values.min() <= 0:
            raise InputError("sample_time axis must be > 0")
        if ax.kind == "plant" and ax.values.min() <= 0 and ax.name not in (
                "load.external_force", "valve.null_offset"):
            raise InputError(f"axis {ax.name!r} must stay > 0")
    if {x.name, y.name} >= {"kp", "k0"}:
        raise InputError("kp and k0 are the same gain; sweep one of them")


def _controller_spec(plant: Plant, controller) -> dict:
    """kp, kd, ki (V/m, V s/m, V/(m s)) and sample_time (s) of ``controller`` (a PID,
    a dict, or None for the plant file's controller)."""
    if controller is None:
        from ..controllers import from_plant
        controller = from_plant(plant)
    if isinstance(controller, dict):
        c = dict(controller)
    else:
        c = {"kp": controller.kp, "kd": getattr(controller, "kd", 0.0),
             "ki": getattr(controller, "ki", 0.0), "sample_time": controller.sample_time}
    for k in ("kp", "sample_time"):
        if k not in c:
            raise InputError(f"controller needs {k!r}")
    c.setdefault("kd", 0.0)
    c.setdefault("ki", 0.0)
    return c




def _point_inputs(sweeper, x: Axis, y: Axis, ctrl: dict, pos: float):
    """Per-point inputs of the map, flattened row by row (y outer, x inner).

    Returns
    -------
    flat : dict
        The two axes' values at each point, by axis name.
    P : numpy.ndarray
        Parameter columns (n_params, N), the nominal values with the swept ones set.
    positions : numpy.ndarray
        Equilibrium position of each point, m.
    gains : dict
        kp, kd, ki of each point.
    T : numpy.ndarray
        Sample time of each point, s.
    k0 : numpy.ndarray or None
        The swept loop gain (1/s), when an axis sweeps it.
    """
    XX, YY = np.meshgrid(x.values, y.values)
    flat = {x.name: XX.ravel(), y.name: YY.ravel()}
    N = len(x) * len(y)
    P = np.tile(sweeper.p0[:, None], (1, N))
    for name, vals in flat.items():
        if name in sweeper.param_names:
            P[sweeper.param_names.index(name)] = vals
    positions = flat.get("position", np.full(N, pos))
    gains = {k: np.broadcast_to(np.asarray(flat.get(k, ctrl[k]), dtype=float), (N,))
             for k in ("kp", "kd", "ki")}
    T = np.broadcast_to(np.asarray(flat.get("sample_time", ctrl["sample_time"]), float), (N,))
    return flat, P, positions, gains, T, flat.get("k0")


def _blocks(positions, P, gains, T, k0, block_size: int) -> list[dict]:
    """The points cut into blocks of ``block_size``: keyword arguments of
    :meth:`~workbench.stability.kernel._Sweeper.evaluate` (contiguous copies)."""
    N = positions.size
    tasks = []
    for s0 in range(0, N, block_size):
        sl = slice(s0, min(N, s0 + block_size))
        tasks.append({"positions": np.ascontiguousarray(positions[sl]),
                      "P": np.ascontiguousarray(P[:, sl]),
                      "kp": np.ascontiguousarray(gains["kp"][sl]),
                      "kd": np.ascontiguousarray(gains["kd"][sl]),
                      "ki": np.ascontiguousarray(gains["ki"][sl]),
                      "T": np.ascontiguousarray(T[sl]),
                      "k0": None if k0 is None else np.ascontiguousarray(k0[sl])})
    return tasks


def _notes(plant: Plant, cat: dict, fallbacks: int) -> tuple[str, ...]:
    """What a reader of the map must know: left-out friction, hidden modes, blank
    points, one-by-one equilibria."""
    notes = []
    if plant.params.has_effect("dry_friction"):
        notes.append("dry friction left out of the tangent models (not differentiable at rest)")
    if np.any(cat["hidden"] > 0):
        notes.append("modes hidden from the position loop (e.g. the pressure sum of a "
                     "closed-centre valve without leakage, |z| = 1) are not counted in |z|max")
    if np.any(np.isnan(cat["rho"])):
        notes.append(f"{int(np.isnan(cat['rho']).sum())} points have no position loop to judge "
                     "(no equilibrium, or the command has no small-signal effect on the "
                     "position, e.g. inside a valve deadband): shown blank")
    if fallbacks:
        notes.append(f"{fallbacks} equilibria needed the one-by-one solver (e.g. a leaking "
                     "closed-centre valve settles at atmosphere)")
    return tuple(notes)


def _boundaries(sweeper, x, y, flat, P, positions, gains, T, k0, npts):
    """Continuous and PCT limits on a coarse sub-grid (P controller only)."""
    ny, nx = len(y), len(x)
    ix = np.unique(np.linspace(0, nx - 1, min(nx, npts)).round().astype(int))
    iy = np.unique(np.linspace(0, ny - 1, min(ny, npts)).round().astype(int))
    idx = (iy[:, None] * nx + ix[None, :]).ravel()
    _, _, res, A, B, _ = sweeper.points(positions[idx], P[:, idx])
    ok = np.isfinite(res)
    A[~ok], B[~ok] = 0.0, 0.0
    w0, zeta, kv = sweeper.dominant_of(A, B)
    Ts = T[idx] / 2 + 1.0 / w0
    kk0 = k0[idx] if k0 is not None else gains["kp"][idx] * kv
    shape = (len(iy), len(ix))
    return {"x": x.values[ix], "y": y.values[iy],
            "w0": w0.reshape(shape), "zeta": zeta.reshape(shape), "kv": kv.reshape(shape),
            "continuous_ratio": (kk0 / (2 * zeta * w0)).reshape(shape),
            "pct_ratio": (kk0 / (2 * zeta / Ts)).reshape(shape)}

