"""The standard kinds' results as the ROS 2 standard types of their interfaces (issue M point 1, D279).

The standard service kinds write CKM's planar conventions: a top-level ``stamp`` (and ``frame``),
poses ``{x, y, yaw}``, twists ``{linear, angular}``, a 3×3 (x, y, yaw) ``covariance`` and a
``dispersion`` (m). A topic typed with the ROS 2 standard type of their interface port
(docs/interfaces.md: ``sensor_msgs/msg/LaserScan``, ``nav_msgs/msg/Odometry``,
``geometry_msgs/msg/PoseWithCovarianceStamped``, ``geometry_msgs/msg/PoseStamped``) gets, on the wire and
in the recording, that message filled from them (:func:`to_standard`, applied by ``ConfigRosTypes.payload``):

- ``stamp`` → ``header.stamp``, ``frame`` → ``header.frame_id`` for any type with a ``header`` and no
  field of the name (a ``stamp`` of the type's own is left to it);
- a planar pose → ``position {x, y, 0}`` (a flying body's ``z`` as it is) and the yaw's quaternion
  ``orientation``;
- a 3×3 (x, y, yaw) covariance → the 6×6 of ROS (rows and columns x, y, yaw at 0, 1, 5); with none
  written, the dispersion d as σx² = σy² = d²/2 (its RMS distance, REP 103's metres);
- a twist ``{linear, angular}`` → ``linear.x`` and ``angular.z``.

What a type cannot hold is named in :class:`Adaptation` ``dropped`` with the reason (the service
publishes it as a quality measure of its own): the adaptation removes exactly those fields, and
``verify`` refuses any other field a kind writes that the type does not hold
(runtime.verification.message_checks). A value already in the ROS shape passes unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

HEADER_FIELDS = {"stamp": "header.stamp", "frame": "header.frame_id"}
"""CKM's top-level stamp and frame: where a ROS type with a ``std_msgs/Header`` keeps them."""
_INDEX = (0, 1, 5)  # x, y, yaw in ROS's (x, y, z, roll, pitch, yaw)


def planar(pose: Mapping[str, Any]) -> dict[str, Any]:
    """A ``geometry_msgs/Pose`` of a pose ``{x, y, yaw}`` (and ``z``, a flying body's height; else 0)."""
    half = float(pose.get("yaw") or 0.0) / 2
    return {"position": {"x": float(pose.get("x") or 0.0), "y": float(pose.get("y") or 0.0),
                         "z": float(pose.get("z") or 0.0)},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(half), "w": math.cos(half)}}


def yaw_of(orientation: Mapping[str, Any]) -> float:
    """The heading of a ``geometry_msgs/Quaternion`` (rotation about z)."""
    x, y, z, w = (float(orientation[k]) for k in ("x", "y", "z", "w"))
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def covariance6(covariance: Any = None, dispersion: Any = None) -> list[float]:
    """The 6×6 row-major covariance of a 3×3 (x, y, yaw) one, else of a dispersion (σx² = σy² = d²/2)."""
    full = [0.0] * 36
    if covariance is not None:
        values = [float(v) for v in covariance]
        if len(values) != 9:
            raise ValueError(f"a planar covariance has 9 values (3x3 x, y, yaw), got {len(values)}")
        for row, a in enumerate(_INDEX):
            for col, b in enumerate(_INDEX):
                full[a * 6 + b] = values[row * 3 + col]
    elif isinstance(dispersion, int | float) and not isinstance(dispersion, bool):
        full[0] = full[7] = float(dispersion) ** 2 / 2
    return full


def _header(value: Mapping[str, Any]) -> dict[str, Any]:
    return {"stamp": value.get("stamp") or 0.0, "frame_id": str(value.get("frame") or "")}


def _planar_pose(value: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The planar pose a value carries: its ``pose {x, y, yaw}``, else its own x, y, yaw; None: not planar."""
    pose = value.get("pose")
    if isinstance(pose, Mapping) and "yaw" in pose:
        return pose
    return value if "yaw" in value and "pose" not in value else None


def _odometry(value: Mapping[str, Any]) -> dict[str, Any]:
    pose = _planar_pose(value) or {}
    twist = value.get("twist") if isinstance(value.get("twist"), Mapping) else {}
    assert isinstance(twist, Mapping)
    return {
        "header": _header(value),
        "child_frame_id": str(value.get("child_frame") or ""),
        "pose": {"pose": planar(pose), "covariance": covariance6(value.get("covariance"), value.get("dispersion"))},
        "twist": {"twist": {"linear": {"x": float(twist.get("linear") or 0.0), "y": 0.0, "z": 0.0},
                            "angular": {"x": 0.0, "y": 0.0, "z": float(twist.get("angular") or 0.0)}}},
    }


def _pose_with_covariance(value: Mapping[str, Any]) -> dict[str, Any]:
    pose = _planar_pose(value) or {}
    covariance = value.get("covariance")
    return {"header": _header(value),
            "pose": {"pose": planar(pose), "covariance": covariance6(covariance, value.get("dispersion"))}}


def _pose_stamped(value: Mapping[str, Any]) -> dict[str, Any]:
    return {"header": _header(value), "pose": planar(_planar_pose(value) or {})}


@dataclass(frozen=True)
class Adaptation:
    """How CKM's planar results become one ROS 2 standard type.

    ``carried`` lists the CKM field paths the type holds after :attr:`convert` (verify's view),
    ``dropped`` the ones it cannot hold, each with the reason it is not lost.
    """

    ros_type: str
    convert: Callable[[Mapping[str, Any]], dict[str, Any]]
    carried: frozenset[str]
    dropped: Mapping[str, str] = field(default_factory=dict)

    def applies(self, value: Mapping[str, Any]) -> bool:
        """Whether ``value`` is in CKM's planar form (a ROS-shaped one has a ``header``)."""
        return "header" not in value and _planar_pose(value) is not None


_PLANAR = frozenset({"stamp", "frame", "pose.x", "pose.y", "pose.yaw"})
_QUALITY = "the service's own quality measure, published with its results"
ADAPTATIONS: dict[str, Adaptation] = {
    a.ros_type: a
    for a in (
        Adaptation("nav_msgs/msg/Odometry", _odometry,
                   _PLANAR | {"x", "y", "yaw", "child_frame", "twist.linear", "twist.angular", "covariance",
                              "dispersion"}),
        Adaptation("geometry_msgs/msg/PoseWithCovarianceStamped", _pose_with_covariance,
                   _PLANAR | {"x", "y", "yaw", "covariance"},
                   {"dispersion": f"with a covariance written, {_QUALITY} (without one, the covariance holds "
                                  "it as σx² = σy² = d²/2)", "reliability": _QUALITY,
                    "filter": "the filter the service's Params chose"}),
        Adaptation("geometry_msgs/msg/PoseStamped", _pose_stamped, _PLANAR | {"pose.z", "x", "y", "z", "yaw"}),
    )
}
"""The standard types whose CKM form is not a field-for-field match, by ROS type."""


def _drop_dispersion(adaptation: Adaptation, value: Mapping[str, Any]) -> bool:
    return "dispersion" in adaptation.dropped and value.get("covariance") is not None


def to_standard(ros_type: str, fields: Mapping[str, Any], value: Mapping[str, Any]) -> Mapping[str, Any]:
    """``value`` as the fields of ``ros_type`` when it is in CKM's form (module docstring), else as it is.

    Args:
        ros_type: the topic's ROS 2 type.
        fields: that type's field definitions by name (``RosTypes.fields``).
        value: what the kind wrote.
    """
    adaptation = ADAPTATIONS.get(ros_type)
    if adaptation is not None and adaptation.applies(value):
        kept = {k: v for k, v in value.items() if k not in adaptation.dropped or
                (k == "dispersion" and not _drop_dispersion(adaptation, value))}
        known = {p.split(".")[0] for p in (*adaptation.carried, *adaptation.dropped)}
        if all(k in known for k in kept):  # else leave it: the encoder names the field that does not fit
            return adaptation.convert(kept)
        return value
    if "header" in fields and "header" not in value and any(k in value and k not in fields for k in HEADER_FIELDS):
        rest = {k: v for k, v in value.items() if k not in HEADER_FIELDS or k in fields}
        return {"header": _header(value), **rest}
    return value


def holds(ros_type: str, fields: Mapping[str, Any], path: str) -> bool | None:
    """Whether ``ros_type`` holds the CKM field ``path`` through :func:`to_standard` (True), drops it on
    purpose (None: see :attr:`Adaptation.dropped`), or leaves it to the type's own fields (False)."""
    adaptation = ADAPTATIONS.get(ros_type)
    if adaptation is not None:
        if path in adaptation.carried:
            return True
        if path in adaptation.dropped:
            return None
    return path in HEADER_FIELDS and "header" in fields and path not in fields


__all__ = ["ADAPTATIONS", "HEADER_FIELDS", "Adaptation", "covariance6", "holds", "planar", "to_standard", "yaw_of"]
