"""The humanoid's pan-tilt head (thesis Table 7.2, Pan-Tilt Track / Fix): the camera is pointed at
a target by image-based servoing — each update moves yaw and pitch by a share of the target's
pixel error, within the joint limits — and the target is *fixed* once it stays within a tolerance
of the image centre."""

from __future__ import annotations

import math

import pybullet as p

from .robots import Robot
from .sensors import Camera


class PanTiltHead:
    """Yaw and pitch joints carrying a camera (positive pitch looks down, as the Nao's)."""

    def __init__(
        self, robot: Robot, camera: Camera, *, yaw: str, pitch: str,
        gain: float = 0.6, tolerance: float = 0.02, width: int = 320, height: int = 240,
    ) -> None:
        self.robot, self.camera = robot, camera
        self.yaw, self.pitch = robot.joint(yaw), robot.joint(pitch)
        cid = robot.world.client
        self.limits = {j: p.getJointInfo(robot.body, j, physicsClientId=cid)[8:10] for j in (self.yaw, self.pitch)}
        self.gain, self.tolerance = gain, tolerance
        self.width, self.height = width, height
        self.goal = [0.0, 0.0]

    def _clamp(self, joint: int, value: float) -> float:
        low, high = self.limits[joint]
        return float(min(max(value, low), high))

    def offset(self, point: tuple[float, float, float]) -> tuple[float, float]:
        """Angular offset (rad, right and down) of a world point from the optical axis."""
        u, v, _depth = self.camera.project(point)
        return math.atan(u), math.atan(v)

    def track(self, point: tuple[float, float, float]) -> bool:
        """One tracking update towards ``point``; True when it is fixed (centred within tolerance)."""
        right, down = self.offset(point)
        self.goal[0] = self._clamp(self.yaw, self.goal[0] - self.gain * right)
        self.goal[1] = self._clamp(self.pitch, self.goal[1] + self.gain * down)
        self.robot.command(self.yaw, "position", self.goal[0], 2.0)
        self.robot.command(self.pitch, "position", self.goal[1], 2.0)
        return max(abs(right), abs(down)) < self.tolerance

    def fixed(self, point: tuple[float, float, float]) -> bool:
        """Whether ``point`` is centred within the tolerance now."""
        right, down = self.offset(point)
        return max(abs(right), abs(down)) < self.tolerance
