"""``ckm-run --record``: a run's topics recorded as a rosbag2 bag (issue L point 2, thesis §4.4.1).

The recorder is one more subscriber of the run's transport, like any node: each recorded
``<Topic>`` (schemas/kernel.xsd) is subscribed to under the name the nodes use (an internal topic
``speed`` of node ``motor-node`` is ``/motor-node/~speed`` on the transport), its samples are
queued by the transport's thread and written by the recorder's own thread through
:class:`runtime.ros.bag.BagRecorder` (MCAP or sqlite3, rosbag2 format 9), each as the ROS type
:class:`runtime.ros.config.ConfigRosTypes` gives its topic. In the bag a topic is named like a
ROS topic: ``/motor_node/speed`` (decision D132).

An item may limit its topic's rate and compress its images (``NAME@HZ:jpeg``, :mod:`.sparse`,
D197): a camera recorded as a frame every few seconds, as JPEG ``CompressedImage``.

A value that does not fit its type is dropped and counted per topic (the first reason logged);
a full queue drops and counts too. Only a failure of the bag itself (a disk error) stops the
recording: :attr:`RunRecorder.failure` says why, for the run's exit code.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import re
import threading
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ckmconf.model import Node, System

from ..network.api import Sample, Subscription, TopicQoS, Transport
from .bag import BagRecorder, Storage, offered_qos
from .config import ConfigRosTypes, all_topics, plain
from .convert import to_message
from .sparse import COMPRESSED, Compression, Item, SpecError, Throttle, compress, is_image_type, parse_spec
from .types import RosTypeError

LOG = logging.getLogger("ckm.record")
BOTH = "mcap+sqlite3"
RECORD_FORMATS: tuple[str, ...] = ("mcap", "sqlite3", BOTH)
TWIN_SUFFIX = "-sqlite3"
"""``--record-format mcap+sqlite3`` writes the same messages into BAG (MCAP) and BAG-sqlite3 (D182)."""
QUEUE_LIMIT = 10_000  # samples waiting for the writer; beyond it they are dropped and counted
_STOP = object()


class RecordingError(ValueError):
    """A ``--record`` request that cannot be met (an unknown topic, a bag that exists)."""


@dataclass(frozen=True)
class RecordedTopic:
    """One topic to record: its configured name, its transport QoS, its bag name and ROS type (in
    the bag: ``CompressedImage`` when compressed, the topic's own type being ``source_type``), its
    rate limit (Hz) and compression (:mod:`.sparse`)."""

    name: str
    qos: TopicQoS
    bag_name: str
    ros_type: str
    rate: float | None = None
    compression: Compression | None = None
    source_type: str | None = None


def bag_topic_name(transport_name: str) -> str:
    """A transport topic name as a ROS topic name: ``/motor-node/~speed`` → ``/motor_node/speed``."""
    parts = [re.sub(r"[^A-Za-z0-9_]", "_", p.lstrip("~")) for p in transport_name.split("/") if p.lstrip("~")]
    return "/" + "/".join(p if p[:1].isalpha() else f"t{p}" for p in parts)


def plan_recording(system: System, nodes: Sequence[Node], spec: str, types: ConfigRosTypes) -> list[RecordedTopic]:
    """The topics ``--record SPEC`` names: ``all`` or comma-separated configured topic names, each
    with its options (``NAME[@HZ][:jpeg|:png]``, :func:`.sparse.parse_spec`).

    External topics are recorded whichever node runs here; internal ones only for the nodes
    running in this process (``nodes``), each under its node-local transport name.
    """
    here = {n.name for n in nodes}
    candidates: list[RecordedTopic] = []
    for topic, node in all_topics(system):
        if topic.scope == "internal":
            if node not in here:
                continue
            transport = f"/{node}/~{topic.name.lstrip('/')}"
        else:
            transport = topic.name
        if any(c.qos.name == transport for c in candidates):
            continue  # an external topic declared at several places
        qos = TopicQoS(transport, topic.type, topic.reliability, topic.history, None, None)  # every sample, no events
        try:
            ros_type = types.ros_type_of(topic.type)
        except RosTypeError as error:
            raise RecordingError(f"topic {topic.name!r}: {error}") from error
        candidates.append(RecordedTopic(topic.name, qos, bag_topic_name(transport), ros_type))
    try:
        items = parse_spec(spec)
    except SpecError as error:
        raise RecordingError(str(error)) from error
    wanted = [item.name for item in items]
    if not wanted:
        raise RecordingError("--record needs 'all' or topic names separated by commas")
    named = [w for w in wanted if w != "all"]
    known = {c.name for c in candidates} | {c.qos.name for c in candidates}
    unknown = [w for w in named if w not in known]
    if unknown:
        names = ", ".join(sorted({c.name for c in candidates})) or "none"
        raise RecordingError(f"--record: no topic {', '.join(map(repr, unknown))} here (topics: {names})")
    if "all" not in wanted:
        candidates = [c for c in candidates if c.name in wanted or c.qos.name in wanted]
    candidates = [_with_options(c, items, types) for c in candidates]
    seen: dict[str, int] = {}
    unique = []
    for candidate in candidates:  # two transport names may sanitise alike: keep bag names apart
        count = seen[candidate.bag_name] = seen.get(candidate.bag_name, 0) + 1
        bag_name = candidate.bag_name if count == 1 else f"{candidate.bag_name}_{count}"
        unique.append(replace(candidate, bag_name=bag_name))
    return unique


def _with_options(topic: RecordedTopic, items: Sequence[Item], types: ConfigRosTypes) -> RecordedTopic:
    """``topic`` with the rate limit and compression of the (last) item naming it."""
    item = next((i for i in reversed(items) if i.name in (topic.name, topic.qos.name)), None)
    if item is None or (item.rate is None and item.compression is None):
        return topic
    if item.compression is None:
        return replace(topic, rate=item.rate)
    if not is_image_type(types.ros, topic.ros_type):
        raise RecordingError(f"--record {topic.name}:{item.compression}: its type {topic.ros_type} is not an image")
    return replace(topic, bag_name=topic.bag_name + "/compressed", ros_type=COMPRESSED, rate=item.rate,
                   compression=item.compression, source_type=topic.ros_type)  # fmt: skip


@dataclass
class _Counts:
    written: int = 0
    dropped: int = 0
    throttled: int = 0
    first_drop: str | None = None


class RunRecorder:
    """Records topics of a running system into a rosbag2 bag, in its own thread.

    Args:
        system: the loaded system.
        nodes: the nodes running in this process.
        path: the bag directory to create (it must not exist).
        spec: ``all`` or comma-separated topic names, each ``NAME[@HZ][:jpeg|:png]`` (:func:`plan_recording`).
        storage: ``mcap``, ``sqlite3`` or ``mcap+sqlite3`` (both: the sqlite3 twin is ``PATH-sqlite3``).

    Everything ``--record`` asks is checked here, before the run starts (RecordingError).
    """

    def __init__(self, system: System, nodes: Sequence[Node], path: Path, spec: str, storage: str) -> None:
        if storage not in RECORD_FORMATS:
            raise RecordingError(f"--record-format {storage!r}: use {' or '.join(RECORD_FORMATS)}")
        storages: list[tuple[Path, Storage]] = [(path, "sqlite3" if storage == "sqlite3" else "mcap")]
        if storage == BOTH:
            storages.append((path.with_name(path.name + TWIN_SUFFIX), "sqlite3"))
        for where, _ in storages:
            if where.exists():
                raise RecordingError(f"{where} exists already: rosbag2 bags are never overwritten")
        self.types = ConfigRosTypes(system)
        self.topics = plan_recording(system, nodes, spec, self.types)
        self.path = path
        self.storage = storage
        self.failure: str | None = None
        self._bags = [BagRecorder(where, storage=kind, types=self.types.ros) for where, kind in storages]
        self._queue: queue.Queue[Any] = queue.Queue(QUEUE_LIMIT)
        self._counts = {t.qos.name: _Counts() for t in self.topics}
        self._by_transport = {t.qos.name: t for t in self.topics}
        self._throttles = {t.qos.name: Throttle(t.rate) for t in self.topics if t.rate is not None}
        self._subscriptions: list[Subscription] = []
        self._lock = threading.Lock()
        self._opened = threading.Event()
        self._thread = threading.Thread(target=self._run, name="ckm-recorder", daemon=True)

    @classmethod
    def in_run(
        cls, system: System, nodes: Sequence[Node], run_dir: Path, label: str | None, spec: str, storage: str
    ) -> RunRecorder:
        """The recorder of a run: its bag is RUN_DIR/bag, or RUN_DIR/bag-LABEL for one node's process
        (``--node``; several may share a run directory)."""
        return cls(system, nodes, run_dir / ("bag" if label is None else f"bag-{label}"), spec, storage)

    def start(self, transport: Transport, timeout: float = 10.0) -> None:
        """Create the bag, declare its topics, subscribe to them through ``transport`` and start writing.

        The bag is opened, written and closed by the recorder's thread alone (sqlite3 connections
        belong to the thread that made them); this waits at most ``timeout`` s for it to open.
        """
        self._thread.start()
        if not self._opened.wait(timeout):
            self._fail(f"the bag {self.path} did not open within {timeout:g} s")
        if self.failure is not None:
            raise RecordingError(self.failure)
        for topic in self.topics:
            self._subscriptions.append(transport.subscribe(topic.qos, self._received))
        LOG.info("recording %d topic(s) into %s (%s)", len(self.topics), self.path, self.storage)

    def stop(self, timeout: float = 10.0) -> None:
        """Stop subscribing, write what is queued and close the bag (at most ``timeout`` seconds)."""
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()
        if self._thread.is_alive():
            with contextlib.suppress(queue.Full):  # a stuck writer is reported below
                self._queue.put(_STOP, timeout=timeout)
            self._thread.join(timeout)
            if self._thread.is_alive():
                self._fail(f"the recorder did not finish writing {self.path} within {timeout:g} s")
                return
        for name, counts in self.statistics()["topics"].items():
            if counts["dropped"]:
                LOG.warning(
                    "recording %s: %d value(s) dropped, first: %s", name, counts["dropped"], counts["firstDrop"]
                )
        if self.failure is None:
            LOG.info("recording finished: %s", self.path)

    def statistics(self) -> dict[str, Any]:
        """What was recorded: per topic its bag name, ROS type, written and dropped counts."""
        with self._lock:
            topics = {
                t.qos.name: {
                    "bagTopic": t.bag_name,
                    "rosType": t.ros_type,
                    "written": self._counts[t.qos.name].written,
                    "dropped": self._counts[t.qos.name].dropped,
                    "firstDrop": self._counts[t.qos.name].first_drop,
                    "throttled": self._counts[t.qos.name].throttled,
                    "maxRate": t.rate,
                    "compression": t.compression,
                }
                for t in self.topics
            }
        bags = [str(bag.path) for bag in self._bags]
        return {"bag": str(self.path), "bags": bags, "format": self.storage, "failure": self.failure, "topics": topics}

    # ------------------------------------------------------------------ internals

    def _received(self, sample: Sample) -> None:
        """The transport's thread: hand the sample over, never block it."""
        if self.failure is not None:
            return
        throttle = self._throttles.get(sample.topic)
        if throttle is not None and not throttle.admit(sample.stamp - sample.offset):  # before queueing a frame
            with self._lock:
                self._counts[sample.topic].throttled += 1
            return
        try:
            self._queue.put_nowait(sample)
        except queue.Full:
            self._drop(sample.topic, f"the recorder's queue is full ({QUEUE_LIMIT} samples)")

    def _run(self) -> None:
        """The recorder's thread: open the bag, write what arrives until told to stop, close it."""
        try:
            for bag in self._bags:
                bag.open()
                for topic in self.topics:
                    qos = offered_qos(topic.qos.reliability, topic.qos.history)
                    bag.add_topic(topic.bag_name, topic.ros_type, qos=qos)
        except Exception as error:
            self._fail(f"cannot record into {self.path}: {type(error).__name__}: {error}")
            self._close()
            return
        finally:
            self._opened.set()
        while True:
            item = self._queue.get()
            if item is _STOP:
                break
            try:
                self._write(item)
            except Exception as error:  # the bag itself failed: nothing more can be recorded
                LOG.exception("recording into %s failed", self.path)
                self._fail(f"recording into {self.path} failed: {type(error).__name__}: {error}")
                break
        self._close()

    def _close(self) -> None:
        for bag in self._bags:
            try:
                bag.close()
            except Exception as error:
                self._fail(f"cannot finish the bag {bag.path}: {type(error).__name__}: {error}")

    def _write(self, sample: Sample) -> None:
        topic = self._by_transport.get(sample.topic)
        if topic is None:
            return
        value = plain(sample.value)
        if topic.qos.type == "bool" and isinstance(value, int | float) and not isinstance(value, bool):
            value = value != 0  # a digital channel reads 0.0 / 1.0: numbers fit bool topics (verify)
        stamp = sample.stamp - sample.offset
        try:
            source = topic.source_type or topic.ros_type
            payload = self.types.payload(source, value)
            ros = self.types.ros
            message = to_message(ros, source, payload)
            if topic.compression is not None:
                data = compress(ros, message, source, topic.compression, stamp)
            else:
                data = ros.encode(topic.ros_type, message)
        except (RosTypeError, TypeError, ValueError) as error:  # this value does not fit the type
            self._drop(sample.topic, str(error))
            return
        if not math.isfinite(stamp) or stamp < 0:  # a publisher's bad clock: this sample, not the bag
            self._drop(sample.topic, f"its time stamp {sample.stamp!r} is not a time since the epoch")
            return
        for bag in self._bags:  # one encoding, the same bytes in every storage
            bag.write_cdr(topic.bag_name, data, stamp)
        with self._lock:
            self._counts[sample.topic].written += 1

    def _drop(self, transport_name: str, reason: str) -> None:
        with self._lock:
            counts = self._counts[transport_name]
            counts.dropped += 1
            first = counts.first_drop is None
            if first:
                counts.first_drop = reason
        if first:
            LOG.warning("recording %s: a value that does not fit is dropped: %s", transport_name, reason)

    def _fail(self, message: str) -> None:
        if self.failure is None:
            self.failure = message
            LOG.error("%s", message)
