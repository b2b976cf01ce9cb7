"""A live view: the channels of the MCAP export, served while the planner drives.

A Foxglove WebSocket server (the Foxglove SDK, ``foxglove-sdk``) carries the same topics, types
and messages as a run's MCAP file (terrapref.interop.mcap_export): ROS 2 messages, CDR-encoded,
with their ros2msg schemas, so Foxglove shows them as it shows the file. The reference path and
the camera's mounting are sent again once a second, so a viewer that connects late has them.

    view = LiveView(port=8765)            # ws://127.0.0.1:8765: Foxglove, "Open connection" (foxglove.sdk.v1 or foxglove.websocket.v1)
    driver = WatchedDriver(planner_driver, view, model)   # a terrapref.sim.Driver
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from terrapref.errors import UserError
from terrapref.extras import needs
from terrapref.interop.mcap_export import COSTMAP_EVERY, TOPICS, FrameData, RunFrames, Scene, write_fixed, write_frame
from terrapref.interop.ros_messages import Message, typestore

if TYPE_CHECKING:
    from terrapref.camera import CameraConfig
    from terrapref.features import PreferenceSetConfig
    from terrapref.groundmap.costmap import Costmap
    from terrapref.planner.planner import Planner, PlannerDriver
    from terrapref.terrain import ClassTable

DEFAULT_HOST, DEFAULT_PORT = "127.0.0.1", 8765  # Foxglove's own default
RESEND_EVERY = 10  # frames between two sendings of the path and the camera's mounting


class LiveView:
    """A Foxglove WebSocket server on ``host``:``port`` (0: a free port) with the export's channels.

    Viewers connect by either name of the protocol, ``foxglove.sdk.v1`` or ``foxglove.websocket.v1``
    (terrapref.interop.ws_front relays them to the SDK's server). ``pace``: a simulated run's
    frames are sent at this many times real time (0: as fast as they come); ``wait``: a run's
    first frame waits until a viewer has subscribed.
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, pace: float = 0.0, wait: bool = False) -> None:
        with needs("robot", "the live view (--live)"):
            import foxglove
            import rosbags  # noqa: F401  (its typestore serialises the messages)
        from terrapref.interop.ws_front import Front

        if not (math.isfinite(pace) and pace >= 0):
            raise UserError("--live-pace", f"expected a factor of real time >= 0 (0: unpaced), got {pace}")
        self.ts = typestore()
        self.context = foxglove.Context()
        self.pace, self.wait = pace, wait
        _check_host(host)
        try:  # the SDK's server, on a free local port, behind the front door where the user asked
            # No server listener: the SDK would call it from its own threads, which can then wait on the
            # GIL while a thread of ours logging a message waits on them (a node that never ends).
            self.server = foxglove.start_server(name="terrapref", host="127.0.0.1", port=0, context=self.context)
            self.front = Front(host, port, int(self.server.port))
        except Exception as exc:  # the host is known to be one to listen on, so the port is at fault
            if hasattr(self, "server"):
                self.server.stop()
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise UserError(f"{host}:{port}", f"cannot serve the live view ({reason})", field="--live-port") from None
        self.host = host
        self.channels = {
            role: foxglove.Channel(
                topic,
                message_encoding="cdr",
                context=self.context,
                schema=foxglove.Schema(name=msgtype, encoding="ros2msg", data=self.ts.generate_msgdef(msgtype, ros_version=2)[0].encode()),
            )
            for role, (topic, msgtype) in TOPICS.items()
        }

    @property
    def port(self) -> int:
        return self.front.port

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def write(self, role: str, t_ns: int, msg: Message) -> None:
        """Send ``msg`` on the channel of ``role``, logged at ``t_ns`` [ns] (what a file's writer does)."""
        self.channels[role].log(bytes(self.ts.serialize_cdr(msg, TOPICS[role][1])), log_time=t_ns)

    def write_changed(self, role: str, t_ns: int, msg: Message, content: object) -> None:
        """Send ``msg`` as :meth:`write` does, changed or not: a viewer that joins later has it within a second."""
        self.write(role, t_ns, msg)

    def wait_for_viewer(self) -> None:
        """Block until a viewer has subscribed to a channel (at once when one has)."""
        while not any(channel.has_sinks() for channel in self.channels.values()):
            time.sleep(0.1)  # in steps: Ctrl-C is heard

    def stop(self) -> None:
        self.server.stop()  # its closing frames go out through the front, which then closes
        self.front.stop()


def _check_host(host: str) -> None:
    """Refuse a host this machine cannot listen on (no such name, an address of another machine),
    naming --live-host; a port's own trouble is left to the server's start."""
    import socket

    try:
        family, kind, proto, _, address = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)[0]
        with socket.socket(family, kind, proto) as probe:
            probe.bind(address)
    except (OSError, UnicodeError) as exc:
        problem = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise UserError(host, f"cannot listen on this address ({problem})", field="--live-host") from None


@dataclass
class LiveRun:
    """One run on a :class:`LiveView`: its fixed messages, then a frame at a time, each sent no
    sooner than the view's pace allows (frame time over pace after the first)."""

    view: LiveView
    scene: Scene
    frames: int = field(default=0)
    _clock: tuple[float, float] | None = None  # the first frame's (run time [s], wall time [s])

    @classmethod
    def start(
        cls,
        view: LiveView,
        path: np.ndarray,
        camera: CameraConfig,
        classes: ClassTable,
        preference: PreferenceSetConfig,
        clock_s: float = 0.0,
    ) -> LiveRun:
        """A run on ``view`` whose frames' times are stamped as ``EPOCH_S + t - clock_s`` (a
        simulated run's times from 0; ``EPOCH_S`` for stamps that are already ROS times)."""
        none = np.zeros((0, 3))
        header = RunFrames(
            times=np.zeros(0),
            poses=none,
            commands=none[:, :2],
            image=_no_image,
            chosen=np.zeros(0, dtype=int),
            path=np.asarray(path, dtype=float),
            camera=camera,
            classes=classes,
            preference=preference,
        )
        if getattr(view, "wait", False):
            view.wait_for_viewer()
        return cls(view, replace(Scene.of(view.ts, header), t0_s=clock_s))

    def frame(self, frame: FrameData, costmap: Callable[[], Costmap | None] | None = None) -> None:
        """Send one frame; with the first and every :data:`RESEND_EVERY`-th, the path and the
        camera's mounting, stamped with that frame's time; with the first and every
        :data:`COSTMAP_EVERY`-th (once a second), the costmap ``costmap`` gives, if given."""
        self._keep_pace(frame.t_s)
        if self.frames % RESEND_EVERY == 0:
            write_fixed(self.view, self.scene, frame.t_s)
        if costmap is not None and self.frames % COSTMAP_EVERY == 0:
            frame = replace(frame, costmap=costmap())
        write_frame(self.view, self.scene, frame)
        self.frames += 1

    def _keep_pace(self, t_s: float) -> None:
        """Sleep until frame time ``t_s`` [s] is due at the view's pace (none: at once)."""
        pace = getattr(self.view, "pace", 0.0)
        if not pace:
            return
        now = time.monotonic()
        if self._clock is None:
            self._clock = (t_s, now)
            return
        due = self._clock[1] + (t_s - self._clock[0]) / pace
        if due > now:
            time.sleep(due - now)


def _no_image(i: int) -> np.ndarray:
    raise IndexError(i)


class WatchedDriver:
    """A planner driver (:class:`terrapref.planner.planner.PlannerDriver`) whose every decision is
    sent to a :class:`LiveView` as it is made: the frame it decided on, the pose, the command, the
    21 trajectories with F_t and the one chosen, and once a second the costmap, when the planner
    has an offset rule. A :class:`terrapref.sim.Driver` itself."""

    def __init__(self, inner: PlannerDriver, view: LiveView) -> None:
        self.inner, self.view = inner, view
        self.run: LiveRun | None = None

    def reset(self, scenario: Any, rng: np.random.Generator) -> None:
        self.inner.reset(scenario, rng)
        policy = self.inner.planner.policy
        self.run = LiveRun.start(self.view, scenario.waypoints, policy.camera, policy.classes, policy.features.preference)

    @property
    def stop_reason(self) -> str | None:
        return self.inner.stop_reason

    def mute(self) -> None:
        """Send nothing more to the view (the run it shows has been scored)."""
        self.run = None

    def act(self, frame: Any) -> Any:
        command = self.inner.act(frame)
        if self.run is None:
            return command
        decision = self.inner.last
        x, y, yaw = (float(v) for v in frame.pose)
        self.run.frame(
            FrameData(
                float(frame.time_s),
                (x, y, yaw),
                (float(command.v), float(command.w)),
                frame.view.image,
                decision.index,
                decision.probs,
                stop=decision.stop,
            ),
            planner_costmap(self.inner.planner),
        )
        return command


def planner_costmap(planner: Planner) -> Callable[[], Costmap] | None:
    """What gives ``planner``'s costmap now, for :meth:`LiveRun.frame` (None: it keeps no ground map)."""
    return planner.costmap if planner.runner.keeps_ground_map else None


def watching(view: LiveView | None) -> Callable[[Any], Any] | None:
    """The wrapper that puts a planner driver on ``view`` (None: none)."""
    return None if view is None else (lambda driver: WatchedDriver(driver, view))
