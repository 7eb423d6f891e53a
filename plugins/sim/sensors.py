"""Simulated sensors: a 2D lidar (``rayTestBatch``), an RGB-D camera (``getCameraImage``: colour and
depth from one render, only when asked, at the asked resolution), an IMU, a contact bumper, and what
an aerial robot adds (D293): an optical-flow velocity over the ground, a position fix and a compass."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from .robots import Robot

Array = npt.NDArray[np.float64]


def _rotation(orientation: tuple[float, ...]) -> Array:
    return np.array(p.getMatrixFromQuaternion(orientation), dtype=float).reshape(3, 3)


class Lidar:
    """A planar scanner on a link: ``beams`` beams over ``fov`` radians, ``range_min``–``range_max`` metres
    (no default: they are the scanner's own data sheet, D284).

    Beams sweep counter-clockwise from -fov/2 to +fov/2 about the link's z axis, starting at the
    link's x axis; a beam that hits nothing reads ``range_max``. ``noise`` is the standard
    deviation (m) added to each hit.
    """

    def __init__(
        self, robot: Robot, link: str, *, beams: int, fov: float, range_max: float, range_min: float = 0.0,
        noise: float = 0.0, seed: int = 0,
    ) -> None:
        self.robot, self.link = robot, robot.link(link)
        self.beams, self.fov, self.range_min, self.range_max = beams, fov, range_min, range_max
        self.noise = noise
        self._rng = np.random.default_rng(seed)
        angles = np.linspace(-fov / 2, fov / 2, beams)
        self.angles = angles
        self._directions = np.stack([np.cos(angles), np.sin(angles), np.zeros(beams)], axis=1)

    def scan(self) -> Array:
        """Ranges (m) of every beam, in beam order."""
        position, orientation = self.robot.link_pose(self.link)
        origin = np.asarray(position)
        directions = self._directions @ _rotation(orientation).T
        starts = origin + directions * self.range_min
        ends = origin + directions * self.range_max
        hits = p.rayTestBatch(starts.tolist(), ends.tolist(), physicsClientId=self.robot.world.client)
        fractions = np.array([hit[2] if hit[0] != self.robot.body else 1.0 for hit in hits])
        ranges = self.range_min + fractions * (self.range_max - self.range_min)
        if self.noise > 0.0:
            hit = fractions < 1.0
            ranges[hit] += self._rng.normal(0.0, self.noise, int(hit.sum()))
        return np.clip(ranges, self.range_min, self.range_max)


def pinhole(width: int, height: int, fov: float) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in pixels of a ``width``×``height`` render of horizontal field of view ``fov``
    (rad): square pixels, the principal point at the image's centre. A :class:`Camera` renders with
    these, and its ``sensor_msgs/msg/CameraInfo`` (plugins.sim.ros_messages) states them."""
    focal = (width / 2) / math.tan(fov / 2)
    return focal, focal, (width - 1) / 2, (height - 1) / 2


@dataclass
class Frame:
    """One render: colour (H×W×3 uint8), depth (H×W metres) and the intrinsics it was taken with."""

    rgb: npt.NDArray[np.uint8]
    depth: Array
    fx: float
    fy: float
    cx: float
    cy: float


class Camera:
    """A pinhole camera on a link whose frame is optical (ROS convention: z forward, y down).

    ``fov`` is the horizontal field of view (rad). ``render(width, height)`` makes one TinyRenderer
    image giving colour and depth together; nothing is rendered until asked.
    """

    def __init__(self, robot: Robot, link: str, *, fov: float, near: float = 0.05, far: float = 10.0) -> None:
        self.robot, self.link = robot, robot.link(link)
        self.view = robot.viewpoint(self.link)  # the link whose renders this camera shares (D240)
        self.fov, self.near, self.far = fov, near, far
        self.renders = 0

    def matrices(self, width: int, height: int) -> tuple[list[float], list[float], float]:
        """View and projection matrices for a ``width``×``height`` image, and the focal length (px)."""
        position, orientation = self.robot.link_pose(self.link)
        rotation = _rotation(orientation)
        forward, up = rotation[:, 2], -rotation[:, 1]
        eye = np.asarray(position)
        view = p.computeViewMatrix(eye.tolist(), (eye + forward).tolist(), up.tolist())
        focal = pinhole(width, height, self.fov)[0]
        fov_y = math.degrees(2 * math.atan((height / 2) / focal))
        projection = p.computeProjectionMatrixFOV(fov_y, width / height, self.near, self.far)
        return list(view), list(projection), focal

    def render(self, width: int = 640, height: int = 480) -> Frame:
        """Render one frame (colour and depth from the same render)."""
        view, projection, _ = self.matrices(width, height)
        _, _, pixels, zbuffer, _ = p.getCameraImage(
            width, height, view, projection, renderer=p.ER_TINY_RENDERER,
            flags=p.ER_NO_SEGMENTATION_MASK, physicsClientId=self.robot.world.client,
        )
        self.renders += 1
        rgba = np.asarray(pixels, dtype=np.uint8).reshape(height, width, 4)
        z = np.asarray(zbuffer, dtype=float).reshape(height, width)
        depth = self.far * self.near / (self.far - (self.far - self.near) * z)
        return Frame(np.ascontiguousarray(rgba[:, :, :3]), depth, *pinhole(width, height, self.fov))

    def project(self, point: tuple[float, float, float]) -> tuple[float, float, float]:
        """Pixel (u, v) and depth (m) where a world point appears, by the pinhole model."""
        position, orientation = self.robot.link_pose(self.link)
        local = _rotation(orientation).T @ (np.asarray(point) - np.asarray(position))
        return float(local[0] / local[2]), float(local[1] / local[2]), float(local[2])


class Imu:
    """Angular velocity (rad/s, body frame) and linear acceleration (m/s², with gravity) of a link."""

    def __init__(self, robot: Robot, link: str, *, noise: float = 0.0, seed: int = 0) -> None:
        self.robot, self.link = robot, robot.link(link)
        self.noise = noise
        self._rng = random.Random(seed)
        self._velocity: Array | None = None
        self._time = 0.0

    def read(self) -> tuple[float, ...]:
        """(wx, wy, wz, ax, ay, az) in the link frame."""
        cid = self.robot.world.client
        if self.link < 0:
            linear, angular = p.getBaseVelocity(self.robot.body, physicsClientId=cid)
        else:
            state = p.getLinkState(self.robot.body, self.link, computeLinkVelocity=True, physicsClientId=cid)
            linear, angular = state[6], state[7]
        rotation = _rotation(self.robot.link_pose(self.link)[1])
        now = self.robot.world.time
        velocity = np.asarray(linear, dtype=float)
        accel = np.zeros(3)
        if self._velocity is not None and now > self._time:
            accel = (velocity - self._velocity) / (now - self._time)
        self._velocity, self._time = velocity, now
        values = [*(rotation.T @ np.asarray(angular)), *(rotation.T @ (accel + np.array([0.0, 0.0, 9.81])))]
        return tuple(float(v) + (self._rng.gauss(0.0, self.noise) if self.noise else 0.0) for v in values)


class Bumper:
    """1 while a link of the robot touches a body other than the floor and itself within ``arc`` (rad,
    centred on the link's heading) of it, else 0 (D236: the Kobuki's three bumpers cover its front half;
    a touch on its back does not press them)."""

    def __init__(self, robot: Robot, link: str, floor: int, arc: float = 2 * math.pi) -> None:
        self.robot, self.link, self.floor, self.arc = robot, robot.link(link), floor, arc

    def pressed(self) -> bool:
        """Whether the link is in contact with an obstacle within the arc now."""
        contacts = p.getContactPoints(bodyA=self.robot.body, linkIndexA=self.link,
                                      physicsClientId=self.robot.world.client)
        touching = [c[5] for c in contacts if c[2] not in (self.floor, self.robot.body)]
        if not touching or self.arc >= 2 * math.pi:
            return bool(touching)
        x, y, heading = self.robot.planar_pose(self.link)
        for cx, cy, _ in touching:  # positionOnA: where the link is touched, in the world
            bearing = math.atan2(cy - y, cx - x) - heading
            if abs(math.atan2(math.sin(bearing), math.cos(bearing))) <= self.arc / 2:
                return True
        return False


def _link_velocity(robot: Robot, link: int) -> Array:
    cid = robot.world.client
    if link < 0:
        return np.asarray(p.getBaseVelocity(robot.body, physicsClientId=cid)[0], dtype=float)
    state = p.getLinkState(robot.body, link, computeLinkVelocity=True, physicsClientId=cid)
    return np.asarray(state[6], dtype=float)


class GroundSensor:
    """What a UAV measures of where it is and how it moves (D293), each value with Gaussian ``noise``
    (s.d., in its unit), of ``link``:

    - :meth:`flow`: the link's velocity over the ground (vx, vy, m/s) in the robot's heading frame (x
      ahead, y left), as an optical-flow sensor with its range finder gives it (PX4Flow, PMW3901);
    - :meth:`position`: x, y, z (m) in the map frame, a fix as UWB, GNSS or motion capture gives it;
    - :meth:`compass`: the heading (yaw, rad, counter-clockwise from the map's x axis, in (−π, π]).
    """

    def __init__(self, robot: Robot, link: str, *, noise: float = 0.0, seed: int = 0) -> None:
        self.robot, self.link, self.noise = robot, robot.link(link), noise
        self._rng = np.random.default_rng(seed)

    def _noisy(self, values: Array) -> tuple[float, ...]:
        if self.noise > 0.0:
            values = values + self._rng.normal(0.0, self.noise, values.shape)
        return tuple(float(v) for v in values)

    def flow(self) -> tuple[float, ...]:
        """(vx, vy) over the ground in the heading frame (the robot's, whatever way the link's frame turns)."""
        _, _, yaw = self.robot.planar_pose(-1)
        vx, vy, _ = _link_velocity(self.robot, self.link)
        c, s = math.cos(yaw), math.sin(yaw)
        return self._noisy(np.array([c * vx + s * vy, -s * vx + c * vy]))

    def position(self) -> tuple[float, ...]:
        """(x, y, z) in the map frame."""
        return self._noisy(np.asarray(self.robot.link_pose(self.link)[0], dtype=float))

    def compass(self) -> float:
        """The heading, wrapped to (−π, π] after the noise."""
        (yaw,) = self._noisy(np.array([self.robot.planar_pose(self.link)[2]]))
        return math.atan2(math.sin(yaw), math.cos(yaw))
