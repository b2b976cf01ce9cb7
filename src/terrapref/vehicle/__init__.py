"""Vehicle dynamics: unicycle (differential-drive) kinematics, its 30 Hz controller, the control set."""

from terrapref.vehicle.body import Vehicle
from terrapref.vehicle.control_set import ControlSet
from terrapref.vehicle.kinematics import (
    MIN_CRUISE_MPS,
    Command,
    Pose,
    VehicleConfig,
    integrate_unicycle,
    pure_pursuit_yaw_rate,
    wrap_angle,
)

__all__ = [
    "MIN_CRUISE_MPS",
    "Command",
    "ControlSet",
    "Pose",
    "Vehicle",
    "VehicleConfig",
    "integrate_unicycle",
    "pure_pursuit_yaw_rate",
    "wrap_angle",
]
