"""Topics of a ROS 2 type travel as CDR on CKMultiPeer and on Zenoh (issue L point 1, D157).

Two transports of one private network on 127.0.0.1, each with the configuration's CDR codec
(tests/data/ros/ros_typed_loop.xml: LaserScan, Float64 and a custom .msg). What goes on the wire is
caught below the transport (CKMultiPeer's TOPICDATA frames, a raw Zenoh subscriber on the same
session) and decoded with ``rosbags``' own Jazzy type store, not CKM code; the receiving transport
hands its subscribers the CKM payload in the codec's plain form (D194). Topics of CKM types stay msgpack.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import msgpack
import numpy as np
import pytest
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import ckmconf
from runtime.network import Transport
from runtime.network.api import TopicQoS
from runtime.network.frames import Frame, FrameType
from runtime.network.wire import WireError, incoming, outgoing
from runtime.resources import codec as plain_codec
from runtime.ros.config import ConfigRosTypes
from runtime.ros.types import CDR_LE_HEADER
from runtime.ros.wire import CDR, CdrWire, install
from tests.conftest import REPO
from tests.runtime.network.conftest import TRANSPORTS, private_network, transports  # noqa: F401 (fixture)

TIMEOUT = 30.0
ROS_DATA = REPO / "tests" / "data" / "ros"
SCAN = TopicQoS("/scan", "sensor_msgs/msg/LaserScan")
SPEED = TopicQoS("/speed", "std_msgs/msg/Float64")
READING = TopicQoS("/reading", "ckm_test_msgs/msg/Reading")
WHEELS = TopicQoS("/wheels", "wheel-state")


def _independent_store() -> Any:
    """rosbags' Jazzy store with the tests' custom messages, for decoding what was on the wire."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for name in ("Quality", "Reading"):
        text = (ROS_DATA / "ckm_test_msgs" / "msg" / f"{name}.msg").read_text()
        store.register(get_types_from_msg(text, f"ckm_test_msgs/msg/{name}"))
    return store


class Wire:
    """The data tails caught on the wire, per topic: ``[value]`` or ``[cdr, 'cdr', type]``."""

    def __init__(self) -> None:
        self.tails: dict[str, list[list[Any]]] = {}
        self._lock = threading.Lock()

    def add(self, topic: str, tail: list[Any]) -> None:
        with self._lock:
            self.tails.setdefault(topic, []).append(tail)

    def of(self, topic: str) -> list[list[Any]]:
        with self._lock:
            return list(self.tails.get(topic, ()))


def _spy(transport: Transport, wire: Wire) -> Callable[[], None]:
    """Catch the data tails arriving at ``transport`` below it; returns how to stop catching."""
    if transport.__class__.__name__ == "MultiPeerTransport":

        def frame(_guid: int, frame: Frame) -> None:
            wire.add(frame.body[0], list(frame.body[3:]))

        transport.peer.add_listener(FrameType.TOPICDATA, frame)  # type: ignore[attr-defined]
        return lambda: None
    session: zenoh.Session = transport._session  # type: ignore[attr-defined]

    def sample(zsample: zenoh.Sample) -> None:
        body = msgpack.unpackb(zsample.payload.to_bytes(), raw=False)
        wire.add("/" + str(zsample.key_expr).removeprefix("ckm/"), body[2:])

    subscriber = session.declare_subscriber("ckm/**", sample)
    return subscriber.undeclare


@pytest.mark.timeout(90)
@pytest.mark.parametrize("kind", TRANSPORTS)
def test_ros_typed_topics_travel_as_cdr(kind: str, transports: Callable[..., Transport]) -> None:  # noqa: F811
    system = ckmconf.load(ROS_DATA / "ros_typed_loop.xml")
    network = private_network(kind)
    a, b = transports(network, "a"), transports(network, "b")
    assert install(a, system) is not None and install(b, system) is not None
    wire = Wire()
    stop_spying = _spy(b, wire)
    subs = {qos.name: b.subscribe(qos) for qos in (SCAN, SPEED, READING, WHEELS)}
    for qos in (SCAN, SPEED, READING, WHEELS):
        assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    ranges = np.linspace(0.5, 4.0, 8, dtype=np.float32)
    scan = {"header": {"stamp": 1700000000.25, "frame_id": "laser"}, "angle_max": 1.5, "ranges": ranges}
    reading = {"label": "mug", "value": 0.75, "where": {"x": 1.0, "y": 2.0}, "quality": {"raw": b"\x01\x02"}}
    wheels = {"stamp": 12.5, "wheelSpeeds": [1.0, 2.0], "history": [], "raw": b"", "pose": {"x": 0.5, "y": 0.0}}
    a.publisher(SCAN).publish(scan)
    a.publisher(SPEED).publish(1.25)  # a number stands for std_msgs/msg/Float64's data
    a.publisher(READING).publish(reading)
    a.publisher(WHEELS).publish(wheels)
    assert all(sub.wait(1, TIMEOUT) for sub in subs.values())
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline and any(not wire.of(q.name) for q in (SCAN, SPEED, READING, WHEELS)):
        time.sleep(0.01)
    stop_spying()

    store = _independent_store()
    for qos in (SCAN, SPEED, READING):
        ((data, tag, type_name),) = wire.of(qos.name)
        assert tag == CDR and type_name == qos.type and data[:4] == CDR_LE_HEADER
        message = store.deserialize_cdr(data, qos.type)
        assert message.__msgtype__ == qos.type
        if qos is SCAN:
            assert message.header.frame_id == "laser" and message.header.stamp.nanosec == 250_000_000
            assert message.angle_max == pytest.approx(1.5) and np.array_equal(message.ranges, ranges)
        elif qos is SPEED:
            assert message.data == 1.25
        else:
            assert (message.label, message.value, message.where.y) == ("mug", 0.75, 2.0)
            assert bytes(message.quality.raw) == b"\x01\x02"
    assert wire.of(WHEELS.name) == [[wheels]]  # a MessageType topic: msgpack as ever

    received = {name: sub.latest() for name, sub in subs.items()}
    assert all(sample is not None for sample in received.values())
    got_scan = received["/scan"].value  # type: ignore[union-attr]
    assert set(got_scan["ranges"]) == {"~nd"}  # the codec's plain form, as a service publishes locally (D194)
    got_scan = plain_codec.decode(got_scan)
    assert got_scan["header"] == {"stamp": 1700000000.25, "frame_id": "laser"}
    assert np.array_equal(got_scan["ranges"], ranges) and got_scan["angle_max"] == pytest.approx(1.5)
    assert received["/speed"].value == 1.25  # type: ignore[union-attr]  # the bare value again
    got_reading = received["/reading"].value  # type: ignore[union-attr]
    assert got_reading["label"] == "mug" and got_reading["quality"]["raw"] == b"\x01\x02"
    assert received["/wheels"].value == wheels  # type: ignore[union-attr]


def test_wire_tails() -> None:
    codec = CdrWire(ConfigRosTypes(ckmconf.load(ROS_DATA / "ros_typed_loop.xml")))
    assert outgoing(None, "/speed", SPEED.type, 2.0) == [2.0]
    assert outgoing(codec, "/wheels", WHEELS.type, {"x": 1}) == [{"x": 1}]  # not a ROS type: as it is
    tail = outgoing(codec, "/speed", SPEED.type, 2.0)
    assert tail[1:] == [CDR, SPEED.type] and incoming(codec, tail) == 2.0
    assert outgoing(codec, "/scan", SCAN.type, {"bogus": 1}) == [{"bogus": 1}]  # does not fit: travels uncoded
    with pytest.raises(WireError, match="no such codec here"):
        incoming(None, tail)
    with pytest.raises(WireError, match="cannot deserialise"):
        incoming(codec, [b"\x00\x01\x00\x00\x01", CDR, SPEED.type])
    with pytest.raises(WireError, match="which cdr does not carry"):
        incoming(codec, [tail[0], CDR, "wheel-state"])
    with pytest.raises(WireError, match="malformed"):
        incoming(codec, [tail[0], CDR])
