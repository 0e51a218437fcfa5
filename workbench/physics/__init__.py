"""Physics of the servodrive as pure functions returning CasADi expressions.

Each function works on plain floats, CasADi SX and MX alike, so that one
symbolic model serves simulation, linearisation, estimation and MPC.
"""

from . import chamber, friction, gas, line, piston, supply, valve

__all__ = ["chamber", "friction", "gas", "line", "piston", "supply", "valve"]
