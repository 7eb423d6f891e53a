"""RoboticArm.MoveIt (Table 7.1, Fig. 7.20) against the real pybullet Turtlebot: every predefined
pose is reached within tolerance, and the gripper closes on an object at the grasp pose and holds it,
in a test room and on the use case's workbench."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pybullet as p
import pytest

from ckmconf.loader import load
from plugins.manipulation.kinematics import read_poses
from plugins.sim.robots import Robot
from plugins.sim.world import World
from tests.conftest import CONFIGS
from tests.plugins.sim.conftest import ROOM, add_box, robot

from .arm_loop import ArmLoop, arm_plugin, to_world

POSES = read_poses(arm_plugin().poses_path)


@pytest.fixture
def loop() -> Iterator[ArmLoop]:
    world = World(ROOM, seed=5)
    plugin = arm_plugin()
    plugin.setup()
    made = ArmLoop(world, robot(world, "turtlebot", (2.0, 2.0, 0.4)), plugin)
    yield made
    plugin.stop()
    world.close()


def test_every_predefined_arm_pose_is_reached_and_puts_the_tool_where_the_pose_file_says(loop: ArmLoop) -> None:
    tolerance = loop.plugin.params["tolerance"]
    for number, name in enumerate(["ready", "pre_grasp", "grasp", "carry", "place", "resting"], 1):
        status = loop.reach({"id": number, "group": "arm", "pose": name})
        assert status == {**status, "state": "reached", "pose": name, "active": True, "error": ""}
        target = loop.plugin.solutions[name].joints
        measured = [loop.robot.joint_state(j)[0] for j in loop.joints[:4]]
        assert max(abs(m - t) for m, t in zip(measured, target, strict=True)) <= tolerance
        pose = POSES.arm[name]
        # within the joint tolerance, the tool point lands within 1 cm of the pose file's target
        assert math.dist(loop.tool_in_base(), (pose.x, pose.y, pose.z)) < 0.01, name
    assert loop.trajectories == 6  # one trajectory per goal
    assert loop.result["active"] == 1


def test_the_gripper_closes_on_an_object_at_the_grasp_pose_and_holds_it_while_the_arm_carries_it(
    loop: ArmLoop,
) -> None:
    grasp = POSES.arm["grasp"]
    top = grasp.z - 0.02  # a 4 cm part on a post, its centre at the grasp point
    cid = loop.world.client
    post = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.03, 0.03, top / 2], physicsClientId=cid)
    p.createMultiBody(0, post, -1, to_world(loop.robot, (grasp.x + 0.01, 0.0, top / 2)), physicsClientId=cid)
    x, y, z = to_world(loop.robot, (grasp.x, 0.0, grasp.z))
    part = add_box(loop.world, (x, y, z), 0.02, [0.0, 0.6, 0.0, 1.0], mass=0.1)
    # square to the fingers: the robot's heading
    p.resetBasePositionAndOrientation(part, (x, y, z), loop.robot.link_pose(-1)[1], physicsClientId=cid)
    loop.world.step(60)
    resting_height = p.getBasePositionAndOrientation(part, physicsClientId=loop.world.client)[0][2]
    steps = [("gripper", "open"), ("arm", "pre_grasp"), ("arm", "grasp"), ("gripper", "closed")]
    for number, (group, pose) in enumerate(steps, 1):
        status = loop.reach({"id": number, "group": group, "pose": pose})
        assert status["state"] == "reached", status
    assert status["holding"] is True  # the fingers stopped on the part, short of closed
    assert loop.gripper.held == part  # the simulator's grasp: both fingers touch it
    status = loop.reach({"id": 5, "group": "arm", "pose": "carry"})
    assert status["state"] == "reached"
    lifted = p.getBasePositionAndOrientation(part, physicsClientId=loop.world.client)[0][2]
    assert loop.gripper.held == part
    assert lifted - resting_height > 0.03  # carry is 4 cm above grasp
    tool = loop.robot.link_pose(loop.robot.link("gripper_tool_link"))[0]
    held_at = p.getBasePositionAndOrientation(part, physicsClientId=cid)[0]
    assert math.dist(held_at, tool) < 0.05  # between the fingers (they reach 2 cm past the tool point)


def test_in_the_use_case_lab_the_arm_picks_the_red_cylinder_off_the_workbench() -> None:
    """environment.xml's workbench cylinder (0.14 kg, 7 cm across, 12 cm tall on the 0.30 m top), the
    Turtlebot stopped with it 0.28 m straight ahead: the PICK sequence of behaviors.xml lifts it."""
    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    with World(environment, seed=1) as lab:
        cylinder = lab.objects["cylinder_red_stripes"]
        truth = lab.pose(cylinder)[0]
        pose = (truth[0], truth[1] - POSES.arm["grasp"].x, math.pi / 2)
        plugin = arm_plugin()
        plugin.setup()
        try:
            loop = ArmLoop(lab, Robot(lab, "turtlebot", lab.load_robot("turtlebot", "turtlebot", pose)), plugin)
            steps = [("gripper", "open"), ("arm", "pre_grasp"), ("arm", "grasp"), ("gripper", "closed"),
                     ("arm", "carry")]
            for number, (group, name) in enumerate(steps, 1):
                assert loop.reach({"id": number, "group": group, "pose": name})["state"] == "reached"
            assert loop.gripper.held == cylinder
            assert lab.pose(cylinder)[0][2] - truth[2] > 0.03  # off the table top
            assert loop.reach({"id": 6, "group": "gripper", "pose": "open"})["state"] == "reached"
            assert loop.gripper.held is None  # opening lets it go
        finally:
            plugin.stop()
