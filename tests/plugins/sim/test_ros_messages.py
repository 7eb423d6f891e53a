"""The simulation's sensors as ROS 2 messages (plugins/sim/ros_messages.py, urdf.py; issue L point 1, D180).

The URDF kinematics is checked against pybullet's own forward kinematics of the same model; the
plugins' messages are encoded as CDR by CKM and decoded by ``rosbags``' own store; their geometry
is checked against the simulated devices (the lidar's beams, the camera's projection).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest
from rosbags.typesys import Stores, get_typestore

import ckmconf
from ckmconf.model.resources import Plugin
from plugins.hardware.sim import SimBackend
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from plugins.sim.client import ENV_ADDRESS
from plugins.sim.ros_messages import RosCamera, RosJointState, RosLaserScan, RosOdometry, RosTf
from plugins.sim.sensors import Camera, Lidar, pinhole
from plugins.sim.urdf import Kinematics, quaternion_multiply, rotate
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from runtime.ros.convert import to_message
from runtime.ros.types import RosTypes
from runtime.verification.verify import verify
from tests.conftest import REPO

from .conftest import robot

EXAMPLE = REPO / "configs" / "examples" / "sim_ros_types.xml"
STORE = get_typestore(Stores.ROS2_JAZZY)
ROS = RosTypes()
CONTEXT = Context(frame=0, stamp=99.0)


def _plugin(name: str, config: Path = EXAMPLE) -> Plugin:
    system = ckmconf.load(config)
    return next(pl for r in system.resources for pl in r.plugins if pl.name == name)


def _ros(type_name: str, payload: Any) -> Any:
    """``payload`` encoded as CDR by CKM, decoded by rosbags' own Jazzy store."""
    return STORE.deserialize_cdr(ROS.encode(type_name, to_message(ROS, type_name, payload)), type_name)


def _chain(model: Kinematics, start: str, end: str, positions: dict[str, float]) -> tuple[Any, Any]:
    """The pose of link ``end`` in link ``start`` composed from the URDF's joint transforms."""
    by_child = {j.child: j for j in model.joints.values()}
    joints = []
    link = end
    while link != start:
        joint = by_child[link]
        joints.append(joint)
        link = joint.parent
    xyz, q = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
    for joint in reversed(joints):
        t, r = model.transform(joint, positions.get(joint.name, 0.0))
        moved = rotate(q, t)
        xyz, q = (xyz[0] + moved[0], xyz[1] + moved[1], xyz[2] + moved[2]), quaternion_multiply(q, r)
    return np.array(xyz), np.array(q)


def test_urdf_transforms_compose_to_pybullets_link_poses(world: World) -> None:
    bot = robot(world, "turtlebot", (1.0, 1.0, 0.3))
    model = Kinematics.of_body("turtlebot")
    positions = {
        "arm_shoulder_pan_joint": 0.4,
        "arm_shoulder_lift_joint": -0.7,
        "arm_elbow_flex_joint": 1.1,
        "arm_wrist_flex_joint": 0.5,
        "gripper_joint": 0.01,
    }
    for name, value in positions.items():
        p.resetJointState(bot.body, bot.joint(name), value, physicsClientId=world.client)
    for start, end in [
        ("arm_base_link", "gripper_tool_link"),
        ("arm_base_link", "gripper_left_link"),
        ("mast_link", "camera_rgb_optical_frame"),
    ]:
        origin, origin_q = bot.link_pose(bot.link(start))
        target, target_q = bot.link_pose(bot.link(end))
        inverse = (-origin_q[0], -origin_q[1], -origin_q[2], origin_q[3])
        expected_xyz = rotate(inverse, tuple(np.subtract(target, origin)))
        end_q = (target_q[0], target_q[1], target_q[2], target_q[3])
        expected_q = np.array(list(quaternion_multiply(inverse, end_q)), dtype=float)
        xyz, q = _chain(model, start, end, positions)
        assert np.allclose(xyz, expected_xyz, atol=1e-5), (start, end)
        assert abs(abs(float(np.dot(q, expected_q))) - 1.0) < 1e-6, (start, end)  # same rotation (q ≡ −q)


ROVER_AND_ARM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="ros-rover-and-arm">
  <MessageType name="RawScan">
    <Field name="stamp" type="time"/><Field name="ranges" type="float32" count="0"/>
  </MessageType>
  <MessageType name="RawImage">
    <Field name="stamp" type="time"/><Field name="data" type="uint8" count="0"/>
  </MessageType>
  <MessageType name="RawDepth">
    <Field name="stamp" type="time"/><Field name="data" type="uint16" count="0"/>
  </MessageType>
  <MessageType name="RawJoints">
    <Field name="stamp" type="time"/><Field name="position" type="float64" count="0"/>
  </MessageType>
  <Topic name="/scan" type="sensor_msgs/msg/LaserScan" reliability="best-effort"/>
  <Topic name="/wrist/image_raw" type="sensor_msgs/msg/Image" reliability="best-effort"/>
  <Topic name="/wrist/camera_info" type="sensor_msgs/msg/CameraInfo" reliability="best-effort"/>
  <Topic name="/wrist/depth" type="sensor_msgs/msg/Image" reliability="best-effort"/>
  <Topic name="/wrist/depth_info" type="sensor_msgs/msg/CameraInfo" reliability="best-effort"/>
  <Topic name="/joint_states" type="sensor_msgs/msg/JointState" reliability="best-effort"/>
  <Node name="cell" kind="service">
    <HWChannel name="laser" direction="in" kind="stream" backend="sim" units="m" min="0" max="4" size="360">
      <Param name="body" value="rover"/><Param name="pose" value="3.0 2.0 0"/>
      <Param name="sensor" value="lidar"/><Param name="link" value="laser_link"/>
      <Param name="fov" value="4.7"/><Param name="rangeMin" value="0.1"/>
    </HWChannel>
    <HWChannel name="wrist_rgb" direction="in" kind="stream" backend="sim" units="rgb8" size="14400">
      <Param name="body" value="station_arm"/><Param name="pose" value="1.0 1.0 0"/>
      <Param name="sensor" value="rgb"/><Param name="link" value="wrist_camera_optical_frame"/>
      <Param name="width" value="80"/><Param name="height" value="60"/><Param name="fov" value="1.5184"/>
    </HWChannel>
    <HWChannel name="wrist_depth" direction="in" kind="stream" backend="sim" units="mm" size="4800">
      <Param name="body" value="station_arm"/><Param name="sensor" value="depth"/>
      <Param name="link" value="wrist_camera_optical_frame"/>
      <Param name="width" value="80"/><Param name="height" value="60"/><Param name="fov" value="1.5184"/>
    </HWChannel>
    <HWChannel name="arm_state" direction="in" kind="bus" backend="sim" units="step" size="3">
      <Param name="body" value="station_arm"/><Param name="joints" value="turret_joint shoulder_joint elbow_joint"/>
      <Param name="scale" value="0.01"/><Param name="offset" value="100"/>
    </HWChannel>
    <Topic name="scan_raw" type="RawScan" scope="internal" reliability="best-effort"/>
    <Topic name="rgb_raw" type="RawImage" scope="internal" reliability="best-effort"/>
    <Topic name="depth_raw" type="RawDepth" scope="internal" reliability="best-effort"/>
    <Topic name="joints_raw" type="RawJoints" scope="internal" reliability="best-effort"/>
    <Sensor name="lidar" channel="laser" topic="scan_raw" period="0.1" extrapolation="none"/>
    <Sensor name="rgb_camera" channel="wrist_rgb" topic="rgb_raw" period="0.5" extrapolation="none"/>
    <Sensor name="depth_camera" channel="wrist_depth" topic="depth_raw" period="0.5" extrapolation="none"/>
    <Sensor name="arm_joints" channel="arm_state" topic="joints_raw" period="0.1" extrapolation="none"/>
  </Node>
  <SmartResource name="RosSensors" node="cell" description="The rover's and the station arm's sensors as ROS 2.">
    <Plugin name="scan" kind="ros-laser-scan"><Param name="channel" value="laser"/></Plugin>
    <Plugin name="rgb" kind="ros-camera"><Param name="channel" value="wrist_rgb"/></Plugin>
    <Plugin name="depth" kind="ros-camera"><Param name="channel" value="wrist_depth"/></Plugin>
    <Plugin name="joints" kind="ros-joint-state"><Param name="channel" value="arm_state"/></Plugin>
    <Profile name="scan"><Use plugin="scan"/></Profile>
    <Profile name="rgb"><Use plugin="rgb"/></Profile>
    <Profile name="depth"><Use plugin="depth"/></Profile>
    <Profile name="joints"><Use plugin="joints"/></Profile>
    <Service name="Scan" rate="0.1" function="The rover's lidar sweeps.">
      <Input name="raw" topic="scan_raw"/><Output name="scan" topic="/scan"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="scan" profile="scan"><Policy measure="latency" upper="0.2" probability="0.9"/></Scenario>
    </Service>
    <Service name="Rgb" rate="0.5" function="The wrist camera's frames and intrinsics.">
      <Input name="raw" topic="rgb_raw"/>
      <Output name="image" topic="/wrist/image_raw"/><Output name="info" topic="/wrist/camera_info"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="rgb" profile="rgb"><Policy measure="latency" upper="0.2" probability="0.9"/></Scenario>
    </Service>
    <Service name="Depth" rate="0.5" function="The wrist camera's depth (mm) and intrinsics.">
      <Input name="raw" topic="depth_raw"/>
      <Output name="image" topic="/wrist/depth"/><Output name="info" topic="/wrist/depth_info"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="depth" profile="depth"><Policy measure="latency" upper="0.2" probability="0.9"/></Scenario>
    </Service>
    <Service name="JointStates" rate="0.1" function="The station arm's joint positions.">
      <Input name="raw" topic="joints_raw"/><Output name="joint_states" topic="/joint_states"/>
      <QualityMeasure name="latency" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="joints" profile="joints"><Policy measure="latency" upper="0.2" probability="0.9"/></Scenario>
    </Service>
  </SmartResource>
  <Environment name="room" frame="map"><Map xmin="0" ymin="0" xmax="6" ymax="4" height="1.5"/></Environment>
</System>
"""
"""A second and third robot model (the rover's lidar, the station arm's wrist camera and joints), each
sensor with values of its own that no lab sensor has: a message carrying a lab value shows here."""


@dataclass(frozen=True)
class Sensors:
    """One robot configuration's sensors as its channels declare them (what the messages must carry)."""

    name: str
    scan: tuple[str, str, int, float, float, float]  # channel, link, beams, fov, range min, range max
    camera: tuple[str, str, str, str, int, int, float]  # rgb, depth channels, their links, width, height, fov
    joints: tuple[str, tuple[str, ...], float, float]  # channel, names, scale, offset


TURTLEBOT = Sensors(
    "turtlebot",
    ("hokuyo", "hokuyo_link", 683, 4.1888, 0.02, 5.6),
    ("xtion_rgb", "xtion_depth", "camera_rgb_optical_frame", "camera_depth_optical_frame", 160, 120, 1.0123),
    (
        "arm_state",
        (
            "arm_shoulder_pan_joint",
            "arm_shoulder_lift_joint",
            "arm_elbow_flex_joint",
            "arm_wrist_flex_joint",
            "gripper_joint",
        ),
        1.0,
        0.0,
    ),
)
ROVER_AND_STATION_ARM = Sensors(
    "rover-and-station-arm",
    ("laser", "laser_link", 360, 4.7, 0.1, 4.0),
    ("wrist_rgb", "wrist_depth", "wrist_camera_optical_frame", "wrist_camera_optical_frame", 80, 60, 1.5184),
    ("arm_state", ("turret_joint", "shoulder_joint", "elbow_joint"), 0.01, 100.0),
)


@pytest.fixture(params=[TURTLEBOT, ROVER_AND_STATION_ARM], ids=lambda sensors: sensors.name)
def robots(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Sensors, Path]:
    """A robot configuration with its ROS plugins: the Turtlebot example, or the rover and the station arm."""
    sensors: Sensors = request.param
    if sensors is TURTLEBOT:
        return sensors, EXAMPLE
    config = tmp_path / "rover_and_arm.xml"
    config.write_text(ROVER_AND_ARM)
    return sensors, config


def _backends(config: Path, *names: str) -> tuple[ManualClock, list[SimBackend]]:
    """The named sim channels of ``config`` set up in one in-process world on a clock the test sets."""
    clock = ManualClock()
    channels = {c.name: c for n in ckmconf.load(config).nodes for c in n.channels}
    with plant_scope(PlantScope(clock)):
        backends = [SimBackend(channels[name]) for name in names]
    for backend in backends:
        backend.setup()
    return clock, backends


def test_a_scan_is_a_laser_scan_of_the_channels_own_lidar(
    robots: tuple[Sensors, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    sensors, config = robots
    channel, link, beams, fov, range_min, range_max = sensors.scan
    monkeypatch.delenv(ENV_ADDRESS, raising=False)  # the world in this process, not a run's server
    clock, (backend,) = _backends(config, channel)
    clock.advance(0.1)
    ranges = backend.read()
    plugin = RosLaserScan(_plugin("scan", config))
    message = _ros("sensor_msgs/msg/LaserScan", plugin.process({"stamp": 12.25, "ranges": ranges}, CONTEXT))
    lidar = backend.device
    assert isinstance(lidar, Lidar) and isinstance(ranges, np.ndarray)
    assert message.header.frame_id == link
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (12, 250_000_000)
    assert (message.angle_min, message.angle_max) == pytest.approx((-fov / 2, fov / 2))  # the channel's fov
    assert math.isclose(message.angle_min, lidar.angles[0], rel_tol=1e-6)  # the beams the device cast
    assert math.isclose(message.angle_min + (beams - 1) * message.angle_increment, lidar.angles[-1], rel_tol=1e-5)
    assert (message.range_min, message.range_max) == pytest.approx((range_min, range_max))  # its own range
    assert (lidar.range_min, lidar.range_max) == pytest.approx((range_min, range_max))
    assert np.allclose(message.ranges, ranges, atol=1e-6) and len(message.ranges) == beams
    assert float(np.max(message.ranges)) <= range_max + 1e-6
    with pytest.raises(ValueError, match=f"{beams + 1} ranges, the channel reads {beams}"):
        plugin.process({"stamp": 1.0, "ranges": np.zeros(beams + 1)}, CONTEXT)
    backend.stop()


def test_a_frame_is_an_image_and_the_camera_info_of_the_channels_own_camera(
    robots: tuple[Sensors, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    sensors, config = robots
    rgb_channel, depth_channel, link, depth_link, width, height, fov = sensors.camera
    monkeypatch.delenv(ENV_ADDRESS, raising=False)
    clock, backends = _backends(config, rgb_channel, depth_channel)
    clock.advance(0.1)
    colour, millimetres = (b.read() for b in backends)
    sim, cameras = backends[0].sim, [b.device for b in backends]
    assert sim is not None and all(isinstance(c, Camera) and c.fov == pytest.approx(fov) for c in cameras)
    frame, depth_frame = (sim.frame(c, width, height) for c in cameras)  # the renders these reads were made of
    rgb, depth = RosCamera(_plugin("rgb", config)), RosCamera(_plugin("depth", config))
    out = rgb.process({"stamp": 3.5, "data": colour}, CONTEXT)
    image = _ros("sensor_msgs/msg/Image", out["image"])
    info = _ros("sensor_msgs/msg/CameraInfo", out["info"])
    assert (image.width, image.height, image.encoding, image.step) == (width, height, "rgb8", 3 * width)
    assert np.array_equal(np.asarray(image.data).reshape(height, width, 3), frame.rgb)
    assert image.header.frame_id == info.header.frame_id == link
    fx, fy, cx, cy = pinhole(width, height, fov)  # the channel's own field of view
    assert np.allclose(info.k, [fx, 0, cx, 0, fy, cy, 0, 0, 1])
    assert np.allclose(info.k, [frame.fx, 0, frame.cx, 0, frame.fy, frame.cy, 0, 0, 1])  # the render's projection
    assert info.distortion_model == "plumb_bob" and (info.width, info.height) == (width, height)
    out = depth.process({"stamp": 3.5, "data": millimetres}, CONTEXT)
    depth_image = _ros("sensor_msgs/msg/Image", out["image"])
    depth_info = _ros("sensor_msgs/msg/CameraInfo", out["info"])
    assert (depth_image.encoding, depth_image.header.frame_id) == ("16UC1", depth_link)
    assert np.array_equal(
        np.frombuffer(bytes(depth_image.data), "<u2").reshape(height, width), np.round(depth_frame.depth * 1000.0)
    )
    assert np.allclose(depth_info.k, info.k)  # one camera's two channels: one projection
    for backend in backends:
        backend.stop()


def test_joint_states_are_the_channels_joints_in_radians(
    robots: tuple[Sensors, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    sensors, config = robots
    channel, names, scale, offset = sensors.joints
    monkeypatch.delenv(ENV_ADDRESS, raising=False)
    _, (backend,) = _backends(config, channel)
    assert backend.sim is not None
    body = backend.values["body"]
    robot = backend.sim.robots[body]
    positions = [0.1 * (i + 1) * (-1) ** i for i in range(len(names))]  # within every joint's limits
    for name, position in zip(names, positions, strict=True):
        p.resetJointState(robot.body, robot.joint(name), position, physicsClientId=backend.sim.world.client)
    raw = backend.read()  # raw units: position / scale + offset
    state = RosJointState(_plugin("joints", config)).process({"stamp": 5.0, "position": np.asarray(raw)}, CONTEXT)
    message = _ros("sensor_msgs/msg/JointState", state)
    assert tuple(message.name) == names
    assert np.allclose(message.position, positions, atol=1e-9)  # back to radians, whatever the channel's scale
    assert np.allclose(np.asarray(raw), np.asarray(positions) / scale + offset)
    backend.stop()


def test_joint_states_odometry_and_tf() -> None:
    joints = RosJointState(_plugin("joints"))
    state = joints.process({"stamp": 5.0, "position": np.array([0.1, -0.2, 0.3, 0.0, 0.01])}, CONTEXT)
    message = _ros("sensor_msgs/msg/JointState", state)
    assert list(message.name) == [
        "arm_shoulder_pan_joint",
        "arm_shoulder_lift_joint",
        "arm_elbow_flex_joint",
        "arm_wrist_flex_joint",
        "gripper_joint",
    ]
    assert np.allclose(message.position, [0.1, -0.2, 0.3, 0.0, 0.01])
    odom = RosOdometry(_plugin("odom")).process(
        {
            "stamp": 5.1,
            "pose": {"x": 2.5, "y": 1.0, "yaw": math.pi / 2},
            "twist": {"linear": 0.2, "angular": 0.1},
            "dispersion": 0.02,
        },
        CONTEXT,
    )
    decoded = _ros("nav_msgs/msg/Odometry", odom)
    assert (decoded.header.frame_id, decoded.child_frame_id) == ("odom", "base_link")
    assert (decoded.pose.pose.orientation.z, decoded.pose.pose.orientation.w) == pytest.approx((0.7071068, 0.7071068))
    assert decoded.pose.covariance[0] == pytest.approx(0.0002) and decoded.twist.twist.angular.z == 0.1
    tf = RosTf(_plugin("tf")).process({"joints": state, "odom": odom}, CONTEXT)
    transforms = _ros("tf2_msgs/msg/TFMessage", tf).transforms
    pairs = {(t.header.frame_id, t.child_frame_id) for t in transforms}
    assert ("odom", "base_link") in pairs and ("base_link", "hokuyo_link") in pairs
    assert ("arm_shoulder_pan_link", "arm_shoulder_lift_link") in pairs
    assert ("base_link", "wheel_left_link") not in pairs  # not measured: left out, as robot_state_publisher does
    assert [t.header.stamp.sec + t.header.stamp.nanosec * 1e-9 for t in transforms] == [pytest.approx(5.1)] * len(pairs)


def test_the_example_verifies_and_a_scan_onto_an_image_topic_is_refused(tmp_path: Path) -> None:
    assert verify(ckmconf.load(EXAMPLE)) == []
    other = tmp_path / "rover_and_arm.xml"
    other.write_text(ROVER_AND_ARM)
    assert verify(ckmconf.load(other)) == []  # the second configuration is a runnable one too
    wrong = tmp_path / "wrong.xml"
    wrong.write_text(
        EXAMPLE.read_text().replace(
            'name="/scan" type="sensor_msgs/msg/LaserScan"', 'name="/scan" type="sensor_msgs/msg/Image"'
        )
    )
    errors = [str(e) for e in verify(ckmconf.load(wrong))]
    assert len(errors) == 1 and "'/scan'" in errors[0] and "sensor_msgs/msg/Image" in errors[0], errors


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('value="hokuyo"/></Plugin>', 'value="lidar"/></Plugin>', "no HWChannel of that name"),
        (
            'kind="ros-laser-scan"><Param name="channel" value="hokuyo"/>',
            'kind="ros-laser-scan"><Param name="channel" value="xtion_rgb"/>',
            "is a rgb channel, not lidar",
        ),
        ('<Param name="link" value="hokuyo_link"/>', '<Param name="link" value="laser"/>', "has no link 'laser'"),
        # no lab value fills in a lidar's geometry (D284): the backend's own refusal
        ('<Param name="fov" value="4.1888"/>', "", "HWChannel 'hokuyo': a lidar needs its field of view"),
        ('max="5.6" size="683"', 'size="683"', "HWChannel 'hokuyo': a lidar needs its range: the HWChannel's max"),
        ('<Param name="rangeMin" value="0.02"/>', '<Param name="rangeMin" value="-1"/>', "'rangeMin'"),
    ],
)
def test_a_plugin_naming_what_the_simulation_lacks_is_refused(old: str, new: str, message: str, tmp_path: Path) -> None:
    config = tmp_path / "bad.xml"
    text = EXAMPLE.read_text()
    assert old in text
    config.write_text(text.replace(old, new))
    with pytest.raises(ParamError, match=message):
        RosLaserScan(_plugin("scan", config))
