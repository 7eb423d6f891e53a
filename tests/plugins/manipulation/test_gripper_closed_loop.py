"""plugin.parallel-gripper and Cartesian arm-motion goals against the real pybullet robots, on two
models: the Turtlebot's 4-DOF arm and two-finger gripper (a 4 cm part on a post), and the station
arm's turret, two pitch joints and parallel jaw (a 0.3 m parcel on a work table). The grasp is the
simulator's (two-finger contact, plugins/sim/grasp.py): the object must rise with the gripper."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pybullet as p
import pytest

from plugins.sim.robots import Robot
from plugins.sim.world import World
from tests.plugins.sim.conftest import ROOM

from .arm_loop import to_world
from .manipulator_loop import STATION, TURTLEBOT, ManipulatorLoop, Model, arm_service, gripper_service


def _loop(model: Model, pose: tuple[float, float, float]) -> Iterator[ManipulatorLoop]:
    world = World(ROOM, seed=5)
    arm, gripper = arm_service(model), gripper_service(model)
    arm.setup()
    gripper.setup()
    robot = Robot(world, model.name, world.load_robot(model.name, model.name, pose))
    world.step(24)
    try:
        yield ManipulatorLoop(world, robot, model, arm, gripper)
    finally:
        arm.stop()
        world.close()


@pytest.fixture
def turtlebot() -> Iterator[ManipulatorLoop]:
    yield from _loop(TURTLEBOT, (2.0, 2.0, 0.4))


@pytest.fixture
def station() -> Iterator[ManipulatorLoop]:
    yield from _loop(STATION, (1.0, 1.0, 0.0))


def _height(loop: ManipulatorLoop, body: int) -> float:
    return float(p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[0][2])


def _box(loop: ManipulatorLoop, centre: tuple[float, float, float], half: tuple[float, float, float],
         mass: float) -> int:
    """A box at a base-frame ``centre``, square to the robot's heading (static when ``mass`` is 0)."""
    cid = loop.world.client
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=cid)
    body = int(p.createMultiBody(mass, shape, -1, to_world(loop.robot, centre), loop.robot.link_pose(-1)[1],
                                 physicsClientId=cid))
    p.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=cid)
    return body


def _pick(loop: ManipulatorLoop, body: int, approach: dict[str, float], grasp: dict[str, float],
          lift: dict[str, float]) -> float:
    """Open, approach, grasp, close (holding), lift; the object's rise."""
    resting = _height(loop, body)
    assert loop.grip({"id": 1, "action": "open"})["state"] == "reached"
    for number, target in enumerate((approach, grasp), 2):
        status = loop.move({"id": number, "group": "arm", "target": target})
        assert status["state"] == "reached", status
        assert math.dist(loop.tool_in_base(), (target["x"], target["y"], target["z"])) < 0.015
    closed = loop.grip({"id": 4, "action": "close", "max_effort": 20.0})
    assert closed["state"] == "holding" and closed["holding"] is True, closed
    assert closed["opening"] > 0.05  # stopped on the object, short of closed
    assert loop.gripper_result["holding"] == 1
    assert loop.grasp.held == body
    assert loop.move({"id": 5, "group": "arm", "target": lift})["state"] == "reached"
    assert loop.grasp.held == body and loop.gripper_result["status"]["state"] == "holding"
    return _height(loop, body) - resting


def test_the_turtlebot_gripper_and_cartesian_arm_goals_lift_a_part(turtlebot: ManipulatorLoop) -> None:
    loop = turtlebot
    grasp = {"x": 0.28, "y": 0.0, "z": 0.36, "pitch": math.pi / 2}
    top = grasp["z"] - 0.02  # a 4 cm part on a post, its centre at the grasp point
    _box(loop, (grasp["x"] + 0.01, 0.0, top / 2), (0.03, 0.03, top / 2), 0.0)
    part = _box(loop, (grasp["x"], 0.0, grasp["z"]), (0.02, 0.02, 0.02), 0.1)
    loop.world.step(60)
    rise = _pick(loop, part, {**grasp, "x": 0.22}, grasp, {"x": 0.22, "y": 0.0, "z": 0.40, "pitch": 1.3})
    assert rise > 0.03
    opened = loop.grip({"id": 6, "action": "open"})
    assert opened["state"] == "reached" and opened["holding"] is False
    assert loop.grasp.held is None and loop.gripper_result["holding"] == 0  # opening lets it go


def test_the_station_arm_jaw_lifts_a_parcel_off_its_work_table(station: ManipulatorLoop) -> None:
    loop = station
    _box(loop, (0.55, 0.0, 0.35), (0.2, 0.25, 0.35), 0.0)  # the work table, top at 0.70 m
    parcel = _box(loop, (0.5, 0.0, 0.776), (0.1, 0.15, 0.075), 0.5)  # 0.2 x 0.3 x 0.15 m, 0.5 kg
    loop.world.step(60)
    grasp = {"x": 0.5, "y": 0.0, "z": 0.80}  # 5 cm under its top: no pitch, the point decides it (D264)
    rise = _pick(loop, parcel, {**grasp, "z": 0.95}, grasp, {**grasp, "z": 1.0})
    assert rise > 0.15
    assert loop.gripper_result["status"]["position"] == pytest.approx(0.15 - 0.03, abs=0.01)  # on its sides
    assert loop.grip({"id": 6, "action": "open"})["state"] == "reached"
    assert loop.grasp.held is None


def test_a_goal_beyond_reach_or_a_pitch_the_station_cannot_set_is_refused_with_its_reason(
    station: ManipulatorLoop,
) -> None:
    far = station.move({"id": 1, "group": "arm", "target": {"x": 1.5, "y": 0.0, "z": 0.8}})
    assert far["state"] == "failed" and "out of reach: the nearest tool point is" in far["error"]
    tilted = station.move({"id": 2, "group": "arm", "target": {"x": 0.5, "y": 0.0, "z": 0.8, "pitch": 1.0}})
    assert tilted["state"] == "failed"
    assert "cannot set the pitch at that point: the tool points at 2.648 rad there, not 1.000" in tilted["error"]
    kept = station.move({"id": 3, "group": "arm", "target": {"x": 0.5, "y": 0.0, "z": 0.8, "pitch": 2.6}})
    assert kept["state"] == "reached"  # within pitchTolerance of what the point gives


def test_a_newer_gripper_command_preempts_the_older_without_a_stale_status(turtlebot: ManipulatorLoop) -> None:
    loop = turtlebot
    loop.command = {"id": 10, "action": "open"}
    loop.run(0.1)
    assert loop.gripper_result["status"]["id"] == 10 and loop.gripper_result["status"]["state"] == "moving"
    loop.command = {"id": 11, "action": "close"}  # before the opening ends
    seen = []
    for _ in range(60):
        loop.run(0.05)
        seen.append((loop.gripper_result["status"]["id"], loop.gripper_result["status"]["state"]))
    assert {ident for ident, _ in seen} == {11}  # never the open command's again
    assert seen[-1] == (11, "reached")  # closed on nothing: reached, not holding
    assert loop.gripper_result["holding"] == 0
