"""One closed loop of two NMPCs fed the same measurements (the tests' shared harness).

The loop is closed by ``a`` on the plant (the workbench simulator, 10 ms samples);
``b`` sees the same measurements and references. The largest difference of plan,
command and force estimate (scaled by 100 N) is returned; ``extra(sa, sb)`` may add
more differences or checks per sample.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from workbench.simulate import Simulator

NAMES = ("x", "v", "p_a", "p_b")


def loop_difference(plant, a, b, samples: int, reference: Callable[[int], float],
                    extra: Callable | None = None) -> float:
    """Largest difference of ``b``'s plans, commands and force estimates from ``a``'s
    over ``samples`` samples of the loop ``a`` closes on ``plant``."""
    sim = Simulator(plant)
    idx = [plant.state_index(k) for k in NAMES]
    x = plant.initial_state(0.10)
    sa = sb = None
    worst = 0.0
    for k in range(samples):
        y = {n: float(x[i]) for n, i in zip(NAMES, idx)}
        r = reference(k)
        sa, ua = a.update(sa, r, y)
        sb, ub = b.update(sb, r, y)
        worst = max(worst, float(np.max(np.abs(np.asarray(sa.X) - np.asarray(sb.X)))),
                    float(np.max(np.abs(np.asarray(sa.U).ravel() - np.asarray(sb.U).ravel()))),
                    abs(ua - ub), abs(sa.d - sb.d) / 100.0,
                    extra(sa, sb) if extra is not None else 0.0)
        x = sim.step(x, float(np.clip(ua, 0.0, 10.0)), 0.01)[-1]
    return worst
