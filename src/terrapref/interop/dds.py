"""ROS 2 on the wire without rclpy: ROS 2's conventions over Eclipse Cyclone DDS.

ROS 2's DDS middlewares (``rmw_cyclonedds_cpp``, ``rmw_fastrtps_cpp``, ``rmw_connextdds``) map a
ROS 2 graph onto plain DDS by documented conventions, and any DDS participant that follows them
is a ROS 2 node on the wire:

- topic ``/X`` is the DDS topic ``rt/X`` (:func:`dds_topic`);
- message type ``pkg/msg/T`` is the DDS type ``pkg::msg::dds_::T_`` (:func:`dds_type`), a final,
  keyless struct whose members are the message's fields in order;
- samples are CDR, little-endian, XCDR1 (encapsulation 0x0001);
- each topic has a QoS profile (:data:`SENSOR_DATA`, :data:`DEFAULT`, :data:`LATCHED`,
  :data:`CLOCK`);
- since Iron, each endpoint's USER_DATA carries ``typehash=RIHS01_<64 hex>;``, the hash of the
  type's description, and the participant's carries ``enclave=/;``.

The DDS types are made from rosbags' ROS 2 message definitions by one generator
(:class:`MessageTypes`), so every type a definition describes (nested messages, arrays,
sequences, strings) has its cyclonedds struct; rosbags also gives the RIHS01 hashes. Messages
are built with rosbags' classes (:mod:`terrapref.interop.ros_messages`) and converted on the
way out; cyclonedds serialises them, an implementation independent of rosbags' serializer.
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from terrapref.errors import UserError
from terrapref.extras import needs

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

DOMAIN_ID_MAX = 232  # the largest domain id whose ports fit in UDP's range (DDS's default port mapping)
ENCLAVE = b"enclave=/;"  # a participant's USER_DATA as ROS 2 sets it (the default security enclave)


def dds_topic(topic: str) -> str:
    """The DDS topic of the ROS 2 topic ``topic`` (absolute: ``/a/b`` -> ``rt/a/b``)."""
    if not topic.startswith("/"):
        raise ValueError(f"{topic!r} is not an absolute ROS 2 topic name")
    return "rt" + topic


def dds_type(msgtype: str) -> str:
    """The DDS type name of the ROS 2 message type ``msgtype`` (``pkg/msg/T`` -> ``pkg::msg::dds_::T_``)."""
    pkg, kind, name = msgtype.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def domain_id(environ: Mapping[str, str] = os.environ) -> int:
    """The DDS domain of ``ROS_DOMAIN_ID`` (default 0), checked."""
    text = environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    if not text.isdigit() or int(text) > DOMAIN_ID_MAX:
        raise UserError("ROS_DOMAIN_ID", f"expected a whole number in [0, {DOMAIN_ID_MAX}], got {text!r}")
    return int(text)


@dataclass(frozen=True)
class QosProfile:
    """A ROS 2 QoS profile, as far as a topic's endpoints need one.

    Attributes:
        name: what the docs and logs call it.
        reliable: reliable delivery (else best effort).
        depth: keep-last history depth [messages].
        transient_local: kept for subscribers that join later (else volatile).
    """

    name: str
    reliable: bool
    depth: int
    transient_local: bool = False

    def qos(self, user_data: bytes):
        """The cyclonedds Qos of an endpoint of this profile, with ``user_data`` (XCDR1 only, as ROS 2's middlewares)."""
        from cyclonedds.core import Policy, Qos

        return Qos(
            Policy.Reliability.Reliable(100_000_000) if self.reliable else Policy.Reliability.BestEffort,
            Policy.History.KeepLast(self.depth),
            Policy.Durability.TransientLocal if self.transient_local else Policy.Durability.Volatile,
            Policy.DataRepresentation(use_cdrv0_representation=True),
            Policy.Userdata(user_data),
        )

    def describe(self) -> str:
        """The profile in words, as the docs and the node's log give it."""
        return (
            f"{'reliable' if self.reliable else 'best effort'}, keep last {self.depth}, "
            f"{'transient local' if self.transient_local else 'volatile'}"
        )


SENSOR_DATA = QosProfile("sensor data", reliable=False, depth=5)  # rclcpp's SensorDataQoS: camera streams
DEFAULT = QosProfile("default", reliable=True, depth=10)  # rclcpp's default: commands, markers, paths
LATCHED = QosProfile("transient local", reliable=True, depth=1, transient_local=True)  # /tf_static, maps: kept for late subscribers
CLOCK = QosProfile("clock", reliable=False, depth=1)  # rclcpp's ClockQoS: /clock, newest only

WAIT_NS = 20_000_000  # the longest the participant's thread waits for data before it looks whether it is to stop [ns]
_BASE = {"bool": "bool", "byte": "uint8", "char": "uint8", "octet": "uint8"}  # ROS 2's byte and char are IDL octet and uint8


class MessageTypes:
    """cyclonedds types of ROS 2 messages, made from the definitions in a rosbags typestore.

    Args:
        ts: rosbags' typestore (:func:`terrapref.interop.ros_messages.typestore`).
    """

    def __init__(self, ts: Typestore) -> None:
        with needs("ros2", "ROS 2 over DDS"):
            import cyclonedds.idl  # noqa: F401  (the extra's package, checked here)
        self.ts = ts
        self._idl: dict[str, type] = {}
        self._lock = threading.Lock()

    def idl(self, msgtype: str) -> type:
        """The cyclonedds struct of ``msgtype`` (``pkg/msg/T``), named ``pkg::msg::dds_::T_``."""
        with self._lock:
            return self._struct(msgtype)

    def _struct(self, msgtype: str) -> type:
        from cyclonedds.idl import make_idl_struct
        from cyclonedds.idl import types as T

        if msgtype not in self._idl:
            fields = {name: self._field(node) for name, node in self.ts.fielddefs[msgtype][1]}
            # An empty message is one uint8 in ROS 2's IDL (a struct needs a member).
            struct = make_idl_struct(
                msgtype.rsplit("/", 1)[1] + "_", dds_type(msgtype), fields or {"structure_needs_at_least_one_member": T.uint8}
            )
            self._idl[msgtype] = _numbers_as_arrays(struct)
        return self._idl[msgtype]

    def _field(self, node: tuple) -> Any:
        """The cyclonedds annotation of one field definition of rosbags' typestore."""
        from cyclonedds.idl import types as T
        from rosbags.typesys.store import Nodetype

        kind, detail = node
        if kind == Nodetype.BASE:
            name, bound = detail
            if name == "string":
                return T.bounded_str[bound] if bound else str
            if name == "wstring":
                raise ValueError("wstring fields are not supported")
            name = _BASE.get(name, name)
            return bool if name == "bool" else getattr(T, name)
        if kind == Nodetype.NAME:
            return self._struct(detail)
        sub, length = detail
        inner = self._field(sub)
        if kind == Nodetype.ARRAY:
            return T.array[inner, length]
        return T.sequence[inner, length] if length else T.sequence[inner]

    def to_idl(self, msg: Any, msgtype: str) -> Any:
        """rosbags' message ``msg`` of ``msgtype`` as an instance of :meth:`idl`'s struct."""
        from rosbags.typesys.store import Nodetype

        values = {}
        for name, (kind, detail) in self.ts.fielddefs[msgtype][1]:
            value = getattr(msg, name)
            if kind == Nodetype.NAME:
                value = self.to_idl(value, detail)
            elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
                sub = detail[0]
                if sub[0] == Nodetype.NAME:
                    value = [self.to_idl(v, sub[1]) for v in value]
                elif isinstance(value, np.ndarray):  # numbers: a sequence as its array (copied at once), a fixed array's uint8 as bytes
                    if kind == Nodetype.ARRAY:
                        value = value.tobytes() if value.dtype == np.uint8 else value.tolist()
                else:
                    value = list(value)
            values[name] = value
        return self.idl(msgtype)(**values)

    def type_hash(self, msgtype: str) -> str:
        """RIHS01 of ``msgtype``'s type description (``RIHS01_<64 hex>``), as ROS 2 Iron and later announce it."""
        return self.ts.hash_rihs01(msgtype)

    def user_data(self, msgtype: str) -> bytes:
        """An endpoint's USER_DATA for ``msgtype``: ``typehash=RIHS01_...;``."""
        return f"typehash={self.type_hash(msgtype)};".encode()


def _numbers_as_arrays(struct: type) -> type:
    """``struct`` with its sequences of numbers (an image's bytes, an occupancy grid's cells, a
    grid map's floats) serialised from a NumPy array in one copy, and ``uint8[]`` read back as bytes.

    The wire is CDR's either way (a uint32 count, then the numbers, aligned, in the buffer's byte
    order), but cyclonedds' own machine packs a Python number per element: 6-31 ms for a 640 x 480
    label or depth image, 47 ms a layer of a 640 x 640 grid map, where the copy takes a fraction of
    a millisecond. A list still goes through cyclonedds' machine, and sequences other than
    ``uint8[]`` read back as its lists."""
    from cyclonedds.idl._machinery import PlainCdrV2SequenceOfPrimitiveMachine, StructMachine

    struct.__idl__.populate()
    for machine in (struct.__idl__.v1_machine, struct.__idl__.v2_machine):
        if not isinstance(machine, StructMachine):  # ROS 2's messages are final structs; anything else is left as it is
            continue
        for name, member in machine.members_machines.items():
            if type(member) is PlainCdrV2SequenceOfPrimitiveMachine:
                machine.members_machines[name] = _array_machine()(member)
    return struct


@functools.cache
def _array_machine() -> type:
    """The machine of :func:`_numbers_as_arrays` (made once cyclonedds is known to be there)."""
    from cyclonedds.idl._machinery import PlainCdrV2SequenceOfPrimitiveMachine

    class ArraySequence(PlainCdrV2SequenceOfPrimitiveMachine):
        def __init__(self, plain: PlainCdrV2SequenceOfPrimitiveMachine) -> None:
            self.__dict__.update(plain.__dict__)

        def serialize(self, buffer: Any, value: Any, *args: Any, **kwargs: Any) -> None:
            if not isinstance(value, np.ndarray):
                return super().serialize(buffer, value, *args, **kwargs)
            if self.max_length is not None and value.size > self.max_length:
                raise ValueError(f"a sequence of {value.size} numbers where at most {self.max_length} fit")
            buffer.align(4)
            buffer.write("I", 4, value.size)
            if value.size:
                buffer.align(self.alignment)
                buffer.write_bytes(value.astype(buffer._endian + self.code, copy=False).tobytes())
            return None

        def deserialize(self, buffer: Any, *args: Any, **kwargs: Any) -> Any:
            if self.code != "B":
                return super().deserialize(buffer, *args, **kwargs)
            buffer.align(4)
            return buffer.read_bytes(buffer.read("I", 4))

    return ArraySequence


class Writer:
    """A ROS 2 publisher: rosbags messages out on one topic."""

    def __init__(self, writer: Any, types: MessageTypes, topic: str, msgtype: str, profile: QosProfile) -> None:
        self._writer, self.types, self.topic, self.msgtype, self.profile = writer, types, topic, msgtype, profile

    def publish(self, msg: Any) -> None:
        """Send ``msg`` (a rosbags message of the writer's type)."""
        self._writer.write(self.types.to_idl(msg, self.msgtype))

    def delivered(self, timeout_s: float) -> bool:
        """Wait until every reliable subscription has what was sent, at most ``timeout_s``; whether it has."""
        from cyclonedds.util import duration

        try:
            self._writer.wait_for_acks(duration(seconds=timeout_s))
        except Exception:  # noqa: BLE001  (cyclonedds raises on a timeout: not delivered in time)
            return False
        return True

    def matched(self) -> int:
        """How many subscriptions this publisher reaches now."""
        return len(self._writer.get_matched_subscriptions())


class Participant:
    """One ROS 2 participant on a DDS domain: publishers, and subscriptions whose messages are
    handed to their callbacks, in the order they came, on one thread of the participant's own.

    No DDS listener is used: cyclonedds would call it from its own threads, which then need the
    GIL, while its Python bindings hold the GIL through a take or a write that can wait on those
    very threads (a process that froze now and then, Ctrl-C unheard). The thread of its own waits
    on a DDS wait set instead (without the GIL) and takes what came.

    Args:
        domain: the DDS domain (ROS_DOMAIN_ID; :func:`domain_id`).
        types: the message types.
        on_error: told of an exception a callback raised (default, or ``on_error`` set to None
            later: it is raised again, ending the thread).
    """

    def __init__(self, domain: int, types: MessageTypes, on_error: Callable[[BaseException], None] | None = None) -> None:
        with needs("ros2", "ROS 2 over DDS"):
            from cyclonedds.core import GuardCondition, Policy, Qos, WaitSet
            from cyclonedds.domain import DomainParticipant
        self.types, self.domain = types, domain
        self.dp = DomainParticipant(domain, qos=Qos(Policy.Userdata(ENCLAVE)))
        self._topics: dict[tuple[str, str], Any] = {}
        self._readers: list[Any] = []  # kept alive: cyclonedds deletes an entity its Python object no longer holds
        self._waitset = WaitSet(self.dp)
        # A wait set with nothing attached returns at once: without this a participant that only
        # publishes (terrapref play's) would spin a core. Set on close, it also ends the wait then.
        self._wake = GuardCondition(self.dp)
        self._waitset.attach(self._wake)
        self._handlers: list[tuple[Any, Callable[[], None]]] = []  # (read condition, what takes and hands on its reader's samples)
        self._lock = threading.Lock()  # guards _handlers: subscriptions may come while the thread runs
        self._closing = False
        self.on_error = on_error
        self._thread = threading.Thread(target=self._dispatch, name="terrapref-dds", daemon=True)
        self._thread.start()

    def _topic(self, topic: str, msgtype: str) -> Any:
        from cyclonedds.topic import Topic

        key = (topic, msgtype)
        if key not in self._topics:
            self._topics[key] = Topic(self.dp, dds_topic(topic), self.types.idl(msgtype))
        return self._topics[key]

    def writer(self, topic: str, msgtype: str, profile: QosProfile, types: MessageTypes | None = None) -> Writer:
        """A publisher of ``msgtype`` on ``topic`` with ``profile``, announcing the type's hash;
        the type from ``types`` when given (another typestore's), else the participant's."""
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        types = types or self.types
        topic_entity = self._topic(topic, msgtype) if types is self.types else Topic(self.dp, dds_topic(topic), types.idl(msgtype))
        if types is not self.types:
            self._topics[topic, f"{msgtype} ({id(types)})"] = topic_entity
        return Writer(DataWriter(self.dp, topic_entity, qos=profile.qos(types.user_data(msgtype))), types, topic, msgtype, profile)

    def subscribe(self, topic: str, msgtype: str, profile: QosProfile, callback: Callable[[Any], None], newest_only: bool = False) -> Any:
        """A subscription to ``msgtype`` on ``topic`` with ``profile``; ``callback`` gets each
        message (a cyclonedds struct with the message's fields), or with ``newest_only`` the
        newest one not handled yet (as a ROS 1 subscriber of queue size 1: a camera stream the
        callback cannot keep up with). A topic may be subscribed with several types: each
        reader hears the publishers of its own."""
        from cyclonedds.core import InstanceState, ReadCondition, SampleState, ViewState
        from cyclonedds.internal import InvalidSample
        from cyclonedds.sub import DataReader

        reader = DataReader(self.dp, self._topic(topic, msgtype), qos=profile.qos(self.types.user_data(msgtype)))

        def handle() -> None:
            samples: list[Any] = []
            while batch := reader.take(N=64):  # all that waits
                samples += [s for s in batch if not isinstance(s, InvalidSample)]  # (a publisher gone: no message)
            for sample in samples[-1:] if newest_only else samples:
                callback(sample)

        condition = ReadCondition(reader, ViewState.Any | InstanceState.Any | SampleState.NotRead)
        with self._lock:
            self._waitset.attach(condition)
            self._handlers.append((condition, handle))
            self._readers.append(reader)
        return reader

    def _dispatch(self) -> None:
        while not self._closing:
            self._waitset.wait(WAIT_NS)  # without the GIL; at most this long, so that a close is heard
            with self._lock:
                handlers = [handle for _, handle in self._handlers]
            for handle in handlers:
                if self._closing:
                    return
                try:
                    handle()
                except BaseException as exc:  # noqa: BLE001  (handed to on_error: the node says it once and carries on)
                    if self.on_error is None:
                        raise
                    self.on_error(exc)

    def close(self) -> None:
        """Stop handing messages to callbacks and leave the domain (remote participants see it go)."""
        self._closing = True
        self._wake.set(True)
        self._thread.join(timeout=5)
        if self._thread.is_alive():  # a callback still runs: its entities are left to the process's end
            return
        self._handlers.clear()
        self._readers.clear()
        self._topics.clear()
        self._waitset = None
        self.dp = None  # cyclonedds deletes the participant, and with it its endpoints
