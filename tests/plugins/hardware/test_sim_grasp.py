"""``hardware.sim`` Param ``grasp``: a gripper channel whose fingers hold what they close on (D87, D187).

Without it the use case's cylinder was held by finger friction alone and slid out while the base
drove home; with it the object both fingers touch is fixed to the wrist until a command opens them."""

from __future__ import annotations

from typing import Any

import pybullet as p
import pytest

from plugins.hardware.simulation import ManualClock, PlantScope
from runtime.kernel.interfaces import ParamError
from tests.plugins.sim.conftest import add_box
from tests.plugins.sim.test_backend import channel, open_all

SCALE, OFFSET = 0.0051183, 511.5  # AX-12 steps, as configs/usecase/nodes.xml
OPEN, CLOSED = OFFSET + 0.045 / SCALE, OFFSET  # the fingers' joint: 0 closed, 0.045 m open
GRIPPER = {"joint": "gripper_joint", "mirror": "gripper_right_joint", "mode": "position", "scale": str(SCALE),
           "offset": str(OFFSET), "body": "turtlebot"}  # fmt: skip


def _open_gripper(name: str) -> tuple[ManualClock, Any, Any, Any]:
    """A gripper channel with ``grasp`` on a Turtlebot at (1, 1), its fingers opened; its world and device."""
    clock = ManualClock()
    (gripper,) = open_all(PlantScope(clock, name=name), channel("gripper", "out", "bus", 1,
                          grasp="arm_wrist_flex_link", pose="1 1 0", **GRIPPER))  # fmt: skip
    gripper.write(OPEN)
    clock.advance(1.0)
    gripper.write(OPEN)  # a write advances the world to the clock first
    sim, device = gripper._require()  # type: ignore[attr-defined]
    return clock, gripper, sim, device


def test_the_fingers_hold_what_they_close_on_until_they_open() -> None:
    clock, gripper, sim, device = _open_gripper("grasp-test")
    robot, world = device.robot, sim.world
    cid = world.client
    tool = robot.link_pose(robot.link("gripper_tool_link"))[0]
    part = add_box(world, tool, 0.012, [0.0, 0.6, 0.0, 1.0], mass=0.05)
    p.resetBasePositionAndOrientation(part, tool, robot.link_pose(robot.link("gripper_tool_link"))[1],
                                      physicsClientId=cid)  # fmt: skip
    p.changeConstraint(p.createConstraint(part, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], tool,
                                          physicsClientId=cid), maxForce=5.0, physicsClientId=cid)  # fmt: skip
    gripper.write(CLOSED)
    clock.advance(2.0)
    gripper.write(CLOSED)  # the actuator repeats its command: still closing
    assert device.grasp.held == part  # both fingers touch it: held to the wrist
    clock.advance(0.5)
    gripper.write(CLOSED)
    assert device.grasp.held == part
    caught = device.grasp.opening_held
    for _ in range(6):  # closing on and on: the fingers stall on it, they do not wedge it out
        clock.advance(0.5)
        gripper.write(CLOSED)
    assert device.grasp.held == part
    assert caught - 0.002 < robot.joint_state(robot.joint("gripper_joint"))[0] <= caught + 1e-4
    gripper.write(OPEN)
    assert device.grasp.held == part  # a command alone does not: the fingers must open
    clock.advance(0.5)
    gripper.write(OPEN)
    assert device.grasp.held is None  # they opened: let go


def test_without_grasp_nothing_is_held() -> None:
    (gripper,) = open_all(PlantScope(ManualClock(), name="grasp-none"), channel("gripper", "out", "bus", 1, **GRIPPER))
    assert gripper._require()[1].grasp is None  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("direction", "params", "message"),
    [
        # The device table's messages (D295): a gripper is an out device, has two fingers, holds a position.
        (
            "in",
            {"joint": "gripper_joint", "mirror": "gripper_right_joint"},
            "a bus in channel cannot be the joint \\+ grasp device: it is served as analog out or bus out",
        ),
        ("out", {"joint": "gripper_joint"}, r"the gripper device \(bus out, joint \+ grasp\) needs Param 'mirror'"),
        (
            "out",
            {"joint": "gripper_joint", "mirror": "gripper_right_joint", "mode": "velocity"},
            r"Param 'mode' is 'velocity': the gripper device \(bus out, joint \+ grasp\) takes position",
        ),
    ],
)
def test_a_bad_grasp_is_refused_naming_the_channel(direction: str, params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=message) as caught:
        open_all(
            PlantScope(ManualClock(), name="grasp-bad"),
            channel("gripper", direction, "bus", 1, body="turtlebot", grasp="arm_wrist_flex_link", **params),
        )
    assert "sim channel 'gripper'" in str(caught.value)


def test_a_static_body_between_the_fingers_is_never_grasped() -> None:
    """The open fingers brushing the drop table while the arm folds must not fix the arm to the table."""
    clock, gripper, _, device = _open_gripper("grasp-static")
    robot = device.robot
    tool, orientation = robot.link_pose(robot.link("gripper_tool_link"))
    table = add_box(device.sim.world, tool, 0.012, [0.6, 0.4, 0.2, 1.0])  # mass 0: static
    p.resetBasePositionAndOrientation(table, tool, orientation, physicsClientId=device.sim.world.client)
    gripper.write(CLOSED)
    clock.advance(2.0)
    gripper.write(CLOSED)
    assert device.grasp.held is None
