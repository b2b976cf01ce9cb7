"""Why a vehicle stands still: the reasons a stop is given with (SPEC 18), shared by the
planner's stop rule and its goal check (terrapref.planner.stop, terrapref.planner.goal), the
command holders that stop on stale frames (the simulated robot's perception, the runtime, the
nodes) and the scores that count stops."""

NO_FREE_WAY, BLIND, STALE = "no_free_way", "blind", "stale"
GOAL, OFF_PATH = "goal", "off_path"
UNSAID = "unsaid"  # a stop whose driver gave no reason (a person letting go of the throttle)
# A reason with its cause after a colon: no way is free, and ground the vehicle cannot take by
# its geometry (a slope past its tilt limits, a step higher than it climbs) is what closes them.
NO_FREE_WAY_GEOMETRY = f"{NO_FREE_WAY}:geometry"

REASONS = {
    NO_FREE_WAY: "no way ahead is free of lethal or unseen ground within the stopping distance",
    NO_FREE_WAY_GEOMETRY: "no way ahead is free within the stopping distance, and the ground past the vehicle's limits "
    "(a slope it would tip on, a step it cannot climb) is what closes them",
    BLIND: "too little of the ground ahead seen for too long",
    STALE: "no fresh frame within the time a command is held, or a clock that does not move on",
    GOAL: "at the end of the path: within the goal tolerance of its last point, or past it",
    OFF_PATH: "farther from the path than the planner may be",
    UNSAID: "the driver stopped without giving a reason",
}


def stop_reason_of(driver: object) -> str | None:
    """The reason ``driver`` gave for its last command (its ``stop_reason``), None if it drives or gives none."""
    return getattr(driver, "stop_reason", None)


STALE_SLACK_S = 1e-9  # a command held exactly its hold time is still fresh, whatever rounding a clock's sums carry [s]


def held_too_long(now_s: float, frame_s: float | None, hold_s: float) -> bool:
    """Whether a command decided on a frame stamped ``frame_s`` (None: none yet) is stale at
    ``now_s``, held for longer than ``hold_s`` [s]: the planner's stop rule decides ``stale`` so
    (terrapref.planner.stop.StopRule.stale), and a robot driven by a driver without one too."""
    return frame_s is None or not now_s - frame_s <= hold_s + STALE_SLACK_S
