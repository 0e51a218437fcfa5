"""Controllers that run in the sampled-data simulation (not python-control's ``control``)."""

from .base import DiscreteController
from .pd import PID, from_plant

__all__ = ["DiscreteController", "PID", "from_plant"]
