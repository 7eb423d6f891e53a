"""Texture skins (plugins/sim/skins.py, D145): the World built from the use case's environment.xml shows
the workbench's learnt prints to the Turtlebot's Xtion, so the real RGB pipeline of resources.xml's
RGBDCamera VGA profile (camera-acquisition → image-resize → orb-keypoints → keypoint-matching)
recognises the red-striped cylinder and tells it from the blue-dotted one; the skin is visual only; a
render worker's mirror world wears the same skins."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

import numpy as np
import pybullet as p
import pytest
from ckm_lab.arm import ARM_JOINTS, POSES
from ckm_lab.devices import XTION_FOV
from ckm_lab.scenes import USECASE_MODEL

from ckmconf.loader import load
from plugins.processing.textures import read_model
from plugins.sim.plan import WorldPlan
from plugins.sim.render import RenderWorker
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera, Frame
from plugins.sim.world import World
from runtime.resources.spt import Topology
from tests.conftest import CONFIGS

ENVIRONMENT = CONFIGS / "usecase" / "environment.xml"
POSE = "7.6 5.35 1.5708"
"""Where the Turtlebot stands before the workbench (nodes.xml's NAV goal), facing +y: the red-striped
cylinder 0.75 m ahead, the blue-dotted one 0.35 m to its right."""
LINK = "camera_rgb_optical_frame"


@pytest.fixture(scope="module")
def recog() -> Iterator[Topology]:
    """RGBDCamera.RGBRecog's VGA profile from the use case's resources.xml."""
    resource = load(CONFIGS / "usecase" / "resources.xml").resource("RGBDCamera")
    assert resource is not None
    profiles = tuple(q for q in resource.profiles if q.name == "VGA")
    used = {name for q in profiles for name in q.root.plugins()}
    part = dataclasses.replace(resource, plugins=tuple(x for x in resource.plugins if x.name in used),
                               profiles=profiles)
    topology = Topology(part)
    topology.setup()
    topology.select("VGA", "VGA")
    yield topology
    topology.stop()


def _turtlebot(world: World) -> Robot:
    """The Turtlebot at POSE with its arm at rest (out of the Xtion's view)."""
    robot = Robot(world, "turtlebot", world.load_robot("turtlebot", "turtlebot", [float(v) for v in POSE.split()]))
    for joint, angle in zip(ARM_JOINTS, POSES["rest"].joints or (), strict=True):
        p.resetJointState(robot.body, robot.joint(joint), angle, physicsClientId=world.client)
    return robot


def _column(world: World, robot: Robot, frame: Frame, name: str) -> float:
    """The image column (0–1) of object ``name``'s centre, projected through the camera's pinhole."""
    position, orientation = robot.link_pose(robot.link(LINK))
    rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
    centre = np.asarray(world.pose(world.objects[name])[0])
    x, _, z = rotation.T @ (centre - np.asarray(position))
    return float((frame.fx * x / z + frame.cx) / frame.rgb.shape[1])


def test_the_xtion_recognises_the_red_cylinder_and_tells_it_from_the_blue_one(recog: Topology) -> None:
    environment = load(ENVIRONMENT).environment
    assert environment is not None
    with World(environment, seed=1, catalog=read_model(USECASE_MODEL)) as world:
        robot = _turtlebot(world)
        frame = Camera(robot, LINK, fov=XTION_FOV).render(640, 480)
        found: dict[str, Any] = {o["name"]: o for o in recog.run(frame.rgb, 0.0).outputs["VGA"]["objects"]}
        red = _column(world, robot, frame, "cylinder_red_stripes")
        blue = _column(world, robot, frame, "cylinder_blue_dots")
    assert 0.3 < red < 0.7 and blue > red + 0.2  # both in view, the blue one to the right
    assert "cylinder_red_stripes" in found and found["cylinder_red_stripes"]["inliers"] >= 8
    # named where the red cylinder stands (half its 7 cm width is 0.05 of the image at 0.75 m) ...
    assert abs(found["cylinder_red_stripes"]["x"] - red) < 0.08
    # ... and the blue one, if named, only where it stands: never mistaken for the red one
    if "cylinder_blue_dots" in found:
        assert abs(found["cylinder_blue_dots"]["x"] - blue) < 0.08


def test_the_skin_is_visual_only() -> None:
    """The cylinder's collision shape is still the plain prism (radius 3.5 cm, 12 cm tall), its mass the
    cylinder's; its visual shape is the skin mesh wearing the learnt print."""
    environment = load(ENVIRONMENT).environment
    assert environment is not None
    with World(environment, seed=1, catalog=read_model(USECASE_MODEL)) as world:
        cid = world.client
        body = world.objects["cylinder_red_stripes"]
        assert world.skins["cylinder_red_stripes"].name == "cylinder_red_stripes"
        assert "box_orange" not in world.skins  # a plain print: nothing to learn, no skin
        collision = p.getCollisionShapeData(body, -1, physicsClientId=cid)[0]
        assert collision[2] == p.GEOM_CYLINDER
        assert collision[3][:2] == pytest.approx((0.12, 0.035))  # (height, radius)
        visual = p.getVisualShapeData(body, physicsClientId=cid)[0]
        assert visual[2] == p.GEOM_MESH
        mass = p.getDynamicsInfo(body, -1, physicsClientId=cid)[0]
        assert mass == pytest.approx(300.0 * np.pi * 0.035**2 * 0.12)
        world.step(240)  # it stands on the workbench as before: it neither sinks nor falls
        assert world.pose(body)[0] == pytest.approx((7.6, 6.1, 0.36), abs=0.003)


def test_a_render_worker_mirror_wears_the_same_skins() -> None:
    """A render worker builds its mirror from the run's WorldPlan: its frame equals the server's own."""
    plan = WorldPlan(str(ENVIRONMENT), 1, str(USECASE_MODEL), {"turtlebot": ("turtlebot", POSE)})
    sim = plan.build()
    worker = RenderWorker(plan)
    try:
        robot = sim.robots["turtlebot"]
        for joint, angle in zip(ARM_JOINTS, POSES["rest"].joints or (), strict=True):
            p.resetJointState(robot.body, robot.joint(joint), angle, physicsClientId=sim.world.client)
        assert worker.await_ready(120.0)
        camera = Camera(robot, LINK, fov=XTION_FOV)
        worker.submit(sim.world, ("turtlebot", LINK, camera.fov, 320, 240))
        mirrored = worker.result()
        assert isinstance(mirrored, Frame), mirrored
        own = camera.render(320, 240)
        assert np.array_equal(mirrored.rgb, own.rgb)
        assert set(sim.world.skins) == {"cylinder_red_stripes", "cylinder_blue_dots", "cylinder_green_checker",
                                        "box_cereal"}
    finally:
        worker.close()
        sim.world.close()
