"""The lab Turtlebot's arm in a bare pybullet world, for the lab's tests and benchmarks (no CKM service:
the general arm is plugin.arm-poses): predefined poses (thesis Fig. 7.20) reached by pybullet's inverse
kinematics (the MoveIt! role of Table 7.1), and the two-finger gripper."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as p

from plugins.sim.robots import Robot

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
        self.wrist = self.joints[3]  # the wrist joint's child link has the joint's index
        self.limits = {j: p.getJointInfo(robot.body, j, physicsClientId=cid)[8:10] for j in self.joints}
        # constant geometry from the model at its current state: wrist-to-tool length, pan axis origin
        wrist_position, _ = robot.link_pose(self.wrist)
        self._tool_length = float(np.linalg.norm(np.subtract(robot.link_pose(self.tool)[0], wrist_position)))
        base_position, base_orientation = robot.link_pose(-1)
        base_rotation = np.array(p.getMatrixFromQuaternion(base_orientation)).reshape(3, 3)
        pan_origin = base_rotation.T @ np.subtract(robot.link_pose(self.joints[0])[0], base_position)
        self._pan_origin = (float(pan_origin[0]), float(pan_origin[1]))

    def solve(self, pose: ArmPose) -> tuple[float, ...]:
        """Joint angles for ``pose``: pybullet's IK brings the wrist joint to the point behind the
        tool target (position only: the pan, shoulder and elbow), and the wrist joint takes the
        rest of the tool's pitch, since the three pitch joints turn about parallel axes."""
        if pose.joints is not None:
            return pose.joints
        assert pose.position is not None
        base_position, base_orientation = self.robot.link_pose(-1)
        rotation = np.array(p.getMatrixFromQuaternion(base_orientation)).reshape(3, 3)
        x, y, _ = pose.position
        pan_x, pan_y = self._pan_origin
        heading = math.atan2(y - pan_y, x - pan_x)
        along = np.array([math.sin(pose.pitch) * math.cos(heading), math.sin(pose.pitch) * math.sin(heading),
                          math.cos(pose.pitch)])
        wrist = np.asarray(base_position) + rotation @ (np.asarray(pose.position) - self._tool_length * along)
        pan, lift, elbow = self._reach(wrist)
        low, high = self.limits[self.joints[3]]
        return pan, lift, elbow, min(max(pose.pitch - lift - elbow, low), high)

    def _reach(self, wrist: np.ndarray, iterations: int = 30) -> tuple[float, float, float]:
        """Pan, shoulder and elbow angles putting the wrist joint at ``wrist`` (world frame).

        pybullet's IK linearises about the joints' current state, so it is re-run from its own
        answer (set on a saved copy of the world's state, restored afterwards: the simulation
        is not disturbed) until the wrist lands within 0.5 mm.
        """
        cid = self.robot.world.client
        body = self.robot.body
        saved = p.saveState(physicsClientId=cid)
        try:
            angles = tuple(self.robot.joint_state(j)[0] for j in self.joints[:3])
            for _ in range(iterations):
                solution = p.calculateInverseKinematics(
                    body, self.wrist, wrist.tolist(), maxNumIterations=100, residualThreshold=1e-6,
                    physicsClientId=cid,
                )
                by_joint = dict(zip(self._movable, solution, strict=True))
                angles = tuple(float(by_joint[j]) for j in self.joints[:3])
                for joint, angle in zip(self.joints[:3], angles, strict=True):
                    p.resetJointState(body, joint, angle, physicsClientId=cid)
                if np.linalg.norm(np.subtract(self.robot.link_pose(self.wrist)[0], wrist)) < 5e-4:
                    break
        finally:
            p.restoreState(saved, physicsClientId=cid)
            p.removeState(saved, physicsClientId=cid)
        return angles[0], angles[1], angles[2]

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
