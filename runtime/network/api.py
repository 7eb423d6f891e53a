"""The publish/subscribe interface every transport offers (CKMultiPeer, Zenoh).

Topics carry msgpack-able values. Every sample is timestamped by its publisher (§3.1.2.10);
QoS comes from the configuration's Topic: reliability, history depth, deadline (a missed
deadline is an event) and lifespan (stale samples are dropped). Events — peers found, lost,
linked, unlinked, deadlines missed, stale samples dropped — go to ``on_event`` callbacks and
to the local topic ``EVENTS_TOPIC``.
"""

from __future__ import annotations

import abc
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from ckmconf.model import Network, Topic

from .wire import WireCodec

EVENTS_TOPIC = "/ckm/events"


@dataclass(frozen=True)
class TopicQoS:
    """A topic's name and quality of service, usually from a configuration's <Topic>."""

    name: str
    type: str = "bytes"
    reliability: Literal["reliable", "best-effort"] = "reliable"
    history: int = 1
    deadline: float | None = None
    lifespan: float | None = None

    @classmethod
    def of(cls, topic: Topic) -> TopicQoS:
        """The QoS of a configuration ``<Topic>`` (TopicType): reliability, history, deadline, lifespan."""
        return cls(topic.name, topic.type, topic.reliability, topic.history, topic.deadline, topic.lifespan)


@dataclass(frozen=True)
class Sample:
    """One received value. ``stamp`` is on the publisher's clock (§3.1.2.10); ``received`` on ours."""

    topic: str
    value: Any
    stamp: float
    source: int
    seq: int
    received: float
    offset: float = 0.0  # publisher clock minus ours, from SYNCTIME

    @property
    def age(self) -> float:
        """Seconds from publication to reception, on one clock."""
        return self.received - (self.stamp - self.offset)


@dataclass(frozen=True)
class NetworkEvent:
    """found, lost, linked, unlinked (peers); deadline-missed, stale-dropped (topics)."""

    kind: str
    peer: int | None = None
    topic: str | None = None
    detail: str = ""


class Subscription:
    """A subscriber's end of a topic: an optional callback (a listener, §3.1.4.4) and the last ``history`` samples."""

    def __init__(
        self,
        qos: TopicQoS,
        callback: Callable[[Sample], None] | None,
        on_close: Callable[[Subscription], None],
        *,
        passive: bool = False,
        on_demand: Callable[[Subscription], None] | None = None,
    ):
        self.qos = qos
        self.callback = callback
        self.received = 0
        self.last_arrival = time.monotonic()  # or the last missed-deadline report
        self.passive = passive
        """An observer (a staleness watch, an idle reader): it gets what flows, but a lazy producer
        does not produce for it (decision D245)."""
        self.asks = 0 if passive else 1
        """How many times the topic was asked for (D245): a reader sees a new count as a new ask."""
        self._asked_at: int | None = None if passive else 0  # samples received when last asked for
        self._samples: deque[Sample] = deque(maxlen=qos.history)
        self._lock = threading.Lock()
        self._on_close = on_close
        self._on_demand = on_demand
        self._arrived = threading.Condition(self._lock)

    def demand(self, wanted: bool) -> None:
        """Ask for the topic (``True``) or only observe it (``False``, passive); the transport tells
        the producers, so a lazy sensor or service runs only while someone asks (D245)."""
        if self.passive != wanted:
            return
        with self._lock:
            self.passive = not wanted
            if wanted:
                self._asked_at = self.received
                self.asks += 1
            self.last_arrival = time.monotonic()  # a deadline runs from when the topic is asked for
        if self._on_demand is not None:
            self._on_demand(self)

    def deliver(self, sample: Sample) -> None:
        """Store an arrived sample in the history, wake waiters, then call the callback (transport side)."""
        with self._lock:
            self._samples.append(sample)
            self.received += 1
            self.last_arrival = time.monotonic()
            self._arrived.notify_all()
        if self.callback is not None:
            self.callback(sample)

    def heard_since_ask(self) -> bool:
        """Whether a sample arrived since the topic was last asked for (never, for one never asked)."""
        with self._lock:
            return self._asked_at is not None and self.received > self._asked_at

    def latest(self, *, since_ask: bool = False) -> Sample | None:
        """The newest sample still within its lifespan, if any; with ``since_ask``, only one that
        arrived since the topic was last asked for: what a lazy producer published before it
        rested is not news when it wakes (D249)."""
        with self._lock:
            sample = self._samples[-1] if self._samples else None
            if since_ask and (self._asked_at is None or self.received <= self._asked_at):
                sample = None
        if (
            sample is not None
            and self.qos.lifespan is not None
            and time.time() - (sample.stamp - sample.offset) > self.qos.lifespan
        ):
            return None
        return sample

    def history(self) -> list[Sample]:
        """The last ``history`` samples received, oldest first (lifespan not applied)."""
        with self._lock:
            return list(self._samples)

    def wait(self, count: int, timeout: float) -> bool:
        """Wait until ``count`` samples have arrived in total (tests, benchmarks)."""
        with self._arrived:
            return self._arrived.wait_for(lambda: self.received >= count, timeout)

    def close(self) -> None:
        """Unsubscribe: the transport stops delivering and may withdraw its TOPICLINK."""
        self._on_close(self)


class Publisher:
    """A publisher's end of a topic."""

    def __init__(self, qos: TopicQoS, send: Callable[[TopicQoS, Any, float], int]) -> None:
        self.qos = qos
        self._send = send

    def publish(self, value: Any, *, stamp: float | None = None) -> int:
        """Publish ``value`` (stamped now unless given); returns the number of remote peers sent to."""
        return self._send(self.qos, value, time.time() if stamp is None else float(stamp))


class Transport(abc.ABC):
    """What the runtime uses to talk (``<Network transport>``): the same for CKMultiPeer (§3.1.4) and Zenoh."""

    guid: int = 0
    codec: WireCodec | None = None  # serialises the topic types it knows (runtime.network.wire)

    @abc.abstractmethod
    def setup(self) -> None:
        """Bind sockets or open the session (no threads yet); raises NetworkError if impossible."""

    @abc.abstractmethod
    def start(self) -> None:
        """Start discovery and the I/O threads; samples flow from here on."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Say goodbye to the peers, stop the threads and close every socket; idempotent."""

    @abc.abstractmethod
    def publisher(self, qos: TopicQoS) -> Publisher:
        """A publisher for the topic described by ``qos``."""

    @abc.abstractmethod
    def subscribe(
        self, qos: TopicQoS, callback: Callable[[Sample], None] | None = None, *, passive: bool = False
    ) -> Subscription:
        """Subscribe to ``qos.name``; ``callback`` (if any) runs on a transport thread per sample.

        A ``passive`` subscription observes the topic without asking for it (D245): see
        :meth:`subscribed`.
        """

    def subscribed(self, topic: str) -> bool:
        """Whether a subscriber here or at a peer asks for ``topic`` (one not passive).

        A lazy producer (``<Sensor lazy>``, ``<Service lazy>``) works only while this holds
        (decision D245). A transport that cannot tell answers True: lazy producers then always work.
        """
        return True

    @abc.abstractmethod
    def on_event(self, callback: Callable[[NetworkEvent], None]) -> None:
        """Call ``callback`` for every network event (peer found/lost, deadline missed, stale dropped)."""

    @abc.abstractmethod
    def peers(self) -> list[int]:
        """GUIDs of the peers this one can currently reach."""

    @abc.abstractmethod
    def wait_for_subscribers(self, topic: str, count: int, timeout: float) -> bool:
        """Wait until ``count`` remote peers subscribe to ``topic`` (tests, benchmarks)."""

    def __enter__(self) -> Transport:
        self.setup()
        self.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()


class NetworkError(RuntimeError):
    """A transport cannot start (``setup()``): no free port, no multicast, no Zenoh session…"""


class GroupKeyError(ValueError):
    """The group key file named by the configuration cannot be used."""


def read_group_key(network: Network, base: Path) -> bytes | None:
    """The group key bytes (file relative to ``base``), or None when the network has none."""
    if network.group_key_file is None:
        return None
    path = (base / network.group_key_file).resolve()
    try:
        key = path.read_bytes().strip()
    except OSError as exc:
        raise GroupKeyError(f"cannot read the group key file {path}: {exc.strerror}") from None
    if len(key) < 16:
        raise GroupKeyError(f"the group key in {path} is too short ({len(key)} bytes; use at least 16)")
    return key
