"""Coverage waypoints of a polygon: the boustrophedon (lawnmower) sweep of ``search-area`` (D269).

Lanes ``spacing`` apart run along the direction ``along`` asks for (``x``, ``y``, or ``long``: the
longer side of the polygon's minimum rotated rectangle), inside the polygon shrunk by ``margin`` so
the sensor's view reaches the outline; on each lane, waypoints ``spacing`` apart cover every piece
of the lane inside the polygon (a concave polygon cuts a lane in several), both ends included, the
lanes taken in turn one way and back, as a lawnmower does. Each waypoint faces the way the sweep
goes. A polygon too small for its margin gets one waypoint: its representative point.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any

import shapely
from shapely import affinity

from ckmconf.model import Param, System
from ckmconf.model.environment import Environment
from runtime.kernel.interfaces import ParamError

Waypoint = tuple[float, float, float]


def _direction(polygon: shapely.Polygon, along: str) -> float:
    """The lanes' heading (rad) for ``along``."""
    if along == "x":
        return 0.0
    if along == "y":
        return math.pi / 2
    ring = list(shapely.minimum_rotated_rectangle(polygon).exterior.coords)
    edges = [(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(ring)]
    dx, dy = max(edges, key=lambda e: math.hypot(*e)) if edges else (1.0, 0.0)
    return math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-12 else 0.0


def _spread(low: float, high: float, spacing: float) -> list[float]:
    """Values from ``low`` to ``high`` at most ``spacing`` apart, both ends included (one: the middle)."""
    length = high - low
    if length < 1e-9:
        return [(low + high) / 2]
    count = math.ceil(length / spacing - 1e-9) + 1
    return [low + length * k / (count - 1) for k in range(count)]


def lawnmower(points: list[tuple[float, float]], spacing: float, margin: float = 0.0,
              along: str = "long") -> list[Waypoint]:
    """The coverage waypoints (x, y, yaw) of the polygon ``points`` (see the module docstring)."""
    if spacing <= 0:
        raise ValueError(f"spacing {spacing} must be positive")
    polygon = shapely.Polygon(points)
    if not polygon.is_valid:
        polygon = polygon.buffer(0)
    inner = polygon.buffer(-margin) if margin > 0 else polygon
    if inner.is_empty or inner.area <= 0:
        centre = polygon.representative_point()
        return [(centre.x, centre.y, 0.0)]
    heading = _direction(polygon, along)
    origin = polygon.centroid
    level = affinity.rotate(inner, -heading, origin=origin, use_radians=True)  # lanes along the x axis
    xmin, ymin, xmax, ymax = level.bounds
    waypoints: list[Waypoint] = []
    forward = True
    for y in _spread(ymin, ymax, spacing):
        cut = level.intersection(shapely.LineString([(xmin - 1.0, y), (xmax + 1.0, y)]))
        pieces = sorted((g for g in getattr(cut, "geoms", [cut]) if isinstance(g, shapely.LineString)
                         and not g.is_empty), key=lambda g: g.bounds[0])
        lane = [(x, y) for piece in pieces for x in _spread(piece.bounds[0], piece.bounds[2], spacing)]
        if not lane:
            continue
        if not forward:
            lane.reverse()
        yaw = heading if forward else heading + math.pi
        for x, y_lane in lane:
            point = affinity.rotate(shapely.Point(x, y_lane), heading, origin=origin, use_radians=True)
            waypoints.append((point.x, point.y, math.remainder(yaw, 2 * math.pi)))
        forward = not forward
    return waypoints


def area_problems(area: Param, system: System | None) -> list[tuple[Param, str]]:
    """The ``area`` Param of a sweeping behavior naming no ``<Area>`` of the system's map."""
    if system is None:
        return []
    environment = system.environment
    names = [a.name for a in environment.areas] if environment is not None else []
    if area.value in names:
        return []
    where = "the system has no <Environment>" if environment is None else f"its Areas: {names}"
    return [(area, f"parameter 'area' = {area.value!r} is no Area of the map ({where})")]


def sweep_waypoints(environment: Environment | None, params: Mapping[str, Any], owner: str) -> list[Waypoint]:
    """The lawnmower waypoints of the Area ``params["area"]`` (``spacing``; ``margin``, negative: half
    the spacing; ``along``); ParamError naming ``owner`` when the map has no such Area."""
    area = next((a for a in environment.areas if a.name == params["area"]), None) if environment else None
    if area is None:
        raise ParamError(f"{owner}: parameter 'area' = {params['area']!r} is no Area of the map")
    spacing, margin = float(params["spacing"]), float(params["margin"])
    return lawnmower(area.points(), spacing, spacing / 2 if margin < 0 else margin, str(params["along"]))
