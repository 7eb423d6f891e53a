"""The rmw_zenoh names on a real Zenoh session (issue L point 3): two loopback sessions, one
announcing a node and a publisher and putting a std_msgs/String sample the rmw_zenoh way, the
other discovering them through ``@ros2_lv`` liveliness and receiving the sample on the data key
expression. No ROS is involved; this checks that the key expressions are valid for Zenoh (the
hermetic ``@ros2_lv`` chunk, ``%`` and ``::``) and that payload and attachment arrive intact."""

from __future__ import annotations

import json
import queue
import socket
import time
from collections.abc import Iterator

import pytest
import zenoh

from runtime.ros.convert import decode_payload, encode_payload
from runtime.ros.rmw_zenoh import (
    Attachment,
    Endpoint,
    EntityKind,
    RmwQos,
    decode_attachment,
    encode_attachment,
    entity_gid,
    liveliness_token,
    parse_liveliness_token,
    topic_keyexpr,
)
from runtime.ros.types import RosTypes

TIMEOUT_S = 10.0


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def _config(listen: list[str], connect: list[str]) -> zenoh.Config:
    config = zenoh.Config()
    for key, value in {
        "mode": "peer",
        "scouting/multicast/enabled": False,
        "listen/endpoints": listen,
        "connect/endpoints": connect,
    }.items():
        config.insert_json5(key, json.dumps(value))
    return config


@pytest.fixture
def sessions() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    ckm = zenoh.open(_config([endpoint], []))
    try:
        ros_side = zenoh.open(_config(["tcp/127.0.0.1:0"], [endpoint]))
        try:
            yield ckm, ros_side
        finally:
            ros_side.close()  # type: ignore[no-untyped-call]
    finally:
        ckm.close()  # type: ignore[no-untyped-call]


def test_a_ckm_publisher_is_seen_and_heard_the_rmw_zenoh_way(sessions: tuple[zenoh.Session, zenoh.Session]) -> None:
    ckm, ros_side = sessions
    ros = RosTypes()
    type_hash = ros.rihs01("std_msgs/msg/String")
    zid = str(ckm.zid())
    node = liveliness_token(0, zid, 0, 0, EntityKind.NODE, "ckm_bridge")
    publisher = liveliness_token(
        0,
        zid,
        0,
        1,
        EntityKind.PUBLISHER,
        "ckm_bridge",
        endpoint=Endpoint("/chatter", "std_msgs/msg/String", type_hash, RmwQos(depth=7)),
    )
    received: queue.Queue[zenoh.Sample] = queue.Queue()
    subscriber = ros_side.declare_subscriber("0/chatter/std_msgs::msg::dds_::String_/*", received.put)
    tokens = [ckm.liveliness().declare_token(node), ckm.liveliness().declare_token(publisher)]
    try:
        deadline = time.monotonic() + TIMEOUT_S
        seen: set[str] = set()
        while time.monotonic() < deadline and seen != {node, publisher}:
            for reply in ros_side.liveliness().get("@ros2_lv/0/**", timeout=1.0):
                if reply.ok is not None:
                    seen.add(str(reply.ok.key_expr))
            time.sleep(0.05)
        assert seen == {node, publisher}
        announced = parse_liveliness_token(publisher)
        assert announced.endpoint is not None and announced.endpoint.type_hash == type_hash

        key = topic_keyexpr(0, "/chatter", "std_msgs/msg/String", type_hash)
        attachment = Attachment(1, time.time_ns(), entity_gid(publisher))
        sample = None
        while sample is None and time.monotonic() < deadline:  # the subscription may take a moment to propagate
            ckm.put(
                key,
                encode_payload(ros, "std_msgs/msg/String", {"data": "hello ROS"}),
                attachment=encode_attachment(attachment),
            )
            try:
                sample = received.get(timeout=0.2)
            except queue.Empty:
                continue
        assert sample is not None, "no sample within the timeout"
        assert str(sample.key_expr) == key
        assert decode_payload(ros, "std_msgs/msg/String", sample.payload.to_bytes()) == {"data": "hello ROS"}
        assert sample.attachment is not None
        assert decode_attachment(sample.attachment.to_bytes()) == attachment
    finally:
        for token in tokens:
            token.undeclare()  # type: ignore[no-untyped-call]
        subscriber.undeclare()  # type: ignore[no-untyped-call]
