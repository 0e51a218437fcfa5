"""The NMPC's estimate of its lumped lines' states (``lines="lumped"``).

The NMPC measures x, v, p_a, p_b; its prediction model with lumped lines
(:func:`.model.prediction_model`) also has each line's node pressures and segment
flows (:data:`.model.LINE_STATES` for one segment per line,
:func:`.model.line_states`), which no rig measures. They are estimated
each sample by a Kalman filter on the NMPC's own model (extended: linearised along
the estimate):

* prediction: the previous sample's state (measured x, v, p_a, p_b and the line
  estimate) one interval on under the command applied since and the force estimate,
  by the NMPC's interval map ``Fj`` (its Jacobian A propagates the covariance);
* correction from the measured chamber pressures: what the model mispredicted in
  p_a, p_b is mostly the flow the lines delivered (a line's flow fills its chamber
  directly), so the innovation corrects the line states by the Kalman gain.

Noise model (scaled as the NMPC's state): the pressure sensors' noise ``pressure_noise``
(Pa, std) on p_a, p_b (at least :data:`PRESSURE_FLOOR` of supply: a sensor's accuracy
class), the measured x and v exact; process noise on the line states only, for what a
single segment lacks of a distributed line (its higher modes): a flow error of
:data:`FLOW_NOISE` of the valve's full flow per sample, and the node pressure that flow
makes in one sample, gamma R T sigma_q T / V_node. Measured (precision rig, 10 ms
ahead, moving sections, 300 Pa pressure noise; /tmp/h14j/pred2.py): position error
90-107 um rms for a flow noise of 1-7 % of the valve's flow and a node noise of
1-100 kPa per sample (the 4-state model 201 um); 161 um with the segment model alone
(no correction), 43 um started from the rig's true line state.

The first sample starts the lines at rest: node pressure = chamber pressure, no flow
(and so does a step that is not finite). The compiled sample (:mod:`.fast`) runs the
same step, generated as C, inside its one call per sample.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .model import NMPC_STATES

__all__ = ["FLOW_NOISE", "PRESSURE_FLOOR", "line_noise", "line_filter", "line_start"]

#: fraction of the valve's full flow (sonic conductance x supply x density at 1 bar,
#: 20 degC) by which a lumped line's flow may be wrong after one sample (44 g/s on the
#: precision rig: 4.4 g/s; the segment model alone was 1.1 g/s rms off the rig's
#: averaged segments, with peaks of several g/s at the line's ringing). Closed loop
#: (precision rig, test profile of tests/test_precision_positioning.py, seed 0; command
#: activity on the moving sections): 0.0025 -> 0.56 V, 0.025 -> 0.38 V, 0.1 -> 0.36 V,
#: 0.3 -> 0.37 V (the estimate then follows the measured pressures; the 4-state model
#: 0.74 V)
FLOW_NOISE = 0.1
#: pressure sensors' noise floor, fraction of supply (0.1 %: an accuracy class)
PRESSURE_FLOOR = 1e-3
#: kg/m^3, air density at 1 bar, 20 degC (ISO 6358's reference)
_RHO0 = 1.185


def line_noise(pb, pressure_noise: float) -> tuple[np.ndarray, np.ndarray]:
    """(Q (nx, nx), R (2, 2)): the filter's process noise per sample on the scaled
    state and the scaled pressure measurement noise (module text)."""
    from ...physics.gas import GAMMA, R_AIR
    prm = pb.model.params
    nx, sx, T = pb.nx, pb.sx, pb.T
    p_sup = float(prm["supply.pressure"])
    cond = prm.get("valve.sonic_conductance")
    q_full = (float(cond) * p_sup * _RHO0 if cond else 4.0 * sx[5])
    sq = FLOW_NOISE * q_full
    names = pb.model.state_names
    n_seg = (nx - 4) // 4
    v_node = (math.pi / 4.0 * float(prm["lines.diameter"]) ** 2 * float(prm["lines.length"])
              / n_seg)
    sp = GAMMA * R_AIR * float(prm["gas.temperature"]) * sq * T / v_node
    q = np.zeros(nx)
    for i in range(4, nx):
        q[i] = (sp if names[i][7] == "p" else sq) / sx[i]
    s_meas = max(float(pressure_noise), PRESSURE_FLOOR * p_sup) / p_sup
    return np.diag(q ** 2), np.eye(2) * s_meas ** 2


def line_start(zm: np.ndarray, nx: int) -> tuple[np.ndarray, np.ndarray]:
    """(scaled state, line covariance (nl, nl) flattened, nl = nx - 4) of the first
    sample: the lines at rest at the measured chamber pressures ``zm`` (scaled x, v,
    p_a, p_b): node pressures those of their chamber, no flow."""
    n = (nx - 4) // 4
    line = [zm[2]] * n + [0.0] * n + [zm[3]] * n + [0.0] * n
    return np.concatenate([zm[:4], line]), np.zeros((nx - 4) ** 2)


def line_filter(pb, pressure_noise: float) -> ca.Function:
    """The filter's step as a CasADi function ``wb_nmpc_lines(zprev, w, d, zm, Pl) ->
    (z, Pl_next)``: the previous scaled state (nx,), the command applied since (scaled),
    the force estimate (N), the measured x, v, p_a, p_b (scaled) and the line states'
    covariance (nl^2,: nl x nl column-major, nl = nx - 4); the state with the lines
    estimated and their new covariance."""
    nx = pb.nx
    nl = nx - 4
    Q, R = line_noise(pb, pressure_noise)
    zprev = ca.SX.sym("zprev", nx)
    w, d = ca.SX.sym("w"), ca.SX.sym("d")
    zm = ca.SX.sym("zm", len(NMPC_STATES))
    Pl = ca.SX.sym("Pl", nl * nl)
    zpred, A, _ = pb.Fj(zprev, w, d)
    P0 = ca.SX.zeros(nx, nx)
    P0[2, 2] = P0[3, 3] = R[0, 0]
    P0[4:, 4:] = ca.reshape(Pl, nl, nl)
    Pp = ca.mtimes([A, P0, A.T]) + ca.DM(Q)
    H = ca.DM(np.eye(nx)[2:4, :])
    S = ca.mtimes([H, Pp, H.T]) + ca.DM(R)
    K = ca.mtimes(ca.mtimes(Pp, H.T), ca.inv(S))
    innov = zm[2:4] - zpred[2:4]
    line = zpred[4:] + ca.mtimes(K[4:, :], innov)
    Pn = Pp - ca.mtimes([K, H, Pp])
    Pn = 0.5 * (Pn + Pn.T)
    return ca.Function("wb_nmpc_lines", [zprev, w, d, zm, Pl],
                       [ca.vertcat(zm, line), ca.reshape(Pn[4:, 4:], nl * nl, 1)],
                       ["zprev", "w", "d", "zm", "Pl"], ["z", "Pl_next"])
