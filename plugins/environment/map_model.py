"""The global map at run time (thesis §6.1.2): bounds, avoided areas, objects, spatial queries.

Built from an ``<Environment>`` record (:meth:`MapModel.from_environment`). Objects are kept by
name with their pose, parts (§6.1.1.1), texture, semantic tag, time mark (``stamp``, seconds
since the epoch) and reliability. Spatial queries go through a shapely STRtree. STRtrees are
immutable, so the tree is built over the objects' shapes at some moment and the objects added or
moved since are kept aside (``_moved``) and checked with the tree's candidates; the tree is rebuilt lazily once
they are more than a twentieth of the map. Each object's centre is also kept in one numpy array
(:attr:`MapModel.xy`), which the per-perception association of eq. 6.1/6.2 scans.

Updates (:meth:`MapModel.observe`) follow the time marks: an observation older than the object's
stamp is stale and ignored (newer wins, which makes sharing between robots converge); a static
object keeps its pose and only refreshes its stamp and reliability; a mobile one moves; a
restricted-area object may not leave its area.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString, Point, box
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import Environment

from .geometry import Footprint, Part
from .objects import MapObject, object_from_record, parse_stamp, small_object
from .semantics import SemanticDictionary

__all__ = ["BOUNDS", "MapModel", "MapObject", "object_from_record", "parse_stamp", "small_object"]

BOUNDS = "map bounds"
"""The name :meth:`MapModel.collisions` gives to leaving the map."""


class MapModel:
    """The global map (§6.1.2): bounds, avoided areas, areas, objects and the semantic dictionary."""

    def __init__(
        self,
        bounds: tuple[float, float, float, float],
        *,
        height: float = 3.0,
        avoided: dict[str, BaseGeometry] | None = None,
        areas: dict[str, BaseGeometry] | None = None,
        semantics: SemanticDictionary | None = None,
        name: str = "map",
    ) -> None:
        self.name = name
        self.bounds = bounds
        self.outline = box(*bounds)
        self.height = height
        self.avoided = dict(avoided or {})
        self.areas = dict(areas or {})
        self.semantics = semantics or SemanticDictionary()
        self._avoided_names = list(self.avoided)
        self._avoided_tree = shapely.STRtree(list(self.avoided.values()))
        self.objects: dict[str, MapObject] = {}
        self.index: dict[str, int] = {}  # name → row of xy
        self.names: list[str] = []
        self._xy = np.zeros((64, 2))
        self._z = np.zeros((64, 2))  # zmin, zmax per row (2.5D zoom selection)
        self._shapes = np.empty(64, dtype=object)  # current shape per row (exact, vectorised tests)
        self._tree: shapely.STRtree | None = None  # built over _shapes[:n]: tree index = row
        self._moved: set[int] = set()  # rows added or moved since the tree was built

    @classmethod
    def from_environment(cls, env: Environment) -> MapModel:
        """The map of an ``<Environment>`` record (§6.1, Fig. 6.2)."""
        bounds = (env.map.xmin, env.map.ymin, env.map.xmax, env.map.ymax)
        model = cls(
            bounds,
            height=env.map.height,
            avoided={a.name: shapely.Polygon(a.points()) for a in env.avoided},
            areas={a.name: shapely.Polygon(a.points()) for a in env.areas},
            semantics=SemanticDictionary(env.semantics),
            name=env.name,
        )
        for record in env.objects:
            model.add(object_from_record(record))
        return model

    # ------------------------------------------------------------------ storage

    @property
    def xy(self) -> np.ndarray:
        """The objects' centres, one row per object in :attr:`names` order (a view: read only)."""
        return self._xy[: len(self.names)]

    def __len__(self) -> int:
        return len(self.objects)

    def __contains__(self, name: object) -> bool:
        return name in self.objects

    def get(self, name: str) -> MapObject:
        """The object of ``<Object>`` ``name`` (§6.1.1); a KeyError if the map has none of that name."""
        return self.objects[name]

    def add(self, obj: MapObject) -> None:
        """Add a new object; a name already in the map is a ValueError."""
        if obj.name in self.objects:
            raise ValueError(f"object {obj.name!r} is already in map {self.name!r}")
        row = len(self.names)
        if row == len(self._xy):
            self._xy = np.concatenate([self._xy, np.zeros_like(self._xy)])
            self._z = np.concatenate([self._z, np.zeros_like(self._z)])
            self._shapes = np.concatenate([self._shapes, np.empty(len(self._shapes), dtype=object)])
        self.objects[obj.name] = obj
        self.index[obj.name] = row
        self.names.append(obj.name)
        self._store(row, obj)

    def _store(self, row: int, obj: MapObject) -> None:
        self._xy[row] = (obj.x, obj.y)
        self._z[row] = (obj.zmin, obj.zmax)
        self._shapes[row] = obj.shape
        self._moved.add(row)

    def add_many(self, objects: Sequence[MapObject]) -> None:
        """Add many objects and index them at once (generated maps, benchmarks)."""
        for obj in objects:
            self.add(obj)
        self._build_index()

    def _set_pose(self, obj: MapObject, x: float, y: float, z: float, yaw: float) -> None:
        if z != obj.z:  # parts hold absolute heights: they rise or sink with the object
            lift = z - obj.z
            obj.parts = tuple(Part(p.local, p.zmin + lift, p.zmax + lift) for p in obj.parts)
        obj.x, obj.y, obj.z, obj.yaw = x, y, z, yaw
        obj.shape = obj._placed(p.local for p in obj.parts)
        self._store(self.index[obj.name], obj)

    # ------------------------------------------------------------------ index

    def _build_index(self) -> None:
        self._tree = shapely.STRtree(self._shapes[: len(self.names)])
        self._moved.clear()

    def candidates(self, region: BaseGeometry) -> list[MapObject]:
        """Objects whose shape intersects ``region`` (STRtree, plus the objects moved since it was built)."""
        return [self.objects[self.names[row]] for row in self.candidate_rows(region).tolist()]

    def candidate_rows(self, region: BaseGeometry) -> np.ndarray:
        """The rows (sorted) of the objects whose current shape intersects ``region``."""
        if self._tree is None or len(self._moved) > max(32, len(self.objects) // 20):
            self._build_index()
        assert self._tree is not None
        rows = self._tree.query(region)
        if self._moved:
            rows = np.union1d(rows, np.fromiter(self._moved, dtype=np.int64, count=len(self._moved)))
        else:
            rows = np.sort(rows)
        keep = shapely.intersects(self._shapes[rows], region)
        found: np.ndarray = rows[keep].astype(np.int64)
        return found

    @property
    def z_ranges(self) -> np.ndarray:
        """``(zmin, zmax)`` of every object, one row per object (a view: read only)."""
        return self._z[: len(self.names)]

    # ------------------------------------------------------------------ queries

    def avoided_at(self, x: float, y: float) -> list[str]:
        """The avoided areas containing the point (§6.1.2: is the robot inside an avoided area)."""
        point = Point(x, y)
        hits = self._avoided_tree.query(point, predicate="intersects")
        return sorted(self._avoided_names[i] for i in hits)

    def collisions(self, footprint: Footprint, x: float, y: float, yaw: float = 0.0) -> list[str]:
        """What a robot of ``footprint`` at ``(x, y, yaw)`` hits: :data:`BOUNDS`, avoided areas, objects."""
        shape = footprint.at(x, y, yaw)
        hits = [] if self.outline.contains(shape) else [BOUNDS]
        hits += sorted(self._avoided_names[i] for i in self._avoided_tree.query(shape, predicate="intersects"))
        for obj in self.candidates(shape):
            obstacle = obj.obstacle(footprint.height)
            if obstacle is not None and obstacle.intersects(shape):
                hits.append(obj.name)
        return hits

    def clearance(self, x: float, y: float, footprint: Footprint | None = None, yaw: float = 0.0) -> float:
        """Distance from the point (or the footprint there) to the nearest avoided area, object or map edge.

        Zero when touching or overlapping one.
        """
        shape = Point(x, y) if footprint is None else footprint.at(x, y, yaw)
        height = math.inf if footprint is None else footprint.height
        best = self.outline.exterior.distance(shape) if self.outline.contains(shape) else 0.0
        if self.avoided:
            index = self._avoided_tree.nearest(shape)
            best = min(best, self.avoided[self._avoided_names[int(index)]].distance(shape))
        for distance, _ in self.nearest(x, y, k=1, max_distance=best, obstacles_for=height, shape=shape):
            best = min(best, distance)
        return best

    def nearest(
        self,
        x: float,
        y: float,
        k: int = 1,
        *,
        tag: str | None = None,
        max_distance: float | None = None,
        obstacles_for: float | None = None,
        shape: BaseGeometry | None = None,
    ) -> list[tuple[float, MapObject]]:
        """The ``k`` objects nearest to the point (shape distance), nearest first, optionally of one tag.

        The search disc doubles from 0.5 m until it holds ``k`` objects at most its radius away,
        so only the STRtree's candidates are measured.
        """
        target = Point(x, y) if shape is None else shape
        limit = math.hypot(self.bounds[2] - self.bounds[0], self.bounds[3] - self.bounds[1])
        if max_distance is not None:
            limit = min(limit, max_distance)
        radius = min(0.5, limit) if limit > 0 else 0.0
        while True:
            found = []
            for obj in self.candidates(target.buffer(radius) if radius > 0 else target):
                if tag is not None and obj.tag != tag:
                    continue
                geometry = obj.shape if obstacles_for is None else obj.obstacle(obstacles_for)
                if geometry is None:
                    continue
                distance = float(geometry.distance(target))
                if distance <= radius:
                    found.append((distance, obj))
            found.sort(key=lambda item: (item[0], item[1].name))
            if len(found) >= k or radius >= limit:
                return found[:k]
            radius = min(radius * 2, limit)

    def in_region(self, region: BaseGeometry, *, tag: str | None = None) -> list[MapObject]:
        """The objects intersecting ``region`` (an area polygon, a zoom box…)."""
        return [o for o in self.candidates(region) if tag is None or o.tag == tag]

    def in_area(self, area: str) -> list[MapObject]:
        """The objects in a named ``<Area>``."""
        return self.in_region(self.areas[area])

    def on_path(self, points: Sequence[tuple[float, float]], footprint: Footprint) -> list[MapObject]:
        """The objects a robot of ``footprint`` would touch following ``points``, in the order met."""
        line = LineString(points) if len(points) > 1 else Point(points[0])
        swept = line.buffer(footprint.bounding_radius)
        hits = []
        for obj in self.candidates(swept):
            obstacle = obj.obstacle(footprint.height)
            if obstacle is not None and obstacle.intersects(swept):
                hits.append((line.project(obstacle.centroid), obj))
        return [obj for _, obj in sorted(hits, key=lambda item: (item[0], item[1].name))]

    def obstacles(self, footprint: Footprint, *, include_mobile: bool = False) -> dict[str, BaseGeometry]:
        """Avoided areas and the objects obstructing a robot of ``footprint`` (static ones unless asked)."""
        found = dict(self.avoided)
        for obj in self.objects.values():
            if not include_mobile and self.semantics.is_mobile(obj.tag):
                continue
            obstacle = obj.obstacle(footprint.height)
            if obstacle is not None:
                found[obj.name] = obstacle
        return found

    def segments(self, height: float, *, include_mobile: bool = False) -> np.ndarray:
        """The edges a planar sensor at ``height`` sees, ``k × 4`` rows ``x1 y1 x2 y2`` (for ray casting).

        The map's outline, the avoided areas and the outlines of the object parts that span
        ``height`` (a laser at 0.3 m sees table legs, not the top; nothing sees a flat marking); mobile
        objects only if asked.
        """
        shapes: list[BaseGeometry] = [self.outline, *self.avoided.values()]
        for obj in self.objects.values():
            if include_mobile or not self.semantics.is_mobile(obj.tag):
                shapes += [floor for floor, zmin, zmax in obj.placed_parts() if zmin <= height <= zmax and zmax > zmin]
        rings = []
        for shape in shapes:
            for polygon in getattr(shape, "geoms", [shape]):
                rings += [polygon.exterior, *polygon.interiors]
        edges = [np.asarray(ring.coords) for ring in rings]
        found: np.ndarray = np.concatenate([np.hstack([c[:-1], c[1:]]) for c in edges])
        return found

    # ------------------------------------------------------------------ updates

    def observe(
        self,
        name: str,
        x: float,
        y: float,
        *,
        stamp: float,
        z: float | None = None,
        yaw: float | None = None,
        reliability: float | None = None,
        source: str | None = None,
    ) -> str:
        """Apply a perception of a known object; returns what happened.

        ``stale`` (older than the object's time mark: ignored), ``refused`` (a restricted-area
        object seen outside its area), ``confirmed`` (static: stamp and reliability refreshed),
        ``moved`` (mobile: pose updated too).
        """
        obj = self.objects[name]
        if stamp < obj.stamp:
            return "stale"
        if obj.area is not None and obj.area in self.areas and not self.areas[obj.area].covers(Point(x, y)):
            return "refused"
        obj.stamp = stamp
        if reliability is not None:
            obj.reliability = reliability
        if source is not None:
            obj.source = source
        if not self.semantics.is_mobile(obj.tag):
            return "confirmed"
        self._set_pose(obj, x, y, obj.z if z is None else z, obj.yaw if yaw is None else yaw)
        return "moved"

    def replace(self, obj: MapObject) -> bool:
        """Put ``obj`` in place of the object of the same name if it is newer (or new); True if applied.

        Newer means a later time mark; equal marks are decided by the larger ``source`` name, so
        every robot applying the same updates in any order ends with the same object.
        """
        old = self.objects.get(obj.name)
        if old is None:
            self.add(obj)
            return True
        if (obj.stamp, obj.source) <= (old.stamp, old.source):  # equal stamps: the larger source wins everywhere
            return False
        self.objects[obj.name] = obj
        self._store(self.index[obj.name], obj)
        return True

    def fingerprint(self) -> list[tuple[str, float, float, float]]:
        """``(name, x, y, stamp)`` of every object, sorted: equal on two maps holding the same objects."""
        return sorted((o.name, round(o.x, 9), round(o.y, 9), o.stamp) for o in self.objects.values())
