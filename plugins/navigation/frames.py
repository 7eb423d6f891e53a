"""Planar frames and message fields shared by the mobile services (thesis §7.1, Table 7.1).

Poses are ``(x, y, yaw)`` tuples: "map" is the Environment's frame, "odom" the wheel odometry's,
"robot" the base (x forward, y left). ``compose(a, b)`` is b expressed in a's parent frame
(a ⊕ b), ``inverse(a)`` undoes it, ``relative(a, b)`` is b seen from a (a⁻¹ ⊕ b). Message
readers raise ValueError naming the owner and the field, so bad input says where it is.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

Pose = tuple[float, float, float]
Point = tuple[float, float]


def wrap(angle: float) -> float:
    """``angle`` wrapped to [-π, π)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def compose(a: Pose, b: Pose) -> Pose:
    """a ⊕ b: pose ``b`` (given in frame ``a``) in ``a``'s parent frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])


def inverse(a: Pose) -> Pose:
    """a⁻¹: the parent frame seen from ``a``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return -c * a[0] - s * a[1], s * a[0] - c * a[1], wrap(-a[2])


def relative(a: Pose, b: Pose) -> Pose:
    """b seen from a (a⁻¹ ⊕ b)."""
    return compose(inverse(a), b)


def transform_point(frame: Pose, point: Point) -> Point:
    """``point`` (given in ``frame``) in ``frame``'s parent."""
    x, y, _ = compose(frame, (point[0], point[1], 0.0))
    return x, y


def number(message: Mapping[str, Any], key: str, owner: str, where: str) -> float:
    """Field ``key`` of ``message`` as a finite float."""
    value = message.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{owner}: {where} field {key!r} must be a finite number, got {value!r}")
    return float(value)


def mapping(value: Any, owner: str, where: str) -> Mapping[str, Any]:
    """``value`` when it is a message (a mapping), else a ValueError naming ``where``."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{owner}: {where} must be a message (a mapping), got {type(value).__name__}")
    return value


def pose_of(message: Mapping[str, Any], owner: str, where: str) -> Pose:
    """The ``pose`` {x, y, yaw} of an Odometry or PoseEstimate message."""
    pose = mapping(message.get("pose"), owner, f"{where} field 'pose'")
    return (
        number(pose, "x", owner, f"{where} pose"),
        number(pose, "y", owner, f"{where} pose"),
        wrap(number(pose, "yaw", owner, f"{where} pose")),
    )


def pose_message(pose: Pose) -> dict[str, float]:
    """A Pose2D message."""
    return {"x": float(pose[0]), "y": float(pose[1]), "yaw": float(pose[2])}


def parse_pose(text: str) -> Pose | None:
    """``"x y yaw"`` as a pose, None when ``text`` is not three finite numbers."""
    parts = text.split()
    if len(parts) != 3:
        return None
    try:
        values = [float(v) for v in parts]
    except ValueError:
        return None
    if not all(math.isfinite(v) for v in values):
        return None
    return values[0], values[1], wrap(values[2])


def polyline_length(points: Sequence[Point]) -> float:
    """Length (m) of the polyline through ``points``."""
    return float(sum(math.dist(a, b) for a, b in itertools.pairwise(points)))


def project(points: Sequence[Point], where: Point, start: int = 0) -> tuple[int, Point, float]:
    """The point of the polyline nearest ``where`` from segment ``start`` on: (segment, point, distance).

    A path is followed forwards, so searching from the segment reached last keeps the projection
    from jumping back to an earlier leg passing close by.
    """
    if len(points) == 1:
        return 0, points[0], math.dist(points[0], where)
    best = (start, points[start], math.inf)
    for i in range(start, len(points) - 1):
        (ax, ay), (bx, by) = points[i], points[i + 1]
        dx, dy = bx - ax, by - ay
        span = dx * dx + dy * dy
        t = 0.0 if span <= 0 else max(0.0, min(1.0, ((where[0] - ax) * dx + (where[1] - ay) * dy) / span))
        near = (ax + t * dx, ay + t * dy)
        d = math.dist(near, where)
        if d < best[2]:
            best = (i, near, d)
    return best


def remaining_length(points: Sequence[Point], segment: int, at: Point) -> float:
    """Length (m) from ``at`` (on segment ``segment``) to the polyline's end."""
    if len(points) < 2:
        return math.dist(at, points[0]) if points else 0.0
    return math.dist(at, points[segment + 1]) + polyline_length(points[segment + 1 :])


def along(points: Sequence[Point], segment: int, at: Point, distance: float) -> Point:
    """The point ``distance`` m further along the polyline from ``at`` (its end when it is shorter)."""
    here, left = at, distance
    for i in range(segment + 1, len(points)):
        step = math.dist(here, points[i])
        if step >= left and step > 0:
            t = left / step
            return here[0] + t * (points[i][0] - here[0]), here[1] + t * (points[i][1] - here[1])
        left -= step
        here = points[i]
    return points[-1]
