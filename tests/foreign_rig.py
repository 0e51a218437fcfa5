"""A rig simulated by other code than the workbench's (test helper, not a test file).

Written from /work/shared/spec/physics.md and formats.md section 2 with numpy/scipy
only: nothing here imports ``workbench.physics`` or ``workbench.plant``. The
differences from the workbench's model are deliberate (a diagnosis must not depend
on sharing its simulator's discretisation):

- valve: four ISO 6358 edges, psi patched by a *linear* (laminar) piece over the
  last 2e-3 of the pressure ratio; temperature factor sqrt(T0/T_up);
- spool dynamics: y'' = w^2 (u - y) - 2 zeta w y' on the command, then null
  offset, clipping to [-1, 1] and overlap (deadband) as in physics.md;
- chambers: polytropic p-balance, or with ``heat_transfer`` a (p, m) mass and energy
  balance (the workbench integrates (p, T)): dm/dt = q_in - q_out,
  dp/dt = (gamma-1)/V (c_p (T_in q_in - T q_out) + h (T_w - T)) - gamma p/V dV/dt,
  T = p V/(m r), wall at the gas temperature;
- lines: ``LINE_NODES`` lumped pi-segments per line (half a segment's volume at each
  end, the valve-end half as its own node, the chamber-end half added to the
  chamber); node capacitance adiabatic, resistance Hagen-Poiseuille + Blasius,
  inertance L/(N A) (the workbench uses a different segment count and layout:
  a full segment's volume at each segment's valve end, none at the chamber). Or
  (``line_model="lumped"``) a second, coarser model: one lumped pi section, half the
  line's volume at the valve port and half added to the chamber, joined by the whole
  line's inertance L/A and its laminar (Hagen-Poiseuille) resistance only;
- leakage: ISO 6358 gap to atmosphere (b = 0.528, the nozzle ratio of physics.md)
  per chamber and a laminar cross-piston leak c (p_a - p_b);
- supply droop: reservoir of volume V_r fed through an ISO 6358 regulator
  restriction (b = 0.528) from the set pressure, dp_s/dt = k r T/V_r (q_reg - q_valve);
- dry friction: a smooth Stribeck curve times tanh(v / v_eps) plus viscous friction
  (the workbench uses Karnopp stick-slip), or (``law="lugre"``) the LuGre bristle model
  (Canudas de Wit et al. 1995): dz/dt = v - sigma0 |v| z / g(v), g(v) = Fc + (Fs - Fc)
  exp(-(v/vs)^2), F = sigma0 z + sigma1 dz/dt, with pre-sliding displacement and
  frictional lag that neither the Karnopp nor the smooth law has;
- end stops: stiff spring-damper at 0 and L.

The PD loop of the plant's [controller] runs every sample_time on the noisy,
quantised position; each controller period is one ``solve_ivp`` call (LSODA) with
the 1 kHz log points as ``t_eval``. Logged: noise (20 um, 500 Pa) and 12-bit
quantisation (position over the stroke, pressures over 0..1 MPa).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

R_AIR, GAMMA, T_REF, RHO0 = 287.0, 1.4, 293.15, 1.185
B_NOZZLE = (2.0 / (GAMMA + 1.0)) ** (GAMMA / (GAMMA - 1.0))
CP = GAMMA * R_AIR / (GAMMA - 1.0)
MU_AIR = 1.81e-5
LAMINAR = 2e-3          #: pressure-ratio width of the laminar patch of psi
LINE_NODES = 5          #: pi-segments per line (the diagnosis fits 3, the workbench 6-16)


def iso_flow(C, b, p1, p2, t_up=T_REF):
    """Mass flow (kg/s) from p1 to p2 (negative if p2 > p1) through an ISO 6358 restriction."""
    if p1 >= p2:
        up, dw, sign = p1, p2, 1.0
    else:
        up, dw, sign = p2, p1, -1.0
    x = dw / up
    if x <= b:
        psi = 1.0
    elif x > 1.0 - LAMINAR:
        z0 = (1.0 - LAMINAR - b) / (1.0 - b)
        psi = math.sqrt(1.0 - z0 * z0) * (1.0 - x) / LAMINAR
    else:
        z = (x - b) / (1.0 - b)
        psi = math.sqrt(1.0 - z * z)
    return sign * C * up * RHO0 * math.sqrt(T_REF / t_up) * psi


def load_plant(plant_file, overrides=None) -> dict:
    """Flat dotted-key dict of a plant TOML file, with ``overrides`` (the concealed values)."""
    doc = tomllib.loads(Path(plant_file).read_text(encoding="utf-8"))
    flat = {f"{sec}.{k}": v for sec, tab in doc.items() if isinstance(tab, dict)
            for k, v in tab.items()}
    flat.update(overrides or {})
    return flat


class ForeignRig:
    """The rig's state equations; ``P`` is the flat dict of :func:`load_plant`."""

    def __init__(self, P: dict, coulomb=0.0, static=0.0, stribeck=0.01, v_eps=2e-3,
                 law="smooth", sigma0=None, sigma1=None, line_model="pi5"):
        self.P = P
        self.k, self.patm, self.T = (P["gas.polytropic_index"], P["gas.atmospheric_pressure"],
                                     P["gas.temperature"])
        self.A = math.pi / 4 * P["cylinder.bore"] ** 2
        self.L, self.m = P["cylinder.stroke"], P["load.mass"]
        self.fc, self.fs, self.vs, self.v_eps = coulomb, static, stribeck, v_eps
        self.heat = P.get("gas.heat_transfer_coefficient")
        self.spool = "valve.bandwidth" in P
        self.droop = "supply.reservoir_volume" in P
        self.lines = "lines.length" in P
        if line_model not in ("pi5", "lumped"):
            raise ValueError(f"line_model {line_model!r}: 'pi5' or 'lumped'")
        self.nodes = LINE_NODES if line_model == "pi5" else 1
        self.blasius = line_model == "pi5"
        idx = 4
        self.i_spool = idx
        idx += 2 if self.spool else 0
        self.i_mass = idx
        idx += 2 if self.heat is not None else 0
        self.i_line = idx
        idx += 4 * self.nodes if self.lines else 0
        self.i_ps = idx
        idx += 1 if self.droop else 0
        self.lugre = law == "lugre" and bool(coulomb)
        self.i_z = idx
        idx += 1 if self.lugre else 0
        self.n = idx
        # bristles: break-away within 0.1 mm of pre-sliding, critically damped on the mass
        self.sigma0 = sigma0 if sigma0 is not None else max(static, coulomb) / 1e-4
        self.sigma1 = sigma1 if sigma1 is not None else 2.0 * math.sqrt(self.sigma0 * self.m)
        if self.lines:
            d = P["lines.diameter"]
            self.a_line = math.pi / 4 * d * d
            self.seg = P["lines.length"] / self.nodes
            self.v_node = self.a_line * self.seg      # interior node: two half segments

    def opening(self, u_spool):
        """Signed metering opening for the command the spool follows."""
        P = self.P
        s = (u_spool - P["valve.command_center"] - P.get("valve.null_offset", 0.0)) \
            / P["valve.command_span"]
        s = min(max(s, -1.0), 1.0)
        d = P.get("valve.deadband", 0.0)
        return math.copysign(max(abs(s) - d, 0.0) / (1.0 - d), s)

    def initial(self, x0, p_a, p_b, u0):
        z = np.zeros(self.n)
        z[:4] = x0, 0.0, p_a, p_b
        if self.spool:
            z[self.i_spool] = u0
        if self.heat is not None:
            z[self.i_mass] = p_a * self.vol_a(x0) / (R_AIR * self.T)
            z[self.i_mass + 1] = p_b * self.vol_b(x0) / (R_AIR * self.T)
        if self.lines:
            j = self.i_line
            z[j:j + self.nodes] = p_a
            z[j + 2 * self.nodes:j + 3 * self.nodes] = p_b
        if self.droop:
            z[self.i_ps] = self.P["supply.pressure"]
        return z

    def vol_a(self, x):
        v = self.P["cylinder.dead_volume_a"] + self.A * x
        return v + (0.5 * self.v_node if self.lines else 0.0)

    def vol_b(self, x):
        v = self.P["cylinder.dead_volume_b"] + self.A * (self.L - x)
        return v + (0.5 * self.v_node if self.lines else 0.0)

    def friction(self, v, z=None, dz=None):
        f = self.P["load.viscous_friction"] * v
        if self.lugre:
            g = self.fc + (self.fs - self.fc) * math.exp(-(v / self.vs) ** 2)
            zd = v - self.sigma0 * abs(v) * z[self.i_z] / g
            dz[self.i_z] = zd
            return f + self.sigma0 * z[self.i_z] + self.sigma1 * zd
        if self.fc:
            f += (self.fc + (self.fs - self.fc) * math.exp(-(v / self.vs) ** 2)) \
                * math.tanh(v / self.v_eps)
        return f

    def line(self, z, j, q_valve, p_end, dz):
        """Rates of one line (nodes j..j+N-1, flows j+N..j+2N-1); returns the chamber inflow."""
        N, T = self.nodes, self.T
        seg, area = self.seg, self.a_line
        d = self.P["lines.diameter"]
        for i in range(N):
            p_i, q_i = z[j + i], z[j + N + i]
            inflow = q_valve if i == 0 else z[j + N + i - 1]
            vol = 0.5 * self.v_node if i == 0 else self.v_node
            dz[j + i] = GAMMA * R_AIR * T / vol * (inflow - q_i)
            p_next = p_end if i == N - 1 else z[j + i + 1]
            rho = 0.5 * (p_i + p_next) / (R_AIR * T)
            vel = q_i / (rho * area)
            re = max(rho * abs(vel) * d / MU_AIR, 1.0)
            # Hagen-Poiseuille 32 mu v / d^2 plus Blasius 0.316 Re^-0.25 / d * rho v|v| / 2
            drop = (32.0 * MU_AIR * vel / (d * d)
                    + self.blasius * 0.158 * re ** -0.25 * rho * vel * abs(vel) / d) * seg
            dz[j + N + i] = area / seg * (p_i - p_next - drop)
        return z[j + 2 * N - 1]

    def rhs(self, t, z, u):
        P, A, T = self.P, self.A, self.T
        x, v, pa, pb = z[0], z[1], z[2], z[3]
        dz = np.zeros(self.n)
        u_sp = u
        if self.spool:
            w = 2 * math.pi * P["valve.bandwidth"]
            y, yd = z[self.i_spool], z[self.i_spool + 1]
            dz[self.i_spool] = yd
            dz[self.i_spool + 1] = w * w * (u - y) - 2 * P["valve.damping"] * w * yd
            u_sp = y
        op = self.opening(u_sp)
        o_in, o_out = max(op, 0.0), max(-op, 0.0)
        ps = z[self.i_ps] if self.droop else P["supply.pressure"]
        if self.heat is not None:
            ma, mb = z[self.i_mass], z[self.i_mass + 1]
            ta, tb = pa * self.vol_a(x) / (ma * R_AIR), pb * self.vol_b(x) / (mb * R_AIR)
        else:
            ta = tb = T
        j = self.i_line
        na, nb = (z[j], z[j + 2 * self.nodes]) if self.lines else (pa, pb)
        tna, tnb = (T, T) if self.lines else (ta, tb)
        C, b = P["valve.sonic_conductance"], P["valve.critical_pressure_ratio"]
        sa, sb = o_in * iso_flow(C, b, ps, na, T), o_out * iso_flow(C, b, ps, nb, T)
        qa = sa - o_out * iso_flow(C, b, na, self.patm, tna)
        qb = sb - o_in * iso_flow(C, b, nb, self.patm, tnb)
        if self.lines:
            qa = self.line(z, j, qa, pa, dz)
            qb = self.line(z, j + 2 * self.nodes, qb, pb, dz)
        if self.droop:
            q_reg = iso_flow(P["supply.regulator_conductance"], B_NOZZLE, P["supply.pressure"],
                             ps, T)
            dz[self.i_ps] = self.k * R_AIR * T / P["supply.reservoir_volume"] * (q_reg - sa - sb)
        la = lb = 0.0
        if "leakage.conductance_to_atmosphere" in P:
            c = P["leakage.conductance_to_atmosphere"]
            la = iso_flow(c, B_NOZZLE, pa, self.patm, ta)
            lb = iso_flow(c, B_NOZZLE, pb, self.patm, tb)
        cross = P.get("leakage.cross_piston", 0.0) * (pa - pb)
        va, vb = self.vol_a(x), self.vol_b(x)
        if self.heat is None:
            dz[2] = self.k / va * (R_AIR * T * (qa - la - cross) - pa * A * v)
            dz[3] = self.k / vb * (R_AIR * T * (qb - lb + cross) + pb * A * v)
        else:
            dz[2], dz[self.i_mass] = self._energy(pa, ta, va, A * v, qa, -la - cross, tb)
            dz[3], dz[self.i_mass + 1] = self._energy(pb, tb, vb, -A * v, qb, -lb + cross, ta)
        force = (pa - pb) * A - self.friction(v, z, dz)
        kwall, m = self.m * (2 * math.pi * 200.0) ** 2, self.m
        if x < 0:
            force -= kwall * x + 1.4 * m * 2 * math.pi * 200.0 * v
        if x > self.L:
            force -= kwall * (x - self.L) + 1.4 * m * 2 * math.pi * 200.0 * v
        dz[0], dz[1] = v, force / m
        return dz

    def _energy(self, p, temp, vol, dvol, q_port, q_other, t_other):
        """(dp/dt, dm/dt) of a chamber with wall heat exchange (energy balance of an ideal gas).

        q_port: from the valve/line (enters at the gas temperature, leaves at ``temp``);
        q_other: leaks (enter at ``t_other`` from the other chamber, leave at ``temp``).
        """
        h_in = h_out = 0.0
        for q, t_in in ((q_port, self.T), (q_other, t_other)):
            if q >= 0:
                h_in += CP * t_in * q
            else:
                h_out += CP * temp * (-q)
        dp = (GAMMA - 1.0) / vol * (h_in - h_out + self.heat * (self.T - temp)) \
            - GAMMA * p / vol * dvol
        return dp, q_port + q_other


def simulate(plant_file, reference, duration, seed=0, overrides=None, friction=None,
             p0=(4.4e5, 4.4e5), rtol=1e-6, line_model="pi5"):
    """Closed-loop PD run of the foreign rig, sampled at 1 kHz.

    Parameters
    ----------
    plant_file : the nominal plant TOML (its [controller] is the loop).
    reference : r(t), m. duration : s. seed : seed of the position sensor noise.
    overrides : concealed dotted keys (formats.md section 2) -> values, SI.
    friction : dict(coulomb, static, stribeck[, v_eps]) of the smooth dry-friction law, or
        with ``law="lugre"`` (and optionally sigma0 N/m, sigma1 N s/m) the LuGre model.
    p0 : chamber pressures at rest at the start, Pa. rtol : LSODA's relative tolerance.
    line_model : "pi5" (5 pi-segments, laminar + Blasius) or "lumped" (one pi section,
        laminar), see the module docstring.

    Returns
    -------
    (t, Z, U, rng): times (s), true states (n, 5: x, v, p_a, p_b and the supply pressure
    at the valve, the reservoir's with supply droop), applied command (V),
    and the noise generator (position noise drawn, the pressures' still to draw).
    """
    P = load_plant(plant_file, overrides)
    rig = ForeignRig(P, **(friction or {}), line_model=line_model)
    dt, Ts = 1e-3, P["controller.sample_time"]
    ratio = int(round(Ts / dt))
    rng = np.random.default_rng(seed)
    n = int(round(duration / dt)) + 1
    t = np.arange(n) * dt
    uc = P["valve.command_center"]
    z = rig.initial(float(reference(0.0)), p0[0], p0[1], uc)
    lsb_x = rig.L / 4096
    nx = rng.normal(0, 20e-6, n)
    Z = np.empty((n, 5))
    U = np.empty(n)
    atol = np.full(rig.n, 1e-2)
    atol[:2] = 1e-9, 1e-7
    if rig.lugre:
        atol[rig.i_z] = 1e-10            # bristle deflection, m (pre-sliding ~0.1 mm)
    if rig.heat is not None:
        atol[rig.i_mass:rig.i_mass + 2] = 1e-12
    if rig.lines:
        nn = rig.nodes
        atol[rig.i_line:rig.i_line + 4 * nn] = 1e-2
        for s in (nn, 3 * nn):
            atol[rig.i_line + s:rig.i_line + s + nn] = 1e-9
    e_prev = None
    for i0 in range(0, n, ratio):
        x_meas = round((z[0] + nx[i0]) / lsb_x) * lsb_x
        e = float(reference(t[i0])) - x_meas
        e_prev = e if e_prev is None else e_prev
        u = min(max(uc + P["controller.kp"] * e + P["controller.kd"] * (e - e_prev) / Ts,
                    P["valve.command_min"]), P["valve.command_max"])
        e_prev = e
        i1 = min(i0 + ratio, n - 1)
        U[i0:i1 + 1] = u
        Z[i0] = *z[:4], (z[rig.i_ps] if rig.droop else P["supply.pressure"])
        if i1 == i0:
            break
        sol = solve_ivp(rig.rhs, (t[i0], t[i1]), z, method="LSODA", args=(u,), rtol=rtol,
                        atol=atol, t_eval=t[i0:i1 + 1])
        Z[i0 + 1:i1 + 1, :4] = sol.y[:4, 1:].T
        Z[i0 + 1:i1 + 1, 4] = sol.y[rig.i_ps, 1:] if rig.droop else P["supply.pressure"]
        z = sol.y[:, -1]
    return t, Z, U, (rng, nx)


def record(plant_file, reference, duration, seed, pressures=True, supply=False, **kw):
    """:func:`simulate` logged as a Recording: noise (20 um, 500 Pa) and 12-bit quantisation;
    ``pressures=False``: position only, ``"p_a"`` or ``"p_b"``: that chamber's pressure
    only (the pressure noise is drawn all the same, so the other signals are the same as
    with both pressures). ``supply=True``: the supply pressure at the valve is logged as
    ``p_s`` too (noise and quantisation as the chamber pressures, drawn after theirs)."""
    from workbench.recording import Recording
    t, Z, U, (rng, nx) = simulate(plant_file, reference, duration, seed, **kw)
    n = len(t)
    lsb_x, lsb_p = load_plant(plant_file)["cylinder.stroke"] / 4096, 1e6 / 4096
    X = np.round((Z[:, 0] + nx) / lsb_x) * lsb_x
    PA = np.round((Z[:, 2] + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p
    PB = np.round((Z[:, 3] + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p
    meta = {"sample_time": t[1] - t[0], "source": "tests/foreign_rig.py"}
    cols = {"p_a": PA, "p_b": PB} if pressures else {}
    if isinstance(pressures, str):
        cols = {pressures: cols[pressures]}
    if supply:
        cols["p_s"] = np.round((Z[:, 4] + rng.normal(0, 500.0, n)) / lsb_p) * lsb_p
    return Recording.from_arrays(t, u=U, x=X, r=np.asarray(reference(t), float),
                                 metadata=meta, **cols)


def simulate_logged(plant_file, reference, duration, seed=0, overrides=None, friction=None,
                    p0=(4.4e5, 4.4e5), rtol=1e-6, line_model="pi5", log_period=1e-3,
                    jitter=0.0, open_loop=None):
    """:func:`simulate` on a logger's own clock: samples every ``log_period`` s, each
    instant moved by up to +-``jitter`` x ``log_period`` (uniform), while the
    controller keeps its own period (the [controller] sample_time, exact). With
    ``open_loop`` (a function t -> u, V) the command is that function held over 10 ms
    instead of the PD loop.

    Returns (t, Z, U, rng): log instants (s), true states (n, 5) as :func:`simulate`,
    the command in force at each instant (V), and the generator for the sensor noise.
    """
    P = load_plant(plant_file, overrides)
    rig = ForeignRig(P, **(friction or {}), line_model=line_model)
    Ts = P["controller.sample_time"] if open_loop is None else 0.01
    rng = np.random.default_rng(seed)
    n = int(round(duration / log_period)) + 1
    t = np.arange(n) * log_period
    if jitter:
        t[1:-1] += rng.uniform(-jitter, jitter, n - 2) * log_period
    uc = P["valve.command_center"]
    z = rig.initial(float(reference(0.0)), p0[0], p0[1], uc)
    lsb_x = rig.L / 4096
    atol = np.full(rig.n, 1e-2)
    atol[:2] = 1e-9, 1e-7
    if rig.lugre:
        atol[rig.i_z] = 1e-10
    if rig.heat is not None:
        atol[rig.i_mass:rig.i_mass + 2] = 1e-12
    if rig.lines:
        nn = rig.nodes
        for s in (nn, 3 * nn):
            atol[rig.i_line + s:rig.i_line + s + nn] = 1e-9
    Z = np.empty((n, 5))
    U = np.empty(n)
    Z[0] = *z[:4], (z[rig.i_ps] if rig.droop else P["supply.pressure"])
    e_prev, k = None, 0
    while k * Ts < t[-1] - 1e-12:
        t0, t1 = k * Ts, min((k + 1) * Ts, t[-1])
        if open_loop is None:
            x_meas = round((z[0] + rng.normal(0, 20e-6)) / lsb_x) * lsb_x
            e = float(reference(t0)) - x_meas
            e_prev = e if e_prev is None else e_prev
            u = uc + P["controller.kp"] * e + P["controller.kd"] * (e - e_prev) / Ts
            e_prev = e
        else:
            u = float(open_loop(t0))
        u = min(max(u, P["valve.command_min"]), P["valve.command_max"])
        sel = np.flatnonzero((t > t0) & (t <= t1))
        U[(t >= t0) & (t <= t1)] = u
        te = t[sel] if len(sel) and t[sel[-1]] == t1 else np.append(t[sel], t1)
        sol = solve_ivp(rig.rhs, (t0, t1), z, method="LSODA", args=(u,), rtol=rtol,
                        atol=atol, t_eval=te)
        Z[sel, :4] = sol.y[:4, :len(sel)].T
        Z[sel, 4] = sol.y[rig.i_ps, :len(sel)] if rig.droop else P["supply.pressure"]
        z = sol.y[:, -1]
        k += 1
    return t, Z, U, rng


def log_csv(path, plant_file, t, Z, U, rng, reference=None, pressures=True, x_noise=20e-6,
            p_noise=500.0, bits=12, colour=0.0, units="si", supply=False, declare=True):
    """Write a logger's CSV of :func:`simulate_logged`'s run.

    Noise: Gaussian, or with ``colour`` in (0, 1) first-order coloured (AR(1) with that
    pole, scaled to the same standard deviation); then ``bits`` quantisation (position
    over the stroke, pressures over 0..1 MPa absolute). ``units``: "si" or "rig" (t in
    ms, x and r in mm, pressures in gauge bar, declared in the header cells).
    ``pressures``: True, False or "p_a"/"p_b". ``supply``: log p_s as well.
    ``declare=False``: the rig units are written under the bare column names, as a
    logger that does not say its units would.
    """
    n = len(t)
    L = load_plant(plant_file)["cylinder.stroke"]

    def noise(sd):
        w = rng.normal(0, sd, n)
        if colour:
            from scipy.signal import lfilter
            w = lfilter([math.sqrt(1 - colour ** 2)], [1, -colour], w)
        return w
    lsb_x, lsb_p = L / 2 ** bits, 1e6 / 2 ** bits
    cols = {"t": t, "u": U, "x": np.round((Z[:, 0] + noise(x_noise)) / lsb_x) * lsb_x}
    if reference is not None:
        cols["r"] = np.asarray(reference(t), float)
    pa = np.round((Z[:, 2] + noise(p_noise)) / lsb_p) * lsb_p
    pb = np.round((Z[:, 3] + noise(p_noise)) / lsb_p) * lsb_p
    if pressures is True or pressures == "p_a":
        cols["p_a"] = pa
    if pressures is True or pressures == "p_b":
        cols["p_b"] = pb
    if supply:
        cols["p_s"] = np.round((Z[:, 4] + noise(p_noise)) / lsb_p) * lsb_p
    head, out = [], []
    for name, y in cols.items():
        if units == "rig" and name == "t":
            head.append("t [ms]"); out.append(y * 1e3)
        elif units == "rig" and name in ("x", "r"):
            head.append(f"{name} [mm]"); out.append(y * 1e3)
        elif units == "rig" and name.startswith("p_"):
            head.append(f"{name} [bar_g]"); out.append((y - 101325.0) / 1e5)
        else:
            head.append(name); out.append(y)
    if not declare:
        head = [h.split(" [")[0] for h in head]
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("# source: tests/foreign_rig.py\n" + ",".join(head) + "\n")
        np.savetxt(fh, np.column_stack(out), delimiter=",", fmt="%.10g")
    return path
