"""``terrapref play``: a ROS 2 log (a bag folder or an MCAP file) published on ROS 2 topics with
``/clock``, as ``ros2 bag play --clock`` would, over DDS (:mod:`terrapref.interop.dds`), so that a
node can be watched driving a recorded log without ROS 2 installed.

Each topic keeps the type of the log (its DDS type and RIHS01 hash made from the definitions
the log carries) and the QoS the log's publisher offered where the log says (``/tf_static``
transient local, say), else ROS 2's default (reliable, keep last 10). A topic the log holds
only one message of (a reference path sent once) is offered transient local, as a latched
publisher would, so that a node that joins later still gets it. ``/clock`` carries the log's
time: at a steady rate, and before each message, at that message's time. A stretch of the log
with no message longer than ``max_gap_s`` (a recording paused, say) is played as that long, the
clock jumping over the rest, as ``rosbag play --skip-empty`` does. A damaged chunk or message
stops the play where it is met, as ``terrapref import`` refuses it, after everything before it
was published.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Collection, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from terrapref.errors import UserError
from terrapref.interop.dds import CLOCK, DEFAULT, LATCHED, MessageTypes, Participant, QosProfile, Writer
from terrapref.interop.ros_messages import typestore

CLOCK_HZ = 40.0  # ros2 bag play --clock's default rate [Hz]
MAX_GAP_S = 5.0  # [s of log] longer than a node's own timeouts (the stop rule's blind_after_s), short enough to see


@dataclass(frozen=True)
class Message:
    """One message of the log: its log time [ns], topic, type and rosbags message."""

    t_ns: int
    topic: str
    msgtype: str
    msg: Any


@dataclass(frozen=True)
class RobotTopics:
    """What a robot file's node reads (``play --robot``): its topics by role (terrapref.interop.robot.load_robot_topics), from ``source``."""

    source: str
    topics: dict[str, str]

    @property
    def played(self) -> dict[str, str]:
        """The topics played, by role: all but the command (the log's commands stay off the node's topics)."""
        return {role: topic for role, topic in self.topics.items() if role != "command"}


class BagPlayer:
    """A ROS 2 log's topics as ROS 2 publishers on one participant.

    Args:
        path: a ROS 2 bag folder or MCAP file.
        domain: the DDS domain (ROS_DOMAIN_ID).
        topics: the topics to play (default: all of them, or with ``robot`` none besides its);
            a name the log does not hold is a UserError.
        robot: also play what this robot file's node reads, each topic checked as ``import``
            checks it (in the log, of a type its role may have, with messages), and the log's
            /tf and /tf_static where it holds them.
    """

    def __init__(self, path: str | Path, domain: int, topics: Collection[str] | None = None, robot: RobotTopics | None = None) -> None:
        from terrapref.interop.bag_reader import check_log_topics, open_log

        self.path = Path(path)
        self.published = 0  # messages published so far (what a play that stops half-way did)
        self.skipped_s = 0.0  # [s of log] the clock jumped over in gaps longer than the longest played
        if self.path.suffix == ".bag" and self.path.exists():
            raise UserError(
                str(path), "a ROS 1 bag: terrapref play publishes ROS 2 logs (a bag folder or .mcap); play ROS 1 bags with rosbag play"
            )
        self.reader = open_log(self.path)
        held = {c.topic for c in self.reader.connections}
        if topics is not None:
            missing = sorted(set(topics) - held)
            if missing:
                raise UserError(str(path), f"holds no topic {', '.join(missing)} (asked for); it holds {', '.join(sorted(held))}")
        if robot is not None:
            check_log_topics(self.reader, robot.played, list(robot.played), str(path), robot.source)
            topics = {*(topics or ()), *robot.played.values(), *({"/tf", "/tf_static"} & held)}
        # A /clock the log recorded is left out: the player's own /clock keeps the log's time.
        self.connections = [c for c in self.reader.connections if (topics is None or c.topic in topics) and c.topic != "/clock"]
        if not sum(c.msgcount for c in self.connections):  # (an empty log's first and last times are not times)
            raise UserError(str(path), "holds no messages to play" + ("" if topics is None else " on the topics asked for"))
        self.types = MessageTypes(self.reader.typestore)
        self.dds = Participant(domain, self.types)
        self.clock = self.dds.writer(
            "/clock", "rosgraph_msgs/msg/Clock", CLOCK, MessageTypes(typestore())
        )  # a log need not hold /clock's type
        self.writers: dict[tuple[str, str], Writer] = {}
        for c in self.connections:
            if (c.topic, c.msgtype) not in self.writers:
                self.writers[c.topic, c.msgtype] = self.dds.writer(c.topic, c.msgtype, self._profile(c))

    def _profile(self, connection) -> QosProfile:
        """The QoS a topic is played with: the one offered in the log, else ROS 2's default;
        transient local for a topic of one message."""
        from rosbags.interfaces import QosDurability, QosReliability

        offered = getattr(getattr(connection, "ext", None), "offered_qos_profiles", None) or []
        if offered:
            q = offered[0]
            return QosProfile(
                "as recorded",
                reliable=q.reliability != QosReliability.BEST_EFFORT,
                depth=max(1, int(q.depth or 10)),
                transient_local=q.durability == QosDurability.TRANSIENT_LOCAL,
            )
        return LATCHED if connection.msgcount == 1 else DEFAULT

    @property
    def span_ns(self) -> tuple[int, int]:
        """The log's first and last message times [ns]."""
        return self.reader.start_time, self.reader.end_time

    def messages(self) -> Iterator[Message]:
        """The messages played, in the log's order.

        Raises:
            UserError: a chunk or message of the log is damaged (met when it is read).
        """
        from terrapref.interop.bag_reader import read_messages

        for conn, t_ns, msg in read_messages(self.reader, self.connections, str(self.path)):
            yield Message(t_ns, conn.topic, conn.msgtype, msg)

    def publish(self, message: Message) -> None:
        """Send one message of the log on its topic."""
        self.writers[message.topic, message.msgtype].publish(message.msg)

    def publish_clock(self, t_ns: int) -> None:
        """``/clock`` at the log's time ``t_ns`` [ns]."""
        T = self.clock.types.ts.types
        self.clock.publish(
            T["rosgraph_msgs/msg/Clock"](clock=T["builtin_interfaces/msg/Time"](sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000))
        )

    def play(
        self,
        rate: float = 1.0,
        clock_hz: float = CLOCK_HZ,
        delay_s: float = 0.0,
        progress: Callable[[int], None] | None = None,
        max_gap_s: float = MAX_GAP_S,
        log: Callable[[str], None] = print,
    ) -> int:
        """Publish every message at its time in the log, ``rate`` times as fast, with ``/clock``
        at ``clock_hz``; a gap between two messages (or before the first) longer than
        ``max_gap_s`` [s of log] is played as ``max_gap_s``, said by ``log``. ``progress`` gets
        the log time [ns] since its start of each message published. The number of messages
        published, also counted in :attr:`published` as they go.

        Raises:
            UserError: a damaged chunk or message, when it is met (what came before it published).
        """
        time.sleep(delay_s)  # discovery: subscribers that are already up match the new publishers meanwhile
        first_ns = last_ns = self.span_ns[0]
        max_gap_ns, skipped_ns = int(max_gap_s * 1e9), 0
        start = time.monotonic()
        next_clock, clock_ns = start, None
        for message in self.messages():
            ticked_ns = skipped_ns  # through a long gap the clock ticks on from the last message, then jumps to this one
            if message.t_ns - last_ns > max_gap_ns:
                cut = message.t_ns - last_ns - max_gap_ns
                log(
                    f"{(message.t_ns - last_ns) * 1e-9:.1f} s without a message after {(last_ns - first_ns) * 1e-9:.1f} s "
                    f"of log: played as {max_gap_s:g} s (--max-gap), the clock jumping {cut * 1e-9:.1f} s"
                )
                skipped_ns += cut
                self.skipped_s = skipped_ns * 1e-9
            last_ns = message.t_ns
            due = start + (message.t_ns - first_ns - skipped_ns) * 1e-9 / rate
            next_clock = self._tick_until(due, next_clock, clock_hz, lambda now: first_ns + ticked_ns + int((now - start) * rate * 1e9))
            if message.t_ns != clock_ns:  # the clock at the message's time, before it
                clock_ns = message.t_ns
                self.publish_clock(clock_ns)
            self.publish(message)
            self.published += 1
            if progress is not None:
                progress(message.t_ns - first_ns)
        return self.published

    def _tick_until(self, due: float, next_clock: float, clock_hz: float, log_ns: Callable[[float], int]) -> float:
        """Wait until the monotonic time ``due`` [s], ``/clock`` ticking at ``clock_hz`` meanwhile at
        ``log_ns(now)``; the time of the next tick."""
        while True:
            now = time.monotonic()
            if now >= due:
                return next_clock
            if now >= next_clock:
                self.publish_clock(log_ns(now))
                next_clock = now + 1.0 / clock_hz
            time.sleep(max(0.0, min(due, next_clock) - now))

    def close(self) -> None:
        """Leave the domain and close the log."""
        self.dds.close()
        self.reader.close()
