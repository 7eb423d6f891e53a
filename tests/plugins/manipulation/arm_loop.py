"""The RoboticArm.MoveIt plugin in a closed loop with the simulated Turtlebot arm.

The loop plays what the use case's turtlebot node does (configs/usecase/nodes.xml): the arm's bus
sensor publishes a JointState without names at 20 Hz, the joint-trajectory controller (the real
``controller.joint-trajectory``, nodes.xml's Params) plays the plugin's trajectories at 60 Hz, and
its commands drive the joints in position mode (the gripper's on both fingers, as the ``mirror``
Param does, at the URDF's effort limit as ``hardware.sim`` does). The plugin sees only its input messages;
the physics is stepped here, in simulated time, and the gripper channel's grasp
(:class:`plugins.sim.grasp.ChannelGrasp`, as ``hardware.sim`` makes it from the ``grasp`` Param)
decides when an object is held.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any

import numpy as np
import pybullet as p
from ckm_lab.devices import KOBUKI

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.controllers.trajectory import JointTrajectory
from plugins.manipulation.arm_poses import ArmPoses
from plugins.sim.grasp import ChannelGrasp
from plugins.sim.robots import DiffDriveBase, Robot
from plugins.sim.world import World
from runtime.resources.spt import Context
from tests.conftest import CONFIGS
from tests.plugins.controllers.vector_records import record

RESOURCES = CONFIGS / "usecase" / "resources.xml"
CONTROL_STEPS = 4  # the controller at 60 Hz on the 240 Hz physics
SERVICE_STEPS = 12  # joint states and the service at 20 Hz

JOINTS = "arm_shoulder_pan_joint arm_shoulder_lift_joint arm_elbow_flex_joint arm_wrist_flex_joint gripper_joint"
"""The Turtlebot arm's joints, as configs/usecase/resources.xml gives them to its arm-poses service."""


def arm_plugin(**params: object) -> ArmPoses:
    """The arm-poses plugin of the use case's resources.xml, with its Params there (its pose file:
    models/arm_poses.yml) but for those ``params`` override."""
    ns = {"c": ET.parse(RESOURCES).getroot().tag.partition("}")[0][1:]}
    record = ET.parse(RESOURCES).getroot().find(".//c:Plugin[@kind='arm-poses']", ns)
    assert record is not None, "resources.xml declares no arm-poses plugin"
    declared = {q.get("name", ""): q.get("value", "") for q in record.findall("c:Param", ns)}
    given = tuple(Param(name=k, value=str(v)) for k, v in {**declared, **params}.items())
    return ArmPoses(Plugin(name="moveit", kind="arm-poses", params=given, loc=Loc(str(RESOURCES), 1, 1, "/Plugin")))


def controller() -> JointTrajectory:
    """nodes.xml's arm_trajectory controller."""
    outputs = ["pan_cmd", "lift_cmd", "elbow_cmd", "wrist_cmd", "gripper_cmd"]
    return JointTrajectory(record(
        "joint-trajectory", 0.02, [("/arm/joint_trajectory", "setpoint"), ("/arm/joint_states", "measure")],
        outputs, 50, joints=JOINTS, interpolation="cubic", maxVelocity="1.5 1.0 1.0 1.5 1.0",
        lowerLimits="-2.6 -2.2 -2.6 -1.8 -0.5", upperLimits="2.6 2.2 2.6 1.8 0.9",
    ))


class ArmLoop:
    """Service plugin → controller → simulated joints → joint states → service plugin."""

    def __init__(self, world: World, robot: Robot, plugin: ArmPoses) -> None:
        self.world, self.robot, self.plugin = world, robot, plugin
        self.controller = controller()
        self.joints = [robot.joint(name) for name in JOINTS.split()]
        self.mirror = robot.joint("gripper_right_joint")
        self.gripper = ChannelGrasp(robot, "gripper_joint", "gripper_right_joint", "arm_wrist_flex_link", 30.0)
        DiffDriveBase(robot, **KOBUKI)  # the wheels held at rest (braked), as the Kobuki's loops do when idle
        self.goal: dict[str, Any] | None = None
        self.trajectory: Any = None
        self.result: dict[str, Any] = {}
        self.trajectories = 0
        self.frames = 0

    def joint_states(self) -> dict[str, Any]:
        """What the arm_joints sensor publishes (D99): no names, positions in the channel's order."""
        positions = np.array([self.robot.joint_state(j)[0] for j in self.joints])
        return {"stamp": self.world.time, "name": [], "position": positions}

    def service(self) -> dict[str, Any]:
        data = {"goal": self.goal, "joint_states": self.joint_states()}
        self.result = self.plugin.process(data, Context(self.frames, self.world.time, "RoboticArm"))
        self.frames += 1
        if "trajectory" in self.result:
            self.trajectory = self.result["trajectory"]
            self.trajectories += 1
        return self.result

    def control(self) -> None:
        measure = [self.robot.joint_state(j)[0] for j in self.joints]
        inputs = {"setpoint": self.trajectory, "measure": measure}
        commands = self.controller.step_outputs(inputs, CONTROL_STEPS * self.world.time_step)
        for joint, command in zip(self.joints[:4], commands, strict=False):
            self.robot.command(joint, "position", float(command))
        for finger in (self.joints[4], self.mirror):  # at the URDF's effort limit, as hardware.sim drives them
            self.robot.command(finger, "position", float(commands[4]))
        self.gripper.command(float(commands[4]))

    def run(self, seconds: float) -> None:
        """Advance the loop by ``seconds`` of simulated time."""
        for _ in range(round(seconds * 240 / SERVICE_STEPS)):
            for _ in range(SERVICE_STEPS // CONTROL_STEPS):
                self.control()
                self.world.step(CONTROL_STEPS)  # the grasp checks its fingers after each advance
            self.service()

    def reach(self, goal: Mapping[str, Any], limit: float = 15.0) -> dict[str, Any]:
        """Send ``goal`` and run until its status is reached or failed (at most ``limit`` s simulated)."""
        self.goal = dict(goal)
        start = self.world.time
        while self.world.time - start < limit:
            self.run(SERVICE_STEPS / 240)
            status = self.result.get("status", {})
            if status.get("id") == goal["id"] and status.get("state") in ("reached", "failed"):
                return dict(status)
        raise AssertionError(f"goal {goal} neither reached nor failed in {limit} s: {self.result}")

    def tool_in_base(self) -> tuple[float, float, float]:
        """The tool point in the robot's base frame (ground truth from the simulation)."""
        base, orientation = self.robot.link_pose(-1)
        rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        tool = self.robot.link_pose(self.robot.link("gripper_tool_link"))[0]
        x, y, z = rotation.T @ (np.asarray(tool) - np.asarray(base))
        return float(x), float(y), float(z)


def to_world(robot: Robot, point: tuple[float, float, float]) -> list[float]:
    """A base-frame point in the world."""
    base, orientation = robot.link_pose(-1)
    yaw = p.getEulerFromQuaternion(orientation)[2]
    x, y, z = point
    return [base[0] + x * math.cos(yaw) - y * math.sin(yaw), base[1] + x * math.sin(yaw) + y * math.cos(yaw),
            base[2] + z]
