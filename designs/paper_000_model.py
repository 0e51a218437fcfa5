"""Paper 000's numbers and the pure functions on them (designs/paper_000.py's model part).

Values quoted from the paper (PAPER, Table I), the assumed settings of the
reproduction, the comparison rows of the summary contract and the derived
quantities (Table I's response, DC gain, poles, distance of an ARX model to it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench import Plant

HERE = Path(__file__).resolve().parent


ROOT = HERE.parent


PLANT = HERE / "plants" / "situm_rodless_nominal.toml"


#: The calibrated plant a full run writes (copied here from DIR/situm_rodless.calibrated.toml).
CALIBRATED = HERE / "plants" / "situm_rodless.toml"


TITLE = "Paper 000 reproduced: calibrated rodless rig, Table I re-identified"


P_ATM = 101325.0


#: Values quoted from paper 000: (value, unit, where).
PAPER = {
    "kv": (0.7, "m/(V s)", "Sec. III, eq. (5), from the 1 V step of Fig. 6"),
    "w0": (32.97, "rad/s", "Table II"),
    "zeta": (1.1, "-", "Table II"),
    "k0": (7.0, "1/s", "eq. (9) with Table II gains"),
    "p_s": (5e5, "Pa", "Table II (absolute or gauge not stated)"),
    "T": (0.01, "s", "Sec. II and Table II"),
    "K_AD": (204.8, "1/V", "Table II"),
    "K_DA": (2.44e-3, "V", "Table II"),
    "K_m": (20.0, "V/m", "Table II"),
    "n": (800, "samples", "Sec. II: 400 estimation + 400 validation"),
}


#: Table I, ARX [4 1 1]: magnitudes and standard deviations quoted from Table I; the
#: signs were lost in the text extraction and are restored as in physics.md (with
#: them the DC gain is 0.98, as a closed position loop must have).
TABLE1_A = np.array([-2.4478, 2.1352, -0.7742, 0.0995])


TABLE1_A_STD = np.array([0.0500, 0.1264, 0.1209, 0.0436])


TABLE1_B = 0.0125


TABLE1_B_STD = 0.0011


#: Reference range of the APRBS: the paper's 0..10 V is the full stroke (K_m = 20 V/m);
#: 5 % margins keep the piston off the end stops (the paper does not say how it did).
R_RANGE = (0.025, 0.475)


#: Parameters estimated from the paper's measurements.
CAL_PARAMS = ("valve.sonic_conductance",)


#: APRBS holds, samples: ASSUMED 0.1 .. 0.6 s (the paper does not give them; with these
#: a 400-sample half holds about a dozen levels).
HOLD = (10, 60)


#: A "large" steady-state error (Fig. 7, qualitative): larger than 1 % of Fig. 7's
#: 400 mm axis, i.e. visible on the printed figure.
LARGE_ERROR = 4e-3


#: Bisection bracket of the deadband (fraction of the command span): the DC gain of the
#: re-identified loop falls through Table I's 0.984 once in it (it is 0.996 at 0.02
#: and 0.953 at 0.12 on the calibrated rig).
DEADBAND_BRACKET = (0.02, 0.2)


#: Fig. 6 as a record: the curve sampled every 5 ms (a curve read off a figure has no
#: sampling of its own), its velocity known to the paper's one digit: 0.7 +- 0.05 m/s,
#: a uniform rounding error of std 0.05 / sqrt(3).
FIG6_DT = 5e-3


FIG6_V_STD = 0.05 / np.sqrt(3.0)


#: Start position of the 1 V steps (Fig. 6 record and the rig's step), m: ASSUMED (the
#: paper does not say); near one end so that 0.3 s at up to 1.5 m/s fit the stroke.
X_STEP = 0.02


def paper_setup(plant: Plant) -> dict:
    """Loop constants from Table II: kp (V/m), ADC and DAC steps, sample time."""
    kad, kda, km = PAPER["K_AD"][0], PAPER["K_DA"][0], PAPER["K_m"][0]
    kp = float(plant.params["controller.kp"])
    return {"kp": kp, "T": PAPER["T"][0], "x_step": 1.0 / (kad * km), "u_step": kda,
            "noise_x": 1.0 / (kad * km) / np.sqrt(12.0), "kp_table2": km * kad * kda}


def table1_response(r: np.ndarray) -> np.ndarray:
    """Output of Table I's ARX model driven by the reference r (m), from rest at r[0]."""
    a = np.r_[1.0, TABLE1_A]
    y = np.full(len(r), r[0])
    for k in range(4, len(r)):
        y[k] = -a[1:] @ y[k - 4:k][::-1] + TABLE1_B * r[k - 2]
    return y


def table1_distance(model) -> float:
    """RMS over a1..a4, b1 of (re-identified - Table I) / combined std, -."""
    d = np.r_[(model.a - TABLE1_A) / np.hypot(TABLE1_A_STD, model.std_a),
              (model.b[0] - TABLE1_B) / np.hypot(TABLE1_B_STD, model.std_b[0])]
    return float(np.sqrt(np.mean(d ** 2)))


def table1_dc_band() -> tuple[float, float]:
    """Table I's closed-loop DC gain B(1)/A(1) and its standard deviation from the
    table's 4-decimal rounding (uniform +-5e-5 per coefficient; the printed std of
    the coefficients, without covariances, cannot be propagated to a sum of them)."""
    a1 = 1.0 + TABLE1_A.sum()
    grad = np.r_[np.full(4, -TABLE1_B / a1 ** 2), 1.0 / a1]
    return TABLE1_B / a1, float(np.linalg.norm(grad) * 5e-5 / np.sqrt(3.0))


def pole_std(model, pole: complex) -> float:
    """Standard deviation of a pole of the re-identified A(q), m-free, from the model's
    full coefficient covariance.

    A root p of A(z) = z^4 + a1 z^3 + ... + a4 moves by dp = -sum_k p^(4-k) da_k / A'(p)
    (implicit function theorem, exact to first order); var(Re dp) + var(Im dp) from
    the covariance of a1..a4. Table I gives standard deviations without covariances,
    which cannot be propagated to its poles (a1..a4 are strongly correlated), so the
    comparison uses this interval and Table I's rounding.
    """
    a = np.asarray(model.a)
    na = len(a)
    cov = np.asarray(model.covariance)[:na, :na]
    sens = -np.array([pole ** (na - k) for k in range(1, na + 1)]) / np.polyval(
        np.polyder(np.r_[1.0, a]), pole)
    return float(np.sqrt(sens.real @ cov @ sens.real + sens.imag @ cov @ sens.imag))


def dominant(poles: np.ndarray) -> complex:
    """The pole of largest magnitude with non-negative imaginary part."""
    p = [z for z in poles if z.imag >= -1e-12]
    return complex(max(p, key=abs))


def row(result, paper, workbench, unit, source, how, agrees) -> dict:
    """One paper_results entry (summary.json contract)."""
    return {"result": result, "paper": paper, "workbench": workbench, "unit": unit,
            "source": source, "how": how, "agrees": bool(agrees)}


def arx_rows(model) -> list[dict]:
    """Table I beside the re-identified coefficients; agreement within 2 combined std."""
    rows = []
    names = [f"a{i + 1}" for i in range(4)] + ["b1"]
    paper = list(TABLE1_A) + [TABLE1_B]
    p_std = list(TABLE1_A_STD) + [TABLE1_B_STD]
    ours = list(model.a) + [float(model.b[0])]
    o_std = list(model.std_a) + [float(model.std_b[0])]
    for nm, p, ps, o, os_ in zip(names, paper, p_std, ours, o_std):
        tol = 2.0 * np.hypot(ps, os_)
        rows.append(row(f"Table I ARX [4 1 1] {nm} (std {ps:g})", p, float(o), "-",
                        "Table I (magnitude and std quoted; sign restored, physics.md)",
                        f"ARX [4 1 1] least squares on the simulated experiment (std "
                        f"{os_:.2g}); agrees within 2 combined std = {tol:.3g}",
                        abs(o - p) <= tol))
    return rows


def pole_rows(model) -> list[dict]:
    """Dominant and fast pole pairs of Table I (derived) beside the re-identified ones."""
    p_poles = np.roots(np.r_[1.0, TABLE1_A])
    o_poles = model.poles
    out = []
    for label, pick in (("dominant", dominant),
                        ("fast", lambda ps: complex(min((z for z in ps if z.imag >= -1e-12),
                                                        key=abs)))):
        pp, po = pick(p_poles), pick(o_poles)
        tol = 2.0 * pole_std(model, po) + 0.0005 * np.sqrt(2.0)
        out.append(row(f"closed-loop {label} poles", f"{pp.real:.3f} +- {abs(pp.imag):.3f}j",
                       f"{po.real:.3f} +- {abs(po.imag):.3f}j", "-",
                       "derived from Table I (physics.md), not printed in the paper",
                       f"roots of the re-identified A(q); agrees within 2 std of the pole "
                       f"(from the ARX covariance) plus Table I's rounding = {tol:.3g}",
                       abs(po - pp) <= tol))
    dc_p = TABLE1_B / (1.0 + TABLE1_A.sum())
    dc_o = float(model.b.sum() / (1.0 + model.a.sum()))
    out.append(row("closed-loop DC gain", round(dc_p, 3), dc_o, "-",
                   "derived from Table I (physics.md: 0.98)",
                   "B(1)/A(1) of the re-identified model; agrees within 0.01 (2 std of Table "
                   "I's rounding). Used to estimate the deadband: agreement by construction",
                   abs(dc_o - dc_p) <= 0.01))
    return out
