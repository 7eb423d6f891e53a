"""Objects sighted by an ``object-detection`` or ``fusion`` service, chosen by label and placed on the map.

Shared by the general perception behaviors (``spot``, ``search-area``). An object's label is any of
its ``label``, ``name``, ``shape`` or ``texture`` fields (docs/interfaces.md): a detector names what
it recognised in one of them. A position whose ``frame`` is ``map`` (the fusion's) is on the map
already; any other is relative to the robot's sensor (x ahead, y to the left), placed on the map
with the robot's pose estimate and the sensor's mount on the robot (the Param ``sensorPose``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior
from runtime.verification.interfaces import Use
from runtime.verification.manifest import P

Pose = tuple[float, float, float]

SIGHTING_USES = (
    Use("detection", "object-detection", "the detector looked in (or 'fusion')", optional=True),
    Use("fusion", "fusion", "the fused recognition looked in (or 'detection')", optional=True),
)
"""The perception a sighting behavior watches: one of the two, as its ``<Uses>`` say."""

SIGHTING_PARAMS = (
    P("label", "", "The object looked for: its label, name, shape or texture as the detector reports it "
                   "(empty: any object)."),
    P("minReliability", 0.5, "Least reliability a sighting must have.", min=0.0, max=1.0),
    P("sensorPose", "0 0 0", "Where the detector's sensor sits on the robot, 'x y yaw' (m, m, rad): places a "
                             "sighting that is not in the map frame.", numbers=(3,), form="'x y yaw'"),
)


def sighting_problems(record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
    """A sighting behavior watches one perception service: ``detection`` or ``fusion``."""
    aliases = {u.alias for u in record.uses} & {"detection", "fusion"}
    if len(aliases) != 1:
        return [(record, "it watches one perception service: add <Uses service=\"…\" as=\"detection\"/> (an "
                         "object-detection service) or as=\"fusion\" (a fusion service), one of the two")]
    return []


def mount_of(text: str, owner: str) -> Pose:
    """The ``sensorPose`` Param as (x, y, yaw); ParamError naming ``owner`` when it is not three numbers."""
    try:
        x, y, yaw = (float(word) for word in text.split())
    except ValueError:
        raise ParamError(f"{owner}: parameter 'sensorPose' = {text!r} is not 'x y yaw'") from None
    return x, y, yaw


def labels(item: Mapping[str, Any]) -> set[str]:
    """The words an object answers to: its label, name, shape and texture."""
    return {str(item[key]) for key in ("label", "name", "shape", "texture") if item.get(key)}


def best_sighting(result: Any, label: str, min_reliability: float) -> dict[str, Any] | None:
    """The most reliable object of ``result`` answering to ``label`` with at least ``min_reliability``."""
    objects = result.get("objects") if isinstance(result, Mapping) else None
    best: dict[str, Any] | None = None
    for item in objects if isinstance(objects, list) else []:
        if not isinstance(item, Mapping) or (label and label not in labels(item)):
            continue
        reliability = item.get("reliability")
        if not isinstance(reliability, int | float) or reliability < min_reliability:
            continue
        if best is None or reliability > best["reliability"]:
            best = dict(item)
    return best


def on_map(item: Mapping[str, Any], robot: Pose | None, mount: Pose) -> tuple[float, float, float] | None:
    """(x, y, z) of a sighted object on the map; None when it is relative to the robot and its pose is unknown."""
    x, y, z = (float(item.get(k) or 0.0) for k in ("x", "y", "z"))
    if item.get("frame") == "map":
        return x, y, z
    if robot is None:
        return None
    mx, my, myaw = mount
    sx, sy = mx + math.cos(myaw) * x - math.sin(myaw) * y, my + math.sin(myaw) * x + math.cos(myaw) * y
    rx, ry, ryaw = robot
    return rx + math.cos(ryaw) * sx - math.sin(ryaw) * sy, ry + math.sin(ryaw) * sx + math.cos(ryaw) * sy, z


def perception(behavior: Behavior) -> Any:
    """The newest objects of the perception service the behavior watches (``fusion`` or ``detection``)."""
    alias = "fusion" if "fusion" in behavior.context.services else "detection"
    return behavior.service(alias).output("objects")


def map_sighting(item: Mapping[str, Any], where: tuple[float, float, float], robot: Pose | None,
                 stamp: float) -> dict[str, Any]:
    """A sighting as an ``ObjectPosition`` on the map: ``{stamp, label, frame: map, x, y, z, reliability,
    observer}`` (the observer: the robot's pose it was placed with, when it was placed with one)."""
    names = [str(item[k]) for k in ("label", "name", "shape", "texture") if item.get(k)]
    position: dict[str, Any] = {"stamp": float(stamp), "label": names[0] if names else "", "frame": "map",
                                "x": where[0], "y": where[1], "z": where[2],
                                "reliability": float(item.get("reliability") or 0.0)}
    position["observer"] = [] if robot is None or item.get("frame") == "map" else [
        dict(zip(("x", "y", "yaw"), robot, strict=True))]
    return position
