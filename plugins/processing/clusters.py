"""The depth-recognition algorithms (thesis §7.4.1): depth image → metres → points → support plane → clusters.

What ``plugin.depth-acquisition`` and ``plugin.euclidean-clustering`` (``depth.py``) and
``plugin.tabletop-clustering`` (``tabletop.py``) run, and what the classifier's training
(``ckm_lab.shape_training``) runs on rendered scenes, so the model is learned from the very pipeline.
Frames: the camera optical frame, x right, y down, z forward (metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from sklearn.cluster import DBSCAN

from .cameras import Camera
from .descriptor import Plane

Depth = npt.NDArray[np.float32]
Points = npt.NDArray[np.float32]
Mask = npt.NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class Cluster:
    """One Euclidean cluster: its camera-frame points (read-only, metres) and the support plane it stands on."""

    points: Points
    plane: Plane | None

    @property
    def count(self) -> int:
        """The number of points."""
        return len(self.points)

    @property
    def centroid(self) -> tuple[float, float, float]:
        """The mean of the points (camera frame, metres)."""
        x, y, z = self.points.mean(axis=0, dtype=np.float64)
        return float(x), float(y), float(z)

    @property
    def extent(self) -> tuple[float, float, float]:
        """Size of the camera-frame bounding box along x, y, z (metres)."""
        x, y, z = self.points.max(axis=0) - self.points.min(axis=0)
        return float(x), float(y), float(z)


def solid_centre(cluster: Cluster) -> tuple[float, float, float]:
    """The centre of the upright round solid (cylinder, sphere) whose visible side ``cluster`` holds.

    A depth camera sees only the near side, so the points' centroid lies about 2r/π in front of the
    axis (2–4 cm for the lab's cans: a grasp aimed there closes short). Seen along the support
    plane's normal the visible side (its middle half in height: a top seen from above is no arc)
    is an arc: the centre of the circle fitted to it (algebraic, least squares) is the axis, at
    the centroid's height. The centroid is kept without a plane, with
    too few points, or when the fit is no plausible arc (radius outside 0.5–30 cm, a centre nearer
    the camera than the surface).
    """
    centroid = np.asarray(cluster.centroid)
    if cluster.plane is None or cluster.count < 10:
        return cluster.centroid
    normal = np.asarray(cluster.plane[:3], np.float64)
    normal /= np.linalg.norm(normal)
    across = np.array([1.0, 0.0, 0.0]) - normal[0] * normal  # the camera's x, made horizontal
    across /= np.linalg.norm(across)
    depthwise = np.cross(normal, across)
    points = cluster.points.astype(np.float64)
    height = points @ normal
    low, high = np.quantile(height, (0.25, 0.75))
    band = points[(height >= low) & (height <= high)]  # the side only: a top seen from above is no arc
    if len(band) < 10:
        return cluster.centroid
    relative = band - centroid
    u, v = relative @ across, relative @ depthwise
    design = np.column_stack([2.0 * u, 2.0 * v, np.ones_like(u)])
    (cu, cv, c), *_ = np.linalg.lstsq(design, u * u + v * v, rcond=None)
    radius = math.sqrt(max(0.0, c + cu * cu + cv * cv))
    centre = centroid + cu * across + cv * depthwise
    if not 0.005 < radius < 0.3 or np.linalg.norm(centre) <= np.linalg.norm(centroid):
        return cluster.centroid
    return float(centre[0]), float(centre[1]), float(centre[2])


def to_metres(image: npt.NDArray[Any], scale: float, owner: str) -> Depth:
    """A new read-only float32 image in metres: integers times ``scale``, floats as they are; no return → NaN."""
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim != 2 or 0 in image.shape:
        raise ValueError(f"{owner} expects a depth image of shape (H, W), got {image.shape}")
    if image.dtype.kind == "u":
        metres = image.astype(np.float32) * np.float32(scale)
        metres[image == 0] = np.nan
    elif image.dtype.kind == "f":
        metres = image.astype(np.float32)  # a copy: the input stays untouched
        with np.errstate(invalid="ignore"):
            metres[~(np.isfinite(metres) & (metres > 0))] = np.nan
    else:
        raise ValueError(f"{owner} expects raw unsigned (16UC1) or float metres (32FC1) depth, got {image.dtype}")
    metres.flags.writeable = False
    return metres


def _rays(shape: tuple[int, ...], camera: Camera) -> tuple[Points, Points]:
    """x/z per column and y/z per row of an image of ``shape`` (intrinsics scaled to its size)."""
    fx, fy, cx, cy = camera.intrinsics(shape[0], shape[1])
    return (np.arange(shape[1], dtype=np.float32) - cx) / fx, (np.arange(shape[0], dtype=np.float32) - cy) / fy


def backproject(
    depth: npt.NDArray[np.floating[Any]], camera: Camera, max_range: float, *, mask: Mask | None = None, step: int = 1
) -> Points:
    """Camera-frame points (N, 3) of the pixels in ``mask`` (default: depth in (0, ``max_range``] m).

    ``step`` keeps every step-th row and column (a cheap subsample for the plane search).
    """
    if mask is None:
        with np.errstate(invalid="ignore"):
            mask = (depth > 0) & (depth <= max_range)
    xn, yn = _rays(depth.shape, camera)
    rows, cols = np.nonzero(mask[::step, ::step])
    rows, cols = rows * step, cols * step
    z = depth[rows, cols].astype(np.float32)
    return np.stack([xn[cols] * z, yn[rows] * z, z], axis=1)


def find_support_plane(
    points: Points, *, distance: float, max_angle: float, iterations: int = 64, samples: int = 2000, seed: int = 0
) -> Plane | None:
    """The dominant near-horizontal plane (RANSAC on a subsample, then a least-squares refit), or None.

    "Near-horizontal": the normal is within ``max_angle`` radians of the image's up (−y). The plane
    must hold a tenth of the points. A fixed seed makes a frame's result reproducible.
    """
    if len(points) < 3:
        return None
    rng = np.random.default_rng(seed)
    sub = points[rng.integers(0, len(points), min(samples, len(points)))].astype(np.float64)
    tri = sub[rng.integers(0, len(sub), (iterations, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1), 1e-12)[:, None]
    offsets = -np.einsum("ij,ij->i", normals, tri[:, 0])
    normals[offsets < 0] *= -1  # orient towards the camera (the origin is above the plane)
    offsets = np.abs(offsets)
    good = -normals[:, 1] >= math.cos(max_angle)
    if not good.any():
        return None
    inlier = np.abs(sub @ normals[good].T + offsets[good]) < distance
    best = int(np.argmax(inlier.sum(axis=0)))
    chosen = sub[inlier[:, best]]
    if len(chosen) < max(3, len(sub) // 10):
        return None
    centre = chosen.mean(axis=0)
    normal = np.linalg.svd(chosen - centre, full_matrices=False)[2][2]
    offset = -float(normal @ centre)
    if offset < 0:
        normal, offset = -normal, -offset
    if -normal[1] < math.cos(max_angle):
        return None
    return float(normal[0]), float(normal[1]), float(normal[2]), offset


def euclidean_clusters(points: Points, tolerance: float, min_points: int) -> list[npt.NDArray[np.intp]]:
    """Indices of the clusters of at least ``min_points`` points, largest first.

    DBSCAN with min_samples=1 is Euclidean clustering (the connected components of the "closer
    than ``tolerance``" graph). At VGA a 2 cm ball around a point holds hundreds of points, so it
    runs on the centroids of voxels of ``tolerance``/2 instead, and the points follow their voxel:
    the same clusters up to a voxel's width at the gaps, in a few milliseconds.
    """
    if len(points) == 0:
        return []
    keys = np.floor(points / np.float32(tolerance / 2)).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    centroids = np.stack([np.bincount(inverse, weights=points[:, i]) for i in range(3)], axis=1) / counts[:, None]
    labels = DBSCAN(eps=tolerance, min_samples=1).fit(centroids).labels_[inverse]
    sizes = np.bincount(labels)
    order = np.argsort(labels, kind="stable")
    groups = np.split(order, np.cumsum(sizes)[:-1])
    return [groups[i] for i in np.argsort(-sizes, kind="stable") if sizes[i] >= min_points]


def segment(
    depth: npt.NDArray[np.floating[Any]],
    camera: Camera,
    *,
    tolerance: float,
    min_points: int,
    max_range: float = 3.5,
    plane: bool = True,
    plane_distance: float = 0.015,
    plane_angle: float = 45.0,
) -> list[Cluster]:
    """The clusters of a depth image in metres, left to right (see EuclideanClustering for the steps)."""
    with np.errstate(invalid="ignore"):
        keep = (depth > 0) & (depth <= max_range)
    support = None
    if plane:
        step = max(1, round(math.sqrt(depth.size / 10_000)))  # ~10,000 pixels are plenty for RANSAC
        sample = backproject(depth, camera, max_range, mask=keep, step=step)
        support = find_support_plane(sample, distance=plane_distance, max_angle=math.radians(plane_angle))
    if support is not None:
        # Height above the plane of every pixel, n·(z·(x/z, y/z, 1)) + d, before building any point.
        xn, yn = _rays(depth.shape, camera)
        a, b, c, d = (np.float32(value) for value in support)
        with np.errstate(invalid="ignore"):
            keep &= depth * (a * xn[None, :] + b * yn[:, None] + c) + d > plane_distance
    points = backproject(depth, camera, max_range, mask=keep)
    clusters = []
    for index in euclidean_clusters(points, tolerance, min_points):
        members = points[index]
        members.flags.writeable = False
        clusters.append(Cluster(members, support))
    return sorted(clusters, key=lambda c: c.centroid[0])
