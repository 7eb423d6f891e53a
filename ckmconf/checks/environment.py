"""Semantic checks of the environment model (environment.xsd, §6.1): bounds, polygons, references, Zoom Map."""

from __future__ import annotations

import math
import re

from shapely.geometry import Point as ShapelyPoint
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.validation import explain_validity

from ..model import Environment, EnvObject, Polygon, Prism, System
from ..model.environment import Geometry2D, Region, Semantic
from .report import Reporter, missing


def check_environment(system: System, report: Reporter) -> None:
    """Check ``<Environment>`` (environment.xsd, §6.1): map bounds, polygons, references, Zoom Map."""
    env = system.environment
    if env is None:
        return
    bounds = env.map
    if bounds.xmin >= bounds.xmax or bounds.ymin >= bounds.ymax:
        report.error(
            bounds, f"map bounds are empty: x [{bounds.xmin:g}, {bounds.xmax:g}], y [{bounds.ymin:g}, {bounds.ymax:g}]"
        )
        return
    outline = ShapelyPolygon(
        [(bounds.xmin, bounds.ymin), (bounds.xmax, bounds.ymin), (bounds.xmax, bounds.ymax), (bounds.xmin, bounds.ymax)]
    )
    report.unique([*env.areas, *env.avoided], "area", f"environment {env.name!r}")
    report.unique(env.textures, "texture", f"environment {env.name!r}")
    report.unique(env.semantics, "semantic tag", "the semantic dictionary", key="tag")
    report.unique(env.objects, "object", f"environment {env.name!r}")
    shapes = {region.name: _region_shape(region, report) for region in (*env.areas, *env.avoided)}
    for region in (*env.areas, *env.avoided):
        shape = shapes[region.name]
        if shape is not None and not outline.buffer(1e-9).contains(shape):
            report.error(region, f"{region.TAG} {region.name!r} reaches outside the map bounds")
    for avoided in env.avoided:
        if avoided.height is not None and avoided.height > bounds.height + 1e-9:
            tall = f"{avoided.height:g} m tall, above the map height ({bounds.height:g} m)"
            report.error(avoided, f"AvoidedArea {avoided.name!r} is {tall}", "height")
    missions = [m.name for m in system.missions]
    for entry in env.semantics:
        if entry.dynamic == "static" and entry.max_speed:
            report.error(entry, 'a static object has no speed (set dynamic="mobile")', "maxSpeed")
        for affordance in entry.affordances:
            if affordance.mission is not None and affordance.mission not in missions:
                report.error(affordance, missing("mission", affordance.mission, "the system", missions), "mission")
    for obj in env.objects:
        _check_object(obj, env, outline, shapes, report)
    _check_zoom(env, report)


def _region_shape(region: Region, report: Reporter) -> ShapelyPolygon | None:
    points = region.points()
    if len(set(points)) < 3:
        report.error(region, f"{region.TAG} {region.name!r} needs at least 3 distinct vertices")
        return None
    shape = ShapelyPolygon(points)
    if not shape.is_valid:
        report.error(region, f"{region.TAG} {region.name!r} is not a simple polygon: {_why(shape)}")
        return None
    return shape


def _why(shape: ShapelyPolygon) -> str:
    reason = str(explain_validity(shape))
    if match := re.match(r"Self-intersection\[([-\d.e]+) ([-\d.e]+)\]", reason):
        return f"its edges cross at ({float(match.group(1)):g}, {float(match.group(2)):g})"
    if match := re.match(r"Ring Self-intersection\[([-\d.e]+) ([-\d.e]+)\]", reason):
        return f"its outline touches itself at ({float(match.group(1)):g}, {float(match.group(2)):g})"
    return reason


def _check_object(
    obj: EnvObject,
    env: Environment,
    outline: ShapelyPolygon,
    shapes: dict[str, ShapelyPolygon | None],
    report: Reporter,
) -> None:
    tags = {s.tag: s for s in env.semantics}
    semantic = tags.get(obj.tag)
    if semantic is None:
        report.error(obj, missing("semantic tag", obj.tag, "the semantic dictionary", tags), "tag")
    if obj.texture is not None and obj.texture not in {t.name for t in env.textures}:
        report.error(
            obj, missing("texture", obj.texture, f"environment {env.name!r}", [t.name for t in env.textures]), "texture"
        )
    where = ShapelyPoint(obj.pose.x, obj.pose.y)
    if not outline.buffer(1e-9).contains(where):
        report.error(obj.pose, f"object {obj.name!r} is outside the map bounds")
    area_names = [a.name for a in env.areas]
    if obj.area is not None:
        if obj.area not in area_names:
            report.error(obj, missing("area", obj.area, f"environment {env.name!r}", area_names), "area")
        else:
            shape = shapes.get(obj.area)
            if shape is not None and not shape.buffer(1e-9).contains(where):
                report.error(obj.pose, f"object {obj.name!r} is outside its area {obj.area!r}")
    elif semantic is not None and semantic.landmark == "restricted-area":
        report.error(obj, f'tag {obj.tag!r} is a restricted-area object: say which area it stays in (area="…")')
    for avoided in env.avoided:
        shape = shapes.get(avoided.name)
        if shape is not None and shape.contains(where):
            report.error(obj.pose, f"object {obj.name!r} stands inside the avoided area {avoided.name!r}")
    geometry = obj.geometry
    if isinstance(geometry, Geometry2D) and geometry.height is not None:
        _check_flat_height(obj, geometry, env, semantic, report)
    prisms: tuple[Prism, ...] = ()
    atoms = getattr(geometry, "atoms", ())
    if hasattr(geometry, "prism"):
        prisms = (geometry.prism,)
    elif hasattr(geometry, "prisms"):
        prisms = geometry.prisms
    for prism in prisms:
        if prism.zmin >= prism.zmax:
            report.error(prism, f"zmin ({prism.zmin:g}) must be below zmax ({prism.zmax:g})", "zmin")
        elif obj.pose.z + prism.zmax > env.map.height + 1e-9:
            top = obj.pose.z + prism.zmax
            report.error(prism, f"the object reaches {top:g} m, above the map height ({env.map.height:g} m)", "zmax")
    for atom in (*atoms, *(p.base for p in prisms)):
        if isinstance(atom, Polygon):
            points = [(v.x, v.y) for v in atom.vertices]
            if len(set(points)) < 3 or not ShapelyPolygon(points).is_valid:
                report.error(
                    atom, f"the polygon of object {obj.name!r} is not a simple polygon with 3 or more vertices"
                )


def _check_flat_height(
    obj: EnvObject, geometry: Geometry2D, env: Environment, semantic: Semantic | None, report: Reporter
) -> None:
    """A ``<Geometry2D height>`` (D294): under the map height; a marking (0) nobody can pick."""
    top = obj.pose.z + (geometry.height or 0.0)
    if top > env.map.height + 1e-9:
        report.error(geometry, f"the object reaches {top:g} m, above the map height ({env.map.height:g} m)", "height")
    if geometry.marking and semantic is not None and any(a.action == "pick" for a in semantic.affordances):
        report.error(
            geometry,
            f"object {obj.name!r} is a flat marking (height 0) but its tag {obj.tag!r} affords pick: "
            "a marking has nothing to grasp (give it a height)",
            "height",
        )


def _check_zoom(env: Environment, report: Reporter) -> None:
    zoom = env.zoom
    if zoom is None:
        return
    width, depth = env.map.xmax - env.map.xmin, env.map.ymax - env.map.ymin
    if zoom.width > width + 1e-9 or zoom.depth > depth + 1e-9:
        report.error(
            zoom, f"the zoom area ({zoom.width:g}×{zoom.depth:g} m) is larger than the map ({width:g}×{depth:g} m)"
        )
    if zoom.height is not None:
        if zoom.mode == "2D":
            report.error(zoom, "height is only for a 2.5D zoom map", "height")
        elif zoom.height > env.map.height + 1e-9:
            report.error(zoom, f"height ({zoom.height:g}) is above the map height ({env.map.height:g})", "height")
    if not math.isfinite(zoom.timeout):
        report.error(zoom, "timeout must be finite", "timeout")
