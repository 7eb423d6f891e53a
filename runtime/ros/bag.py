"""rosbag2 recordings of CKM topics, and their replay as a sensor source (issue L point 2).

:class:`BagRecorder` writes a rosbag2 bag, format version 9 (``metadata.yaml`` with
``type_description_hash`` and the QoS profiles each topic was offered with), in either storage
``ros2 bag`` knows: ``mcap`` (one ``.mcap`` file, profile ``ros2``, ``ros2msg`` schemas, ``cdr``
message encoding; what Foxglove opens) or ``sqlite3`` (one ``.db3`` file). It uses the ``rosbags``
writer, so nothing from ROS needs to be installed; the tests read the files back with independent
readers (``mcap`` + ``mcap-ros2-support``, and plain ``sqlite3``).

:class:`BagSource` reads any rosbag2 bag (custom types are taken from the definitions stored in
it) and yields :class:`BagMessage` items — topic, ROS type, time in seconds and the CKM payload of
:mod:`runtime.ros.convert` — either as fast as they come or paced like the recording (``play``), so
a bag can stand in for a simulated or real device.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol

from rosbags.interfaces import (
    MessageDefinitionFormat,
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg

from ckmconf.model import Topic

from .convert import from_message, to_message
from .types import RosTypeError, RosTypes

Storage = Literal["mcap", "sqlite3"]
BAG_VERSION: Literal[9] = 9
_STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}


class BagError(RuntimeError):
    """A bag that cannot be written or read as asked."""


def _qos_time(seconds: float | None) -> QosTime:
    if seconds is None:
        return QosTime(0, 0)  # rosbag2's "infinite"/default
    sec = math.floor(seconds)
    return QosTime(sec, round((seconds - sec) * 1e9))


def offered_qos(
    reliability: str = "reliable", history: int = 1, deadline: float | None = None, lifespan: float | None = None
) -> Qos:
    """The ROS 2 QoS profile of a CKM ``<Topic>`` (reliability, history depth, deadline, lifespan)."""
    return Qos(
        history=QosHistory.KEEP_LAST,
        depth=history,
        reliability=QosReliability.BEST_EFFORT if reliability == "best-effort" else QosReliability.RELIABLE,
        durability=QosDurability.VOLATILE,
        deadline=_qos_time(deadline),
        lifespan=_qos_time(lifespan),
        liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=QosTime(0, 0),
        avoid_ros_namespace_conventions=False,
    )


class RecordedSample(Protocol):
    """What a received CKM sample offers (``runtime.network.api.Sample``)."""

    @property
    def topic(self) -> str:
        """The name of the ``<Topic>`` (kernel.xsd ``TopicType``) the value was published on."""

    @property
    def value(self) -> Any:
        """The CKM payload, as :mod:`runtime.ros.convert` turns it into a ROS message."""

    @property
    def stamp(self) -> float:
        """The publication time in seconds, on the publisher's clock (§3.1.2.10)."""

    @property
    def offset(self) -> float:
        """The publisher's clock minus ours (from SYNCTIME), subtracted to record on one clock."""


class BagRecorder:
    """Records CKM topics into a new rosbag2 bag directory.

    Args:
        path: the bag directory; it must not exist (rosbag2 never overwrites a bag).
        storage: ``"mcap"`` or ``"sqlite3"``.
        types: the type store (custom types registered); a fresh Jazzy store by default.

    Use as a context manager, or call :meth:`open` and :meth:`close`.
    """

    def __init__(self, path: str | Path, *, storage: Storage = "mcap", types: RosTypes | None = None) -> None:
        if storage not in _STORAGES:
            raise BagError(f"unknown bag storage {storage!r} (known: {', '.join(_STORAGES)})")
        self.path = Path(path)
        self.storage: Storage = storage
        self.types = types or RosTypes()
        self._writer: Writer | None = None
        self._connections: dict[str, Any] = {}
        self._topic_types: dict[str, str] = {}

    def open(self) -> None:
        """Create the bag directory and its storage file."""
        if self._writer is not None:
            raise BagError(f"{self.path}: already open")
        if self.path.exists():
            raise BagError(f"{self.path} exists already: rosbag2 bags are never overwritten")
        writer = Writer(self.path, version=BAG_VERSION, storage_plugin=_STORAGES[self.storage])
        writer.open()
        self._writer = writer

    def add_topic(self, topic: str, type_name: str, *, qos: Qos | None = None) -> None:
        """Declare ``topic`` carrying ROS type ``type_name`` (once per topic, before writing it)."""
        writer = self._open_writer()
        if topic in self._connections:
            raise BagError(f"{self.path}: topic {topic} is declared already (as {self._topic_types[topic]})")
        msgdef = self.types.msgdef(type_name)  # raises RosTypeError for an unknown type
        self._connections[topic] = writer.add_connection(
            topic,
            type_name,
            msgdef=msgdef,
            rihs01=self.types.rihs01(type_name),
            offered_qos_profiles=[qos or offered_qos()],
        )
        self._topic_types[topic] = type_name

    def add_topics(self, topics: Iterable[Topic]) -> list[str]:
        """Declare every configured ``<Topic>`` whose type is a known ROS 2 type, offered the QoS
        it is configured with; returns their names (topics of CKM types are left out)."""
        declared = []
        for topic in topics:
            if topic.type in self.types and topic.name not in self._connections:
                qos = offered_qos(topic.reliability, topic.history, topic.deadline, topic.lifespan)
                self.add_topic(topic.name, topic.type, qos=qos)
                declared.append(topic.name)
        return declared

    def write_sample(self, sample: RecordedSample) -> None:
        """Record a received sample at its publication time, on this host's clock."""
        self.write(sample.topic, sample.value, sample.stamp - sample.offset)

    def write(self, topic: str, payload: Any, stamp: float) -> None:
        """Record the CKM ``payload`` of ``topic`` at ``stamp`` seconds (since the UNIX epoch)."""
        type_name = self._type_of(topic)
        self.write_cdr(topic, self.types.encode(type_name, to_message(self.types, type_name, payload)), stamp)

    def write_cdr(self, topic: str, data: bytes, stamp: float) -> None:
        """Record an already serialised CDR message of ``topic`` at ``stamp`` seconds."""
        self._type_of(topic)
        if not math.isfinite(stamp) or stamp < 0:
            raise BagError(f"{self.path}: {topic}: a message time must be non-negative seconds, got {stamp!r}")
        self._open_writer().write(self._connections[topic], round(stamp * 1e9), data)

    def close(self) -> None:
        """Finish the storage file and write ``metadata.yaml``."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.close()

    def __enter__(self) -> BagRecorder:
        self.open()
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()

    def _open_writer(self) -> Writer:
        if self._writer is None:
            raise BagError(f"{self.path}: the bag is not open")
        return self._writer

    def _type_of(self, topic: str) -> str:
        if topic not in self._topic_types:
            raise BagError(f"{self.path}: topic {topic} was not declared with add_topic")
        return self._topic_types[topic]


@dataclass(frozen=True)
class BagMessage:
    """One recorded message: its topic, ROS type, time (seconds since the epoch) and CKM payload."""

    topic: str
    type: str
    time: float
    payload: Any


class BagSource:
    """Replays a rosbag2 bag (MCAP or sqlite3) as a source of CKM samples.

    Args:
        path: the bag directory (with its ``metadata.yaml``).
        types: the type store to decode with; types the bag defines and the store lacks are added.
        topics: only these topics (all by default).
    """

    def __init__(self, path: str | Path, *, types: RosTypes | None = None, topics: Iterable[str] | None = None) -> None:
        self.path = Path(path)
        self.types = types or RosTypes()
        self.topics = None if topics is None else frozenset(topics)

    def topic_types(self) -> dict[str, str]:
        """Every topic of the bag with its ROS type."""
        with self._reader() as reader:
            return {c.topic: c.msgtype for c in reader.connections}

    def messages(self) -> Iterator[BagMessage]:
        """Every message in time order, decoded to CKM payloads, as fast as they can be read."""
        for topic, msgtype, timestamp, data in self.records():
            try:
                payload = from_message(self.types, msgtype, self.types.decode(msgtype, data))
            except RosTypeError as error:
                raise BagError(f"{self.path}: {topic} at {timestamp} ns: {error}") from error
            yield BagMessage(topic, msgtype, timestamp * 1e-9, payload)

    def records(self) -> Iterator[tuple[str, str, int, bytes]]:
        """Every message in time order as it is stored: (topic, ROS type, time in ns, CDR bytes).

        The types of the selected topics are in :attr:`types` once the first record is yielded
        (``hardware.bag`` keeps the bytes and decodes a message only when it is played)."""
        with self._reader() as reader:
            connections = [c for c in reader.connections if self.topics is None or c.topic in self.topics]
            missing = sorted((self.topics or frozenset()) - {c.topic for c in reader.connections})
            if missing:
                raise BagError(f"{self.path}: no topic {', '.join(missing)} in the bag")
            for connection in connections:
                self._learn(connection)
            for connection, timestamp, data in reader.messages(connections=connections):
                yield connection.topic, connection.msgtype, timestamp, bytes(data)

    def play(
        self,
        *,
        speed: float = 1.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> Iterator[BagMessage]:
        """The messages paced as recorded: each is yielded once ``clock`` has advanced by its
        offset from the first message divided by ``speed`` (so ``speed=2`` plays twice as fast)."""
        if not speed > 0:
            raise BagError(f"replay speed must be positive, got {speed!r}")
        start_clock: float | None = None
        start_time = 0.0
        for message in self.messages():
            if start_clock is None:
                start_clock, start_time = clock(), message.time
            due = start_clock + (message.time - start_time) / speed
            wait = due - clock()
            if wait > 0:
                sleep(wait)
            yield message

    def _reader(self) -> Reader:
        if not (self.path / "metadata.yaml").is_file():
            raise BagError(f"{self.path}: not a rosbag2 bag (no metadata.yaml)")
        return Reader(self.path)

    def _learn(self, connection: Any) -> None:
        """Register a type the bag defines (a custom .msg) and the store does not know."""
        if connection.msgtype in self.types:
            return
        if connection.msgdef.format != MessageDefinitionFormat.MSG or not connection.msgdef.data:
            raise BagError(
                f"{self.path}: {connection.topic}: unknown type {connection.msgtype} and no .msg definition in the bag"
            )
        self.types.store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
