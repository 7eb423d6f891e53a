"""Publish/subscribe over Zenoh (``<Network transport="zenoh">``), with CKMultiPeer's semantics.

Naming (topics as key expressions under ``ckm/``, liveliness tokens of peers and subscribers)
and the session configuration are in :mod:`.zenoh_session`.

Because the leading slash is dropped, "/a/b" and "a/b" are one topic here (two in CKMultiPeer).

Wire format: the payload is msgpack ``[seq, stamp, value]`` as in CKMultiPeer's TOPICDATA
(``[seq, stamp, cdr, "cdr", type]`` for a type the transport's codec serialises: :mod:`.wire`)
(the topic is the key expression); the attachment is the publisher's GUID (8 bytes,
big-endian). There is no SYNCTIME: ``Sample.offset`` is 0, clocks are
assumed synchronised (NTP) for lifespan checks.

A CKM group key is refused: Zenoh has no shared-key authentication, and an HMAC over the
payload alone would leave discovery and subscriber tokens open to anyone on the LAN. Secure a
Zenoh system with Zenoh's own TLS (mutual) or user-password authentication instead.
"""

from __future__ import annotations

import atexit
import functools
import logging
import struct
import threading
import time
import weakref
from collections.abc import Callable
from typing import Any

import msgpack
import zenoh

from ckmconf.model import Network

from .api import EVENTS_TOPIC, NetworkError, NetworkEvent, Publisher, Sample, Subscription, TopicQoS, Transport
from .frames import FrameError, unpack_body
from .qos import DeadlineWatchdog, SubscriptionTable, deliver
from .wire import WireError, incoming, outgoing, undecodable
from .zenoh_session import (
    PEER_TOKENS,
    PREFIX,
    SOURCE,
    SUB_TOKENS,
    guid_after,
    guid_of,
    key_expr,
    topic_path,
    zenoh_config,
    zenoh_reason,
)

LOG = logging.getLogger("ckm.zenoh")

# Sessions still open at interpreter exit make the process hang (DESIGN.md, "Pitfalls"):
# whatever the caller forgot to stop is stopped at exit (see _stop_forgotten).
_OPEN: weakref.WeakSet[ZenohTransport] = weakref.WeakSet()

KEYED_CONFIG_ERROR = (
    "the Zenoh transport cannot use a CKM group key (group_key_file): Zenoh has no shared-key "
    "authentication; configure TLS or user-password authentication in Zenoh instead"
)


class ZenohTransport(SubscriptionTable, Transport):
    """The Zenoh transport: same lifecycle, QoS and events as ``MultiPeerTransport``."""

    def __init__(self, network: Network, *, name: str = "peer", key: bytes | None = None) -> None:
        if key is not None:
            raise ValueError(KEYED_CONFIG_ERROR)
        self.network = network
        self.name = name
        self.guid = 0
        self.dropped_stale = 0
        self.dropped_malformed = 0
        self._session: zenoh.Session | None = None
        self._stopped = False
        self._lock = threading.RLock()  # our tables; never held while calling into Zenoh
        self._changed = threading.Condition(self._lock)
        self._declaring = threading.Lock()  # serialises declarations; Zenoh callbacks never take it
        self._subs: dict[str, list[Subscription]] = {}
        self._seq: dict[str, int] = {}
        self._peers: set[int] = set()
        self._remote_subs: dict[str, set[int]] = {}  # key expression → remote GUIDs
        self._callbacks: list[Callable[[NetworkEvent], None]] = []
        self._zsubs: dict[str, tuple[zenoh.Subscriber[None], zenoh.LivelinessToken]] = {}
        self._zpubs: dict[tuple[str, str], zenoh.Publisher] = {}
        self._own: list[zenoh.LivelinessToken | zenoh.Subscriber[None]] = []
        self._attachment = b""
        self._deadlines = DeadlineWatchdog(self._watched, self._emit, "ckm-zenoh-deadlines")

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Open the Zenoh session (NetworkError if impossible) and derive the GUID from its id."""
        try:
            session = zenoh.open(zenoh_config(self.network))
        except zenoh.ZError as exc:  # no router to connect to, port taken…
            raise NetworkError(f"cannot open the Zenoh session: {zenoh_reason(exc)}") from None
        _OPEN.add(self)
        self.guid = guid_of(session.zid())
        self._attachment = SOURCE.pack(self.guid)
        with self._lock:
            self._session = session
            topics = list(self._subs)
        for topic in topics:  # subscriptions made before setup()
            self._sync_topic(topic)

    def start(self) -> None:
        """Watch peer and subscriber liveliness tokens, declare ours, start the deadline watchdog."""
        session = self._session
        assert session is not None, "call setup() first"
        liveliness = session.liveliness()
        with self._declaring:
            # Watch before announcing; history=True also reports the tokens already there.
            self._own.append(liveliness.declare_subscriber(f"{PEER_TOKENS}/*", self._on_peer_token, history=True))
            self._own.append(liveliness.declare_subscriber(f"{SUB_TOKENS}/**", self._on_sub_token, history=True))
            self._own.append(liveliness.declare_token(f"{PEER_TOKENS}/{self.guid}"))
        self._deadlines.start()

    def stop(self) -> None:
        """Undeclare every entity and close the session; idempotent."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
        self._deadlines.stop()
        with self._declaring:
            session, self._session = self._session, None
            entities: list[Any] = [token for _, token in self._zsubs.values()]
            entities += [zsub for zsub, _ in self._zsubs.values()]
            entities += [*self._zpubs.values(), *reversed(self._own)]  # our peer token goes first
            self._zsubs.clear()
            self._zpubs.clear()
            self._own.clear()
        for entity in entities:
            _release(entity.undeclare)
        if session is not None:
            _release(session.close)
        _OPEN.discard(self)
        with self._changed:
            self._peers.clear()
            self._remote_subs.clear()
            self._changed.notify_all()

    # ------------------------------------------------------------------ API

    def publisher(self, qos: TopicQoS) -> Publisher:
        """A publisher on the topic's key expression (a bad name is refused here)."""
        if qos.name != EVENTS_TOPIC:
            key_expr(qos.name)  # refuse a bad name now, not at the first publish
        return Publisher(qos, self._publish)

    def subscribe(
        self, qos: TopicQoS, callback: Callable[[Sample], None] | None = None, *, passive: bool = False
    ) -> Subscription:
        """Subscribe to ``qos.name``; the Zenoh subscriber and token follow the local subscriptions.

        ``passive`` is kept but not told to the producers: :meth:`subscribed` is always True here (D245).
        """
        if qos.name != EVENTS_TOPIC:
            key_expr(qos.name)
        subscription = Subscription(qos, callback, self._unsubscribe, passive=passive)
        with self._lock:
            self._subs.setdefault(qos.name, []).append(subscription)
        self._sync_topic(qos.name)
        return subscription

    def on_event(self, callback: Callable[[NetworkEvent], None]) -> None:
        """Call ``callback`` for every network event."""
        self._callbacks.append(callback)

    def peers(self) -> list[int]:
        """GUIDs of the transports whose liveliness token is present."""
        with self._lock:
            return sorted(self._peers)

    def wait_for_subscribers(self, topic: str, count: int, timeout: float) -> bool:
        """Wait up to ``timeout`` s until ``count`` remote subscribers of ``topic`` appear."""
        key = key_expr(topic)
        with self._changed:
            return self._changed.wait_for(lambda: len(self._remote_subs.get(key, ())) >= count, timeout)

    # ------------------------------------------------------------------ declarations

    def _sync_topic(self, topic: str) -> None:
        """Declare or undeclare the Zenoh subscriber and token of ``topic`` to match our subscriptions."""
        if topic == EVENTS_TOPIC:
            return  # local only, like CKMultiPeer
        with self._declaring:
            session = self._session
            with self._lock:
                wanted = bool(self._subs.get(topic)) and not self._stopped
            declared = self._zsubs.get(topic)
            if session is None or wanted == (declared is not None):
                return
            if declared is not None:
                zsub, token = self._zsubs.pop(topic)
                _release(token.undeclare)  # first, so publishers stop counting us
                _release(zsub.undeclare)
                return
            callback = functools.partial(self._on_sample, topic)
            zsub = session.declare_subscriber(key_expr(topic), callback, allowed_origin=zenoh.Locality.REMOTE)
            # Declared after the subscriber, and declarations travel in order: whoever sees the
            # token already routes data to us.
            token = session.liveliness().declare_token(f"{SUB_TOKENS}/{self.guid}/{topic_path(topic)}")
            self._zsubs[topic] = (zsub, token)

    def _unsubscribe(self, subscription: Subscription) -> None:
        with self._lock:
            subs = self._subs.get(subscription.qos.name, [])
            if subscription in subs:
                subs.remove(subscription)
        self._sync_topic(subscription.qos.name)

    def _zenoh_publisher(self, session: zenoh.Session, qos: TopicQoS) -> zenoh.Publisher:
        publisher = self._zpubs.get((qos.name, qos.reliability))
        if publisher is not None:
            return publisher
        with self._declaring:
            publisher = self._zpubs.get((qos.name, qos.reliability))
            if publisher is None:
                reliable = qos.reliability == "reliable"
                publisher = session.declare_publisher(
                    key_expr(qos.name),
                    congestion_control=zenoh.CongestionControl.BLOCK if reliable else zenoh.CongestionControl.DROP,
                    reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
                    allowed_destination=zenoh.Locality.REMOTE,  # local subscribers get the object itself
                )
                self._zpubs[(qos.name, qos.reliability)] = publisher
            return publisher

    # ------------------------------------------------------------------ publishing and receiving

    def _publish(self, qos: TopicQoS, value: Any, stamp: float) -> int:
        with self._lock:
            seq = self._seq[qos.name] = self._seq.get(qos.name, 0) + 1
            local = list(self._subs.get(qos.name, ()))
            session = self._session
        if local:
            deliver(local, Sample(qos.name, value, stamp, self.guid, seq, time.time()), self._emit)
        if session is None or qos.name == EVENTS_TOPIC:
            return 0
        tail = outgoing(self.codec, qos.name, qos.type, value)  # [value] or [cdr, 'cdr', type]
        payload = msgpack.packb([seq, float(stamp), *tail], use_bin_type=True)
        try:
            self._zenoh_publisher(session, qos).put(payload, attachment=self._attachment)
        except zenoh.ZError:
            if self._stopped:
                return 0  # stop() raced with this publish
            raise
        with self._lock:
            return len(self._remote_subs.get(key_expr(qos.name), ()))

    def _on_sample(self, topic: str, zsample: zenoh.Sample) -> None:
        if self._stopped:
            return
        attachment = zsample.attachment
        try:
            (source,) = SOURCE.unpack(attachment.to_bytes() if attachment is not None else b"")
            body = unpack_body(zsample.payload.to_bytes(), self.network.max_frame)
        except (struct.error, FrameError):
            body = []
        if len(body) not in (3, 5) or type(body[0]) is not int or type(body[1]) not in (int, float):
            self.dropped_malformed += 1
            LOG.warning("ignoring a malformed sample on %s", zsample.key_expr)
            return
        if source == self.guid:
            return  # our own sample: local subscribers already had it
        seq, stamp = body[:2]
        with self._lock:
            local = list(self._subs.get(topic, ()))
        if not local:
            return
        try:
            value = incoming(self.codec, body[2:])
        except WireError as error:
            undecodable(topic, error)
            return
        sample = Sample(topic, value, float(stamp), source, seq, time.time())
        if deliver(local, sample, self._emit):
            self.dropped_stale += 1

    # ------------------------------------------------------------------ discovery and events

    def _on_peer_token(self, zsample: zenoh.Sample) -> None:
        guid = guid_after(str(zsample.key_expr), PEER_TOKENS)
        if guid is None or guid == self.guid or self._stopped:
            return
        alive = zsample.kind == zenoh.SampleKind.PUT
        with self._changed:
            if (guid in self._peers) == alive:
                return  # a repeated report (history and live declaration can overlap)
            if alive:
                self._peers.add(guid)
            else:
                self._peers.discard(guid)
                for guids in self._remote_subs.values():
                    guids.discard(guid)
            self._changed.notify_all()
        if alive:
            self._emit(NetworkEvent("found", guid, None, "liveliness token declared"))
        else:
            self._emit(NetworkEvent("lost", guid, None, "liveliness token gone (stopped or lease expired)"))

    def _on_sub_token(self, zsample: zenoh.Sample) -> None:
        key = str(zsample.key_expr)
        guid = guid_after(key, SUB_TOKENS)
        if guid is None or guid == self.guid or self._stopped:
            return
        topic_key = f"{PREFIX}/{key.removeprefix(SUB_TOKENS + '/').partition('/')[2]}"
        with self._changed:
            guids = self._remote_subs.setdefault(topic_key, set())
            if zsample.kind == zenoh.SampleKind.PUT:
                guids.add(guid)
            else:
                guids.discard(guid)
            self._changed.notify_all()


def _release(undeclare: Callable[[], Any]) -> None:
    """Undeclare a Zenoh entity or close a session; a failure only matters to the logs."""
    try:
        undeclare()
    except zenoh.ZError as exc:
        LOG.debug("releasing a Zenoh entity failed: %s", exc)


def _stop_forgotten() -> None:
    for transport in list(_OPEN):
        transport.stop()


# zenoh-python runs Python callbacks on non-daemon threads that live until their subscriber is
# undeclared, and the interpreter joins those threads *before* running atexit handlers; so the
# safety net must run earlier, where concurrent.futures hooks its own shutdown.
getattr(threading, "_register_atexit", atexit.register)(_stop_forgotten)
