"""The learned local planner (SPEC 9): segmentation image, pose and path in; a command out."""

from terrapref.planner.planner import Decision, Planner, PlannerDriver

__all__ = ["Decision", "Planner", "PlannerDriver"]
