"""The planner for a robot's control loop: ``terrapref.runtime.PlannerRuntime`` (docs/robot.md).

It lives in :mod:`terrapref.interop.runtime` beside the other robot-facing code; this module is
its public name.
"""

from terrapref.groundmap.costmap import Costmap
from terrapref.interop.runtime import STOP, DepthFrame, PlannerRuntime, RobotSettings, RuntimeDecision

__all__ = ["STOP", "Costmap", "DepthFrame", "PlannerRuntime", "RobotSettings", "RuntimeDecision"]
