"""workbench: design and validation of controllers for electropneumatic servodrives.

One symbolic CasADi model of the drive (valve, chambers, piston, friction, lines,
leakage, supply) serves simulation, exact linearisation, identification and control.

Every public name is imported on first use (``workbench.Plant``, ``workbench.simulate``,
``from workbench import linearize``): ``import workbench`` and the command line's
``--help`` stay fast, and CasADi, SciPy and Matplotlib are loaded only by the
commands that need them.
"""

from __future__ import annotations

import importlib

from .errors import InputError, WorkbenchError

__version__ = "0.1.0"

#: Sub-modules imported on first use (they pull in casadi, scipy, matplotlib, ...).
_LAZY = ("controllers", "equilibrium", "linearize", "physics", "simulate", "units",
         "stability", "validate", "report", "identify", "diagnose", "plots", "recording",
         "robustness", "signals", "references", "replay", "integrate", "metrics")

#: Classes imported on first use: name -> defining module.
_LAZY_NAMES = {"Plant": "plant", "PlantParams": "params"}

__all__ = ["InputError", "WorkbenchError", "Plant", "PlantParams", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    if name in _LAZY_NAMES:
        value = getattr(importlib.import_module(f".{_LAZY_NAMES[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'workbench' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
