"""One stepping library: tableaux, steppers and one JIT cache (in the style of diffrax).

A solver is an immutable tableau (:mod:`.tableaux`) plus one stepping function
(:mod:`.steppers`) that turns it, a right-hand side and a step size into CasADi
expressions or step Functions; each caller keeps its own loop. :mod:`.linalg` is
the unpivoted LU written out in SX used by the implicit steps, :mod:`.jit` the one
cache of compiled C.

Examples
--------
>>> import casadi as ca
>>> from workbench import integrate
>>> x = ca.SX.sym("x")
>>> step = ca.Function("s", [x], [integrate.explicit_rk(integrate.RK4, lambda z: -z, x, 0.1)])
>>> round(float(step(1.0)), 8)        # exp(-0.1) = 0.90483742
0.9048375
"""

from .jit import cache_dir, compiled, have_compiler, shared_library
from .steppers import (METHODS, explicit_rk, radau_sensitivity, radau_simplified_newton,
                       radau_stages, radau_step_functions, rosenbrock, step_function)
from .tableaux import (RADAU_IIA, RADAU_IIA_1, RADAU_IIA_2, RADAU_IIA_3, RK4, RODAS4, ROS2,
                       ROS4, ButcherTableau, RosenbrockTableau)

__all__ = [
    "ButcherTableau", "RosenbrockTableau", "RK4", "RADAU_IIA", "RADAU_IIA_1", "RADAU_IIA_2",
    "RADAU_IIA_3", "ROS2", "ROS4", "RODAS4",
    "explicit_rk", "rosenbrock", "radau_simplified_newton", "radau_stages",
    "radau_sensitivity", "radau_step_functions", "step_function", "METHODS",
    "compiled", "cache_dir", "have_compiler", "shared_library",
]
