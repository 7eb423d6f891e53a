"""CKM topics seen by ROS 2 nodes running rmw_zenoh, and theirs by CKM (issue L point 3, decision D159).

:class:`RmwZenohBridge` joins a CKM transport (CKMultiPeer or Zenoh) to a Zenoh session on the ROS
side (a peer or client of ``rmw_zenohd``), following rmw_zenoh's conventions
(:mod:`runtime.ros.rmw_zenoh`, the version docs/ros.md names):

- it declares a node liveliness token (``ckm_bridge`` by default) and, per bridged ``<Topic>`` of a
  ROS 2 type, a publisher and a subscription token with the topic's type, RIHS01 hash and QoS, so
  ``ros2 topic list -t`` on the ROS side shows CKM's topics;
- every CKM sample of a bridged topic is put on the topic's key expression
  ``<domain>/<name>/<dds type>/<hash>`` as CDR with the 33-byte attachment (sequence number, the
  sample's publication time, the publisher's GID);
- every sample a ROS node puts on a bridged topic (any type hash) is decoded and published on the CKM
  transport, stamped with its attachment's source time.

Loops are cut at both ends: the Zenoh publisher reaches remote sessions only and the subscriber
hears remote ones only, and a CKM sample that is the very object the bridge just published is not
sent back. One bridge per system (two would pass each other's samples round). Values are converted
as on the wire (:class:`runtime.ros.wire.CdrWire`); a value that does not fit its type is dropped and
counted (the first reason logged per topic).
"""

from __future__ import annotations

import collections
import contextlib
import logging
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import zenoh

from ckmconf.model import System, Topic
from ckmconf.rostypes import is_ros_type

from ..network.api import Publisher, Sample, Subscription, TopicQoS, Transport
from .config import ConfigRosTypes, all_topics
from .rmw_zenoh import (
    Attachment,
    AttachmentFormat,
    Endpoint,
    EntityKind,
    RmwQos,
    decode_attachment,
    encode_attachment,
    entity_gid,
    liveliness_token,
    topic_keyexpr,
)
from .types import dds_type_name
from .wire import CdrWire

LOG = logging.getLogger("ckm.ros.bridge")
RECENT = 16  # objects the bridge published per topic, remembered to not send them back


@dataclass
class BridgedTopic:
    """One bridged topic: its configuration, rmw names and counts."""

    topic: Topic
    type_hash: str
    keyexpr: str
    publisher_token: str = ""
    subscription_token: str = ""
    to_ros: int = 0
    to_ckm: int = 0
    dropped: int = 0
    first_drop: str | None = None
    recent: collections.deque[Any] = field(default_factory=lambda: collections.deque(maxlen=RECENT))


class RmwZenohBridge:
    """Bridges the ROS-typed ``<Topic>`` s of a system between a CKM transport and rmw_zenoh.

    Args:
        system: the loaded system.
        transport: the CKM transport (started or not; subscriptions are made at :meth:`start`).
        topics: the topic names to bridge (default: every external topic of a ROS 2 type).
        domain_id: the ROS domain (``ROS_DOMAIN_ID``).
        node_name: the ROS node name the bridge announces.
        attachment: ``compact`` (33 bytes, current rmw_zenoh) or ``labelled`` (releases to 0.2.3).
    """

    def __init__(
        self,
        system: System,
        transport: Transport,
        *,
        topics: Iterable[str] | None = None,
        domain_id: int = 0,
        node_name: str = "ckm_bridge",
        attachment: AttachmentFormat = "compact",
    ) -> None:
        self.transport = transport
        self.domain_id = domain_id
        self.node_name = node_name
        self.attachment: AttachmentFormat = attachment
        self.codec = CdrWire(ConfigRosTypes(system))
        candidates: dict[str, Topic] = {}
        for topic, _ in all_topics(system):
            if topic.scope == "external" and is_ros_type(topic.type) and self.codec.encodes(topic.type):
                candidates.setdefault(topic.name, topic)
        wanted = list(candidates) if topics is None else list(topics)
        unknown = [name for name in wanted if name not in candidates]
        if unknown:
            raise ValueError(f"no external topic of a ROS 2 type named {', '.join(unknown)} to bridge")
        ros = self.codec.types.ros
        self.topics: dict[str, BridgedTopic] = {}
        for name in wanted:
            topic = candidates[name]
            type_hash = ros.rihs01(topic.type)
            self.topics[name] = BridgedTopic(topic, type_hash, topic_keyexpr(domain_id, name, topic.type, type_hash))
        self._entities: list[Any] = []  # tokens, Zenoh publishers and subscribers: undeclared at stop
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._ckm_publishers: dict[str, Publisher] = {}
        self._subscriptions: list[Subscription] = []
        self._seq: dict[str, int] = {}
        self._lock = threading.Lock()

    def start(self, session: zenoh.Session) -> None:
        """Declare the node's and endpoints' tokens on ``session`` and start passing samples."""
        zid = str(session.zid())
        liveliness = session.liveliness()
        self._entities.append(liveliness.declare_token(self._token(zid, 0, EntityKind.NODE, None)))
        entity = 1
        for name, bridged in self.topics.items():
            topic = bridged.topic
            endpoint = Endpoint(
                name, topic.type, bridged.type_hash,
                RmwQos.of_topic(topic.reliability, topic.history, topic.deadline, topic.lifespan),
            )  # fmt: skip
            bridged.publisher_token = self._token(zid, entity, EntityKind.PUBLISHER, endpoint)
            bridged.subscription_token = self._token(zid, entity + 1, EntityKind.SUBSCRIPTION, endpoint)
            entity += 2
            self._publishers[name] = session.declare_publisher(
                bridged.keyexpr,
                congestion_control=zenoh.CongestionControl.DROP,  # never block the transport's thread
                allowed_destination=zenoh.Locality.REMOTE,
            )
            self._entities.append(self._publishers[name])
            wildcard = f"{self.domain_id}/{name.strip('/')}/{dds_type_name(topic.type)}/*"  # any hash
            self._entities.append(
                session.declare_subscriber(wildcard, self._from_ros(bridged), allowed_origin=zenoh.Locality.REMOTE)
            )
            qos = TopicQoS.of(topic)
            self._ckm_publishers[name] = self.transport.publisher(qos)
            self._subscriptions.append(self.transport.subscribe(qos, self._from_ckm(bridged)))
            self._entities += [liveliness.declare_token(bridged.publisher_token)]
            self._entities += [liveliness.declare_token(bridged.subscription_token)]
        LOG.info("bridging %d topic(s) to rmw_zenoh (domain %d) as %s", len(self.topics), self.domain_id, zid)

    def stop(self) -> None:
        """Stop passing samples and withdraw every token (the session stays the caller's)."""
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()
        for entity in reversed(self._entities):
            with contextlib.suppress(zenoh.ZError):  # the session closed first: its entities went with it
                entity.undeclare()
        self._entities.clear()
        self._publishers.clear()

    def statistics(self) -> dict[str, dict[str, Any]]:
        """Per bridged topic: samples passed each way, dropped, and the first drop's reason."""
        with self._lock:
            return {
                name: {"toRos": b.to_ros, "toCkm": b.to_ckm, "dropped": b.dropped, "firstDrop": b.first_drop}
                for name, b in self.topics.items()
            }

    # ------------------------------------------------------------------ internals

    def _token(self, zid: str, entity: int, kind: EntityKind, endpoint: Endpoint | None) -> str:
        return liveliness_token(self.domain_id, zid, 0, entity, kind, self.node_name, endpoint=endpoint)

    def _from_ckm(self, bridged: BridgedTopic) -> Any:
        name = bridged.topic.name

        def forward(sample: Sample) -> None:
            with self._lock:
                if any(sample.value is mine for mine in bridged.recent):
                    return  # what the bridge itself published from the ROS side
            try:
                data = self.codec.encode(bridged.topic.type, sample.value)
            except (ValueError, TypeError) as error:
                self._drop(bridged, f"to ROS: {error}")
                return
            with self._lock:
                seq = self._seq[name] = self._seq.get(name, 0) + 1
            stamp = round((sample.stamp - sample.offset) * 1e9)
            attachment = Attachment(seq, stamp, entity_gid(bridged.publisher_token))
            publisher = self._publishers.get(name)
            if publisher is None:
                return  # stopping
            try:
                publisher.put(data, attachment=encode_attachment(attachment, self.attachment))
            except zenoh.ZError as error:
                self._drop(bridged, f"to ROS: {error}")
                return
            with self._lock:
                bridged.to_ros += 1

        return forward

    def _from_ros(self, bridged: BridgedTopic) -> Any:
        name = bridged.topic.name

        def receive(zsample: zenoh.Sample) -> None:
            try:
                value = self.codec.decode(bridged.topic.type, zsample.payload.to_bytes())
                raw = zsample.attachment
                stamp = decode_attachment(raw.to_bytes()).source_timestamp * 1e-9 if raw is not None else time.time()
            except ValueError as error:
                self._drop(bridged, f"from ROS ({zsample.key_expr}): {error}")
                return
            publisher = self._ckm_publishers.get(name)
            if publisher is None:
                return
            with self._lock:  # the value is in the codec's plain form, CDR on the CKM side or not (D194)
                bridged.recent.append(value)  # the very object: not sent back when it comes round
                bridged.to_ckm += 1
            publisher.publish(value, stamp=stamp)

        return receive

    def _drop(self, bridged: BridgedTopic, reason: str) -> None:
        with self._lock:
            bridged.dropped += 1
            first = bridged.first_drop is None
            if first:
                bridged.first_drop = reason
        if first:
            LOG.warning("bridge %s: a sample is dropped: %s", bridged.topic.name, reason)
