"""Shapes of the environment model (thesis §6.1.1.1): atomic elements, object parts, robot footprints.

An object's geometry is built from atomic elements given in the object's own frame: 2D atoms
(``<Circle>``, ``<Rectangle>``, ``<Polygon>``) and 2.5D prisms (a 2D atom extruded from ``zmin``
to ``zmax``). Placed at the object's ``<Pose>``, each atom becomes a :class:`Part`: a floor
polygon in the map frame and the height range it occupies (unbounded for a 2D atom, which is
"projected onto the floor" and obstructs at every height, unless its ``<Geometry2D height>`` bounds
it: a block that tall, or at ``0`` a flat marking that obstructs nothing, D294).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from shapely import affinity
from shapely.geometry import Point
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import (
    Atom2D,
    Circle,
    Geometry,
    Geometry2D,
    Geometry3D,
    Geometry25D,
    Polygon,
    Pose,
    Prism,
    Rectangle,
)

Dimension = Literal["2D", "2.5D", "3D"]


@dataclass(frozen=True)
class Part:
    """One atomic element of an object, placed in the map frame (§6.1.1.1).

    ``zmin``/``zmax`` are absolute heights in metres; a 2D atom spans every height
    (``-inf``..``inf``) unless its ``<Geometry2D height>`` is given; a marking's part is flat
    (``zmin == zmax``).
    """

    local: BaseGeometry
    zmin: float
    zmax: float

    @property
    def solid(self) -> bool:
        """Whether the part has a thickness: a flat one (a marking, D294) is seen, never run into."""
        return self.zmax > self.zmin


def atom_shape(atom: Atom2D) -> BaseGeometry:
    """The floor polygon of a 2D atomic element, in its object's frame."""
    if isinstance(atom, Circle):
        return Point(atom.x, atom.y).buffer(atom.radius, quad_segs=8)
    if isinstance(atom, Rectangle):
        half_w, half_d = atom.width / 2, atom.depth / 2
        corners = ShapelyPolygon([(-half_w, -half_d), (half_w, -half_d), (half_w, half_d), (-half_w, half_d)])
        return affinity.translate(affinity.rotate(corners, atom.yaw, origin=(0, 0), use_radians=True), atom.x, atom.y)
    if isinstance(atom, Polygon):
        return ShapelyPolygon([(v.x, v.y) for v in atom.vertices])
    raise TypeError(f"not a 2D atomic element: {atom!r}")


def object_parts(geometry: Geometry, pose_z: float) -> tuple[Dimension, tuple[Part, ...]]:
    """The parts of a ``<Geometry2D>``, ``<Geometry25D>`` or ``<Geometry3D>`` (object frame, absolute z)."""
    if isinstance(geometry, Geometry2D):
        low, high = (-math.inf, math.inf) if geometry.height is None else (pose_z, pose_z + geometry.height)
        return "2D", tuple(Part(atom_shape(a), low, high) for a in geometry.atoms)
    if isinstance(geometry, Geometry25D):
        prisms: tuple[Prism, ...] = (geometry.prism,)
        dimension: Dimension = "2.5D"
    elif isinstance(geometry, Geometry3D):
        prisms, dimension = geometry.prisms, "3D"
    else:
        raise TypeError(f"not an object geometry: {geometry!r}")
    return dimension, tuple(Part(atom_shape(p.base), pose_z + p.zmin, pose_z + p.zmax) for p in prisms)


def place(shape: BaseGeometry, x: float, y: float, yaw: float) -> BaseGeometry:
    """``shape`` (object frame) rotated by ``yaw`` and moved to ``(x, y)`` (map frame)."""
    turned = affinity.rotate(shape, yaw, origin=(0, 0), use_radians=True) if yaw else shape
    return affinity.translate(turned, x, y)


def pose_tuple(pose: Pose) -> tuple[float, float, float, float]:
    """A ``<Pose>`` as ``(x, y, z, yaw)``."""
    return pose.x, pose.y, pose.z, pose.yaw


@dataclass(frozen=True)
class Footprint:
    """A robot's footprint (§6.1.2): round (``radius``) or rectangular (``width`` × ``depth``).

    ``height`` is how tall the robot is: parts of objects entirely above it (a table top over a
    small robot, a ceiling lamp) do not obstruct it.
    """

    radius: float | None = None
    width: float | None = None
    depth: float | None = None
    height: float = math.inf

    def __post_init__(self) -> None:
        round_ = self.radius is not None
        rect = self.width is not None or self.depth is not None
        if round_ == rect:
            raise ValueError("a footprint is either round (radius) or rectangular (width and depth)")
        sizes = [self.radius] if round_ else [self.width, self.depth]
        if any(s is None or not (s > 0 and math.isfinite(s)) for s in sizes):
            raise ValueError(f"footprint sizes must be positive and finite, got {sizes}")
        if not self.height > 0:
            raise ValueError(f"footprint height must be positive, got {self.height}")

    @classmethod
    def round(cls, radius: float, height: float = math.inf) -> Footprint:
        """A round robot of ``radius`` m, ``height`` m tall (unbounded: every object part obstructs it)."""
        return cls(radius=radius, height=height)

    @classmethod
    def rectangle(cls, width: float, depth: float, height: float = math.inf) -> Footprint:
        """A rectangular robot of ``width`` × ``depth`` m, ``height`` m tall (unbounded by default)."""
        return cls(width=width, depth=depth, height=height)

    @property
    def bounding_radius(self) -> float:
        """The radius of the smallest circle around the footprint (what planning inflates by)."""
        if self.radius is not None:
            return self.radius
        assert self.width is not None and self.depth is not None
        return math.hypot(self.width, self.depth) / 2

    def at(self, x: float, y: float, yaw: float = 0.0) -> BaseGeometry:
        """The footprint's floor polygon with the robot at ``(x, y, yaw)``; rectangles have width along heading."""
        if self.radius is not None:
            return Point(x, y).buffer(self.radius, quad_segs=16)
        assert self.width is not None and self.depth is not None
        half_w, half_d = self.width / 2, self.depth / 2
        corners = ShapelyPolygon([(-half_w, -half_d), (half_w, -half_d), (half_w, half_d), (-half_w, half_d)])
        return place(corners, x, y, yaw)
