"""``plugin.tabletop-clustering``: Euclidean clusters of objects standing on the floor OR on a table (§7.4.1).

``euclidean-clustering`` removes the dominant near-horizontal plane only. From the Turtlebot's
Xtion (0.43 m high, pitched down 0.35 rad) the floor fills more of the image than the workbench
top, so the floor is removed and the workbench top with every object on it stays one large
cluster: nothing on the table is ever classified. This plugin removes up to ``planes``
near-horizontal support planes in turn (each the dominant one of the points left, holding at
least a tenth of them), keeps what stands more than ``planeDistance`` above its plane and above
the first (lowest-lying, dominant) one, clusters it as ``euclidean-clustering`` does, and hands
each cluster the plane it stands on (the nearest one below its lowest points), so the shape
descriptor measures its height above the table top, as the KD-tree model was trained
(``shapes.describe``). Same Params as ``euclidean-clustering`` plus ``planes``; same output
(``list[Cluster]``, left to right) for ``kdtree-shape-classifier``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from runtime.verification.manifest import P, Params, as_params

from .cameras import Camera
from .clusters import Cluster, Depth, backproject, euclidean_clusters, find_support_plane
from .depth import EuclideanClustering
from .descriptor import Plane

MIN_SHARE = 0.05
"""Share of the image's points a further support plane must hold (the workbench top holds ~20 %)."""


def _heights(points: np.ndarray[Any, Any], plane: Plane) -> np.ndarray[Any, Any]:
    a, b, c, d = plane
    heights: np.ndarray[Any, Any] = points @ np.array([a, b, c], dtype=np.float32) + np.float32(d)
    return heights


def support_planes(sample: np.ndarray[Any, Any], *, count: int, distance: float, max_angle: float) -> list[Plane]:
    """Up to ``count`` near-horizontal planes of ``sample``, the dominant first, each found among the
    points the previous ones did not explain and holding ``MIN_SHARE`` of the whole sample (a table
    top; not a slice through the objects left once the floor and the table are gone)."""
    planes: list[Plane] = []
    left = sample
    for index in range(count):
        plane = find_support_plane(left, distance=distance, max_angle=max_angle, seed=index)
        if plane is None:
            break
        near = np.abs(_heights(left, plane)) < distance
        if np.count_nonzero(near) < MIN_SHARE * len(sample):
            break
        planes.append(plane)
        left = left[~near]
    return planes


def tabletop_segment(
    depth: Depth,
    camera: Camera,
    *,
    tolerance: float,
    min_points: int,
    max_range: float,
    planes: int,
    plane_distance: float,
    plane_angle: float,
) -> list[Cluster]:
    """The clusters of a depth image (metres) above its support planes, each with its own plane."""
    with np.errstate(invalid="ignore"):
        keep = (depth > 0) & (depth <= max_range)
    step = max(1, round(math.sqrt(depth.size / 10_000)))  # ~10,000 pixels are plenty for RANSAC
    sample = backproject(depth, camera, max_range, mask=keep, step=step)
    found = support_planes(sample, count=planes, distance=plane_distance, max_angle=math.radians(plane_angle))
    points = backproject(depth, camera, max_range, mask=keep)
    above = np.ones(len(points), dtype=bool)
    if found:
        heights = np.stack([_heights(points, plane) for plane in found], axis=1)
        above = (heights[:, 0] > plane_distance) & np.all(np.abs(heights) >= plane_distance, axis=1)
    points = points[above]
    clusters = []
    for index in euclidean_clusters(points, tolerance, min_points):
        members = points[index]
        members.flags.writeable = False
        support: Plane | None = None
        if found:  # the plane it stands on: the highest one below its lowest points
            bottoms = [float(np.percentile(_heights(members, plane), 2)) for plane in found]
            below = [(h, plane) for h, plane in zip(bottoms, found, strict=True) if h > -plane_distance]
            support = min(below, key=lambda item: item[0])[1] if below else found[0]
        clusters.append(Cluster(members, support))
    return sorted(clusters, key=lambda c: c.centroid[0])


class TabletopClustering(EuclideanClustering):
    """``plugin.tabletop-clustering``: a depth image (metres) → ``list[Cluster]`` above up to ``planes``
    support planes (the floor, table tops); see the module doc."""

    PARAMS: ClassVar[Mapping[str, Any]] = as_params(EuclideanClustering.PARAMS) | Params(
        P("planes", 3, "Most near-horizontal support planes removed (floor, table tops).", min=1),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if not self.params["planes"] >= 1:
            raise ParamError(f"{self.owner}: parameter 'planes' = {self.params['planes']} must be at least 1")
        if not self.params["plane"]:
            raise ParamError(f"{self.owner}: parameter 'plane' must stay true (use euclidean-clustering without)")

    def process(self, data: Any, context: Context) -> list[Cluster]:
        """The clusters standing on the floor or on a table, left to right."""
        depth, camera = self.depth_image(data)
        return tabletop_segment(depth, camera, planes=self.params["planes"], **self.clustering())
