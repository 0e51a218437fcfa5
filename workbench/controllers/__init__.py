"""Controllers that run in the sampled-data simulation (not python-control's ``control``)."""

from .base import DiscreteController
from .pd import (PID, from_plant, pd_zero_on_slow_pole, pd_zero_on_slow_pole_at,
                 slow_time_constant)

__all__ = ["DiscreteController", "PID", "from_plant", "pd_zero_on_slow_pole",
           "pd_zero_on_slow_pole_at", "slow_time_constant"]
