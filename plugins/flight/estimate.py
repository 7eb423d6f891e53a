"""Where a flying robot is, from the inputs of a ``flight`` service (docs/interfaces.md ``flight``).

A multirotor indoors has no wheel odometry: its position comes from a fix (UWB, motion capture,
GNSS outdoors; the simulator's ``position`` sensor), its heading from a compass or the fix's own
orientation, its velocity over ground from optical flow, its height above what lies under it from a
range finder. Each reader accepts the shapes a sensor or a ROS 2 node gives (CKM's ``{x, y, z,
yaw}``, ``geometry_msgs/PoseStamped``, ``nav_msgs/Odometry``, ``std_msgs/Float64``,
``sensor_msgs/Range``) and says which input is wrong when none fits.

:class:`Estimator` blends them: between fixes the flow's velocity carries the estimate forward (on
the heading), and each new fix pulls it back by ``fix_gain`` (1: the fix as it is).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from runtime.ros.interface_types import yaw_of


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def read_position(value: Any, owner: str) -> tuple[float, float, float, float | None]:
    """(x, y, z, yaw or None) of a position fix or pose message.

    Raises:
        ValueError: ``value`` is no position (the message names the input ``position``).
    """
    point: Any = value
    yaw: float | None = None
    if isinstance(point, Mapping) and isinstance(point.get("point"), Mapping):
        point = point["point"]  # PointStamped
    if isinstance(point, Mapping) and isinstance(point.get("pose"), Mapping):
        point = point["pose"]  # CKM {pose: {...}}, PoseStamped, Odometry (pose.pose)
        if isinstance(point.get("pose"), Mapping):
            point = point["pose"]
    if isinstance(point, Mapping) and isinstance(point.get("position"), Mapping):
        orientation = point.get("orientation")
        if isinstance(orientation, Mapping) and all(_number(orientation.get(k)) is not None for k in "xyzw"):
            yaw = yaw_of(orientation)
        point = point["position"]
    if isinstance(point, Mapping):
        xyz = [_number(point.get(k)) for k in ("x", "y", "z")]
        if all(v is not None for v in xyz):
            if yaw is None and "yaw" in point:
                yaw = _number(point.get("yaw"))
            x, y, z = (float(v) for v in xyz if v is not None)
            return x, y, z, yaw
    raise ValueError(f"{owner}: input 'position' must give finite x, y and z (a position fix, a pose or a "
                     f"PoseStamped), got {value!r}"[:300])


def read_scalar(value: Any, owner: str, name: str, fields: tuple[str, ...]) -> float:
    """A number given bare or in the first of ``fields`` a message has (``data``, ``range``, ``yaw``…).

    Raises:
        ValueError: no finite number there (the message names the input).
    """
    number = _number(value)
    if number is None and isinstance(value, Mapping):
        number = next((n for n in (_number(value.get(f)) for f in fields) if n is not None), None)
    if number is None:
        raise ValueError(f"{owner}: input {name!r} must be a finite number or a message with "
                         f"{' or '.join(repr(f) for f in fields)}, got {value!r}"[:300])
    return number


def read_velocity(value: Any, owner: str) -> tuple[float, float]:
    """(ahead, left) velocity over ground in the heading frame (optical flow) (m/s).

    Raises:
        ValueError: no two finite components there.
    """
    part = value.get("linear", value) if isinstance(value, Mapping) else value
    if isinstance(part, Mapping):
        for names in (("x", "y"), ("vx", "vy")):
            pair = [_number(part.get(n)) for n in names]
            if all(v is not None for v in pair):
                return float(pair[0] or 0.0), float(pair[1] or 0.0)
    if isinstance(part, list | tuple) and len(part) >= 2:
        pair = [_number(v) for v in part[:2]]
        if all(v is not None for v in pair):
            return float(pair[0] or 0.0), float(pair[1] or 0.0)
    raise ValueError(f"{owner}: input 'velocity' must give the velocity over ground (x and y, or vx and vy, "
                     f"in the heading frame), got {value!r}"[:300])


@dataclass
class Pose3:
    """A flying body's estimate: position (m, map frame, z above the floor) and heading (rad)."""

    x: float
    y: float
    z: float
    yaw: float

    def distance(self, other: Pose3) -> float:
        """Straight-line distance between the two positions."""
        return math.dist((self.x, self.y, self.z), (other.x, other.y, other.z))


class Estimator:
    """The position blend of the module docstring; ``vz`` is the climb rate between fixes."""

    def __init__(self, fix_gain: float) -> None:
        self.fix_gain = fix_gain
        self.pose: Pose3 | None = None
        self.vz = 0.0
        self.speed = 0.0  # horizontal m/s, from successive estimates
        self.last_fix = -math.inf  # stamp of the newest fix taken
        self._fix: tuple[float, float, float, float | None] | None = None
        self._at = 0.0

    def update(self, now: float, fix: tuple[float, float, float, float | None] | None, heading: float | None,
               velocity: tuple[float, float] | None) -> Pose3 | None:
        """The estimate at ``now`` from the newest inputs (a fix equal to the last one is not new)."""
        pose = self.pose
        dt = max(0.0, now - self._at) if pose is not None else 0.0
        self._at = now
        before = None if pose is None else (pose.x, pose.y, pose.z)
        if pose is not None and velocity is not None and dt > 0.0:
            c, s = math.cos(pose.yaw), math.sin(pose.yaw)
            pose.x += (c * velocity[0] - s * velocity[1]) * dt
            pose.y += (s * velocity[0] + c * velocity[1]) * dt
        if fix is not None and fix != self._fix:
            self._fix, self.last_fix = fix, now
            x, y, z, _ = fix
            if pose is None:
                pose = self.pose = Pose3(x, y, z, 0.0)
            else:
                g = self.fix_gain
                pose.x, pose.y, pose.z = pose.x + g * (x - pose.x), pose.y + g * (y - pose.y), pose.z + g * (z - pose.z)
        if pose is None:
            return None
        if heading is not None:
            pose.yaw = heading
        elif self._fix is not None and self._fix[3] is not None:
            pose.yaw = self._fix[3]
        if before is not None and dt > 0.0:
            self.vz = (pose.z - before[2]) / dt
            self.speed = math.hypot(pose.x - before[0], pose.y - before[1]) / dt
        return Pose3(pose.x, pose.y, pose.z, pose.yaw)
