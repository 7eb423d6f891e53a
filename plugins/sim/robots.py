"""Robot bodies of the simulated laboratory: joints by name, and the differential-drive base
with wheel encoders and noisy odometry (thesis §7.1, Table 7.1 "Mobile Base Displacement")."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import pybullet as p

from .world import World


class Robot:
    """A URDF body in a :class:`World`, with its joints and links looked up by name."""

    def __init__(self, world: World, name: str, body: int) -> None:
        self.world = world
        self.name = name
        self.body = body
        self.joints: dict[str, int] = {}
        self.links: dict[str, int] = {"base_link": -1}
        cid = world.client
        for index in range(p.getNumJoints(body, physicsClientId=cid)):
            info = p.getJointInfo(body, index, physicsClientId=cid)
            self.joints[info[1].decode()] = index
            self.links[info[12].decode()] = index

    def joint(self, name: str) -> int:
        """The index of joint ``name``; KeyError naming the robot's joints if it has none such."""
        if name not in self.joints:
            raise KeyError(f"robot {self.name!r} has no joint {name!r} (it has: {', '.join(sorted(self.joints))})")
        return self.joints[name]

    def link(self, name: str) -> int:
        """The index of link ``name`` (-1 for the base); KeyError naming the robot's links if none."""
        if name not in self.links:
            raise KeyError(f"robot {self.name!r} has no link {name!r} (it has: {', '.join(sorted(self.links))})")
        return self.links[name]

    def max_effort(self, joint: int) -> float:
        """The joint's effort limit from the model (N·m or N; 10 when the model gives none)."""
        return float(p.getJointInfo(self.body, joint, physicsClientId=self.world.client)[10] or 10.0)

    def joint_state(self, joint: int) -> tuple[float, float, float]:
        """Position, velocity and applied motor effort of a joint."""
        position, velocity, _, effort = p.getJointState(self.body, joint, physicsClientId=self.world.client)
        return float(position), float(velocity), float(effort)

    def command(self, joint: int, mode: str, value: float, force: float | None = None) -> None:
        """Drive a joint: ``position`` (rad or m), ``velocity`` (rad/s or m/s) or ``effort`` (N·m or N,
        held until the next command)."""
        cid = self.world.client
        limit = force if force is not None else self.max_effort(joint)
        if mode in ("position", "velocity"):
            self.world.torques.pop((self.body, joint), None)
        if mode == "position":
            p.setJointMotorControl2(self.body, joint, p.POSITION_CONTROL, targetPosition=value, force=limit,
                                    physicsClientId=cid)
        elif mode == "velocity":
            p.setJointMotorControl2(self.body, joint, p.VELOCITY_CONTROL, targetVelocity=value, force=limit,
                                    physicsClientId=cid)
        elif mode == "effort":
            # torque control needs the default velocity motor switched off first
            p.setJointMotorControl2(self.body, joint, p.VELOCITY_CONTROL, force=0.0, physicsClientId=cid)
            self.world.torques[(self.body, joint)] = value  # applied at every step by World.step
        else:
            raise ValueError(f"joint mode {mode!r} is not position, velocity or effort")

    def link_pose(self, link: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """World position and orientation of a link's frame (the base's for -1)."""
        cid = self.world.client
        if link < 0:
            position, orientation = p.getBasePositionAndOrientation(self.body, physicsClientId=cid)
            return tuple(position), tuple(orientation)
        state = p.getLinkState(self.body, link, computeForwardKinematics=True, physicsClientId=cid)
        return tuple(state[4]), tuple(state[5])

    def viewpoint(self, link: int) -> int:
        """The lowest-numbered link that is always exactly where ``link`` is: joined to it by fixed
        joints only and at its pose now (D240). A camera on either sees the same image, so the two
        share one render (the Xtion's RGB and depth optical frames coincide in the model)."""
        cid = self.world.client

        def rigid_root(index: int) -> int:
            while index >= 0 and p.getJointInfo(self.body, index, physicsClientId=cid)[2] == p.JOINT_FIXED:
                index = p.getJointInfo(self.body, index, physicsClientId=cid)[16]
            return index

        root, (position, orientation) = rigid_root(link), self.link_pose(link)
        for other in sorted(self.links.values()):
            if other == link:
                break
            if rigid_root(other) != root:
                continue
            there, turned = self.link_pose(other)
            same_turn = min(math.dist(turned, orientation), math.dist(turned, [-q for q in orientation])) < 1e-9
            if math.dist(there, position) < 1e-9 and same_turn:  # q and -q: one rotation
                return other
        return link

    def planar_pose(self, link: int = -1) -> tuple[float, float, float]:
        """Ground-truth (x, y, yaw) of a link's frame (the base's for -1) in the world."""
        (x, y, _), (qx, qy, qz, qw) = self.link_pose(link)
        return x, y, math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))


@dataclass
class OdometryNoise:
    """Odometry error model: each wheel's travel is scaled by (1 + N(0, ``slip``)) per update."""

    slip: float = 0.0
    seed: int = 0


class DiffDriveBase:
    """The differential-drive base: wheel speeds, encoder ticks and dead-reckoned odometry.

    Odometry integrates the noisy wheel travel between two ``update()`` calls (exact arc
    formula), so its drift grows with the distance driven and with ``noise.slip``. The wheel joints,
    radius and track are the robot's own (no default); ``ticks()`` needs the encoders' ``ticks_per_rev``.
    """

    def __init__(
        self, robot: Robot, *, left: str, right: str, wheel_radius: float, wheel_base: float,
        ticks_per_rev: float | None = None, noise: OdometryNoise | None = None,
    ) -> None:
        self.robot = robot
        self.left, self.right = robot.joint(left), robot.joint(right)
        self.wheel_radius = wheel_radius
        self.wheel_base = wheel_base
        self.ticks_per_rev = ticks_per_rev
        self.noise = noise or OdometryNoise()
        self._rng = random.Random(self.noise.seed)
        self.pose = robot.planar_pose()
        """Odometry estimate (x, y, yaw), starting at the true pose."""
        self._angles = self._wheel_angles()
        for joint in (self.left, self.right):
            robot.command(joint, "velocity", 0.0)

    def _wheel_angles(self) -> tuple[float, float]:
        return self.robot.joint_state(self.left)[0], self.robot.joint_state(self.right)[0]

    def drive(self, linear: float, angular: float, force: float = 2.0) -> None:
        """Set the base velocity (m/s, rad/s) through the two wheel motors."""
        half = angular * self.wheel_base / 2
        self.robot.command(self.left, "velocity", (linear - half) / self.wheel_radius, force)
        self.robot.command(self.right, "velocity", (linear + half) / self.wheel_radius, force)

    def ticks(self) -> tuple[int, int]:
        """Encoder counts of the left and right wheels."""
        if self.ticks_per_rev is None:
            raise ValueError(f"robot {self.robot.name!r}: the base was made without its encoders' ticks_per_rev")
        left, right = self._wheel_angles()
        scale = self.ticks_per_rev / (2 * math.pi)
        return int(left * scale), int(right * scale)

    def update(self) -> tuple[float, float, float]:
        """Integrate the wheel travel since the previous update; returns the odometry pose."""
        left, right = self._wheel_angles()
        d_left = (left - self._angles[0]) * self.wheel_radius
        d_right = (right - self._angles[1]) * self.wheel_radius
        self._angles = (left, right)
        if self.noise.slip > 0.0:
            d_left *= 1.0 + self._rng.gauss(0.0, self.noise.slip)
            d_right *= 1.0 + self._rng.gauss(0.0, self.noise.slip)
        distance = (d_left + d_right) / 2
        turn = (d_right - d_left) / self.wheel_base
        x, y, yaw = self.pose
        mid = yaw + turn / 2
        self.pose = (x + distance * math.cos(mid), y + distance * math.sin(mid), yaw + turn)
        return self.pose
