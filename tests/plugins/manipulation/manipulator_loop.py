"""An arm-motion service (plugin.arm-poses, its gripper left out) and a gripper service
(plugin.parallel-gripper) in a closed loop with a simulated robot, for any robot model.

As a node would run them: the joint states at 20 Hz, one ``controller.joint-trajectory`` per service
at 60 Hz (the arm's joints; the measured finger joint), its commands driving the joints in position
mode (the finger's also on its ``mirror``, as the sim channel's Param does), and the gripper
channel's grasp (:class:`plugins.sim.grasp.ChannelGrasp`, as ``hardware.sim`` makes it from the
``grasp`` Param) deciding what the fingers hold. The services see only their input messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet as p

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.controllers.trajectory import JointTrajectory
from plugins.manipulation.arm_poses import ArmPoses
from plugins.manipulation.gripper import ParallelGripper
from plugins.sim.grasp import ChannelGrasp
from plugins.sim.robots import Robot
from plugins.sim.world import World
from runtime.resources.spt import Context
from tests.conftest import CONFIGS, REPO
from tests.plugins.controllers.vector_records import record

CONTROL_STEPS = 4  # the controllers at 60 Hz on the 240 Hz physics
SERVICE_STEPS = 12  # joint states and the services at 20 Hz


@dataclass(frozen=True)
class Model:
    """A robot model's arm and gripper, as a system's Params would name them."""

    name: str
    arm: tuple[str, ...]
    finger: str
    mirror: str
    palm: str
    poses: str
    hold_force: float


TURTLEBOT = Model("turtlebot", ("arm_shoulder_pan_joint", "arm_shoulder_lift_joint", "arm_elbow_flex_joint",
                                "arm_wrist_flex_joint"), "gripper_joint", "gripper_right_joint",
                  "arm_wrist_flex_link", str(CONFIGS / "usecase" / "models" / "arm_poses.yml"), 30.0)
STATION = Model("station_arm", ("turret_joint", "shoulder_joint", "elbow_joint"), "left_finger_joint",
                "right_finger_joint", "palm_link", str(CONFIGS / "examples" / "models" / "station_arm_poses.yml"),
                60.0)
LOC = Loc(str(REPO / "configs" / "examples" / "sim_station.xml"), 1, 1, "/Plugin")


def plugin_record(name: str, kind: str, **params: object) -> Plugin:
    return Plugin(name=name, kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in params.items()), loc=LOC)


def arm_service(model: Model, **params: object) -> ArmPoses:
    """plugin.arm-poses on the model's arm alone (Param gripper false)."""
    given = {"model": model.name, "poses": model.poses, "joints": " ".join(model.arm), "gripper": "false",
             "timeout": 3.0, **params}
    return ArmPoses(plugin_record("arm", "arm-poses", **given))


def gripper_service(model: Model, **params: object) -> ParallelGripper:
    """plugin.parallel-gripper on the model's measured finger joint."""
    given = {"model": model.name, "joints": model.finger, **params}
    return ParallelGripper(plugin_record("gripper", "parallel-gripper", **given))


def _controller(joints: tuple[str, ...], velocity: str) -> JointTrajectory:
    outputs = [f"j{i}" for i in range(len(joints))]
    return JointTrajectory(record("joint-trajectory", 0.02, [("/setpoint", "setpoint"), ("/measure", "measure")],
                                  outputs, 50, joints=" ".join(joints), interpolation="cubic", maxVelocity=velocity))


class ManipulatorLoop:
    """Both services → their controllers → simulated joints → joint states → both services."""

    def __init__(self, world: World, robot: Robot, model: Model, arm: ArmPoses, gripper: ParallelGripper) -> None:
        self.world, self.robot, self.model = world, robot, model
        self.arm, self.gripper = arm, gripper
        self.arm_joints = [robot.joint(j) for j in model.arm]
        self.finger, self.mirror = robot.joint(model.finger), robot.joint(model.mirror)
        self.arm_control = _controller(model.arm, "1.5")
        self.finger_control = _controller((model.finger,), "1.0")
        self.grasp = ChannelGrasp(robot, model.finger, model.mirror, model.palm, model.hold_force)
        self.arm_goal: dict[str, Any] | None = None
        self.command: dict[str, Any] | None = None
        self.arm_result: dict[str, Any] = {}
        self.gripper_result: dict[str, Any] = {}
        self.trajectories: dict[str, Any] = {"arm": None, "gripper": None}
        self.frames = 0

    def _states(self, joints: list[int]) -> dict[str, Any]:
        positions = np.array([self.robot.joint_state(j)[0] for j in joints])
        return {"stamp": self.world.time, "name": [], "position": positions}

    def services(self) -> None:
        context = Context(self.frames, self.world.time, "manipulator")
        self.frames += 1
        self.arm_result = self.arm.process({"goal": self.arm_goal, "joint_states": self._states(self.arm_joints)},
                                           context)
        self.gripper_result = self.gripper.process(
            {"command": self.command, "joint_states": self._states([self.finger])}, context)
        for name, result in (("arm", self.arm_result), ("gripper", self.gripper_result)):
            if "trajectory" in result:
                self.trajectories[name] = result["trajectory"]

    def control(self) -> None:
        dt = CONTROL_STEPS * self.world.time_step
        measure = [self.robot.joint_state(j)[0] for j in self.arm_joints]
        commands = self.arm_control.step_outputs({"setpoint": self.trajectories["arm"], "measure": measure}, dt)
        for joint, command in zip(self.arm_joints, commands, strict=True):
            self.robot.command(joint, "position", float(command))
        finger = self.finger_control.step_outputs(
            {"setpoint": self.trajectories["gripper"], "measure": [self.robot.joint_state(self.finger)[0]]}, dt)
        for joint in (self.finger, self.mirror):  # at the URDF's effort limit, as hardware.sim drives them
            self.robot.command(joint, "position", float(finger[0]))
        self.grasp.command(float(finger[0]))

    def run(self, seconds: float) -> None:
        """Advance the loop by ``seconds`` of simulated time."""
        for _ in range(round(seconds * 240 / SERVICE_STEPS)):
            for _ in range(SERVICE_STEPS // CONTROL_STEPS):
                self.control()
                self.world.step(CONTROL_STEPS)  # the grasp checks its fingers after each advance
            self.services()

    def _until(self, result: str, ident: int, ends: tuple[str, ...], limit: float) -> dict[str, Any]:
        start = self.world.time
        while self.world.time - start < limit:
            self.run(SERVICE_STEPS / 240)
            status = getattr(self, result).get("status", {})
            if status.get("id") == ident and status.get("state") in ends:
                return dict(status)
        raise AssertionError(f"goal {ident} did not end in {limit} s: {getattr(self, result)}")

    def move(self, goal: Mapping[str, Any], limit: float = 15.0) -> dict[str, Any]:
        """Send an arm goal; its status once reached or failed."""
        self.arm_goal = dict(goal)
        return self._until("arm_result", goal["id"], ("reached", "failed"), limit)

    def grip(self, command: Mapping[str, Any], limit: float = 10.0) -> dict[str, Any]:
        """Send a gripper command; its status once it ended."""
        self.command = dict(command)
        return self._until("gripper_result", command["id"], ("reached", "holding", "stalled", "failed"), limit)

    def tool_in_base(self) -> tuple[float, float, float]:
        """The tool point in the robot's base frame (ground truth from the simulation)."""
        base, orientation = self.robot.link_pose(-1)
        rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        tool = self.robot.link_pose(self.robot.link("gripper_tool_link"))[0]
        x, y, z = rotation.T @ (np.asarray(tool) - np.asarray(base))
        return float(x), float(y), float(z)
