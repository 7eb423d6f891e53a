"""The goals of a ``flight`` service (``ckm_interfaces/msg/FlightGoal``) and how one is flown.

A goal is ``{id, action, frame, x, y, z, yaw}``: ``takeoff`` climbs ``z`` metres above where the
robot stands, ``goto`` flies to (x, y, z) (``frame`` ``map``, z above the floor; or ``robot``:
ahead, left, up from where it is) and turns to ``yaw`` (NaN or absent: keep the heading) — in
legs: up to the higher of its height and the goal's, level to above the goal, down to it — ``land``
descends where it is until it rests, ``hold`` hovers where it is. Every goal carries a fresh id; a
newer one preempts the older (PX4's and MAVROS' offboard set-points work alike).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from .estimate import Pose3

ACTIONS = ("takeoff", "goto", "land", "hold")
FRAMES = ("map", "robot")


def wrap(angle: float) -> float:
    """``angle`` in (−π, π]."""
    return math.atan2(math.sin(angle), math.cos(angle))


@dataclass
class Flight:
    """One goal being flown: its target, how it stands, and why it failed."""

    id: Any
    action: str
    target: Pose3 | None = None
    legs: list[Pose3] = field(default_factory=list)  # waypoints before the target (climb, transit)
    keep_heading: bool = True
    state: str = "active"  # active | arrived | landed | failed
    reason: str = ""
    started: float | None = None
    deadline: float = math.inf
    settled_since: float | None = None
    heights: list[tuple[float, float]] = field(default_factory=list)  # (stamp, z) while landing
    raw: Mapping[str, Any] = field(default_factory=dict)

    def fail(self, reason: str) -> Flight:
        """This goal, failed for ``reason``."""
        self.state, self.reason = "failed", reason
        return self


def _float(message: Mapping[str, Any], name: str, default: float | None) -> float | None:
    value = message.get(name, default)
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"field {name!r} = {value!r} is not a number")
    return float(value)


def accept(message: Any, pose: Pose3 | None, landed: bool) -> Flight:
    """The goal ``message`` asks, its target resolved from ``pose`` (failed when it cannot be flown)."""
    if not isinstance(message, Mapping):
        return Flight(None, "").fail(f"the goal is {type(message).__name__}, not a FlightGoal")
    goal_id, action = message.get("id"), str(message.get("action") or "")
    flight = Flight(goal_id, action, raw=dict(message))
    if isinstance(goal_id, bool) or not isinstance(goal_id, int):
        return flight.fail(f"goal id {goal_id!r} is not an integer")
    if action not in ACTIONS:
        return flight.fail(f"goal {goal_id}: action {action!r} is not one of {', '.join(ACTIONS)}")
    if pose is None:
        return flight.fail(f"goal {goal_id}: no position fix received yet: no pose to fly from")
    frame = str(message.get("frame") or "map")
    try:
        x, y, z = (_float(message, k, None) for k in ("x", "y", "z"))
        yaw = _float(message, "yaw", math.nan)
    except ValueError as exc:
        return flight.fail(f"goal {goal_id}: {exc}")
    keep = yaw is None or not math.isfinite(yaw)
    flight.keep_heading = keep
    heading = pose.yaw if keep or yaw is None else yaw
    if action == "takeoff":
        if z is None or not math.isfinite(z) or z <= 0.0:
            return flight.fail(f"goal {goal_id}: a takeoff needs z, the height to climb (m, > 0), got {z!r}")
        flight.target = Pose3(pose.x, pose.y, pose.z + z, heading)
    elif action == "goto":
        if landed:
            return flight.fail(f"goal {goal_id}: the robot has landed: take off first")
        if frame not in FRAMES:
            return flight.fail(f"goal {goal_id}: frame {frame!r} is not one of {', '.join(FRAMES)}")
        if x is None or y is None or z is None or not all(math.isfinite(v) for v in (x, y, z)):
            return flight.fail(f"goal {goal_id}: a goto needs finite x, y and z")
        if frame == "robot":
            c, s = math.cos(pose.yaw), math.sin(pose.yaw)
            x, y, z = pose.x + c * x - s * y, pose.y + s * x + c * y, pose.z + z
            heading = pose.yaw + (0.0 if keep or yaw is None else yaw)
        flight.target = Pose3(x, y, z, wrap(heading))
        cruise = max(pose.z, z)  # climb first, fly level, descend last: the legs verify checks
        if cruise > pose.z:
            flight.legs.append(Pose3(pose.x, pose.y, cruise, pose.yaw))
        if cruise > z:
            flight.legs.append(Pose3(x, y, cruise, wrap(heading)))
    else:  # land and hold: where it is
        flight.target = Pose3(pose.x, pose.y, pose.z, pose.yaw)
    return flight
