"""What a flying robot meets at an altitude (D294): the solids of an ``<Environment>`` with their heights.

The solids are those the simulated world (:mod:`plugins.sim.world`, D85) builds, so a flight the
helper clears is one the simulator lets through:

- the map's outline and height (``<Map height>``) bound the mapped space: a body leaving it meets
  ``"map bounds"`` (the walls stand just outside the bounds, the map height tall);
- each ``<AvoidedArea>`` stands from the floor to its ``height`` (the map's when absent);
- each ``<Object>`` prism (``<Geometry25D>``/``<Geometry3D>``) spans ``Pose z + zmin`` to
  ``Pose z + zmax``; a ``<Geometry2D>`` is a block from ``Pose z`` to ``Pose z + height``
  (``FOOTPRINT_HEIGHT``, 0.75 m, when absent) and a marking (``height="0"``) is no solid at all.

Objects are taken at their configured pose (a carried or moved one is not followed). Ground
planning (:mod:`.planner`) is unchanged by heights: an avoided area stays avoided by ground robots.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import shapely
from shapely.geometry import LineString, Point
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import Environment, EnvObject, Geometry2D, Geometry3D, Geometry25D, Prism

from .geometry import atom_shape, place

BOUNDS = "map bounds"
"""The name a body leaving the mapped space (the map's outline, up to its height) meets."""
FLOOR = "floor"
"""The name a body flying lower than its own half height meets."""

XY = tuple[float, float]


@dataclass(frozen=True)
class Solid:
    """One solid of the environment: its floor polygon in the map frame and the heights it spans (m)."""

    name: str
    floor: BaseGeometry
    zmin: float
    zmax: float


def object_solids(obj: EnvObject) -> list[Solid]:
    """The solids of one ``<Object>`` as the simulated world stands it (a marking: none)."""
    geometry = obj.geometry
    pose = obj.pose
    prisms: Sequence[Prism]
    if isinstance(geometry, Geometry2D):
        if geometry.marking:
            return []
        prisms = [Prism(zmin=0.0, zmax=geometry.solid_height, base=atom) for atom in geometry.atoms]
    elif isinstance(geometry, Geometry25D):
        prisms = [geometry.prism]
    elif isinstance(geometry, Geometry3D):
        prisms = geometry.prisms
    else:
        raise TypeError(f"not an object geometry: {geometry!r}")
    return [
        Solid(obj.name, place(atom_shape(q.base), pose.x, pose.y, pose.yaw), pose.z + q.zmin, pose.z + q.zmax)
        for q in prisms
    ]


class Airspace:
    """The environment's solids with their heights, for flights at an altitude (see the module docstring)."""

    def __init__(self, env: Environment) -> None:
        bounds = env.map
        self.height = bounds.height
        self.outline = shapely.box(bounds.xmin, bounds.ymin, bounds.xmax, bounds.ymax)
        solids = [Solid(a.name, shapely.Polygon(a.points()), 0.0, a.top(bounds.height)) for a in env.avoided]
        for obj in env.objects:
            solids += object_solids(obj)
        self.solids = tuple(solids)
        self._tree = shapely.STRtree([s.floor for s in self.solids])

    def _swept(self, points: Sequence[XY], radius: float) -> BaseGeometry:
        if radius < 0 or not math.isfinite(radius):
            raise ValueError(f"radius must be finite and zero or more, got {radius}")
        if not points:
            raise ValueError("no point given")
        path = LineString(points) if len(set(points)) > 1 else Point(points[0])
        return path.buffer(radius) if radius > 0 else path

    def _under(self, swept: BaseGeometry) -> list[Solid]:
        return [self.solids[int(i)] for i in self._tree.query(swept, predicate="intersects")]

    def highest(
        self, points: Sequence[XY], *, radius: float = 0.0, below: float = math.inf
    ) -> tuple[float, str | None]:
        """The top (m) of the highest solid under a point or path (``radius``: the body's), and its name.

        Only solids starting below ``below`` count (a table top over a low flight is not under it);
        ``(0.0, None)`` over bare floor; ``(map height, "map bounds")`` when the path leaves the map.
        """
        swept = self._swept(points, radius)
        if not self.outline.contains(swept):
            return self.height, BOUNDS
        best: tuple[float, str | None] = (0.0, None)
        for solid in self._under(swept):
            if solid.zmin < below and solid.zmax > best[0]:
                best = (solid.zmax, solid.name)
        return best

    def blockers(self, a: XY, b: XY, altitude: float, *, radius: float = 0.0, half_height: float = 0.0) -> list[str]:
        """What a body flying straight from ``a`` to ``b`` at ``altitude`` meets, in the order met.

        The body is a cylinder of ``radius`` reaching ``half_height`` above and below ``altitude``; a
        solid blocks it when their height ranges overlap and their floor shapes meet along the way.
        """
        if half_height < 0 or not math.isfinite(altitude + half_height):
            raise ValueError(f"altitude {altitude} and half height {half_height}: finite, the half height zero or more")
        low, high = altitude - half_height, altitude + half_height
        swept = self._swept([a, b], radius)
        hits: list[tuple[float, str]] = []
        if low < -1e-9:
            hits.append((0.0, FLOOR))
        if high > self.height + 1e-9 or not self.outline.contains(swept):
            hits.append((0.0, BOUNDS))
        line = LineString([a, b]) if a != b else Point(a)
        for solid in self._under(swept):
            if solid.zmin < high and solid.zmax > low:
                hits.append((line.project(solid.floor.centroid) if a != b else 0.0, solid.name))
        names = [name for _, name in sorted(hits)]
        return list(dict.fromkeys(names))  # a multi-prism object once

    def clears(self, a: XY, b: XY, altitude: float, *, radius: float = 0.0, half_height: float = 0.0) -> bool:
        """Whether a straight flight from ``a`` to ``b`` at ``altitude`` meets nothing (:meth:`blockers`)."""
        return not self.blockers(a, b, altitude, radius=radius, half_height=half_height)
