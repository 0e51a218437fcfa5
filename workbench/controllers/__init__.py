"""Controllers that run in the sampled-data simulation (not python-control's ``control``)."""

from .base import DiscreteController
from .compensation import Compensated, DeadbandInverse, FrictionModel, friction_force
from .feedback_linearizing import (SAMPLING_LIMIT, FeedbackLinearizing, Feasibility,
                                   ReferenceModel, error_gains, feasibility,
                                   feedback_linearizing)
from .force import (PLAN_RULES, DriveModel, ForceTracker, PressurePlan, force_tracker,
                    motion_force, pressure_plan, smooth_profile)
from .inversion import CommandMap, FlowCommand, ValveInversion
from .mpc import NMPC, Recorder, prediction_model
from .observer import KalmanObserver, Observed, kalman_observer
from .pd import (PID, from_plant, pd_zero_on_slow_pole, pd_zero_on_slow_pole_at,
                 slow_time_constant)
from .sensors import RigSensors
from .design import AxisLimits, axis_limits, design  # noqa: E402  (the function shadows the module name)

__all__ = ["DiscreteController", "PID", "from_plant", "pd_zero_on_slow_pole",
           "pd_zero_on_slow_pole_at", "slow_time_constant",
           "ValveInversion", "FlowCommand", "CommandMap",
           "DriveModel", "PressurePlan", "PLAN_RULES", "pressure_plan", "motion_force",
           "smooth_profile", "ForceTracker", "force_tracker",
           "FeedbackLinearizing", "Feasibility", "ReferenceModel", "feedback_linearizing",
           "feasibility", "error_gains", "SAMPLING_LIMIT", "NMPC", "Recorder", "prediction_model",
           "design", "axis_limits", "AxisLimits", "KalmanObserver", "kalman_observer", "Observed",
           "RigSensors", "Compensated", "DeadbandInverse", "FrictionModel", "friction_force"]
