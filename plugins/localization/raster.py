"""Occupancy grid and distance field of a 2D map at laser height (thesis §6.1 records, §6.2 localization).

Built from the ``<Environment>`` records (schemas/environment.xsd): the map bounds become a wall,
avoided areas are obstacles, and every object atom that the scan plane crosses (a 2D footprint of no
height, one whose ``height`` reaches the plane, or a prism with ``zmin <= scan_height <= zmax``; never
a flat marking, D294) is placed at the object's pose. Shapely rasterises the
shapes on the cell centres; OpenCV's exact Euclidean distance transform gives each cell the distance to
the nearest occupied cell, which both the ray caster (sphere tracing) and the likelihood-field
sensor models read.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
import shapely
from shapely import affinity
from shapely.geometry import Point as ShapelyPoint
from shapely.geometry import Polygon as ShapelyPolygon
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import (
    Atom2D,
    Circle,
    Environment,
    EnvObject,
    Geometry2D,
    Geometry3D,
    Geometry25D,
    Rectangle,
)

Array = npt.NDArray[np.float64]
WALL = 0.1
"""Thickness (m) of the wall drawn along the map bounds."""


def atom_polygon(atom: Atom2D) -> BaseGeometry:
    """A ``<Circle>``, ``<Rectangle>`` or ``<Polygon>`` atom as a shapely shape in its object's frame."""
    if isinstance(atom, Circle):
        return ShapelyPoint(atom.x, atom.y).buffer(atom.radius, quad_segs=8)
    if isinstance(atom, Rectangle):
        box = shapely.box(-atom.width / 2, -atom.depth / 2, atom.width / 2, atom.depth / 2)
        turned = affinity.rotate(box, atom.yaw, origin=(0, 0), use_radians=True)
        return affinity.translate(turned, atom.x, atom.y)
    return ShapelyPolygon([(v.x, v.y) for v in atom.vertices])


def object_shapes(obj: EnvObject, scan_height: float) -> list[BaseGeometry]:
    """The atoms of ``<Object>`` ``obj`` that the scan plane at ``scan_height`` (m) cuts, in the map frame."""
    geometry = obj.geometry
    atoms: list[Atom2D] = []
    z = obj.pose.z  # heights are measured from the object's <Pose> z, as the simulated world places them
    if isinstance(geometry, Geometry2D):
        # no height: projected onto the floor, a wall at every height (§6.1.1.1); a marking (0) is no wall
        if geometry.height is None or (geometry.height > 0 and z <= scan_height <= z + geometry.height):
            atoms = list(geometry.atoms)
    else:
        prisms = (geometry.prism,) if isinstance(geometry, Geometry25D) else geometry.prisms
        if isinstance(geometry, Geometry3D | Geometry25D):
            atoms = [p.base for p in prisms if z + p.zmin <= scan_height <= z + p.zmax]
    shapes = []
    for atom in atoms:
        turned = affinity.rotate(atom_polygon(atom), obj.pose.yaw, origin=(0, 0), use_radians=True)
        shapes.append(affinity.translate(turned, obj.pose.x, obj.pose.y))
    return shapes


def environment_obstacles(env: Environment, scan_height: float = 0.2) -> list[BaseGeometry]:
    """What a planar laser at ``scan_height`` sees in ``<Environment>`` ``env``: avoided areas and cut objects."""
    shapes: list[BaseGeometry] = [ShapelyPolygon(a.points()) for a in env.avoided]
    for obj in env.objects:
        shapes.extend(object_shapes(obj, scan_height))
    return shapes


@dataclass(frozen=True)
class GridMap:
    """An occupancy grid with its distance field; cell (row, col) covers ``origin + (col, row) * resolution``.

    ``free`` marks cells inside the bounds with no obstacle; ``distance`` is metres to the nearest
    occupied cell (0 on obstacles). Poses outside the grid read as occupied.
    """

    origin: tuple[float, float]
    resolution: float
    occupied: npt.NDArray[np.bool_]
    distance: npt.NDArray[np.float32]
    bounds: tuple[float, float, float, float]

    @classmethod
    def from_shapes(
        cls, bounds: tuple[float, float, float, float], shapes: Iterable[BaseGeometry], resolution: float = 0.05
    ) -> GridMap:
        """Rasterise ``shapes`` inside ``bounds`` (xmin, ymin, xmax, ymax), walled by ``WALL`` m."""
        xmin, ymin, xmax, ymax = bounds
        if not (xmax > xmin and ymax > ymin):
            raise ValueError(f"map bounds {bounds} are empty")
        if resolution <= 0:
            raise ValueError(f"grid resolution {resolution} must be positive")
        ox, oy = xmin - WALL, ymin - WALL
        cols = int(np.ceil((xmax - xmin + 2 * WALL) / resolution))
        rows = int(np.ceil((ymax - ymin + 2 * WALL) / resolution))
        xs = ox + (np.arange(cols) + 0.5) * resolution
        ys = oy + (np.arange(rows) + 0.5) * resolution
        gx, gy = np.meshgrid(xs, ys)
        occupied = (gx < xmin) | (gx > xmax) | (gy < ymin) | (gy > ymax)
        union = shapely.union_all([s for s in shapes if not s.is_empty])
        if not union.is_empty:
            # thin shapes (table legs, shelf sides) must leave a mark even if they miss every cell centre
            grown = union.buffer(resolution * 0.35)
            occupied |= shapely.contains_xy(grown, gx, gy)
        free = (~occupied).astype(np.uint8)
        exact = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        distance = exact.astype(np.float32) * np.float32(resolution)
        return cls((ox, oy), resolution, occupied, distance, (xmin, ymin, xmax, ymax))

    @classmethod
    def from_environment(cls, env: Environment, resolution: float = 0.05, scan_height: float = 0.2) -> GridMap:
        """The grid of ``<Environment>`` ``env`` (``<Map>`` bounds, avoided areas, objects) at ``scan_height``."""
        bounds = (env.map.xmin, env.map.ymin, env.map.xmax, env.map.ymax)
        return cls.from_shapes(bounds, environment_obstacles(env, scan_height), resolution)

    @property
    def shape(self) -> tuple[int, int]:
        """The grid's (rows, columns): the ``<Map>`` bounds plus the wall, in cells (§6.1.2 global map)."""
        rows, cols = self.occupied.shape
        return rows, cols

    def cells(self, x: Array, y: Array) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.bool_]]:
        """Row and column of each point and whether it lies on the grid (indices are clipped)."""
        col = np.floor((x - self.origin[0]) / self.resolution).astype(np.intp)
        row = np.floor((y - self.origin[1]) / self.resolution).astype(np.intp)
        rows, cols = self.shape
        inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        return np.clip(row, 0, rows - 1), np.clip(col, 0, cols - 1), inside

    def distance_at(self, x: Array, y: Array, outside: float = 0.0) -> npt.NDArray[np.float32]:
        """Distance (m) to the nearest obstacle at each point; ``outside`` off the grid."""
        row, col, inside = self.cells(x, y)
        return np.where(inside, self.distance[row, col], np.float32(outside))

    def is_free(self, x: Array, y: Array, clearance: float = 0.0) -> npt.NDArray[np.bool_]:
        """Whether each point is on the grid, inside the bounds and at least ``clearance`` m from obstacles."""
        result: npt.NDArray[np.bool_] = self.distance_at(x, y) > clearance
        return result

    def free_cells(self, clearance: float = 0.0) -> Array:
        """Centres (k, 2) of the cells at least ``clearance`` m from any obstacle (where random particles go)."""
        rows, cols = np.nonzero(self.distance > clearance)
        return np.stack(
            [self.origin[0] + (cols + 0.5) * self.resolution, self.origin[1] + (rows + 0.5) * self.resolution], axis=1
        )


def random_poses(free: Array, resolution: float, rng: np.random.Generator, count: int) -> Array:
    """``count`` poses uniform over the ``free`` cell centres (jittered within their cell), uniform headings.

    Both filters draw their uniform prior and their random particles with it.
    """
    picked = free[rng.integers(0, len(free), count)]
    jitter = rng.uniform(-0.5, 0.5, (count, 2)) * resolution
    return np.column_stack([picked + jitter, rng.uniform(-np.pi, np.pi, count)])
