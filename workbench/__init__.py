"""workbench: design and validation of controllers for electropneumatic servodrives.

One symbolic CasADi model of the drive (valve, chambers, piston, friction, lines,
leakage, supply) serves simulation, exact linearisation, identification and control.
"""

from . import controllers, linearize, physics, simulate, units
from .errors import InputError, WorkbenchError
from .params import PlantParams
from .plant import Plant

__version__ = "0.1.0"

__all__ = [
    "InputError", "WorkbenchError", "Plant", "PlantParams",
    "controllers", "linearize", "physics", "simulate", "units", "__version__",
]
