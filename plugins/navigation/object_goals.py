"""A map object as a Navigation goal (issue M): the pose short of it, facing it, and its scan points.

A goal naming an ``<Object>`` of the Environment means "go up to it": the robot's centre stops
``clearance`` (its radius and the configured gap) beyond the object's outline, on the side the robot
comes from, facing the object's centre. When that side is taken by another obstacle, the nearest
free side is chosen (turning the approach by steps of ``STEP`` either way). The object itself is then
no obstacle of the plan (:meth:`plugins.navigation.routes.Routes.aim_at`), and scan points on it
(:func:`on_object`) do not block the path's last leg. A flat marking (``<Geometry2D height="0">``, a
landing pad, a dock marking: nobody's obstacle, D294) is driven onto: the goal is its centre, keeping
the heading the robot comes with.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import shapely

from plugins.environment.geometry import Footprint
from plugins.environment.map_model import MapModel
from plugins.environment.objects import MapObject

from .frames import Point, Pose

STEP = math.radians(15)
"""How far each other approach side is turned from the robot's own."""


def _edge(obj: MapObject, centre: Point, heading: float) -> float:
    """The distance from ``centre`` to the object's outline along ``heading`` (its farthest crossing)."""
    span = 2 * math.hypot(*np.subtract(obj.shape.bounds[2:], obj.shape.bounds[:2])) + 1.0
    ray = shapely.LineString([centre, (centre[0] + span * math.cos(heading), centre[1] + span * math.sin(heading))])
    crossing = ray.intersection(obj.shape.boundary)
    points = [(g.x, g.y) for g in getattr(crossing, "geoms", [crossing]) if isinstance(g, shapely.Point)]
    return max((math.dist(centre, p) for p in points), default=0.0)


def _beyond(obj: MapObject, centre: Point, heading: float, clearance: float) -> Point:
    """The point along ``heading`` from ``centre`` that is ``clearance`` from the object's outline (a
    corner nearer than the crossing face is allowed for: the distance is the polygon's, not the ray's)."""
    reach = _edge(obj, centre, heading) + clearance
    for _ in range(8):
        x, y = centre[0] + reach * math.cos(heading), centre[1] + reach * math.sin(heading)
        short = clearance - float(obj.shape.distance(shapely.Point(x, y)))
        if short < 1e-9:
            break
        reach += short
    return x, y


def standoff_pose(model: MapModel, obj: MapObject, here: Point, clearance: float, footprint: Footprint) -> Pose:
    """The pose ``clearance`` beyond ``obj``'s outline on the side of ``here``, facing it; the nearest free side.

    Raises:
        ValueError: no side of the object leaves room for ``footprint`` (the reason names the obstacles).
    """
    centre = (float(obj.shape.centroid.x), float(obj.shape.centroid.y))
    dx, dy = here[0] - centre[0], here[1] - centre[1]
    own = math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-9 else 0.0
    if obj.obstacle() is None:  # a marking: onto it, facing the way the robot comes
        hits = [name for name in model.collisions(footprint, *centre) if name != obj.name]
        if not hits:
            return centre[0], centre[1], math.atan2(-dy, -dx)
    blockers: set[str] = set()
    for k in range(int(math.pi / STEP) + 1):
        for heading in dict.fromkeys((own + k * STEP, own - k * STEP)):
            x, y = _beyond(obj, centre, heading, clearance)
            hits = [name for name in model.collisions(footprint, x, y) if name != obj.name]
            if not hits:
                return x, y, math.atan2(centre[1] - y, centre[0] - x)
            blockers.update(hits)
    raise ValueError(f"no side of object {obj.name!r} leaves room for the robot: {', '.join(sorted(blockers))}")


def on_object(hits: npt.NDArray[np.float64], obj: MapObject, margin: float) -> npt.NDArray[np.bool_]:
    """Which scan endpoints (k, 2) lie on the goal object (within ``margin`` of its outline)."""
    if not len(hits):
        return np.zeros(0, dtype=bool)
    mask: npt.NDArray[np.bool_] = shapely.distance(obj.shape, shapely.points(hits)) <= margin
    return mask
