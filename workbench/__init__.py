"""workbench: design and validation of controllers for electropneumatic servodrives.

One symbolic CasADi model of the drive (valve, chambers, piston, friction, lines,
leakage, supply) serves simulation, exact linearisation, identification and control.
"""

from . import controllers, equilibrium, linearize, physics, simulate, units
from .errors import InputError, WorkbenchError
from .params import PlantParams
from .plant import Plant

__version__ = "0.1.0"

#: Sub-packages imported on first use (they pull in reportlab, dask, matplotlib...).
_LAZY = ("stability", "validate", "report", "identify", "diagnose", "plots", "recording",
         "robustness", "signals", "references", "replay", "integrate", "metrics")

__all__ = [
    "InputError", "WorkbenchError", "Plant", "PlantParams",
    "controllers", "equilibrium", "linearize", "physics", "simulate", "units", "__version__", *_LAZY,
]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    raise AttributeError(f"module 'workbench' has no attribute {name!r}")
