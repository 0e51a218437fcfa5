"""The servodrive as one symbolic CasADi model.

:class:`Plant` composes the physics of :mod:`workbench.physics` according to a
plant file into named CasADi Functions::

    f(x, u, p) -> xdot      state derivative
    h(x, u, p) -> y         outputs

with the states, input, outputs and **all physical parameters** (the vector ``p``,
names in :attr:`Plant.param_names`, nominal values in :attr:`Plant.p0`) symbolic,
so the same model serves simulation, linearisation, estimation and MPC.

The valve follows the law the plant file selects with ``[valve] law``: four ISO 6358
edges (default) or paper 003's input-affine law, whose polynomial coefficients are
then entries of ``p`` too (``valve.affine_psi_in[0]``, ...), so a grey-box fit can
adjust them (see :mod:`workbench.params` for the keys).

Examples
--------
>>> from workbench import Plant
>>> plant = Plant.from_toml("designs/plants/situm_rodless.toml")
>>> plant.state_names
('x', 'v', 'p_a', 'p_b')
>>> xdot = plant.f(plant.initial_state(0.25), 5.0, plant.p0)
>>> bool(abs(xdot.full()).max() < 1e-9)         # at rest at the valve centre: equilibrium
True
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from . import equilibrium
from .params import SCHEMA, PlantParams
from .physics import chamber, friction, gas, line, piston, supply, valve
from .plant_signals import (FLOW_SCALE, INPUT_SIGNALS, KINDS, OUTPUT_SIGNALS, PRESSURE_SCALE,
                            VELOCITY_SCALE, Signal, state_signals, valued)

__all__ = ["Signal", "Plant", "OUTPUT_SIGNALS", "KINDS", "PRESSURE_SCALE", "VELOCITY_SCALE",
           "FLOW_SCALE"]


class Plant:
    """Electropneumatic servodrive: composition of the physics for one plant file.

    Parameters
    ----------
    params : PlantParams
        Validated plant description.
    friction : {"stick", "smooth"}
        Dry-friction form: ``"stick"`` (Karnopp, sticks honestly; for simulation)
        or ``"smooth"`` (differentiable; for optimisation). Irrelevant without
        the ``dry_friction`` effect.

    Attributes
    ----------
    f, h : casadi.Function
        State derivative and outputs, both ``(x, u, p)``.
    states, inputs, outputs : tuple of Signal
        Each with its kind, SI unit, scale and rest value for this plant (see
        :class:`Signal`; :meth:`signal`, :meth:`states_of_kind`, :meth:`state_scales`,
        :meth:`rest_state`): no code outside this module reads meaning from names.
    param_names : tuple of str
        Dotted plant-file keys of the entries of ``p``; array keys contribute one
        entry per coefficient, named ``"<key>[i]"`` (e.g. ``"valve.affine_phi[0]"``).
        Keys of the valve law not selected (:attr:`valve_law`) are left out: they do
        not enter the dynamics.
    valve_law : str
        ``"iso6358"`` or ``"input_affine"``.
    p0 : numpy.ndarray
        Nominal parameter values (SI).
    """

    def __init__(self, params: PlantParams, friction: str = "stick") -> None:
        if friction not in ("stick", "smooth"):
            raise ValueError(f"friction must be 'stick' or 'smooth', got {friction!r}")
        self.params = params
        self.friction = friction
        self.name = params.name
        self.valve_law: str = params["valve.law"]
        names: list[str] = []
        for k in SCHEMA:
            if not k.physical or k.law not in (None, self.valve_law):
                continue
            if k.path not in params.values and k.default is None:
                continue
            if k.kind == "floats":
                names += [f"{k.path}[{j}]" for j in range(len(params[k.path]))]
            else:
                names.append(k.path)
        self.param_names: tuple[str, ...] = tuple(names)
        self.p0 = np.array([float(params[n]) for n in self.param_names])
        self.segments = 0
        if params.has_effect("line_dynamics"):
            self.segments = int(params.get("lines.segments")
                                or line.default_segments(params["lines.length"]))
        self.states = self._valued(state_signals(params, self.segments))
        self.inputs = self._valued(INPUT_SIGNALS)
        self.outputs = self._valued(OUTPUT_SIGNALS)
        nx, npar = len(self.states), len(self.param_names)
        self.x_sym = ca.SX.sym("x", nx)
        self.u_sym = ca.SX.sym("u", 1)
        self.p_sym = ca.SX.sym("p", npar)
        xdot, y = self._build(self.x_sym, self.u_sym, self.p_sym, friction, underlap=0.0)
        self.xdot_expr, self.y_expr = xdot, y
        args = [self.x_sym, self.u_sym, self.p_sym]
        self.f = ca.Function("f", args, [xdot], ["x", "u", "p"], ["xdot"])
        self.h = ca.Function("h", args, [y], ["x", "u", "p"], ["y"])

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_toml(cls, path: str | os.PathLike, friction: str = "stick") -> "Plant":
        """Load and validate a plant file (formats.md sections 1-2)."""
        return cls(PlantParams.from_toml(path), friction=friction)

    def to_toml(self, path: str | os.PathLike) -> None:
        """Write the plant file (atomic)."""
        self.params.to_toml(path)

    def with_params(self, **changes: Any) -> "Plant":
        """A new plant with dotted keys changed (None removes an optional key)."""
        return Plant(self.params.replace(**changes), friction=self.friction)

    def with_friction(self, friction: str) -> "Plant":
        """The same plant with the other dry-friction form."""
        return Plant(self.params, friction=friction)

    # ---------------------------------------------------------------- signals
    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.states)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.outputs)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.inputs)

    @property
    def effects(self) -> tuple[str, ...]:
        return self.params.effects

    def state_index(self, name: str) -> int:
        try:
            return self.state_names.index(name)
        except ValueError:
            raise KeyError(f"no state '{name}'; states: {', '.join(self.state_names)}") from None

    def output_index(self, name: str) -> int:
        try:
            return self.output_names.index(name)
        except ValueError:
            raise KeyError(f"no output '{name}'; outputs: {', '.join(self.output_names)}") from None

    def param_index(self, name: str) -> int:
        try:
            return self.param_names.index(name)
        except ValueError:
            raise KeyError(f"no parameter '{name}' in this plant; parameters: "
                           f"{', '.join(self.param_names)}") from None

    def _valued(self, signals: Sequence[Signal]) -> tuple[Signal, ...]:
        """``signals`` with this plant's scale and rest value (see :class:`Signal`)."""
        return valued(self.params, signals, self.stroke, self.area_a, self.area_b)

    def signal(self, name: str) -> Signal:
        """The state, output or input called ``name`` (a state first: ``p_s`` is both a
        state, with supply droop, and an output; both have the same meaning)."""
        for group in (self.states, self.outputs, self.inputs):
            for sig in group:
                if sig.name == name:
                    return sig
        raise KeyError(f"no signal '{name}'; states: {', '.join(self.state_names)}; outputs: "
                       f"{', '.join(self.output_names)}; inputs: {', '.join(self.input_names)}")

    def states_of_kind(self, kind: str, parts: Sequence[str] | None = None) -> tuple[int, ...]:
        """Indices of the states of ``kind`` (a key of :data:`KINDS`), optionally only
        those of the given ``parts`` (``"piston"``, ``"chamber"``, ``"line"``,
        ``"valve"``, ``"supply"``)."""
        if kind not in KINDS:
            raise KeyError(f"unknown signal kind '{kind}'; kinds: {', '.join(KINDS)}")
        return tuple(i for i, s in enumerate(self.states)
                     if s.kind == kind and (parts is None or s.part in parts))

    def state_scales(self) -> np.ndarray:
        """:attr:`Signal.scale` of every state, in state order (SI units)."""
        return np.array([s.scale for s in self.states])

    def output_scales(self) -> np.ndarray:
        """:attr:`Signal.scale` of every output, in output order (SI units)."""
        return np.array([s.scale for s in self.outputs])

    def rest_state(self, state: Any = None, u: Any = None, p: Any = None) -> Any:
        """A state whose effect states are at rest given the basic ones.

        The basic states (x, v, p_a, p_b: :attr:`Signal.effect` empty) are taken from
        ``state`` (default: their :attr:`Signal.rest`); every state an effect adds takes
        its rest value: the value of the signal it :attr:`Signal.follows` (line nodes
        their chamber's pressure, the spool the command ``u``), the parameter named by
        :attr:`Signal.rest_key` (temperatures, reservoir), otherwise its ``rest``
        (flows and the spool rate: 0).

        Parameters
        ----------
        state : sequence of float or casadi vector, optional
            A full state (SI); only its basic entries are read.
        u : float or casadi scalar, optional
            Command, V (default: the valve centre).
        p : parameter vector, optional
            Read for :attr:`Signal.rest_key` (default: the plant's nominal values).

        Returns
        -------
        numpy.ndarray, or a casadi column when any argument is symbolic.
        """
        values: dict[str, Any] = {"u": self.inputs[0].rest if u is None else u}
        out: list[Any] = []
        for i, sig in enumerate(self.states):
            if not sig.effect:
                val = sig.rest if state is None else state[i]
            elif sig.follows:
                val = values[sig.follows]
            elif sig.rest_key and p is not None and sig.rest_key in self.param_names:
                val = p[self.param_index(sig.rest_key)]
            else:
                val = sig.rest
            values[sig.name] = val
            out.append(val)
        if any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in out):
            return ca.vertcat(*out)
        return np.array(out, dtype=float)

    # ---------------------------------------------------------------- geometry
    @property
    def area_a(self) -> float:
        """Piston area on side a, m^2."""
        return math.pi / 4.0 * self.params["cylinder.bore"] ** 2

    @property
    def area_b(self) -> float:
        """Annulus area on side b (rod side), m^2."""
        return math.pi / 4.0 * (self.params["cylinder.bore"] ** 2
                                - self.params["cylinder.rod_diameter"] ** 2)

    @property
    def stroke(self) -> float:
        return float(self.params["cylinder.stroke"])

    @property
    def controller_params(self) -> Mapping[str, Any]:
        """The plant file's ``[controller]`` keys (empty without a controller)."""
        return {k.split(".", 1)[1]: v for k, v in self.params.values.items()
                if k.startswith("controller.")}

    # ---------------------------------------------------------------- the model
    def _build(self, X, U, P, friction_form: str, underlap: float):
        """State derivative and outputs as expressions of ``X``, ``U``, ``P``.

        One step per physical part, each a function below: the spool, the valve's
        port flows, the lines, the leaks, the chambers, the piston and the supply.

        Parameters
        ----------
        X, U, P : casadi.SX
            State (SI, :attr:`states` order), command (V) and parameters (:attr:`param_names`).
        friction_form : {"stick", "smooth"}
            Dry-friction form (with the ``dry_friction`` effect).
        underlap : float
            Leak of every valve edge, fraction of full opening (0 for the real valve).

        Returns
        -------
        (xdot, y) : casadi.SX
        """
        prm = self.params
        pv = {n: P[i] for i, n in enumerate(self.param_names)}
        s = self._unpack(X, pv)
        area_a, area_b = _areas(pv)
        derivs: dict[str, Any] = {}
        u_valve = U[0]
        if s.spool is not None:
            derivs["spool"], derivs["spool_rate"] = valve.spool_dynamics(
                s.spool, s.spool_rate, U[0], pv["valve.bandwidth"], pv["valve.damping"])
            u_valve = s.spool
        q_va, q_vb, q_sup = _valve_flows(prm, s, pv, _opening(u_valve, pv), underlap)
        q_a, q_b = _line_flows(s, q_va, q_vb, pv, derivs)
        leaks = _leaks(s, pv)
        dp_a, dp_b = _chamber_rates(s, q_a, q_b, leaks, area_a, area_b, pv, derivs,
                                    heat=prm.has_effect("heat_transfer"))
        force = piston.pneumatic_force(s.p_a, s.p_b, area_a, area_b,
                                       pv["gas.atmospheric_pressure"])
        dry = friction_form if prm.has_effect("dry_friction") else None
        acc = _acceleration(s, force, pv, dry)
        if prm.has_effect("supply_droop"):
            derivs["p_s"] = supply.reservoir_rate(
                s.p_s, pv["supply.pressure"], pv["supply.regulator_conductance"],
                pv["supply.reservoir_volume"], q_sup, pv["gas.temperature"],
                k=pv["gas.polytropic_index"])
        derivs.update(x=s.v, v=acc, p_a=dp_a, p_b=dp_b)
        xdot = ca.vertcat(*[derivs[sig.name] for sig in self.states])
        y = ca.vertcat(s.x, s.v, s.p_a, s.p_b, s.p_s, q_sup, force)
        return xdot, y

    def _unpack(self, X, pv: Mapping[str, Any]) -> "_States":
        """The named quantities of the state vector ``X`` (in the order of
        :func:`~workbench.plant_signals.state_signals`); where an effect is off, its
        quantity from the parameters ``pv`` (the gas temperature, the set pressure)."""
        prm = self.params
        s = _States(x=X[0], v=X[1], p_a=X[2], p_b=X[3], t_a=pv["gas.temperature"],
                    t_b=pv["gas.temperature"], p_s=pv["supply.pressure"])
        i = 4
        if prm.has_effect("valve_dynamics"):
            s.spool, s.spool_rate = X[i], X[i + 1]
            i += 2
        if prm.has_effect("heat_transfer"):
            s.t_a, s.t_b = X[i], X[i + 1]
            i += 2
        n = self.segments
        if n:
            s.line_a_p = [X[i + j] for j in range(n)]
            s.line_a_q = [X[i + n + j] for j in range(n)]
            s.line_b_p = [X[i + 2 * n + j] for j in range(n)]
            s.line_b_q = [X[i + 3 * n + j] for j in range(n)]
            i += 4 * n
        if prm.has_effect("supply_droop"):
            s.p_s = X[i]
        return s

    def regularised_f(self, underlap: float) -> ca.Function:
        """``f`` of a valve whose every edge leaks ``underlap`` (fraction of full opening).

        Used only to pin the equilibrium pressures of a closed-centre valve,
        which the ideal valve leaves undetermined.

        Under the input-affine law the same leak is added as
        ``underlap * Gamma(1) * (psi_in(p) - psi_out(p))`` at each port (the inflow of a
        fully open inlet minus the outflow of a fully open exhaust, scaled), which
        pins a closed centre (phi = 0) at the pressure where the fitted inlet and
        exhaust gains agree, as the four-edge leak does. Where phi is a real leakage
        it dominates this term and :func:`workbench.equilibrium.operating_point`'s
        refinement on the real ``f`` moves to phi's balance.
        """
        xdot, _ = self._build(self.x_sym, self.u_sym, self.p_sym, self.friction, underlap)
        return ca.Function("f_reg", [self.x_sym, self.u_sym, self.p_sym], [xdot],
                           ["x", "u", "p"], ["xdot"])

    # ---------------------------------------------------------------- helpers
    def pvec(self, **changes: float) -> np.ndarray:
        """Nominal parameter vector with some entries replaced by dotted name.

        ``load__mass=2.0`` or ``**{"valve.affine_psi_in[2]": 0.06}`` (indexed names of
        array keys cannot be keyword arguments, pass them through a dict).
        """
        p = self.p0.copy()
        for name, val in changes.items():
            p[self.param_index(name.replace("__", "."))] = val
        return p

    def initial_state(self, x0: float, p_a: float | None = None, p_b: float | None = None,
                      v0: float = 0.0, u0: float | None = None) -> np.ndarray:
        """A consistent state at position ``x0`` (m): see :func:`workbench.equilibrium.initial_state`.

        Pressures default to the equilibrium of the valve at rest at ``x0``
        (:func:`workbench.equilibrium.operating_point`); the states effects add take
        their rest values (:meth:`rest_state`): line nodes their chamber's pressure,
        line flows zero, temperatures the gas temperature, the spool the command
        ``u0`` (default: the equilibrium command) and the supply its set pressure.
        """
        return equilibrium.initial_state(self, x0, p_a=p_a, p_b=p_b, v0=v0, u0=u0)

    def evaluate_f(self, x: Sequence[float], u: float, p: Sequence[float] | None = None) -> np.ndarray:
        """Numeric state derivative."""
        return np.asarray(self.f(x, u, self.p0 if p is None else p)).ravel()

    def evaluate_h(self, x: Sequence[float], u: float, p: Sequence[float] | None = None) -> np.ndarray:
        """Numeric outputs."""
        return np.asarray(self.h(x, u, self.p0 if p is None else p)).ravel()

    def chamber_masses(self, state: Sequence[float]) -> tuple[float, float]:
        """Gas mass (kg) in chambers a and b (lines excluded) for a numeric state."""
        st = dict(zip(self.state_names, np.asarray(state, dtype=float)))
        T = self.params["gas.temperature"]
        v_a, v_b, _, _ = chamber.volumes(st["x"], 0.0, self.area_a, self.area_b, self.stroke,
                                         self.params["cylinder.dead_volume_a"],
                                         self.params["cylinder.dead_volume_b"])
        return (chamber.chamber_mass(st["p_a"], v_a, st.get("T_a", T)),
                chamber.chamber_mass(st["p_b"], v_b, st.get("T_b", T)))

    def full_opening_flow(self) -> float:
        """Mass flow (kg/s) through one fully open edge from supply to atmosphere.

        Under the input-affine law: the flow into a port held at atmospheric
        pressure with the valve fully open, phi(p_atm) + psi_in(p_atm) Gamma(1).
        """
        prm = self.params
        if self.valve_law == "input_affine":
            return float(valve.affine_flow(
                prm["gas.atmospheric_pressure"], valve.gamma_odd(1.0, prm["valve.affine_gamma"]),
                prm["valve.affine_phi"], prm["valve.affine_psi_in"],
                prm["valve.affine_psi_out"]))
        return float(gas.iso6358_flow(prm["valve.sonic_conductance"],
                                      prm["valve.critical_pressure_ratio"],
                                      prm["supply.pressure"], prm["gas.atmospheric_pressure"],
                                      prm["gas.temperature"], prm["gas.temperature"]))

    def to_dict(self) -> dict[str, Any]:
        """Facts a rig engineer checks first (SI), JSON-ready (``workbench check --json``)."""
        from . import units
        prm = self.params
        p_s, p_atm = prm["supply.pressure"], prm["gas.atmospheric_pressure"]
        q_full = self.full_opening_flow()
        dead_a, dead_b = prm["cylinder.dead_volume_a"], prm["cylinder.dead_volume_b"]
        v_a_max = chamber.volumes(self.stroke, 0.0, self.area_a, self.area_b, self.stroke,
                                  dead_a, dead_b)[0]          # piston at x = stroke
        v_b_max = chamber.volumes(0.0, 0.0, self.area_a, self.area_b, self.stroke,
                                  dead_a, dead_b)[1]          # piston at x = 0
        return {
            "name": self.name,
            "area_a_m2": self.area_a,
            "area_b_m2": self.area_b,
            "stroke_m": self.stroke,
            "volume_a_max_m3": v_a_max,
            "volume_b_max_m3": v_b_max,
            "max_force_extend_N": (p_s - p_atm) * self.area_a,
            "max_force_retract_N": (p_s - p_atm) * self.area_b,
            "valve_law": self.valve_law,
            "valve_flow_full_opening_kg_s": q_full,
            "valve_flow_full_opening_l_min_anr": units.kg_s_to_l_min_anr(q_full),
            "effects": list(self.effects),
            "states": list(self.state_names),
            "parameters": len(self.param_names),
            "controller": dict(self.controller_params),
        }

    def summary(self) -> str:
        """One line for people: name, bore/stroke, supply, valve flow, effects."""
        d = self.to_dict()
        return (f"{d['name']}: stroke {d['stroke_m'] * 1e3:.0f} mm, piston area "
                f"{d['area_a_m2'] * 1e4:.2f} cm^2, supply "
                f"{self.params['supply.pressure'] / 1e5:.2f} bar abs, valve "
                f"{d['valve_flow_full_opening_l_min_anr']:.0f} l/min ANR ({d['valve_law']}), "
                f"effects: {', '.join(d['effects']) or 'none'}")

    def __repr__(self) -> str:
        eff = ", ".join(self.effects) or "no effects"
        law = "" if self.valve_law == "iso6358" else f", valve law {self.valve_law}"
        return f"Plant({self.name!r}, {len(self.states)} states, {eff}{law})"


# ---------------------------------------------------------------------- the model, part by part
@dataclass
class _States:
    """Symbolic quantities of one state vector, by meaning (see :meth:`Plant._unpack`).

    x (m), v (m/s), p_a, p_b (Pa); the spool and its rate (V, V/s; None without
    valve dynamics); the chamber temperatures t_a, t_b (K; the gas temperature
    without heat transfer); the node pressures (Pa) and segment flows (kg/s) of
    lines a and b (empty without line dynamics); the supply pressure p_s (Pa; the
    set pressure without supply droop).
    """

    x: Any
    v: Any
    p_a: Any
    p_b: Any
    t_a: Any
    t_b: Any
    p_s: Any
    spool: Any = None
    spool_rate: Any = None
    line_a_p: list = field(default_factory=list)
    line_a_q: list = field(default_factory=list)
    line_b_p: list = field(default_factory=list)
    line_b_q: list = field(default_factory=list)


def _areas(pv: Mapping[str, Any]):
    """Piston areas (m^2) on sides a and b from the bore and rod diameter."""
    bore, rod = pv["cylinder.bore"], pv["cylinder.rod_diameter"]
    return ca.pi / 4.0 * bore ** 2, ca.pi / 4.0 * (bore ** 2 - rod ** 2)


def _opening(u_valve, pv: Mapping[str, Any]):
    """Effective valve opening (-1..1) for the command the spool follows, V
    (null offset and deadband when the plant has them)."""
    offset = pv["valve.null_offset"] if "valve.null_offset" in pv else 0.0
    deadband = pv["valve.deadband"] if "valve.deadband" in pv else 0.0
    s = valve.spool_position(u_valve, pv["valve.command_center"], pv["valve.command_span"],
                             offset)
    return valve.effective_opening(s, deadband)


def _valve_flows(prm: PlantParams, s: _States, pv: Mapping[str, Any], opening, underlap: float):
    """Mass flows (kg/s) out of the valve into ports a and b, and drawn from the supply.

    The ports are the chambers, or the first nodes of the lines (at the gas
    temperature) with line dynamics. ``[valve] law`` selects four ISO 6358 edges or
    paper 003's input-affine law.
    """
    T = pv["gas.temperature"]
    lines = bool(s.line_a_p)
    port_a, port_b = (s.line_a_p[0], s.line_b_p[0]) if lines else (s.p_a, s.p_b)
    port_ta, port_tb = (T, T) if lines else (s.t_a, s.t_b)
    if prm["valve.law"] == "input_affine":
        # Paper 003's approximation II at both ports (port b mirrored); it does
        # not see the supply pressure or the gas temperatures, and its supply
        # draw is the inflow part max(q_a, 0) + max(q_b, 0).
        coeffs = {name: [pv[f"valve.{name}[{j}]"] for j in range(len(prm[f"valve.{name}"]))]
                  for name in ("affine_phi", "affine_psi_in", "affine_psi_out",
                               "affine_gamma")}
        return valve.affine_port_flows(
            opening, port_a, port_b, coeffs["affine_phi"], coeffs["affine_psi_in"],
            coeffs["affine_psi_out"], coeffs["affine_gamma"], underlap=underlap)
    return valve.four_edge_flows(
        opening, s.p_s, port_a, port_b, pv["gas.atmospheric_pressure"],
        pv["valve.sonic_conductance"], pv["valve.critical_pressure_ratio"], T, port_ta,
        port_tb, underlap, underlap_law=prm["valve.underlap_law"])


def _line_flows(s: _States, q_va, q_vb, pv: Mapping[str, Any], derivs: dict):
    """Mass flows (kg/s) into chambers a and b: the valve's own without line
    dynamics, else the last segment's of each line, whose node and segment rates
    go into ``derivs``."""
    if not s.line_a_p:
        return q_va, q_vb
    length, diam, T = pv["lines.length"], pv["lines.diameter"], pv["gas.temperature"]
    dpa, dqa = line.line_rates(s.line_a_p, s.line_a_q, q_va, s.p_a, length, diam, T)
    dpb, dqb = line.line_rates(s.line_b_p, s.line_b_q, q_vb, s.p_b, length, diam, T)
    for j in range(len(s.line_a_p)):
        derivs[f"line_a_p{j}"], derivs[f"line_a_q{j}"] = dpa[j], dqa[j]
        derivs[f"line_b_p{j}"], derivs[f"line_b_q{j}"] = dpb[j], dqb[j]
    return s.line_a_q[-1], s.line_b_q[-1]


def _leaks(s: _States, pv: Mapping[str, Any]):
    """(leak_a, leak_b, cross), kg/s: leaks from chambers a and b to atmosphere and
    across the piston (cross > 0: a -> b); zero for the keys the plant lacks."""
    leak_a = leak_b = cross = 0.0
    if "leakage.conductance_to_atmosphere" in pv:
        c_leak, p_atm = pv["leakage.conductance_to_atmosphere"], pv["gas.atmospheric_pressure"]
        leak_a = supply.leak_to_atmosphere(s.p_a, p_atm, c_leak, s.t_a)
        leak_b = supply.leak_to_atmosphere(s.p_b, p_atm, c_leak, s.t_b)
    if "leakage.cross_piston" in pv:
        cross = supply.cross_piston_leak(s.p_a, s.p_b, pv["leakage.cross_piston"])
    return leak_a, leak_b, cross


def _chamber_rates(s: _States, q_a, q_b, leaks, area_a, area_b, pv: Mapping[str, Any],
                   derivs: dict, heat: bool):
    """Pressure rates (Pa/s) of chambers a and b for the inflows ``q_a``, ``q_b``
    (kg/s) less ``leaks`` (:func:`_leaks`); with ``heat`` (transfer to the walls) their
    temperature rates (K/s) go into ``derivs``, else the gas is polytropic."""
    leak_a, leak_b, cross = leaks
    T, k = pv["gas.temperature"], pv["gas.polytropic_index"]
    v_a, v_b, dv_a, dv_b = chamber.volumes(s.x, s.v, area_a, area_b, pv["cylinder.stroke"],
                                           pv["cylinder.dead_volume_a"],
                                           pv["cylinder.dead_volume_b"])
    if not heat:
        dp_a = chamber.pressure_rate(s.p_a, v_a, dv_a, q_a - leak_a - cross, k, T)
        dp_b = chamber.pressure_rate(s.p_b, v_b, dv_b, q_b - leak_b + cross, k, T)
        return dp_a, dp_b
    h = pv["gas.heat_transfer_coefficient"]

    def split(q):
        return ca.fmax(q, 0.0), ca.fmax(-q, 0.0)

    qa_in, qa_out = split(q_a)
    qb_in, qb_out = split(q_b)
    xa_in, xa_out = split(-cross)   # cross > 0: a -> b
    xb_in, xb_out = split(cross)
    tq_a = T * qa_in + s.t_b * xa_in
    tq_b = T * qb_in + s.t_a * xb_in
    dp_a, derivs["T_a"] = chamber.pressure_temperature_rates(
        s.p_a, s.t_a, v_a, dv_a, tq_a, qa_in + xa_in, qa_out + xa_out + leak_a, h, T)
    dp_b, derivs["T_b"] = chamber.pressure_temperature_rates(
        s.p_b, s.t_b, v_b, dv_b, tq_b, qb_in + xb_in, qb_out + xb_out + leak_b, h, T)
    return dp_a, dp_b


def _acceleration(s: _States, force, pv: Mapping[str, Any], dry_friction: str | None):
    """Piston acceleration, m/s^2: pneumatic ``force`` (N) less the external load,
    the end stops' force, viscous friction and, with ``dry_friction`` (its form,
    ``"stick"`` or ``"smooth"``), Coulomb/Stribeck friction."""
    L, m, beta = pv["cylinder.stroke"], pv["load.mass"], pv["load.viscous_friction"]
    drive = force - pv["load.external_force"] + piston.end_stop_force(s.x, s.v, L, m)
    if dry_friction is None:
        return (drive - beta * s.v) / m
    fc, fs, vs = (pv["friction.coulomb"], pv["friction.static"],
                  pv["friction.stribeck_velocity"])
    if dry_friction == "stick":
        return friction.stick_slip_acceleration(s.v, drive, m, beta, fc, fs, vs)
    return (drive - friction.smooth_friction(s.v, fc, fs, vs, beta)) / m
