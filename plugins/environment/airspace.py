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
import shapely.ops
from shapely.geometry import LineString, Point
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import Environment, EnvObject, Geometry2D, Geometry3D, Geometry25D, Prism

from .geometry import atom_shape, place

BOUNDS = "map bounds"
"""The name a body leaving the mapped space (the map's outline, up to its height) meets."""
FLOOR = "floor"
"""The name a body flying lower than its own half height meets."""

XY = tuple[float, float]
XYZ = tuple[float, float, float]


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
        """What a body flying straight from ``a`` to ``b`` at ``altitude`` meets, in the order met
        (:meth:`path_blockers` at one altitude)."""
        return self.path_blockers((*a, altitude), (*b, altitude), radius=radius, half_height=half_height)

    def clears(self, a: XY, b: XY, altitude: float, *, radius: float = 0.0, half_height: float = 0.0) -> bool:
        """Whether a straight flight from ``a`` to ``b`` at ``altitude`` meets nothing (:meth:`blockers`)."""
        return not self.blockers(a, b, altitude, radius=radius, half_height=half_height)

    def path_blockers(self, start: XYZ, end: XYZ, *, radius: float = 0.0, half_height: float = 0.0) -> list[str]:
        """What a body flying the straight segment ``start`` → ``end`` (x, y, z: a climb, a descent or a
        level flight) meets, in the order met.

        The body is a vertical cylinder of ``radius`` reaching ``half_height`` above and below its
        centre. Over each solid the segment's centre spans the heights it has while the body is over
        the solid's floor; the solid blocks when those, widened by ``half_height``, overlap its own.
        """
        points = (*start, *end)
        if len(start) != 3 or len(end) != 3 or not all(math.isfinite(v) for v in points):
            raise ValueError(f"a flight goes between two finite (x, y, z) points, got {start} and {end}")
        if half_height < 0 or not math.isfinite(half_height):
            raise ValueError(f"half height {half_height}: finite, zero or more")
        (x0, y0, z0), (x1, y1, z1) = start, end
        ground = [(x0, y0), (x1, y1)]
        swept = self._swept(ground, radius)
        hits: list[tuple[float, str]] = []
        if min(z0, z1) - half_height < -1e-9:
            hits.append((0.0, FLOOR))
        if max(z0, z1) + half_height > self.height + 1e-9 or not self.outline.contains(swept):
            hits.append((0.0, BOUNDS))
        line = LineString(ground) if ground[0] != ground[1] else None
        for solid in self._under(swept):
            first, last = self._over(line, solid, radius)
            low = min(z0 + first * (z1 - z0), z0 + last * (z1 - z0)) - half_height
            high = max(z0 + first * (z1 - z0), z0 + last * (z1 - z0)) + half_height
            if solid.zmin < high and solid.zmax > low:
                hits.append((first * (line.length if line is not None else 0.0), solid.name))
        names = [name for _, name in sorted(hits)]
        return list(dict.fromkeys(names))  # a multi-prism object once

    def path_clear(self, start: XYZ, end: XYZ, *, radius: float = 0.0, half_height: float = 0.0) -> bool:
        """Whether the straight flight ``start`` → ``end`` meets nothing (:meth:`path_blockers`)."""
        return not self.path_blockers(start, end, radius=radius, half_height=half_height)

    @staticmethod
    def _over(line: LineString | None, solid: Solid, radius: float) -> tuple[float, float]:
        """The share (0..1) of the way at which the body comes over ``solid`` and the share where it leaves."""
        if line is None:  # straight up or down: over it the whole way
            return 0.0, 1.0
        zone = solid.floor.buffer(radius) if radius > 0 else solid.floor
        piece = line.intersection(zone)
        if piece.is_empty:  # the swept body only grazes it (the buffers' polygons differ): where it comes nearest
            share = line.project(shapely.ops.nearest_points(line, zone)[0], normalized=True)
            return share, share
        ends = [line.project(Point(c), normalized=True) for g in getattr(piece, "geoms", [piece]) for c in g.coords]
        return min(ends), max(ends)
