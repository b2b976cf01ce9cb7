"""Robot logs read with ``rosbags``: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP) and MCAP files.

:func:`open_reader` opens a log with rosbags' AnyReader, leaving out (and listing) the topics
whose message definition in the log cannot be read instead of refusing the whole log;
:func:`read_messages` yields its messages deserialised, and a damaged chunk or message ends the
read with one line naming the log and where the damage was met. :class:`Bag` is a log as an
import reads it: the topics a robot file names checked for their types and messages, every
failure of the reader a one-line UserError.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from terrapref.errors import UserError, one_line
from terrapref.extras import needs
from terrapref.interop.robot import RobotConfig

TYPES = {  # the message types each role of a robot file's topics may have
    "segmentation": ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"),
    "camera_info": ("sensor_msgs/msg/CameraInfo",),
    "odometry": ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    "command": ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"),
    "path": ("nav_msgs/msg/Path",),
    "depth": ("sensor_msgs/msg/Image",),
    "depth_info": ("sensor_msgs/msg/CameraInfo",),
}


def open_reader(path: Path):
    """rosbags' AnyReader over ``path``, opened, except that a connection whose message definition
    cannot be parsed (or whose hash does not match it) is left out, in ``unreadable``, instead of
    failing the whole log. As AnyReader, the ROS 2 Humble types serve a log that carries no
    definitions at all."""
    with needs("robot", "reading ROS bags"):
        from rosbags.highlevel import AnyReader

    class TolerantReader(AnyReader):
        def _open(self) -> None:
            for reader in self.readers:
                self.stack.enter_context(reader)
            connections = [c for reader in self.readers for c in reader.connections]
            definitions = tuple((c.msgtype, c.msgdef.format, c.msgdef.data, c.digest) for c in connections)
            self.typestore, flaws = _checked_types(definitions, self.is2)
            self.unreadable = {c.topic: (c.msgtype, flaw) for c, flaw in zip(connections, flaws) if flaw is not None}
            self.connections = [c for c, flaw in zip(connections, flaws) if flaw is None]

    reader = TolerantReader([path])
    reader.open()
    return reader


@functools.lru_cache(maxsize=8)
def _checked_types(definitions: tuple, is2: bool):
    """The typestore of a log's connections, given as (message type, definition format, definition,
    hash) each, and each connection's flaw (None where it is readable): a definition that cannot be
    parsed, or whose hash does not match it. A log without definitions is read with the ROS 2
    Humble types. Kept for the logs opened next (one drive's logs carry the same definitions), so
    that the store's serialisers are generated once: shared, it is only read."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_typestore

    defined = any(fmt != MessageDefinitionFormat.NONE for _, fmt, _, _ in definitions)
    types = {} if defined else dict(get_typestore(Stores.ROS2_HUMBLE).fielddefs)
    flaws: list[str | None] = []
    for msgtype, fmt, data, digest in definitions:
        try:
            own = _definition_types(msgtype, fmt, data)
            if own and digest:  # a definition and its hash: checked against each other
                trial = get_typestore(Stores.EMPTY)
                trial.register({**types, **own})
                if digest != (trial.hash_rihs01(msgtype) if is2 else trial.generate_msgdef(msgtype)[1]):
                    raise ValueError("its hash does not match its definition")
        except Exception as exc:  # the type system's errors vary with the definition's flaw
            flaws.append(one_line(exc, 80))
            continue
        types.update(own)
        flaws.append(None)
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    return store, tuple(flaws)


def _definition_types(msgtype: str, fmt, data: str) -> dict:
    """The message types a connection's own definition (its format ``fmt`` and text ``data``)
    declares (none when it carries none)."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    if fmt == MessageDefinitionFormat.MSG:
        return get_types_from_msg(data, msgtype)
    if fmt == MessageDefinitionFormat.IDL:
        sep = "=" * 80 + "\n"
        parts = [p.split("\n", 1)[1] for p in data.split(sep)[1:]] if data.startswith(f"{sep}IDL: ") else [data]
        types: dict = {}
        for idl in parts:
            types.update(get_types_from_idl(idl))
        return types
    return {}


def open_log(path: Path):
    """:func:`open_reader` over ``path``, every failure of the reader on a damaged or foreign file
    a one-line UserError naming it, as ``import``, ``replay`` and ``play`` refuse it."""
    source = str(path)
    if not path.exists():
        raise UserError(source, "no such file or folder")
    try:
        return open_reader(path)
    except UserError:  # the robot extra is missing
        raise
    except Exception as exc:  # the reader's errors on a damaged or foreign file are many kinds
        raise UserError(source, f"not a readable ROS 1 bag, ROS 2 bag or MCAP file ({one_line(exc)})") from None


def check_log_topics(reader, topics: Mapping[str, str], roles: Sequence[str], source: str, robot_source: str) -> None:
    """Every topic of ``roles`` in ``topics`` (a robot file's, by role; the file ``robot_source``) is
    in the log ``reader`` opened (``source``), of a type it may have, with messages; what is not
    is said at once, every topic in one message, in the order of :data:`TYPES` (``import`` and
    ``play --robot`` alike)."""
    problems = [p for role in TYPES if role in roles and (p := topic_problem(reader, topics[role], role))]
    if problems:
        have = sorted({c.topic for c in reader.connections})
        shown = ", ".join(have[:12]) + (" ..." if len(have) > 12 else "")
        raise UserError(source, f"{'; '.join(problems)} (topics in {robot_source}; the bag has {shown or 'no topics'})", field="topics")


def topic_problem(reader, topic: str, role: str) -> str | None:
    """What is wrong with ``topic`` as the topic of ``role`` in the log ``reader`` opened (None: nothing)."""
    conns = [c for c in reader.connections if c.topic == topic]
    if not conns and topic in reader.unreadable:
        msgtype, why = reader.unreadable[topic]
        return f"topics.{role} {topic} has type {msgtype}, whose definition in the log cannot be read ({why})"
    if not conns:
        return f"topics.{role} {topic} is not in the bag"
    wrong = sorted({c.msgtype for c in conns if c.msgtype not in TYPES[role]})
    if wrong:
        return f"topics.{role} {topic} has type {', '.join(wrong)}, expected {' or '.join(TYPES[role])}"
    if sum(c.msgcount for c in conns) == 0:
        return f"topics.{role} {topic} has no messages"
    return None


def read_messages(reader, connections: list, source: str) -> Iterator[tuple[Any, int, Any]]:
    """(connection, log time [ns], message) of ``connections`` in the log's order, deserialised,
    from a reader :func:`open_reader` opened. A damaged chunk or message stops the read with a
    one-line UserError naming ``source`` and where the damage was met, once everything before it
    has been yielded.

    Raises:
        UserError: a chunk or message of the log cannot be read.
    """
    it = reader.messages(connections=connections)
    n, last_ns = 0, None
    while True:
        try:
            conn, t_ns, raw = next(it)
            msg = reader.deserialize(raw, conn.msgtype)
        except StopIteration:
            return
        except Exception as exc:  # damaged chunk or message: the reader's own error types vary
            after = "at its start" if last_ns is None else f"{(last_ns - reader.start_time) * 1e-9:.3f} s into the log"
            raise UserError(source, f"damaged: message {n + 1} of the read ({after}) cannot be read ({one_line(exc)})") from None
        n, last_ns = n + 1, t_ns
        yield conn, t_ns, msg


class Bag:
    """The bag, opened with rosbags; every failure of the reader is a one-line UserError.

    A topic whose message definition in the log cannot be read (``ros2 bag record -a`` stores
    service events' ``*_Event`` types as the raw service definition) is left out and listed in
    ``unreadable``; only a topic the robot file asks for makes that an error."""

    def __init__(self, path: Path) -> None:
        self.source = str(path)
        self.reader = open_log(path)
        self.unreadable: dict[str, tuple[str, str]] = self.reader.unreadable  # topic -> (type, why)

    def check_topics(self, robot: RobotConfig, roles: Sequence[str]) -> None:
        """Every topic of ``roles`` in the robot file is in the bag, of a type it may have, with
        messages (:func:`check_log_topics`)."""
        check_log_topics(self.reader, robot.topics, roles, self.source, robot.source)

    def connections(self, topic: str, role: str, source: str) -> list:
        """The connections of ``topic``, checked as the topic of ``role`` that the robot file
        ``source`` names; a problem is a UserError naming the field."""
        problem = topic_problem(self.reader, topic, role)
        if problem:
            raise UserError(self.source, f"{problem} (topics in {source})", field=f"topics.{role}")
        return [c for c in self.reader.connections if c.topic == topic]

    def messages(self, conns: list) -> Iterator[tuple[Any, int, Any]]:
        """(connection, bag time [ns], message), deserialised; a damaged message is a UserError."""
        return read_messages(self.reader, conns, self.source)

    def close(self) -> None:
        """Close the reader, quietly."""
        try:
            self.reader.close()
        except Exception:  # closing a half-read damaged file must not hide the real error
            pass
