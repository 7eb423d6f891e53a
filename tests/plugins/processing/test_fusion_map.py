"""GlobalRecog.Fusion in the MAP frame (§6.3.1, group mission): inputs mounted on robots (URDF forward
kinematics), placed with the Turtlebot's pose estimate and the Nao's head angles; rendered scenes of the
use case's lab run through the real RGB and depth pipelines (benchmarks/fusion_scene.py)."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest

from benchmarks.fusion import base_for
from benchmarks.fusion_scene import LINK, NAO_LINK, Lab
from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.fusion import FeatureFusion
from plugins.processing.mounts import compose, model_path, planar, read_mount
from plugins.sim.robots import Robot
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from tests.conftest import CONFIGS

CTX = Context(frame=0, stamp=0.0, resource="GlobalRecog")
OWNER = "plugin 'f' (feature-fusion)"
MOUNTED = {
    "inputs": "rgb: line; depth: point; pantilt: line",
    "mounts": f"rgb: turtlebot {LINK}; depth: turtlebot camera_depth_optical_frame; pantilt: nao {NAO_LINK}",
    "bases": "pantilt: 8.75 5.55 2.3",
    "headJoints": "HeadYaw HeadPitch",
    "objects": "cylinder_green_checker: cylinder green_checker",
}
NAO = (8.75, 5.55, 2.3)
"""The Nao at the workbench's right front corner, turned towards the green cylinder."""


def fusion(params: Mapping[str, object]) -> FeatureFusion:
    given = {"fx": 525, "calibrationWidth": 640, "calibrationHeight": 480} | dict(params)  # the line inputs' camera
    return FeatureFusion(
        Plugin(name="f", kind="feature-fusion", params=tuple(Param(name=k, value=str(v)) for k, v in given.items()))
    )


@pytest.fixture(scope="module")
def lab() -> Iterator[Lab]:
    made = Lab("VGA", "QVGA", seed=3, nao=NAO)
    yield made
    made.close()


def front_of(lab: Lab, name: str, distance: float, around: float) -> tuple[float, float, float]:
    """The Turtlebot's pose whose camera is ``distance`` m from ``name``, ``around`` rad off its front, facing it."""
    x, y, _ = lab.targets[name].centre
    angle = -math.pi / 2 + around
    camera = (x + distance * math.cos(angle), y + distance * math.sin(angle))
    mount = read_mount(model_path("turtlebot", Path()), LINK).pose().translation
    return base_for(camera, angle + math.pi, (float(mount[0]), float(mount[1])))


def head_towards(lab: Lab, name: str) -> dict[str, float]:
    """Pan and tilt pointing the Nao's camera roughly at ``name`` (the head's own geometry, not the fusion's)."""
    x, y, z = lab.targets[name].centre
    dx, dy = x - NAO[0], y - NAO[1]
    pan = math.atan2(dy, dx) - NAO[2]
    return {"pan": math.atan2(math.sin(pan), math.cos(pan)), "tilt": math.atan2(0.52 - z, math.hypot(dx, dy))}


def located(out: Mapping[str, Any], name: str) -> dict[str, Any]:
    found: list[dict[str, Any]] = [o for o in out["objects"] if o["name"] == name]
    assert len(found) == 1, found
    return found[0]


# --------------------------------------------------------------------------- the mount chain


def test_urdf_mounts_match_the_simulated_robots_links() -> None:
    """The fusion's forward kinematics (URDF read by lxml) agrees with pybullet's link poses."""
    with World() as world:
        turtlebot = Robot(world, "tb", world.load_robot("tb", "turtlebot", (1.0, 2.0, 0.7)))
        nao = Robot(world, "nao", world.load_robot("nao", "nao", (3.0, 1.0, -0.4)))
        angles = {"HeadYaw": 0.5, "HeadPitch": 0.3}
        for joint, angle in angles.items():
            p.resetJointState(nao.body, nao.joint(joint), angle, physicsClientId=world.client)
        for robot, model, link, pose in (
            (turtlebot, "turtlebot", LINK, (1.0, 2.0, 0.7)),
            (nao, "nao", NAO_LINK, (3.0, 1.0, -0.4)),
        ):
            mount = read_mount(model_path(model, Path()), link)
            mine = compose(planar(*pose), mount.pose(angles))
            position, orientation = robot.link_pose(robot.link(link))
            assert np.allclose(mine.translation, position, atol=1e-6)
            assert np.allclose(mine.rotation, np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3), atol=1e-6)
    assert read_mount(model_path("nao", Path()), NAO_LINK).joints == ("HeadYaw", "HeadPitch")


# --------------------------------------------------------------------------- rendered scenes in the map


def test_one_cylinder_seen_from_two_robot_poses_lands_at_one_map_position(lab: Lab) -> None:
    """The depth and RGB results of two renders from different poses fuse, each time, into one object at
    the cylinder's true map position: the robot's pose estimate places them, not the camera frame."""
    truth = np.array(lab.targets["cylinder_green_checker"].centre)
    places = []
    for pose in (
        front_of(lab, "cylinder_green_checker", 0.55, 0.25),
        front_of(lab, "cylinder_green_checker", 0.6, -0.1),
    ):
        view = lab.observe(pose)
        obj = located(view.fused, "cylinder_green_checker")
        assert obj["frame"] == "map" and sorted(obj["sources"]) == ["depth", "rgb"]
        assert obj["texture"] == "green_checker" and obj["shape"] == "cylinder"
        at = np.array([obj["x"], obj["y"], obj["z"]])
        assert math.dist(at[:2], truth[:2]) < 0.045  # the visible surface's centroid: a radius in front at most
        places.append(at)
        wrong = lab.fusion.process(
            {
                "rgb": view.rgb,
                "depth": view.depth,
                "pose": {"pose": {"x": pose[0] + 0.5, "y": pose[1], "yaw": pose[2]}},
            },
            CTX,
        )
        shifted = [o for o in wrong["objects"] if o["shape"] == "cylinder" and o["x"] is not None]
        assert min(abs(o["x"] - at[0] - 0.5) for o in shifted) < 0.01  # the estimate, not the truth, places it
    assert math.dist(places[0], places[1]) < 0.05


def test_the_nao_line_and_the_turtlebot_point_fuse_into_one_map_object(lab: Lab) -> None:
    """The Turtlebot's depth point and RGB line and the Nao's pan-tilt line (its map pose Param composed
    with the head angles) are one object: three sources, at the true position."""
    pose = front_of(lab, "cylinder_green_checker", 0.55, 0.25)
    view = lab.observe(pose)
    head = head_towards(lab, "cylinder_green_checker")
    pantilt = lab.look(head["pan"], head["tilt"])
    assert "cylinder_green_checker" in [o["name"] for o in pantilt["objects"]]  # the blue one may show behind
    estimate = {"pose": {"x": pose[0], "y": pose[1], "yaw": pose[2]}}
    data = {"rgb": view.rgb, "depth": view.depth, "pose": estimate, "pantilt": pantilt, "head": head}
    out = lab.fusion.process(data, CTX)
    obj = located(out, "cylinder_green_checker")
    assert sorted(obj["sources"]) == ["depth", "pantilt", "rgb"] and obj["frame"] == "map"
    truth = lab.targets["cylinder_green_checker"].centre
    assert math.dist((obj["x"], obj["y"]), truth[:2]) < 0.045 and abs(obj["z"] - truth[2]) < 0.05
    alone = lab.fusion.process({"pantilt": pantilt, "head": head}, CTX)
    ray = located(alone, "cylinder_green_checker")  # a lone line: where it points, from the Nao's camera
    origin, direction = np.array(ray["origin"]), np.array(ray["direction"])
    t = float((np.array(truth) - origin) @ direction)
    assert np.linalg.norm(origin + t * direction - np.array(truth)) < 0.05
    assert alone["unplaced"] == 0
    turned = lab.fusion.process({"pantilt": pantilt, "head": {"pan": head["pan"] + 0.3, "tilt": head["tilt"]}}, CTX)
    moved = np.array(located(turned, "cylinder_green_checker")["direction"])
    assert math.degrees(math.acos(float(np.clip(moved @ direction, -1, 1)))) == pytest.approx(17.2, abs=0.5)


# --------------------------------------------------------------------------- unknown poses, params, messages


def test_observations_wait_for_the_robot_pose_and_head_state() -> None:
    plugin = fusion(MOUNTED)
    rgb = {"objects": [{"name": "cylinder_green_checker", "x": 0.5, "y": 0.5, "reliability": 0.6}]}
    depth = {"objects": [{"name": "cylinder", "x": 0.0, "y": 0.0, "z": 0.6, "reliability": 0.9}]}
    out = plugin.process({"rgb": rgb, "depth": depth, "pantilt": rgb, "pose": None, "head": None}, CTX)
    assert out == {"objects": [], "reliability": 0.0, "unplaced": 3}
    out = plugin.process({"depth": depth, "pose": {"pose": {"x": 7.0, "y": 5.0, "yaw": math.pi / 2}}}, CTX)
    (obj,) = out["objects"]
    assert out["unplaced"] == 0 and obj["frame"] == "map" and obj["sources"] == ["depth"]
    assert obj["y"] > 5.4 and abs(obj["x"] - 7.0) < 0.05  # 0.6 m ahead of a robot facing +y
    assert obj["observer"] == [{"x": 7.0, "y": 5.0, "yaw": math.pi / 2}]  # the pose that placed it (D172)
    again = plugin.process({"depth": depth}, CTX)  # the last pose estimate holds until a new one comes
    assert again["objects"][0]["y"] == obj["y"]
    assert plugin.process({"pantilt": rgb, "head": {"pan": 0.0, "tilt": 0.2}}, CTX)["unplaced"] == 0


def test_unmounted_inputs_keep_the_sensor_frame() -> None:
    plugin = fusion({"inputs": "depth: point"})
    (obj,) = plugin.process({"depth": {"objects": [{"name": "box", "x": 0, "y": 0, "z": 1, "reliability": 1}]}}, CTX)[
        "objects"
    ]
    assert obj["frame"] == "sensor" and "unplaced" not in plugin.process({}, CTX)


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"mounts": "lidar: turtlebot base_link"}, "parameter 'mounts' names 'lidar', not an input of 'inputs'"),
        ({"mounts": "rgb: turtlebot"}, "parameter 'mounts' for 'rgb' needs a robot model and a link"),
        (
            {"mounts": "rgb: turtlebot nowhere"},
            "parameter 'mounts' for 'rgb': robot model .*turtlebot.urdf: no link 'nowhere'",
        ),
        (
            {"mounts": "rgb: missing_robot camera"},
            "parameter 'mounts' for 'rgb': robot model .*missing_robot.urdf: cannot read it",
        ),
        ({"bases": "rgb: 1 2 3"}, "parameter 'bases' names 'rgb', which has no entry in 'mounts'"),
        (
            {"mounts": "pantilt: nao CameraTop_optical_frame", "bases": "pantilt: 1 2"},
            "parameter 'bases' for 'pantilt' needs 3 finite numbers",
        ),
        ({"poseInput": "rgb"}, "parameter 'poseInput' = 'rgb' must name an input not in 'inputs'"),
        ({"headInput": "pose"}, "parameters 'poseInput' and 'headInput' name the same input"),
        ({"headJoints": "HeadYaw"}, "parameter 'headJoints' needs the pan and the tilt joint names"),
        (
            {"mounts": "pantilt: nao CameraTop_optical_frame"},
            "the mount of input 'pantilt' moves joints HeadYaw HeadPitch: parameter 'headJoints' must name the joints",
        ),
        (
            {"mounts": "depth: turtlebot camera_depth_optical_frame", "poses": "depth: 0 0 0 0 0 0"},
            "input 'depth' has both a static 'poses' entry and a 'mounts' entry",
        ),
    ],
)
def test_bad_map_params_are_refused(params: Mapping[str, object], message: str) -> None:
    with pytest.raises(ParamError, match=f"^{re.escape(OWNER)}: {message}"):
        fusion({"inputs": "rgb: line; depth: point; pantilt: line"} | dict(params))


def test_a_mount_relative_to_the_configuration_file(tmp_path: Path) -> None:
    (tmp_path / "bot.urdf").write_text(
        '<robot name="bot"><link name="base_link"/><link name="cam"/>'
        '<joint name="j" type="fixed"><parent link="base_link"/><child link="cam"/>'
        '<origin xyz="0.1 0 0.5" rpy="-1.5707963 0 -1.5707963"/></joint></robot>'
    )
    record = Plugin(
        name="f",
        kind="feature-fusion",
        loc=Loc(str(tmp_path / "system.xml"), 1, 1, "/"),
        params=(Param(name="inputs", value="depth: point"), Param(name="mounts", value="depth: bot.urdf cam")),
    )
    plugin = FeatureFusion(record)
    out = plugin.process(
        {
            "depth": {"objects": [{"name": "box", "x": 0, "y": 0, "z": 1, "reliability": 1}]},
            "pose": {"pose": {"x": 2.0, "y": 1.0, "yaw": 0.0}},
        },
        CTX,
    )
    obj = out["objects"][0]
    assert (obj["x"], obj["y"], obj["z"]) == pytest.approx((3.1, 1.0, 0.5), abs=1e-6)  # z forward = robot x


MALFORMED = [
    ({"pose": {"x": 1}}, "input 'pose' field 'pose' is missing or not a mapping of x, y, yaw"),
    ({"pose": {"pose": {"x": 1, "y": "2", "yaw": 0}}}, "input 'pose' field 'pose.y' is not a number: '2'"),
    ({"head": [0, 0]}, "input 'head' message is not a mapping of pan and tilt"),
    ({"head": {"pan": 0.1}}, "input 'head' field 'tilt' is not a number: None"),
    ({"head": {"pan": 90, "tilt": 0}}, "input 'head' fields 'pan'/'tilt' = 90.0, 0.0 are not angles in radians"),
]


@pytest.mark.parametrize(("data", "message"), MALFORMED)
def test_malformed_pose_and_head_messages_name_the_input(data: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError) as caught:
        fusion(MOUNTED).process(data, CTX)
    assert str(caught.value) == f"{OWNER}: {message}"


def test_the_use_case_resources_still_load_the_fusion() -> None:
    """The lead wires mounts in resources.xml later: the plugin still accepts the current record."""
    loc = Loc(str(CONFIGS / "usecase" / "resources.xml"), 1, 1, "/")
    record = Plugin(
        name="f",
        kind="feature-fusion",
        loc=loc,
        params=(
            Param(name="inputs", value="rgb: line; depth: point; pantilt: line"),
            Param(name="environment", value="environment.xml"),
            Param(name="mounts", value="rgb: turtlebot camera_rgb_optical_frame; pantilt: nao CameraTop_optical_frame"),
            Param(name="bases", value="pantilt: 5.5 5.2 0"),
            Param(name="headJoints", value="HeadYaw HeadPitch"),
            Param(
                name="cameras", value="rgb: 577.3 577.3 319.5 239.5 640 480; pantilt: 723.3 723.3 319.5 239.5 640 480"
            ),
        ),
    )
    plugin = FeatureFusion(record)
    plugin.setup()
    assert plugin.frame == "map" and plugin.catalog["cylinder_green_checker"] == ("cylinder", "green_checker")
