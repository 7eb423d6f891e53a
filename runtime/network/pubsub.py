"""Publish/subscribe over CKMultiPeer (§3.1.4.3): TOPICLINKS tell who subscribes what; TOPICDATA goes only there.

Local subscribers get the very object published, with no serialization. Remote peers get one
TOPICDATA frame per sample — ``[topic, seq, stamp, value]``, or ``[topic, seq, stamp, cdr,
"cdr", type]`` for a topic type the transport's codec serialises (:mod:`.wire`) — encoded once for
all links when there is no group key. Best-effort topics drop a sample rather than wait for a busy link.

In a lock-step run (``ckm-run --lockstep``, D190, D220) every TOPICDATA and TOPICLINKS frame between
two transports of the run is counted where it is sent and where it arrives (:mod:`runtime.lockstep_frames`),
so the run's clock never moves with one in flight, and an arrived one is handed over at the clock's
next instant; the transport holds the clock from its set-up until it heard every other transport of
the run. Off lock-step none of this runs.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ckmconf.model import Network

from .. import lockstep
from ..lockstep_frames import Ledger, ledger
from .api import EVENTS_TOPIC, NetworkEvent, Publisher, Sample, Subscription, TopicQoS, Transport
from .frames import Frame, FrameType, encode
from .multipeer import MultiPeer, PeerEvent
from .qos import DeadlineWatchdog, SubscriptionTable, deliver
from .wire import WireError, incoming, outgoing, undecodable

LOG = logging.getLogger("ckm.pubsub")
BEST_EFFORT_WAIT = 0.002  # a best-effort sample waits this long for a busy link, then is dropped


class MultiPeerTransport(SubscriptionTable, Transport):
    """The CKMultiPeer transport (``<Network transport="multipeer">``)."""

    def __init__(self, network: Network, *, name: str = "peer", key: bytes | None = None) -> None:
        self.peer = MultiPeer(network, name=name, key=key)
        self._subs: dict[str, list[Subscription]] = {}
        self._remote_subs: dict[str, set[int]] = {}
        self._remote_demand: dict[str, set[int]] = {}  # the peers asking for each topic (not passive, D245)
        self._announced: tuple[list[str], list[str]] | None = None
        self._seq: dict[str, int] = {}
        self._callbacks: list[Callable[[NetworkEvent], None]] = []
        self._lock = threading.RLock()
        self._links_lock = threading.Lock()
        self._deadlines = DeadlineWatchdog(self._watched, self._emit, "ckm-deadlines")
        self.dropped_stale = 0
        self.dropped_busy = 0
        self._ledger: Ledger | None = None  # lock-step only (D220)
        self._heard: set[int] = set()  # peers whose TOPICLINKS arrived (lock-step: the clock waits for them)
        self.peer.add_listener(FrameType.TOPICDATA, self._on_data)
        self.peer.add_listener(FrameType.TOPICLINKS, self._on_links)
        self.peer.on_event(self._on_peer_event)

    @property
    def guid(self) -> int:  # type: ignore[override]
        """This peer's GUID (§3.1.4.1), known after :meth:`setup`."""
        return self.peer.guid

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Bind the peer's sockets (:meth:`MultiPeer.setup`); in lock-step, join the run's ledger (D220)."""
        self.peer.setup()
        self._ledger = ledger(lockstep.active())
        if self._ledger is not None:
            self._ledger.register(self.guid)
            self._ledger.hold_links(self.guid, lambda: self._heard)

    def start(self) -> None:
        """Start the peer and the deadline watchdog."""
        with lockstep.unheld_children():  # its threads wait in socket calls, never on a lock-step clock
            self.peer.start()
        self._deadlines.start()

    def stop(self) -> None:
        """Stop the deadline watchdog and the peer."""
        self._deadlines.stop()
        if self._ledger is not None:
            self._ledger.unregister(self.guid)
        self.peer.stop()

    # ------------------------------------------------------------------ API

    def publisher(self, qos: TopicQoS) -> Publisher:
        """A publisher sending locally and as TOPICDATA to the subscribed peers only."""
        return Publisher(qos, self._publish)

    def subscribe(
        self, qos: TopicQoS, callback: Callable[[Sample], None] | None = None, *, passive: bool = False
    ) -> Subscription:
        """Subscribe locally; a topic's first subscription, and its first asking for it, announce it in TOPICLINKS."""
        subscription = Subscription(qos, callback, self._unsubscribe, passive=passive, on_demand=self._demand_changed)
        with self._lock:
            first = not self._subs.get(qos.name)
            asked = not passive and not self._asked(qos.name)
            self._subs.setdefault(qos.name, []).append(subscription)
        if (first or asked) and qos.name != EVENTS_TOPIC:
            self._announce_links()
        return subscription

    def subscribed(self, topic: str) -> bool:
        """Whether a subscription here, or a peer's (TOPICLINKS), asks for ``topic`` (D245)."""
        with self._lock:
            return self._asked(topic) or bool(self._remote_demand.get(topic))

    def _asked(self, topic: str) -> bool:
        return any(not s.passive for s in self._subs.get(topic, ()))

    def _demand_changed(self, subscription: Subscription) -> None:
        if subscription.qos.name != EVENTS_TOPIC:
            self._announce_links()

    def on_event(self, callback: Callable[[NetworkEvent], None]) -> None:
        """Call ``callback`` for every network event."""
        self._callbacks.append(callback)

    def peers(self) -> list[int]:
        """Peers reachable directly or through a relay (PROXYWRAPPER)."""
        return self.peer.reachable()

    def wait_for_subscribers(self, topic: str, count: int, timeout: float) -> bool:
        """Wait up to ``timeout`` s until ``count`` remote peers subscribe ``topic``."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if len(self._remote_subs.get(topic, ())) >= count:
                return True
            time.sleep(0.002)
        return len(self._remote_subs.get(topic, ())) >= count

    # ------------------------------------------------------------------ publishing

    def _publish(self, qos: TopicQoS, value: Any, stamp: float) -> int:
        with self._lock:
            seq = self._seq[qos.name] = self._seq.get(qos.name, 0) + 1
            local = list(self._subs.get(qos.name, ()))
            remote = list(self._remote_subs.get(qos.name, ()))
        if local:
            deliver(local, Sample(qos.name, value, stamp, self.guid, seq, time.time()), self._emit)
        if not remote:
            return 0
        body = [qos.name, seq, stamp, *outgoing(self.codec, qos.name, qos.type, value)]  # value or cdr, 'cdr', type
        links = [self.peer.links.get(g) for g in remote]
        routed = sum(
            self._send(g, FrameType.TOPICDATA, body) for g, link in zip(remote, links, strict=True) if link is None
        )
        return routed + self._send_links([link for link in links if link is not None], qos, body)

    def _send(self, guid: int, kind: FrameType, body: list[Any]) -> bool:
        """One frame to one peer, directly or routed; counted in lock-step (D220)."""
        counted = self._ledger is not None and self._ledger.sending(guid)
        sent = self.peer.send(guid, kind, body)
        if counted and not sent:
            self._ledger.unsent(guid)  # type: ignore[union-attr]
        return sent

    def _send_links(self, links: list[Any], qos: TopicQoS, body: list[Any]) -> int:
        counts = self._ledger
        if self.peer.key is None:
            data = encode(FrameType.TOPICDATA, body)
            sent = 0
            wait = BEST_EFFORT_WAIT if qos.reliability == "best-effort" else None
            for link in links:
                counted = counts is not None and counts.sending(link.remote_guid)
                if link.send_encoded(data, wait=wait):
                    sent += 1
                    continue
                if counted:
                    counts.unsent(link.remote_guid)  # type: ignore[union-attr]
                if wait is not None:
                    self.dropped_busy += 1
            return sent
        if counts is not None:
            return sum(self._send(link.remote_guid, FrameType.TOPICDATA, body) for link in links)
        return sum(link.send(FrameType.TOPICDATA, body) for link in links)

    # ------------------------------------------------------------------ receiving

    def _on_data(self, guid: int, frame: Frame) -> None:
        body = frame.body
        if self._ledger is not None and self._ledger.arrived(guid, lambda: self._data(guid, body)):
            return  # lock-step: handed over at the clock's next instant (D220)
        self._data(guid, body)

    def _data(self, guid: int, body: list[Any]) -> None:
        if (
            len(body) not in (4, 6)
            or not isinstance(body[0], str)
            or not isinstance(body[1], int)
            or not isinstance(body[2], (float, int))
        ):
            LOG.warning("ignoring a malformed TOPICDATA frame from %s", guid)
            return
        topic, seq, stamp = body[:3]
        with self._lock:
            local = list(self._subs.get(topic, ()))
        if not local:
            return
        try:
            value = incoming(self.codec, body[3:])
        except WireError as error:
            undecodable(topic, error)
            return
        offset = self.peer.clock.offset(guid)
        sample = Sample(topic, value, float(stamp), guid, seq, time.time(), offset)
        if deliver(local, sample, self._emit):
            self.dropped_stale += 1

    def _on_links(self, guid: int, frame: Frame) -> None:
        body = frame.body
        if self._ledger is not None:
            self._heard.add(guid)  # on arrival: the clock waits for it (its effect comes at the next instant)
            if self._ledger.arrived(guid, lambda: self._links(guid, body)):
                return
        self._links(guid, body)

    def _links(self, guid: int, body: list[Any]) -> None:
        # ["subs", topics] or ["subs", topics, asked]: the topics the peer asks for, not only observes (D245)
        if (
            len(body) not in (2, 3)
            or body[0] != "subs"
            or not all(isinstance(part, list) for part in body[1:])
        ):
            LOG.warning("ignoring a malformed TOPICLINKS frame from %s", guid)
            return
        topics = {t for t in body[1] if isinstance(t, str)}
        asked = topics if len(body) == 2 else topics & {t for t in body[2] if isinstance(t, str)}
        with self._lock:
            for table, names in ((self._remote_subs, topics), (self._remote_demand, asked)):
                for name, guids in table.items():
                    if name not in names:
                        guids.discard(guid)
                for name in names:
                    table.setdefault(name, set()).add(guid)

    def _announce_links(self, guids: list[int] | None = None) -> None:
        with self._links_lock:  # states computed and sent in one order: the peers end at the newest
            with self._lock:
                topics = sorted(name for name, subs in self._subs.items() if subs and name != EVENTS_TOPIC)
                asked = [name for name in topics if self._asked(name)]
            if guids is None and self._announced == (topics, asked):
                return  # every peer has it already (a demand toggled back and forth, a second subscriber)
            if guids is None:
                self._announced = (topics, asked)
            body = ["subs", topics, asked]
            if self._ledger is None:
                self.peer.broadcast(FrameType.TOPICLINKS, body, guids)
                return
            for guid in guids if guids is not None else self.peer.reachable():  # one by one: each is counted
                self._send(guid, FrameType.TOPICLINKS, body)

    def _unsubscribe(self, subscription: Subscription) -> None:
        with self._lock:
            subs = self._subs.get(subscription.qos.name, [])
            if subscription in subs:
                subs.remove(subscription)
        self._announce_links()  # sent only if the topic or its demand went

    # ------------------------------------------------------------------ events and deadlines

    def _on_peer_event(self, event: PeerEvent) -> None:
        if event.kind == "linked":
            self._announce_links([event.guid])
        elif event.kind in ("unlinked", "lost"):
            with self._lock:
                for table in (self._remote_subs, self._remote_demand):
                    for guids in table.values():
                        guids.discard(event.guid)
            if event.kind == "lost":
                self.peer.clock.forget(event.guid)
        self._emit(NetworkEvent(event.kind, event.guid, None, event.reason or event.name))
