"""The mobile manipulator's arm: predefined poses (thesis Fig. 7.20) reached by pybullet's inverse
kinematics (the MoveIt! role of Table 7.1), and the two-finger gripper."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p

from .robots import Robot

ARM_JOINTS = ("arm_shoulder_pan_joint", "arm_shoulder_lift_joint", "arm_elbow_flex_joint", "arm_wrist_flex_joint")


@dataclass(frozen=True)
class ArmPose:
    """A predefined pose: joint angles (``joints``), or a tool-point target in the base frame
    (``position``, m) with the tool's pitch (rad; π/2 points the gripper forward, π down)."""

    joints: tuple[float, ...] | None = None
    position: tuple[float, float, float] | None = None
    pitch: float = math.pi / 2


POSES: Mapping[str, ArmPose] = {
    "rest": ArmPose(joints=(0.0, -0.4, 2.0, 1.2)),
    "pre-grasp": ArmPose(position=(0.28, 0.0, 0.20)),
    "grasp": ArmPose(position=(0.33, 0.0, 0.20)),
    "lift": ArmPose(position=(0.30, 0.0, 0.32)),
    "carry": ArmPose(position=(0.22, 0.0, 0.34)),
    "place": ArmPose(position=(0.33, 0.0, 0.22)),
}
"""Fig. 7.20's predefined positions for the turtlebot.urdf arm (tool point in the base frame)."""


class Arm:
    """The arm joints of a robot, driven to predefined poses through inverse kinematics."""

    def __init__(
        self, robot: Robot, *, joints: Sequence[str] = ARM_JOINTS, tool: str = "gripper_tool_link",
        poses: Mapping[str, ArmPose] = POSES, force: float = 3.0,
    ) -> None:
        self.robot = robot
        self.joints = [robot.joint(name) for name in joints]
        self.tool = robot.link(tool)
        self.poses = dict(poses)
        self.force = force
        cid = robot.world.client
        # calculateInverseKinematics answers one value per movable joint, in joint order
        self._movable = [j for j in range(p.getNumJoints(robot.body, physicsClientId=cid))
                         if p.getJointInfo(robot.body, j, physicsClientId=cid)[2] != p.JOINT_FIXED]
        self.target: tuple[float, ...] = tuple(robot.joint_state(j)[0] for j in self.joints)

    def solve(self, pose: ArmPose) -> tuple[float, ...]:
        """Joint angles for ``pose`` (IK for a tool target)."""
        if pose.joints is not None:
            return pose.joints
        assert pose.position is not None
        base_position, base_orientation = self.robot.link_pose(-1)
        rotation = np.array(p.getMatrixFromQuaternion(base_orientation)).reshape(3, 3)
        target = np.asarray(base_position) + rotation @ np.asarray(pose.position)
        yaw = p.getEulerFromQuaternion(base_orientation)[2]
        orientation = p.getQuaternionFromEuler([0.0, pose.pitch, yaw])
        solution = p.calculateInverseKinematics(
            self.robot.body, self.tool, target.tolist(), orientation, maxNumIterations=200,
            residualThreshold=1e-5, physicsClientId=self.robot.world.client,
        )
        by_joint = dict(zip(self._movable, solution, strict=False))
        return tuple(float(by_joint[j]) for j in self.joints)

    def go(self, name: str) -> tuple[float, ...]:
        """Start moving to the predefined pose ``name``; returns the joint target."""
        if name not in self.poses:
            raise KeyError(f"arm pose {name!r} is not one of {', '.join(self.poses)}")
        self.target = self.solve(self.poses[name])
        for joint, angle in zip(self.joints, self.target, strict=False):
            self.robot.command(joint, "position", angle, self.force)
        return self.target

    def error(self) -> float:
        """Largest joint distance (rad) to the current target."""
        return max(abs(self.robot.joint_state(j)[0] - t) for j, t in zip(self.joints, self.target, strict=False))

    def tool_position(self) -> tuple[float, ...]:
        """World position of the tool point."""
        return self.robot.link_pose(self.tool)[0]
