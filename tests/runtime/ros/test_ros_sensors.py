"""Kernel sensors and Smart Resource services publishing ROS 2 types themselves (issue L, D193, D194).

A node of simulated devices (a lidar, a camera, a joint bus: pybullet) whose Sensors' topics are
``sensor_msgs/msg/LaserScan``, ``Image``, ``JointState`` and ``std_msgs/msg/Float64MultiArray`` runs
on one transport with the configuration's CDR codec; a second transport of the same private loopback
network subscribes. What travels is caught below the receiving transport and decoded with
``rosbags``' own Jazzy store; the local and the remote subscriber get equal values. A topic type
that cannot carry a whole read is refused by ``verify`` and by the kernel with one message at one
place. A service's results on an Output of a ROS 2 type travel as CDR and reach a ServiceClient.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

import ckmconf
from ckmconf.errors import ConfigError
from ckmconf.model import System
from ckmconf.model.resources import Plugin
from plugins.hardware.simulation import PlantScope, plant_scope
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, Transport
from runtime.network.api import TopicQoS
from runtime.registry import Registry
from runtime.resources import codec
from runtime.resources.client import ServiceClient, ServiceDirectory
from runtime.resources.resource import SmartResourceRuntime
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.ros.types import CDR_LE_HEADER
from runtime.ros.wire import CDR, install
from runtime.verification.verify import verify
from tests.runtime.kernel.test_vector_sensors import CHANNELS, ROOM, TYPES
from tests.runtime.network.conftest import TRANSPORTS, private_network, transports  # noqa: F401 (fixture)
from tests.runtime.ros.test_wire import Wire, _spy

TIMEOUT = 30.0
ROS_TOPICS = """
    <Topic name="/scan" type="sensor_msgs/msg/LaserScan"/>
    <Topic name="/image" type="sensor_msgs/msg/Image"/>
    <Topic name="/joint_states" type="sensor_msgs/msg/JointState"/>
    <Topic name="/joint_vector" type="std_msgs/msg/Float64MultiArray"/>
"""
ROS_SENSORS = """
    <Sensor name="lidar" channel="laser" topic="/scan" period="0.1" extrapolation="none"/>
    <Sensor name="camera" channel="colour" topic="/image" period="0.1" extrapolation="none"/>
    <Sensor name="arm" channel="joints" topic="/joint_states" period="0.1" extrapolation="none"/>
    <Sensor name="arm_vector" channel="joints" topic="/joint_vector" period="0.1" extrapolation="none"/>
"""


def _system(tmp_path: Path, topics: str, sensors: str) -> System:
    path = tmp_path / "ros_sensors.xml"
    path.write_text(
        f'<System xmlns="urn:ckm:1" version="1.0" name="ros-sensors">{TYPES}{topics}<Node name="robot" '
        f'kind="light">{CHANNELS}{sensors}</Node>{ROOM}</System>'
    )
    return ckmconf.load(path)


def _same(a: Any, b: Any) -> bool:
    """Deep equality of decoded payloads (arrays by dtype and values)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    return bool(a == b)


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kind", TRANSPORTS)
def test_kernel_sensors_publish_ros_types_as_cdr(
    kind: str, tmp_path: Path, transports: Callable[..., Transport]  # noqa: F811
) -> None:
    made = _system(tmp_path, ROS_TOPICS, ROS_SENSORS)
    assert verify(made) == []
    network = private_network(kind)
    node_side, remote = transports(network, "node"), transports(network, "remote")
    assert install(node_side, made) is not None and install(remote, made) is not None
    names = ("/scan", "/image", "/joint_states", "/joint_vector")
    local: dict[str, dict[int, Any]] = {n: {} for n in names}
    far: dict[str, dict[int, Any]] = {n: {} for n in names}

    def keep(into: dict[str, dict[int, Any]], name: str) -> Callable[[Sample], None]:
        return lambda sample: into[name].__setitem__(sample.seq, sample.value)

    runtime = NodeRuntime(made.nodes[0], made, node_side)
    for name in names:
        node_side.subscribe(runtime.topic(name), keep(local, name))
        remote.subscribe(TopicQoS(name), keep(far, name))
    wire = Wire()
    stop_spying = _spy(remote, wire)
    with plant_scope(PlantScope(time.monotonic, name=f"ros-sensors-{kind}")):
        runtime.setup()
    runtime.start()
    try:
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline and not all(set(local[n]) & set(far[n]) and wire.of(n) for n in names):
            time.sleep(0.05)
    finally:
        runtime.stop()
        stop_spying()
    for name in names:  # one sample, seen by a subscriber in the node's process and by one across the network
        seq = max(set(local[name]) & set(far[name]))
        mine, theirs = codec.decode(local[name][seq]), codec.decode(far[name][seq])
        if name == "/image":  # as from ros-camera: the header travels in the CDR, an Image arrives as pixels
            mine = mine["data"]
        assert _same(mine, theirs), name

    store = get_typestore(Stores.ROS2_JAZZY)  # rosbags' own, not CKM's store
    messages: dict[str, Any] = {}
    for name, (data, tag, type_name) in ((n, wire.of(n)[-1]) for n in names):
        assert tag == CDR and data[:4] == CDR_LE_HEADER, name
        messages[name] = store.deserialize_cdr(data, type_name)
    scan = messages["/scan"]
    assert scan.header.frame_id == "laser_link" and abs(scan.header.stamp.sec - time.time()) < 120
    assert scan.angle_min == pytest.approx(-1.5708, abs=1e-4) and scan.angle_max == pytest.approx(1.5708, abs=1e-4)
    assert scan.angle_increment == pytest.approx(3.1416 / 90, abs=1e-6)
    assert (scan.range_min, scan.range_max, scan.scan_time) == (0.0, 5.0, pytest.approx(0.1))
    assert len(scan.ranges) == 91 and 2.5 < scan.ranges[45] < 3.05  # the wall x = 6 seen from x = 3
    image = messages["/image"]
    assert (image.width, image.height, image.encoding, image.step) == (16, 12, "rgb8", 48)
    assert len(image.data) == 16 * 12 * 3 and image.header.frame_id == "wrist_camera_optical_frame"
    joints = messages["/joint_states"]
    assert joints.name == ["turret_joint", "shoulder_joint", "elbow_joint"] and len(joints.position) == 3
    vector = messages["/joint_vector"]
    assert np.allclose(vector.data, joints.position, atol=0.05)


@pytest.mark.parametrize(
    ("topic", "expected"),
    [
        ('<Topic name="/speed" type="std_msgs/msg/Float64"/>', "which has no array of numbers to hold them"),
        ('<Topic name="/speed" type="sensor_msgs/msg/Image"/>', "but an Image needs the channel's Params"),
    ],
)
def test_verify_and_the_kernel_refuse_alike(
    tmp_path: Path, topic: str, expected: str, transports: Callable[..., Transport]  # noqa: F811
) -> None:
    made = _system(tmp_path, topic, '<Sensor name="lidar" channel="laser" topic="/speed" period="0.1"/>')
    (found,) = verify(made)
    assert expected in found.message and found.xpath.endswith("/Sensor[@name='lidar']/@topic")
    assert found.message.startswith("sensor 'lidar' writes whole reads of channel 'laser' (size 91) onto topic")
    runtime = NodeRuntime(made.nodes[0], made, transports(private_network(), "refused"))
    with pytest.raises(ConfigError) as refused, plant_scope(PlantScope(time.monotonic, name="refused")):
        runtime.setup()
    assert str(refused.value) == str(found)  # same FILE:LINE:COL, same words


def test_a_scalar_sensor_on_a_ros_type_without_a_number_is_refused_alike(
    tmp_path: Path, transports: Callable[..., Transport]  # noqa: F811
) -> None:
    channel = '<HWChannel name="wheel" direction="in"/>'
    path = tmp_path / "scalar.xml"
    path.write_text(
        '<System xmlns="urn:ckm:1" version="1.0" name="scalar"><Topic name="/scan" type="sensor_msgs/msg/LaserScan"/>'
        f'<Node name="robot" kind="light">{channel}'
        '<Sensor name="speed" channel="wheel" topic="/scan" period="0.1"/></Node></System>'
    )
    made = ckmconf.load(path)
    (found,) = verify(made)
    assert found.message == (
        "sensor 'speed' writes single numbers (channel 'wheel', size 1) onto topic '/scan' of ROS type "
        "sensor_msgs/msg/LaserScan: sensor_msgs/msg/LaserScan has no 'data' field to hold them (a ROS-typed "
        "topic carries a dict of its fields)"
    )
    runtime = NodeRuntime(made.nodes[0], made, transports(private_network(), "scalar"))
    with pytest.raises(ConfigError) as refused:
        runtime.setup()
    assert str(refused.value) == str(found)


SERVICE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="ros-service">
  <Topic name="/ranges" type="sensor_msgs/msg/LaserScan"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="Scanner" node="pc">
    <Plugin name="sweep" kind="test-sweep"/>
    <Profile name="SWEEP"><Use plugin="sweep"/></Profile>
    <Service name="Scan" rate="0.05">
      <Output name="scan" topic="/ranges"/>
      <QualityMeasure name="rate" kind="qos" domain="performance" source="rate"/>
      <Scenario name="SWEEP" profile="SWEEP"><Policy measure="rate" upper="10"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


class Sweep(ProcessingPlugin):
    """A scan of four ranges growing with each frame, as ``ros-laser-scan`` returns one."""

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.frames = 0

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        self.frames += 1
        ranges = np.full(4, float(data), dtype=np.float32)
        return {"header": {"stamp": 1700000000.5, "frame_id": "laser"}, "angle_max": 1.0, "ranges": ranges}


@pytest.mark.timeout(120)
@pytest.mark.parametrize("kind", TRANSPORTS)
def test_service_results_travel_as_cdr_of_their_output_type(
    kind: str, tmp_path: Path, transports: Callable[..., Transport]  # noqa: F811
) -> None:
    path = tmp_path / "service.xml"
    path.write_text(SERVICE, encoding="utf-8")
    made = ckmconf.load(path)
    network = private_network(kind)
    server, remote = transports(network, "resource"), transports(network, "client")
    assert install(server, made) is not None and install(remote, made) is not None
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "test-sweep", Sweep)
    counter = iter(range(1, 1_000_000))
    resource = made.resource("Scanner")
    assert resource is not None
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"sweep": lambda: next(counter)}, announce_period=0.2
    )
    wire = Wire()
    stop_spying = _spy(remote, wire)
    with runtime:
        entry = ServiceDirectory(remote).wait_for("Scanner", "Scan", timeout=TIMEOUT)
        with ServiceClient(remote, entry, "agent1") as client:
            received: list[Any] = []
            client.data("scan", received.append)
            client.connect(timeout=TIMEOUT)
            deadline = time.monotonic() + TIMEOUT
            while time.monotonic() < deadline and (len(received) < 2 or not wire.of("/ranges/agent1")):
                time.sleep(0.05)
    stop_spying()
    assert len(received) >= 2, "the client heard no result"
    latest = received[-1]  # decoded by the client as any result: the codec's plain form
    assert latest["header"] == {"stamp": 1700000000.5, "frame_id": "laser"} and latest["angle_max"] == 1.0
    assert latest["ranges"].dtype == np.float32 and latest["ranges"].shape == (4,) and latest["ranges"][0] >= 1
    data, tag, type_name = wire.of("/ranges/agent1")[-1]
    assert (tag, type_name, data[:4]) == (CDR, "sensor_msgs/msg/LaserScan", CDR_LE_HEADER)
    message: Any = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(data, type_name)
    assert message.header.frame_id == "laser" and message.header.stamp.nanosec == 500_000_000
    assert len(message.ranges) == 4
