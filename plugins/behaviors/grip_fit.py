"""Whether the object a pick names fits its gripper (issue N point 2, D296), for ``verify``: the
environment Object's narrowest horizontal width against the full opening of the jaw of the gripper
service the behavior uses, both read from the configuration alone.

The jaw is the ``parallel-gripper`` plugin of the service (its ``model`` and finger ``joints``; a
finger its sim channel mirrors, Param ``mirror`` of the channel driving the first, is the second); the
opening is the URDF's (:func:`plugins.urdf_model.jaw_opening`). When any of it cannot be found — no
environment, another gripper kind, one finger and no mirror — nothing is said: nothing is guessed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ckmconf.model import System
from ckmconf.model.environment import Circle, EnvObject, Geometry2D, Geometry3D, Polygon, Rectangle
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.resources import Plugin
from plugins.manipulation.kinematics import MODELS
from plugins.urdf_model import jaw_opening
from runtime.resources.spt import config_dir

GRIPPER_KIND = "parallel-gripper"


def narrowest(obj: EnvObject) -> float | None:
    """The object's narrowest horizontal width (m): the least, over its shapes, of a shape's width in
    its narrowest direction (a jaw may close on any one of them); None without a shape."""
    geometry = obj.geometry
    if isinstance(geometry, Geometry3D):
        atoms = [prism.base for prism in geometry.prisms]
    elif isinstance(geometry, Geometry2D):
        atoms = list(geometry.atoms)
    else:
        atoms = [geometry.prism.base]
    widths = [w for w in (_width(atom) for atom in atoms) if w is not None]
    return min(widths) if widths else None


def _width(atom: Any) -> float | None:
    if isinstance(atom, Circle):
        return 2.0 * atom.radius
    if isinstance(atom, Rectangle):
        return min(atom.width, atom.depth)
    if isinstance(atom, Polygon):
        return _polygon_width([(v.x, v.y) for v in atom.vertices])
    return None


def _polygon_width(points: Sequence[tuple[float, float]]) -> float | None:
    """The width of the points' convex hull in its narrowest direction: the least, over the directions
    of every pair of points, of the extent across it (a hull edge's is among them and is the least)."""
    best: float | None = None
    for i, (ax, ay) in enumerate(points):
        for bx, by in points[i + 1 :]:
            length = math.hypot(bx - ax, by - ay)
            if length == 0.0:
                continue
            nx, ny = -(by - ay) / length, (bx - ax) / length
            across = [x * nx + y * ny for x, y in points]
            extent = max(across) - min(across)
            best = extent if best is None else min(best, extent)
    return best


def _gripper_plugin(record: BehaviorRecord, system: System) -> Plugin | None:
    """The parallel-gripper plugin of the service the behavior uses as ``gripper``, if it has one."""
    use = next((u for u in record.uses if u.alias == "gripper"), None)
    if use is None or "." not in use.service:
        return None
    resource_name, service_name = use.service.split(".", 1)
    resource = system.resource(resource_name)
    if resource is None:
        return None
    service = next((s for s in resource.services if s.name == service_name), None)
    if service is None:
        return None
    profiles = {scenario.profile for scenario in service.scenarios}
    outputs = {profile.output_plugin() for profile in resource.profiles if profile.name in profiles}
    found = [plugin for plugin in resource.plugins if plugin.name in outputs and plugin.kind == GRIPPER_KIND]
    return found[0] if len(found) == 1 else None


def _fingers(plugin: Plugin, system: System) -> list[str]:
    """The jaw's two finger joints: the plugin's ``joints``, or its one finger and the mirror of the
    sim channel driving it."""
    values = {p.name: p.value for p in plugin.params}
    joints = values.get("joints", "").split()
    if len(joints) != 1:
        return joints
    for channel in (c for node in system.nodes for c in node.channels if c.backend == "sim"):
        given = {p.name: p.value for p in channel.params}
        if given.get("joint") == joints[0] and given.get("mirror"):
            return [joints[0], given["mirror"]]
    return joints


def fit_problems(record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
    """The ``object`` Param naming no Object of the map, or an Object wider than the full opening of
    the gripper the behavior uses."""
    param = next((p for p in record.params if p.name == "object"), None)
    if param is None or not param.value.strip() or system is None or system.environment is None:
        return []
    environment = system.environment
    obj = next((o for o in environment.objects if o.name == param.value), None)
    if obj is None:
        names = [o.name for o in environment.objects]
        return [(param, f"parameter 'object' = {param.value!r} is no Object of the map (its Objects: {names})")]
    width = narrowest(obj)
    plugin = _gripper_plugin(record, system)
    if width is None or plugin is None:
        return []
    model = {p.name: p.value for p in plugin.params}.get("model", "")
    path = config_dir(plugin) / model if Path(model).suffix else MODELS / f"{model}.urdf"
    fingers = _fingers(plugin, system)
    try:
        opening = jaw_opening(path, fingers) if path.is_file() else None
    except ValueError:
        return []  # the gripper plugin's own set-up and checks report its model
    if opening is None or width <= opening:
        return []
    return [
        (
            param,
            f"parameter 'object' = {param.value!r}: the object is {width:.3f} m across at its "
            f"narrowest, wider than the full opening {opening:.3f} m of the gripper (plugin "
            f"{plugin.name!r}, {path.name}'s {' and '.join(fingers[:2])} at their upper limits)",
        )
    ]
