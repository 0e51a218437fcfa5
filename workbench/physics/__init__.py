"""Physics of the servodrive as pure functions, written once for every backend.

Each law is written on :mod:`workbench.physics.ops` and works on plain floats,
numpy arrays (element-wise, broadcasting) and CasADi SX, MX and DM alike, so one
definition serves simulation, linearisation, estimation, MPC and the numpy code of
controllers and diagnosis (no twin is needed for speed).
"""

from . import chamber, friction, gas, line, ops, piston, supply, valve

__all__ = ["chamber", "friction", "gas", "line", "ops", "piston", "supply", "valve"]
