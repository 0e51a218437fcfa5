"""Closed-loop simulation of the paper-000 rig (15 mm rodless, 500 mm stroke, P loop at 10 ms).

Runs until the classical design chain lands (issue 3, ``designs/situm_p_pd.py``):
exact linearisation at mid-stroke side by side with paper 000's formulas, then the
nonlinear plant in closed loop with the plant file's P controller for steps both
ways, a ramp and holds. Writes ``reports/situm_rodless_sim/``: ``trajectory.csv``,
``trajectory.png``, ``summary.json``.

Usage: python designs/situm_rodless_sim.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from workbench import Plant, controllers, linearize, simulate
from workbench.params import atomic_write_text
from workbench.plots import trajectory_figure

HERE = Path(__file__).resolve().parent
PLANT = HERE / "plants" / "situm_rodless_nominal.toml"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE.parent / "reports" / "situm_rodless_sim"),
                    help="output folder (default reports/situm_rodless_sim)")
    ap.add_argument("--quick", action="store_true", help="short profile (smoke test)")
    args = ap.parse_args(argv)
    out = Path(args.out)

    plant = Plant.from_toml(PLANT)
    prm = plant.params
    op = linearize.operating_point(plant, 0.25)
    lin = linearize.tangent(plant, op)
    red = linearize.reduced_position_model(lin)
    w0_paper = linearize.paper000_w0(plant.area_a, prm["load.mass"], prm["supply.pressure"],
                                     plant.stroke, kappa=1.4)
    zeta_paper = linearize.paper000_zeta(plant.area_a, prm["load.mass"], prm["supply.pressure"],
                                         plant.stroke, prm["load.viscous_friction"], kappa=1.4)
    ctrl = controllers.from_plant(plant)
    k0 = ctrl.kp * red.kv
    print(f"plant {plant.name}: {len(plant.states)} states, effects: "
          f"{', '.join(plant.effects) or 'none'}")
    print(f"paper 000 formulas : w0 = {w0_paper:6.2f} rad/s, zeta = {zeta_paper:.3f} "
          "(kappa = 1.4, p = supply, no dead volume)")
    print(f"exact linearisation: w0 = {red.w0:6.2f} rad/s, zeta = {red.zeta:.3f}, "
          f"Kv = {red.kv:.3f} m/(V s) at x = 0.25 m, p_a = p_b = {op.p_a / 1e5:.3f} bar")
    print(f"loop gain K0 = kp Kv = {k0:.2f} 1/s (paper: 7.0)")

    if args.quick:
        ref = simulate.profile([(0, 0.25), (0.3, 0.25), (0.3, 0.30), (1.2, 0.30)])
    else:
        ref = simulate.profile([(0, 0.25), (0.5, 0.25), (0.5, 0.10), (3.0, 0.10),
                                (3.0, 0.40), (5.5, 0.40), (7.5, 0.20), (9.0, 0.20)])
    t0 = time.perf_counter()
    run = simulate.closed_loop(plant, ctrl, ref, x0=0.25,
                               output_times=np.arange(0.0, ref.duration + 1e-9, 0.001))
    wall = time.perf_counter() - t0
    err = run["x"] - run.reference
    out.mkdir(parents=True, exist_ok=True)
    run.to_csv(out / "trajectory.csv")
    trajectory_figure([run], ["P loop"], out / "trajectory.png",
                      title=f"{plant.name}: P position loop, kp = {ctrl.kp:g} V/m, "
                            f"T = {ctrl.sample_time * 1e3:g} ms")
    summary = {
        "plant": str(PLANT.relative_to(HERE.parent)),
        "operating_point": {"x": op.x, "u": op.u, "p_a": op.p_a, "p_b": op.p_b},
        "paper000_formulas": {"w0": w0_paper, "zeta": zeta_paper},
        "exact_linearisation": red.to_dict(),
        "loop_gain_k0": k0,
        "simulation": {"duration_s": float(ref.duration), "wall_s": wall,
                       "max_abs_error_m": float(np.max(np.abs(err))),
                       "final_error_m": float(err[-1]),
                       "pressure_range_pa": [float(min(run["p_a"].min(), run["p_b"].min())),
                                             float(max(run["p_a"].max(), run["p_b"].max()))]},
    }
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"simulated {ref.duration:.1f} s in {wall:.2f} s; final error "
          f"{err[-1] * 1e3:.2f} mm")
    print(f"wrote {out / 'trajectory.csv'}, {out / 'trajectory.png'}, {out / 'summary.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
