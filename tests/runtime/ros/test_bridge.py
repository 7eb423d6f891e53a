"""CKM topics seen and heard by an rmw_zenoh ROS 2 node, and the other way (issue L point 3, D159).

A CKMultiPeer transport on a private network carries the topics of tests/data/ros/ros_typed_loop.xml
(/scan a LaserScan, /reading a custom .msg). The bridge's Zenoh session listens on 127.0.0.1; a
second session, connected to it, plays the ROS 2 node: it reads the graph from the ``@ros2_lv``
liveliness tokens, subscribes and puts on the rmw_zenoh key expressions, and encodes and decodes CDR
with ``rosbags``' own store (not CKM code).
"""

from __future__ import annotations

import queue
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import ckmconf
from runtime.network import Transport
from runtime.network.api import Sample, TopicQoS
from runtime.ros.bridge import RmwZenohBridge
from runtime.ros.rmw_zenoh import (
    Attachment,
    EntityKind,
    RmwQos,
    decode_attachment,
    encode_attachment,
    entity_gid,
    parse_liveliness_token,
)
from runtime.ros.types import RosTypes
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network, transports  # noqa: F401 (fixture)
from tests.runtime.ros.test_rmw_zenoh_live import sessions  # noqa: F401 (fixture: two connected sessions)

TIMEOUT = 20.0
ROS_DATA = REPO / "tests" / "data" / "ros"
SCAN_KEY = "0/scan/sensor_msgs::msg::dds_::LaserScan_/"


def _store() -> Any:
    store = get_typestore(Stores.ROS2_JAZZY)
    for name in ("Quality", "Reading"):
        text = (ROS_DATA / "ckm_test_msgs" / "msg" / f"{name}.msg").read_text()
        store.register(get_types_from_msg(text, f"ckm_test_msgs/msg/{name}"))
    return store


def _graph(session: zenoh.Session, count: int) -> list[str]:
    """The ``@ros2_lv`` tokens alive, once there are ``count`` (bounded wait)."""
    deadline, seen = time.monotonic() + TIMEOUT, []
    while time.monotonic() < deadline:
        seen = [str(r.ok.key_expr) for r in session.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok]
        if len(seen) == count:
            break
        time.sleep(0.05)
    return sorted(seen)


@pytest.mark.timeout(90)
def test_ckm_topics_are_seen_and_heard_by_an_rmw_zenoh_node_and_back(
    sessions: tuple[zenoh.Session, zenoh.Session],  # noqa: F811
    transports: Callable[..., Transport],  # noqa: F811
) -> None:
    bridge_session, ros_node = sessions
    system = ckmconf.load(ROS_DATA / "ros_typed_loop.xml")
    ckm = transports(private_network("multipeer"), "ckm")
    bridge = RmwZenohBridge(system, ckm)
    assert set(bridge.topics) == {"/scan", "/reading"}  # the external topics of a ROS 2 type
    bridge.start(bridge_session)
    try:
        # the ROS graph: the node, and a publisher and a subscription per topic, typed and hashed
        tokens = [parse_liveliness_token(t) for t in _graph(ros_node, 5)]
        ros = RosTypes()
        assert [t.node_name for t in tokens] == ["ckm_bridge"] * 5
        assert {t.kind for t in tokens} == {EntityKind.NODE, EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION}
        endpoints = {(t.kind, t.endpoint.topic, t.endpoint.type_name, t.endpoint.type_hash, t.endpoint.qos)
                     for t in tokens if t.endpoint is not None}  # fmt: skip
        scan_hash = ros.rihs01("sensor_msgs/msg/LaserScan")
        scan_qos = RmwQos(reliability=2, depth=5)  # best-effort, history 5 (the <Topic>)
        assert (EntityKind.PUBLISHER, "/scan", "sensor_msgs/msg/LaserScan", scan_hash, scan_qos) in endpoints
        assert (EntityKind.SUBSCRIPTION, "/scan", "sensor_msgs/msg/LaserScan", scan_hash, scan_qos) in endpoints
        assert {e[1] for e in endpoints} == {"/scan", "/reading"}

        # CKM → ROS: a CKM sample arrives as CDR with the 33-byte attachment of the publisher's GID
        heard: queue.Queue[zenoh.Sample] = queue.Queue()
        listener = ros_node.declare_subscriber(SCAN_KEY + "*", heard.put)
        ranges = np.linspace(0.2, 3.0, 6, dtype=np.float32)
        publisher, got = ckm.publisher(TopicQoS.of(system.topics[0])), None
        deadline = time.monotonic() + TIMEOUT
        while got is None and time.monotonic() < deadline:  # the subscription takes a moment to reach the bridge
            publisher.publish({"header": {"frame_id": "laser"}, "ranges": ranges}, stamp=1700000000.5)
            try:
                got = heard.get(timeout=0.2)
            except queue.Empty:
                continue
        listener.undeclare()  # type: ignore[no-untyped-call]
        assert got is not None, "the ROS node heard nothing"
        assert str(got.key_expr) == SCAN_KEY + scan_hash
        message = _store().deserialize_cdr(got.payload.to_bytes(), "sensor_msgs/msg/LaserScan")
        assert message.header.frame_id == "laser" and np.array_equal(message.ranges, ranges)
        assert got.attachment is not None and len(got.attachment.to_bytes()) == 33
        attachment = decode_attachment(got.attachment.to_bytes())
        publisher_token = next(t for t in _graph(ros_node, 5) if "/MP/" in t and "%scan/" in t)
        assert attachment.source_gid == entity_gid(publisher_token)
        assert attachment.source_timestamp == 1_700_000_000_500_000_000 and attachment.sequence_number >= 1

        # ROS → CKM: a ROS node's sample is published on the CKM transport, stamped with its source time
        store = _store()
        reading = store.types["ckm_test_msgs/msg/Reading"](
            label="cup",
            value=2.5,
            where=store.types["geometry_msgs/msg/Point"](x=1.0, y=0.0, z=0.5),
            quality=store.types["ckm_test_msgs/msg/Quality"](reliability=0.75, raw=np.array([7], dtype=np.uint8)),
        )
        data = bytes(store.serialize_cdr(reading, "ckm_test_msgs/msg/Reading"))
        received: queue.Queue[Sample] = queue.Queue()
        ckm.subscribe(TopicQoS("/reading", "ckm_test_msgs/msg/Reading"), received.put)
        echoes: queue.Queue[zenoh.Sample] = queue.Queue()
        echo = ros_node.declare_subscriber(
            "0/reading/**", echoes.put, allowed_origin=zenoh.Locality.REMOTE
        )  # what the bridge would send back
        key = f"0/reading/ckm_test_msgs::msg::dds_::Reading_/{ros.rihs01('geometry_msgs/msg/Point')}"  # any hash
        gid = bytes(range(16))
        sample, deadline = None, time.monotonic() + TIMEOUT
        while sample is None and time.monotonic() < deadline:
            ros_node.put(key, data, attachment=encode_attachment(Attachment(1, 1_700_000_001_000_000_000, gid)))
            try:
                sample = received.get(timeout=0.2)
            except queue.Empty:
                continue
        assert sample is not None, "CKM heard nothing from the ROS node"
        assert sample.stamp == 1700000001.0
        assert sample.value["label"] == "cup" and sample.value["where"] == {"x": 1.0, "y": 0.0, "z": 0.5}
        assert sample.value["quality"]["raw"] == b"\x07"
        time.sleep(0.5)  # what the bridge published from ROS is not sent back to ROS
        assert echoes.empty()
        echo.undeclare()  # type: ignore[no-untyped-call]
        stats = bridge.statistics()
        assert stats["/scan"]["toRos"] >= 1 and stats["/reading"]["toCkm"] >= 1 and stats["/reading"]["toRos"] == 0
        assert all(s["dropped"] == 0 for s in stats.values())
    finally:
        bridge.stop()
    assert _graph(ros_node, 0) == []  # every token withdrawn
