"""Environment objects (thesis §6.1.1): pose, parts, texture, semantic tag, time mark, reliability."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from shapely.geometry import Point
from shapely.geometry.base import BaseGeometry
from shapely.ops import unary_union

from ckmconf.model.environment import EnvObject

from .geometry import Dimension, Part, object_parts, place


def parse_stamp(stamp: str | None) -> float:
    """An ``<Object stamp>`` (ISO 8601) as seconds since the epoch; 0 when absent."""
    if not stamp:
        return 0.0
    return datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()


@dataclass
class MapObject:
    """An environment object in the map (§6.1.1): pose, parts, texture, tag, time mark, reliability."""

    name: str
    tag: str
    x: float
    y: float
    z: float = 0.0
    yaw: float = 0.0
    parts: tuple[Part, ...] = ()
    dimension: Dimension = "2D"
    texture: str | None = None
    area: str | None = None
    stamp: float = 0.0
    reliability: float = 1.0
    source: str = "map"
    shape: BaseGeometry = field(init=False)

    def __post_init__(self) -> None:
        self.shape = self._placed(p.local for p in self.parts)

    def _placed(self, shapes: Iterable[BaseGeometry]) -> BaseGeometry:
        placed = [place(s, self.x, self.y, self.yaw) for s in shapes]
        if len(placed) == 1:
            return placed[0]
        return unary_union(placed) if placed else Point(self.x, self.y)

    def obstacle(self, height: float = math.inf) -> BaseGeometry | None:
        """The floor footprint of the parts a robot of ``height`` runs into (those starting below it; a
        flat marking's part is none)."""
        low = [p.local for p in self.parts if p.solid and p.zmin < height and p.zmax > 0]
        if len(low) == len(self.parts):
            return self.shape
        return self._placed(low) if low else None

    def placed_parts(self) -> list[tuple[BaseGeometry, float, float]]:
        """Each part's floor polygon in the map frame with its height range."""
        return [(place(p.local, self.x, self.y, self.yaw), p.zmin, p.zmax) for p in self.parts]

    @property
    def zmin(self) -> float:
        """The lowest height (m) of the parts (§6.1.1.1): ``-inf`` with a 2D atom of no height, the ``<Pose>`` z
        with none."""
        return min((p.zmin for p in self.parts), default=self.z)

    @property
    def zmax(self) -> float:
        """The highest height (m) of the parts (§6.1.1.1): ``inf`` with a 2D atom of no height, the ``<Pose>`` z
        with none."""
        return max((p.zmax for p in self.parts), default=self.z)


def object_from_record(record: EnvObject) -> MapObject:
    """A map object from an ``<Object>`` record (pose, geometry, texture, area, time mark)."""
    dimension, parts = object_parts(record.geometry, record.pose.z)
    pose = record.pose
    return MapObject(
        name=record.name,
        tag=record.tag,
        x=pose.x,
        y=pose.y,
        z=pose.z,
        yaw=pose.yaw,
        parts=parts,
        dimension=dimension,
        texture=record.texture,
        area=record.area,
        stamp=parse_stamp(record.stamp),
    )


def small_object(
    name: str, tag: str, x: float, y: float, *, z: float = 0.0, radius: float = 0.05, **kw: Any
) -> MapObject:
    """A perceived object of unknown geometry: a 2.5D cylinder of ``radius`` centred at height ``z``."""
    part = Part(_disc(radius), z - radius, z + radius)
    return MapObject(name=name, tag=tag, x=x, y=y, z=z, parts=(part,), dimension="2.5D", **kw)


@functools.lru_cache(maxsize=64)
def _disc(radius: float) -> BaseGeometry:
    """One shared disc per radius (shapely geometries are immutable)."""
    return Point(0, 0).buffer(radius, quad_segs=4)
