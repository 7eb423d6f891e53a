"""The simulation's sensors as ROS 2 messages (plugins/sim/ros_messages.py, urdf.py; issue L point 1, D180).

The URDF kinematics is checked against pybullet's own forward kinematics of the same model; the
plugins' messages are encoded as CDR by CKM and decoded by ``rosbags``' own store; their geometry
is checked against the simulated devices (the lidar's beams, the camera's projection).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest
from rosbags.typesys import Stores, get_typestore

import ckmconf
from ckmconf.model.resources import Plugin
from plugins.sim.ros_messages import RosCamera, RosJointState, RosLaserScan, RosOdometry, RosTf
from plugins.sim.sensors import Camera, Lidar
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
    positions = {"arm_shoulder_pan_joint": 0.4, "arm_shoulder_lift_joint": -0.7, "arm_elbow_flex_joint": 1.1,
                 "arm_wrist_flex_joint": 0.5, "gripper_joint": 0.01}
    for name, value in positions.items():
        p.resetJointState(bot.body, bot.joint(name), value, physicsClientId=world.client)
    for start, end in [("arm_base_link", "gripper_tool_link"), ("arm_base_link", "gripper_left_link"),
                       ("mast_link", "camera_rgb_optical_frame")]:
        origin, origin_q = bot.link_pose(bot.link(start))
        target, target_q = bot.link_pose(bot.link(end))
        inverse = (-origin_q[0], -origin_q[1], -origin_q[2], origin_q[3])
        expected_xyz = rotate(inverse, tuple(np.subtract(target, origin)))
        end_q = (target_q[0], target_q[1], target_q[2], target_q[3])
        expected_q = np.array(list(quaternion_multiply(inverse, end_q)), dtype=float)
        xyz, q = _chain(model, start, end, positions)
        assert np.allclose(xyz, expected_xyz, atol=1e-5), (start, end)
        assert abs(abs(float(np.dot(q, expected_q))) - 1.0) < 1e-6, (start, end)  # same rotation (q ≡ −q)


def test_a_scan_is_a_laser_scan_of_the_lidars_geometry(world: World) -> None:
    plugin = RosLaserScan(_plugin("scan"))
    bot = robot(world, "turtlebot", (1.0, 1.0, 0.0))
    lidar = Lidar(bot, "hokuyo_link", beams=683, fov=4.1888, range_min=0.02, range_max=5.6)
    ranges = lidar.scan()
    message = _ros("sensor_msgs/msg/LaserScan", plugin.process({"stamp": 12.25, "ranges": ranges}, CONTEXT))
    assert message.header.frame_id == "hokuyo_link"
    assert (message.header.stamp.sec, message.header.stamp.nanosec) == (12, 250_000_000)
    assert math.isclose(message.angle_min, lidar.angles[0], rel_tol=1e-6)
    assert math.isclose(message.angle_min + 682 * message.angle_increment, lidar.angles[-1], rel_tol=1e-5)
    assert (message.range_min, message.range_max) == pytest.approx((0.02, 5.6))
    assert np.allclose(message.ranges, ranges, atol=1e-6) and len(message.ranges) == 683
    with pytest.raises(ValueError, match="360 ranges, the channel reads 683"):
        plugin.process({"stamp": 1.0, "ranges": np.zeros(360)}, CONTEXT)


def test_a_frame_is_an_image_and_the_camera_info_of_its_projection(world: World) -> None:
    rgb, depth = RosCamera(_plugin("rgb")), RosCamera(_plugin("depth"))
    bot = robot(world, "turtlebot", (1.0, 1.0, 0.0))
    frame = Camera(bot, "camera_rgb_optical_frame", fov=1.0123).render(160, 120)
    out = rgb.process({"stamp": 3.5, "data": frame.rgb.ravel()}, CONTEXT)
    image = _ros("sensor_msgs/msg/Image", out["image"])
    info = _ros("sensor_msgs/msg/CameraInfo", out["info"])
    assert (image.width, image.height, image.encoding, image.step) == (160, 120, "rgb8", 480)
    assert np.array_equal(np.asarray(image.data).reshape(120, 160, 3), frame.rgb)
    assert image.header.frame_id == info.header.frame_id == "camera_rgb_optical_frame"
    assert np.allclose(info.k, [frame.fx, 0, frame.cx, 0, frame.fy, frame.cy, 0, 0, 1])
    assert info.distortion_model == "plumb_bob" and (info.width, info.height) == (160, 120)
    millimetres = np.round(frame.depth * 1000.0)
    out = depth.process({"stamp": 3.5, "data": millimetres.ravel()}, CONTEXT)
    depth_image = _ros("sensor_msgs/msg/Image", out["image"])
    assert (depth_image.encoding, depth_image.header.frame_id) == ("16UC1", "camera_depth_optical_frame")
    assert np.array_equal(np.frombuffer(bytes(depth_image.data), "<u2").reshape(120, 160), millimetres)


def test_joint_states_odometry_and_tf() -> None:
    joints = RosJointState(_plugin("joints"))
    state = joints.process({"stamp": 5.0, "position": np.array([0.1, -0.2, 0.3, 0.0, 0.01])}, CONTEXT)
    message = _ros("sensor_msgs/msg/JointState", state)
    assert list(message.name) == ["arm_shoulder_pan_joint", "arm_shoulder_lift_joint", "arm_elbow_flex_joint",
                                  "arm_wrist_flex_joint", "gripper_joint"]
    assert np.allclose(message.position, [0.1, -0.2, 0.3, 0.0, 0.01])
    odom = RosOdometry(_plugin("odom")).process(
        {"stamp": 5.1, "pose": {"x": 2.5, "y": 1.0, "yaw": math.pi / 2}, "twist": {"linear": 0.2, "angular": 0.1},
         "dispersion": 0.02}, CONTEXT)
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
    wrong = tmp_path / "wrong.xml"
    wrong.write_text(EXAMPLE.read_text().replace('name="/scan" type="sensor_msgs/msg/LaserScan"',
                                                 'name="/scan" type="sensor_msgs/msg/Image"'))
    errors = [str(e) for e in verify(ckmconf.load(wrong))]
    assert len(errors) == 1 and "'/scan'" in errors[0] and "sensor_msgs/msg/Image" in errors[0], errors


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('value="hokuyo"/></Plugin>', 'value="lidar"/></Plugin>', "no HWChannel of that name"),
        ('kind="ros-laser-scan"><Param name="channel" value="hokuyo"/>',
         'kind="ros-laser-scan"><Param name="channel" value="xtion_rgb"/>', "is a rgb channel, not lidar"),
        ('<Param name="link" value="hokuyo_link"/>', '<Param name="link" value="laser"/>', "has no link 'laser'"),
    ],
)
def test_a_plugin_naming_what_the_simulation_lacks_is_refused(old: str, new: str, message: str,
                                                               tmp_path: Path) -> None:
    config = tmp_path / "bad.xml"
    text = EXAMPLE.read_text()
    assert old in text
    config.write_text(text.replace(old, new))
    with pytest.raises(ParamError, match=message):
        RosLaserScan(_plugin("scan", config))
