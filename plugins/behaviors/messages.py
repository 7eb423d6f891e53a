"""The messages the behaviors exchange with the services of the standard interfaces (docs/interfaces.md).

What the simulated or real services implement:

- ``/nav/status`` (Navigation.AMCL ``status``): ``{"goal": str, "state": "planning" | "active" |
  "arrived" | "failed" | "cancelled", "path_length": m, "remaining": m, "reason": str}``.
- ``/base/move_goal`` (a behavior's ``move``): ``{"id": int, "frame": "robot", "x": m, "y": m,
  "yaw": rad}``; ``/base/move_status`` (MobileBase.Displacement ``move_status``): ``{"id": int,
  "state": "moving" | "done" | "failed", "remaining": m, "total": m, "reason": str}``.
- ``/arm/goal`` (``arm_goal``): ``{"id": int, "group": "arm" | "gripper", "pose": name}``;
  ``/arm/status`` (RoboticArm.MoveIt ``status``): ``{"id": int, "state": "moving" | "reached" |
  "failed", "pose": name, "active": bool}``.
- recognition results (Fusion, Pan-Tilt Recog.): ``{"objects": [{"name", "shape", "texture",
  "x", "y", "z", "reliability", "sources"}], "reliability"}``.

Frames (docs/decisions.md D125): an object position whose ``frame`` is ``map`` (the fused
recognition, the Nao's tracked target) is turned into the robot frame with the robot's pose
estimate (``/nav/pose``: the ``nav`` service's ``pose`` output or a ``pose`` input); any other frame
is taken as already relative to the robot.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any

from runtime.missions.behaviors import Behavior
from runtime.verification.manifest import P

_ids = itertools.count(1)  # goal ids, fresh across every behavior of the process

TARGET_PARAMS = (
    P("target", "", "Shape (or name) of the object looked for."),
    P("targetTexture", "", "Texture of the object looked for."),
)
"""The Params that choose a recognised object (:func:`find_target`)."""


def _state(message: Any, goal_id: int | None = None) -> str | None:
    """The ``state`` of a status message (for our goal id, when one is given)."""
    if not isinstance(message, Mapping):
        return None
    if goal_id is not None and message.get("id") != goal_id:
        return None
    state = message.get("state")
    return state if isinstance(state, str) else None


def _failed(what: str, message: Any) -> str:
    """``what`` failed, with the status's ``reason`` when it gives one (MoveStatus, NavigationStatus)."""
    reason = message.get("reason") if isinstance(message, Mapping) else None
    return f"{what}: {reason}" if isinstance(reason, str) and reason else what


def _share_done(message: Any) -> float:
    """1 − remaining / total of a status message, 0 when unknown."""
    if not isinstance(message, Mapping):
        return 0.0
    total, remaining = message.get("total", message.get("path_length")), message.get("remaining")
    if not isinstance(total, int | float) or not isinstance(remaining, int | float) or total <= 0:
        return 0.0
    return max(0.0, min(1.0, 1.0 - remaining / total))


def find_target(result: Any, shape: str, texture: str, min_sources: int = 1) -> dict[str, Any] | None:
    """The most reliable recognised object of ``shape`` whose texture mentions ``texture``."""
    if not isinstance(result, Mapping) or not isinstance(result.get("objects"), list):
        return None
    best: dict[str, Any] | None = None
    for item in result["objects"]:
        if not isinstance(item, Mapping):
            continue
        name = str(item.get("name", ""))
        shapes = {str(item.get("shape", "")), name}
        textures = f"{item.get('texture', '')} {name}"
        sources = item.get("sources")
        count = len(sources) if isinstance(sources, list) else 1
        if shape and not any(shape in s for s in shapes):
            continue
        if texture and texture not in textures:
            continue
        if count < min_sources:
            continue
        if best is None or float(item.get("reliability", 0)) > float(best.get("reliability", 0)):
            best = dict(item)
    return best


def robot_pose(message: Any) -> tuple[float, float, float] | None:
    """(x, y, yaw) of a ``PoseEstimate`` (``{"pose": {"x", "y", "yaw"}}``) or a bare pose, else None."""
    pose = message.get("pose", message) if isinstance(message, Mapping) else None
    if not isinstance(pose, Mapping) or not all(isinstance(pose.get(k), int | float) for k in ("x", "y", "yaw")):
        return None
    return float(pose["x"]), float(pose["y"]), float(pose["yaw"])


def in_robot_frame(position: Mapping[str, Any], pose: tuple[float, float, float] | None) -> tuple[float, float] | None:
    """The (x, y) of an object position relative to the robot; None when it is in the map frame
    and the robot's pose is unknown."""
    x, y = float(position.get("x") or 0.0), float(position.get("y") or 0.0)
    if position.get("frame") != "map":
        return x, y
    if pose is None:
        return None
    px, py, yaw = pose
    dx, dy = x - px, y - py
    return math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy


def object_position(found: Mapping[str, Any], stamp: float) -> dict[str, Any]:
    """A recognised object as an ``ObjectPosition``: ``{stamp, label, frame, x, y, z, reliability, observer}``."""

    def number(key: str) -> float:
        value = found.get(key)
        return float(value) if isinstance(value, int | float) else 0.0

    position = {
        "stamp": float(stamp),
        "label": str(found.get("name", "")),
        "frame": str(found.get("frame", "camera")),
        "x": number("x"),
        "y": number("y"),
        "z": number("z"),
        "reliability": number("reliability"),
    }
    observer = observer_pose(found)
    position["observer"] = [dict(zip(("x", "y", "yaw"), observer, strict=True))] if observer else []
    return position


def observer_pose(position: Mapping[str, Any]) -> tuple[float, float, float] | None:
    """The robot pose a ``map`` position was placed with (its ``observer`` list, D172), else None."""
    observer = position.get("observer")
    return robot_pose(observer[0]) if isinstance(observer, list) and len(observer) == 1 else None


class _Goals(Behavior):
    """Sends goals and follows their statuses by id."""

    def _send(self, output: str, goal: dict[str, Any]) -> int:
        goal_id = next(_ids)
        self.write(output, {"id": goal_id, **goal})
        return goal_id
