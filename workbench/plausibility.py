"""Physical plausibility of a plant, beyond the plant file's types and ranges.

``workbench check`` runs :func:`check_plant`; it refuses (``InputError``) a plant
that loads but cannot be right or cannot be run:

* **valve flows within ISO 6358 limits.** No flow law may pass more than the choked
  flow of the stated sonic conductance, ``C p_s rho_ANR sqrt(T_ANR / T)`` (ISO 6358:
  the largest flow of the restriction at supply pressure, whatever b). The input-affine
  law (a fitted polynomial) is evaluated over the whole operating range (each port
  pressure from atmosphere to supply, the opening from -1 to 1) and refused when it
  exceeds :data:`FLOW_MARGIN` times that limit, or when it fills a chamber at
  supply pressure or exhausts one at atmosphere by more than that margin of the
  choked flow (a flow against the pressure difference).
* **controller period against the fastest pole.** The tangent model at mid-stroke
  gives the plant's fastest eigenvalue; a controller period below
  :data:`MIN_PERIOD_RATIO` of its time constant samples ten thousand times per time
  constant, which no loop needs, and every simulated second costs ``1 / T`` steps.
* **memory of a run.** A simulated run stores time, states, command and outputs at
  every controller sample; a :data:`RUN_SECONDS` s run that would need more than
  :data:`MAX_RUN_BYTES` is refused with the number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import InputError, WorkbenchError
from .physics import gas, valve

__all__ = ["FLOW_MARGIN", "MIN_PERIOD_RATIO", "RUN_SECONDS", "MAX_RUN_BYTES",
           "CENTER_TOLERANCE", "Plausibility", "check_plant", "check_controller"]

#: A flow law may exceed the ISO 6358 choked flow of the stated conductance by this
#: factor (a fitted polynomial overshoots a little between its data points).
FLOW_MARGIN = 1.5
#: Smallest controller period as a fraction of the fastest time constant, -.
MIN_PERIOD_RATIO = 1e-4
#: Duration of the run whose memory is estimated, s (the validation profile's order).
RUN_SECONDS = 10.0
#: Largest memory a run of :data:`RUN_SECONDS` may need, bytes.
MAX_RUN_BYTES = 1e9
#: Largest distance of a controller's centre command from the valve's centre, as a
#: fraction of the command span: beyond it the valve is more than half open at zero
#: error, and the loop drives the piston into an end stop instead of regulating.
CENTER_TOLERANCE = 0.5


@dataclass(frozen=True)
class Plausibility:
    """What :func:`check_plant` measured (SI).

    Attributes
    ----------
    choked_flow : kg/s, ISO 6358 choked flow of the stated conductance at supply.
    max_flow : kg/s, largest |port flow| of the valve law over the operating range.
    fastest_pole : rad/s, largest |eigenvalue| of the tangent model at mid-stroke
        (NaN when the equilibrium could not be found).
    run_bytes : bytes a :data:`RUN_SECONDS` s closed-loop run stores (NaN without a
        controller).
    notes : remarks that are not errors.
    """

    choked_flow: float
    max_flow: float
    fastest_pole: float
    run_bytes: float
    notes: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite values as None)."""
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None
        return {"choked_flow_kg_s": num(self.choked_flow), "max_flow_kg_s": num(self.max_flow),
                "fastest_pole_rad_s": num(self.fastest_pole),
                "run_bytes_10s": num(self.run_bytes), "notes": list(self.notes)}

    def summary(self) -> str:
        """A few lines for people."""
        lines = [f"valve flow max {self.max_flow * 1e3:.3g} g/s <= ISO 6358 choked flow "
                 f"{self.choked_flow * 1e3:.3g} g/s of the stated conductance"]
        if math.isfinite(self.fastest_pole):
            lines.append(f"fastest pole {self.fastest_pole:.4g} rad/s")
        if math.isfinite(self.run_bytes):
            lines.append(f"a {RUN_SECONDS:g} s run stores {self.run_bytes / 1e6:.3g} MB")
        return "\n".join(lines + list(self.notes))


def _choked_flow(prm: Any) -> float:
    """ISO 6358 choked mass flow of the stated conductance from supply, kg/s."""
    T = prm["gas.temperature"]
    return float(prm["valve.sonic_conductance"] * prm["supply.pressure"] * gas.RHO_ANR
                 * math.sqrt(gas.T_REF / T))


def _affine_flows(prm: Any) -> tuple[float, float]:
    """(largest |port flow|, largest flow against the pressure difference), kg/s."""
    p_atm, p_s = prm["gas.atmospheric_pressure"], prm["supply.pressure"]
    s = np.linspace(-1.0, 1.0, 41)[:, None]
    p = np.linspace(p_atm, p_s, 41)[None, :]
    gamma = valve.gamma_odd(s, prm["valve.affine_gamma"])
    q = np.asarray(valve.affine_flow(p, gamma, prm["valve.affine_phi"],
                                     prm["valve.affine_psi_in"], prm["valve.affine_psi_out"]),
                   dtype=float)
    q = np.broadcast_to(q, (s.size, p.size))
    wrong = max(float(np.max(q[:, -1])), float(np.max(-q[:, 0])))  # fill at p_s, empty at p_atm
    return float(np.max(np.abs(q))), wrong


def _fastest_pole(plant: Any, notes: list[str]) -> float:
    from . import linearize
    try:
        lin = linearize.tangent(plant, x=0.5 * plant.stroke)
    except WorkbenchError as exc:
        notes.append(f"note: no equilibrium at mid-stroke, fastest pole unknown ({exc})")
        return math.nan
    ev = np.asarray(lin.eigenvalues)
    return float(np.max(np.abs(ev))) if ev.size else math.nan


def check_plant(plant: Any) -> Plausibility:
    """Check a plant's physical plausibility (module docstring).

    Parameters
    ----------
    plant : Plant

    Returns
    -------
    Plausibility

    Raises
    ------
    InputError
        Naming the plant file and the key, with the numbers that contradict.
    """
    prm = plant.params
    src = prm.source
    notes: list[str] = []
    choked = _choked_flow(prm)
    if plant.valve_law == "input_affine":
        q_max, wrong = _affine_flows(prm)
        if not (q_max <= FLOW_MARGIN * choked):
            raise InputError(
                f"the input-affine valve law passes up to {q_max:.4g} kg/s, more than "
                f"{FLOW_MARGIN:g} x the ISO 6358 choked flow {choked:.4g} kg/s of the stated "
                f"sonic_conductance at supply pressure: the fitted polynomials are not a "
                "valve (fitted beyond their data?)", source=src, location="[valve] affine_psi_in")
        if wrong > FLOW_MARGIN * choked * 0.1:
            notes.append(f"note: the valve law moves {wrong:.3g} kg/s against the pressure "
                         "difference (filling a chamber at supply or exhausting one at "
                         "atmosphere)")
    else:
        q_max = float(plant.full_opening_flow())
    pole = _fastest_pole(plant, notes)
    run_bytes = math.nan
    if plant.params.has_controller:
        T = float(prm["controller.sample_time"])
        per_sample = 8.0 * (2 + len(plant.state_names) + len(plant.output_names))
        run_bytes = RUN_SECONDS / T * per_sample
        if math.isfinite(pole) and pole > 0 and T * pole < MIN_PERIOD_RATIO:
            raise InputError(
                f"sample_time {T:g} s is {T * pole:.2g} of the plant's fastest time constant "
                f"(1/{pole:.4g} rad/s = {1 / pole:.3g} s): below {MIN_PERIOD_RATIO:g} no loop "
                f"gains anything, and a {RUN_SECONDS:g} s run takes {RUN_SECONDS / T:.3g} "
                f"steps ({run_bytes / 1e9:.3g} GB); a typo?", source=src,
                location="[controller] sample_time")
        if run_bytes > MAX_RUN_BYTES:
            raise InputError(
                f"sample_time {T:g} s: a {RUN_SECONDS:g} s run stores {RUN_SECONDS / T:.3g} "
                f"samples, {run_bytes / 1e9:.3g} GB (limit {MAX_RUN_BYTES / 1e9:g} GB)",
                source=src, location="[controller] sample_time")
    return Plausibility(choked, q_max, pole, run_bytes, tuple(notes))


def check_controller(plant: Any, controller: Any) -> None:
    """Refuse a controller whose command at zero error does not centre the plant's valve.

    A position loop rests where its command at zero error, ``u_center``, holds the
    spool centred (``command_center + null_offset``). A controller built with another
    centre (e.g. the default ``u_center = 0 V`` for a 0..10 V valve centred at 5 V)
    opens the valve fully at zero error: the piston runs into an end stop, and a
    validation reports absurd overshoot instead of an error.

    Parameters
    ----------
    plant : Plant
    controller : object
        Checked when it has a ``u_center`` (V); others pass.

    Raises
    ------
    InputError
        When ``u_center`` lies outside the valve's command range or more than
        :data:`CENTER_TOLERANCE` of the span from the valve's centre.
    """
    u_center = getattr(controller, "u_center", None)
    if not isinstance(u_center, (int, float)):
        return
    prm = plant.params
    centre = float(prm["valve.command_center"]) + float(prm.get("valve.null_offset", 0.0))
    span = float(prm["valve.command_span"])
    lo, hi = float(prm["valve.command_min"]), float(prm["valve.command_max"])
    opening = abs(float(u_center) - centre) / span
    if math.isfinite(u_center) and lo <= u_center <= hi and opening <= CENTER_TOLERANCE:
        return
    raise InputError(
        f"the controller's centre command u_center = {u_center:g} V opens the valve by "
        f"{100 * opening:.0f} % of its span at zero error (the valve is centred at "
        f"{centre:g} V, span {span:g} V, range [{lo:g}, {hi:g}] V): the loop would drive "
        "the piston into an end stop. Build the controller with u_center = "
        f"{centre:g} (plant.params['valve.command_center']), u_min = {lo:g}, u_max = {hi:g}",
        source=prm.source, location="[valve] command_center")
