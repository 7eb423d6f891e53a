"""Vector sensors (decision D99): a node with simulated lidar, cameras and a joint bus publishes whole
scans, frames and joint vectors, shaped by each topic's type; verify accepts exactly that."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import ckmconf
from ckmconf.model import System
from plugins.hardware.simulation import PlantScope, plant_scope
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, Transport, open_transport
from runtime.resources import codec
from runtime.verification.verify import verify
from tests.runtime.network.conftest import private_network

TYPES = """
  <MessageType name="Scan">
    <Field name="stamp" type="time"/>
    <Field name="range_max" type="float32"/>
    <Field name="ranges" type="float32" count="0"/>
  </MessageType>
  <MessageType name="Image">
    <Field name="stamp" type="time"/>
    <Field name="width" type="uint32"/>
    <Field name="height" type="uint32"/>
    <Field name="encoding" type="string"/>
    <Field name="data" type="bytes"/>
  </MessageType>
  <MessageType name="Pose2D">
    <Field name="x" type="float64"/><Field name="y" type="float64"/><Field name="yaw" type="float64"/>
  </MessageType>
"""
ROOM = """
  <Environment name="room" frame="map"><Map xmin="0" ymin="0" xmax="6" ymax="4" height="1.5"/></Environment>
"""
CHANNELS = """
    <HWChannel name="laser" direction="in" kind="stream" backend="sim" units="m" min="0" max="5" size="91">
      <Param name="body" value="rover"/><Param name="pose" value="3.0 2.0 0"/>
      <Param name="sensor" value="lidar"/><Param name="link" value="laser_link"/><Param name="fov" value="3.1416"/>
    </HWChannel>
    <HWChannel name="colour" direction="in" kind="stream" backend="sim" units="rgb8" size="576">
      <Param name="body" value="station_arm"/><Param name="pose" value="1.0 1.0 0"/>
      <Param name="sensor" value="rgb"/><Param name="link" value="wrist_camera_optical_frame"/>
      <Param name="width" value="16"/><Param name="height" value="12"/><Param name="fov" value="1.5184"/>
    </HWChannel>
    <HWChannel name="depth" direction="in" kind="stream" backend="sim" units="mm" size="192">
      <Param name="body" value="station_arm"/><Param name="sensor" value="depth"/>
      <Param name="link" value="wrist_camera_optical_frame"/>
      <Param name="width" value="16"/><Param name="height" value="12"/><Param name="fov" value="1.5184"/>
    </HWChannel>
    <HWChannel name="joints" direction="in" kind="bus" backend="sim" units="rad" size="3">
      <Param name="body" value="station_arm"/><Param name="joints" value="turret_joint shoulder_joint elbow_joint"/>
    </HWChannel>
"""


def system(tmp_path: Path, topics: str, sensors: str) -> System:
    """A one-node system of sim channels in an empty 6 × 4 m room."""
    path = tmp_path / "vectors.xml"
    path.write_text(
        f'<System xmlns="urn:ckm:1" version="1.0" name="vectors">{TYPES}<Node name="robot" kind="light">'
        f"{CHANNELS}{topics}{sensors}</Node>{ROOM}</System>"
    )
    return ckmconf.load(path)


GOOD_TOPICS = """
    <Topic name="scan" type="Scan" scope="internal"/>
    <Topic name="image" type="Image" scope="internal"/>
    <Topic name="depth_frame" type="bytes" scope="internal"/>
    <Topic name="joint_vector" type="float32" scope="internal"/>
"""
GOOD_SENSORS = """
    <Sensor name="lidar" channel="laser" topic="scan" period="0.1" extrapolation="none"/>
    <Sensor name="camera" channel="colour" topic="image" period="0.1" extrapolation="none"/>
    <Sensor name="depth_camera" channel="depth" topic="depth_frame" period="0.1" extrapolation="none"/>
    <Sensor name="arm" channel="joints" topic="joint_vector" period="0.05">
      <Adaptation><Linear gain="1" offset="10"/></Adaptation>
    </Sensor>
"""


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="vector-test")
    running.setup()
    running.start()
    yield running
    running.stop()


def test_whole_scans_frames_and_joint_vectors_reach_their_topics(tmp_path: Path, transport: Transport) -> None:
    made = system(tmp_path, GOOD_TOPICS, GOOD_SENSORS)
    assert verify(made) == []
    received: dict[str, Any] = {}

    def keep(name: str) -> Any:
        def on(sample: Sample) -> None:
            received[name] = codec.decode(sample.value)  # how every consumer reads a vector topic (D127)

        return on

    runtime = NodeRuntime(made.nodes[0], made, transport)
    for name in ("scan", "image", "depth_frame", "joint_vector"):
        transport.subscribe(runtime.topic(name), keep(name))
    with plant_scope(PlantScope(time.monotonic, name="vectors")):
        runtime.setup()
    runtime.start()
    try:
        deadline = time.monotonic() + 15.0
        while len(received) < 4 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        runtime.stop()
    assert set(received) == {"scan", "image", "depth_frame", "joint_vector"}

    scan = received["scan"]
    assert list(scan) == ["stamp", "range_max", "ranges"]
    assert scan["ranges"].dtype == np.float32 and scan["ranges"].shape == (91,)
    assert abs(scan["stamp"] - time.time()) < 60.0
    ahead = float(scan["ranges"][45])  # the middle beam looks along +x at the wall x = 6 from x = 3
    assert 2.5 < ahead < 3.05, ahead

    image = received["image"]
    assert (image["width"], image["height"], image["encoding"]) == (16, 12, "rgb8")
    assert isinstance(image["data"], bytes) and len(image["data"]) == 16 * 12 * 3

    depth = received["depth_frame"]
    assert isinstance(depth, np.ndarray) and depth.shape == (192,) and float(depth.max()) > 0.0

    joints = received["joint_vector"]
    assert joints.dtype == np.float32 and joints.shape == (3,)
    assert all(math.isclose(float(v), 10.0, abs_tol=0.5) for v in joints)  # the chain ran on each element


def test_verify_refuses_what_the_runtime_cannot_publish(tmp_path: Path) -> None:
    topics = """
    <Topic name="pose" type="Pose2D" scope="internal"/>
    <Topic name="text" type="string" scope="internal"/>
    <Topic name="frame" type="bytes" scope="internal"/>
    <Topic name="arm_pose" type="Pose2D" scope="internal"/>
    """
    sensors = """
    <Sensor name="lidar" channel="laser" topic="pose" period="0.1"/>
    <Sensor name="camera" channel="colour" topic="text" period="0.1"/>
    <Sensor name="depth_camera" channel="depth" topic="frame" period="0.1">
      <Adaptation><Linear gain="0.001" offset="0"/></Adaptation>
    </Sensor>
    <Sensor name="arm" channel="joints" topic="arm_pose" period="0.05"/>
    """
    problems = sorted((e.xpath.rsplit("/", 1)[-1], e.message) for e in verify(system(tmp_path, topics, sensors)))
    assert [p[0] for p in problems] == ["@topic", "@topic", "Adaptation"], problems
    # three joints fit Pose2D's three numbers field by field; 91 ranges do not, nor frames a string
    assert any("(size 91) onto topic 'pose' of type Pose2D, which has no field" in m for _, m in problems)
    assert any("onto topic 'text' of type string" in m for _, m in problems)
    assert "not to the frames or scans of stream channel 'depth'" in problems[2][1]
