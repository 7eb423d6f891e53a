"""Shapes for depth recognition (thesis §7.4.1): a synthetic depth camera and the lab's objects.

- ``render_depth_scene`` ray-casts a floor and a few lab objects (boxes, cylinders, spheres) into
  a uint16 depth image in millimetres, as an Asus Xtion would deliver it, with the axial noise
  model of Nguyen, Izadi and Lovell (2012): σ(z) = 1.2 mm + 1.9 mm·(z − 0.4 m)².
- ``XTION`` is the lab's Asus Xtion at VGA, the camera the renderer and the shape model's training
  draw with. The cluster descriptor (``describe``, ``DESCRIPTOR_FIELDS``), the model's PCD files
  (``read_pcd``, ``format_pcd``) and ``Camera`` are the general ones of :mod:`plugins.processing`,
  imported here too, where the depth tests have always found them.

Frames: the camera optical frame has x right, y down, z forward (metres); the world frame of the
renderer has X right, Y forward, Z up, with the camera at (0, 0, ``Camera.elevation``) pitched down
by ``Camera.tilt`` radians.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

from plugins.processing.cameras import Camera
from plugins.processing.descriptor import DESCRIPTOR_FIELDS, AnyFloats, FloatArray, Plane, describe
from plugins.processing.pcd import MAX_PCD_BYTES, PCD_KEYS, PcdError, ShapeModel, format_pcd, read_pcd

__all__ = [
    "DESCRIPTOR_FIELDS",
    "LAB_SCENE",
    "MAX_PCD_BYTES",
    "PCD_KEYS",
    "XTION",
    "Camera",
    "PcdError",
    "Plane",
    "RenderedScene",
    "Shape",
    "ShapeKind",
    "ShapeModel",
    "Truth",
    "describe",
    "format_pcd",
    "read_pcd",
    "render_depth_scene",
]

ShapeKind = Literal["box", "cylinder", "sphere"]

XTION = Camera(525.0, 525.0, 319.5, 239.5, 640, 480)
"""The thesis lab's Asus Xtion at VGA (640 × 480): what the synthetic renderer draws with; no plugin's default."""


@dataclass(frozen=True)
class Shape:
    """A solid standing on the floor at (x, y) in the world frame (metres, radians).

    ``size``: box (width, depth, height), cylinder (radius, height), sphere (radius,).
    """

    kind: ShapeKind
    x: float
    y: float
    size: tuple[float, ...]
    yaw: float = 0.0
    name: str = ""

    @property
    def top(self) -> float:
        """Height of the solid's top above the floor."""
        return 2 * self.size[0] if self.kind == "sphere" else self.size[-1]

    @property
    def reach(self) -> float:
        """Horizontal radius of a circle that contains the footprint."""
        return math.hypot(self.size[0], self.size[1]) / 2 if self.kind == "box" else self.size[0]


@dataclass(frozen=True)
class Truth:
    """Ground truth of one rendered object: centre of the solid in the camera frame, visible pixels."""

    name: str
    kind: ShapeKind
    x: float
    y: float
    z: float
    pixels: int


@dataclass(frozen=True)
class RenderedScene:
    """A rendered depth image (uint16 millimetres) and the ground truth of its objects."""

    depth: npt.NDArray[np.uint16]
    truth: list[Truth]


# The interaction objects of Fig. 7.5 (configs/usecase/environment.xml) and a ball, 1 m ahead.
LAB_SCENE: tuple[Shape, ...] = (
    Shape("box", -0.33, 1.0, (0.07, 0.05, 0.15), yaw=0.3, name="box_cereal"),
    Shape("cylinder", -0.11, 1.05, (0.035, 0.12), name="cylinder"),
    Shape("box", 0.11, 0.95, (0.06, 0.06, 0.10), name="box_orange"),
    Shape("sphere", 0.33, 1.0, (0.05,), name="ball"),
)


def _to_camera(camera: Camera, points: FloatArray) -> FloatArray:
    """World points (N, 3) in the camera frame."""
    s, c = math.sin(camera.tilt), math.cos(camera.tilt)
    x, y, z = points[:, 0], points[:, 1], points[:, 2] - camera.elevation
    return np.stack([x, -s * y - c * z, c * y - s * z], axis=1)


def _hit(shape: Shape, o: FloatArray, dx: AnyFloats, dy: AnyFloats, dz: AnyFloats) -> AnyFloats:
    """Ray parameter (= optical depth) of the first hit on ``shape``, inf where missed."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if shape.kind == "box":
            cy, sy = math.cos(shape.yaw), math.sin(shape.yaw)
            ox, oy = cy * (o[0] - shape.x) + sy * (o[1] - shape.y), -sy * (o[0] - shape.x) + cy * (o[1] - shape.y)
            lx, ly = cy * dx + sy * dy, -sy * dx + cy * dy
            w, d, h = shape.size
            near, far = np.full(lx.shape, -np.inf), np.full(lx.shape, np.inf)
            for org, dir_, lo, hi in ((ox, lx, -w / 2, w / 2), (oy, ly, -d / 2, d / 2), (o[2], dz, 0.0, h)):
                t1, t2 = (lo - org) / dir_, (hi - org) / dir_
                near = np.maximum(near, np.minimum(t1, t2))
                far = np.minimum(far, np.maximum(t1, t2))
            return np.where((near <= far) & (near > 0), near, np.inf)
        if shape.kind == "cylinder":
            r, h = shape.size
            px, py = o[0] - shape.x, o[1] - shape.y
            a, b, c = dx * dx + dy * dy, 2 * (px * dx + py * dy), px * px + py * py - r * r
            t = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)
            zt = o[2] + t * dz
            side = np.where((t > 0) & (zt >= 0) & (zt <= h), t, np.inf)
            tc = (h - o[2]) / dz
            cap = np.where((tc > 0) & ((px + tc * dx) ** 2 + (py + tc * dy) ** 2 <= r * r), tc, np.inf)
            return np.fmin(side, cap)
        r = shape.size[0]
        px, py, pz = o[0] - shape.x, o[1] - shape.y, o[2] - r
        a, b = dx * dx + dy * dy + dz * dz, 2 * (px * dx + py * dy + pz * dz)
        t = (-b - np.sqrt(b * b - 4 * a * (px * px + py * py + pz * pz - r * r))) / (2 * a)
        return np.where(t > 0, t, np.inf)


def render_depth_scene(
    objects: Sequence[Shape] | None = None,
    resolution: tuple[int, int] = (480, 640),
    seed: int = 0,
    *,
    camera: Camera = XTION,
    noise: bool = True,
    depth_range: tuple[float, float] = (0.4, 6.0),
) -> RenderedScene:
    """A depth image (rows × cols, uint16 mm, 0 = no return) of ``objects`` (default ``LAB_SCENE``) on a floor.

    Each object is ray-cast only inside the image box of its bounding box, so a VGA frame of a
    few objects takes a few milliseconds. Pixels outside ``depth_range`` read 0, as on the Xtion.
    """
    objects = LAB_SCENE if objects is None else objects
    rows, cols = resolution
    fx, fy, cx, cy = camera.intrinsics(rows, cols)
    s, c = math.sin(camera.tilt), math.cos(camera.tilt)
    xn, yn = (np.arange(cols) - cx) / fx, (np.arange(rows) - cy) / fy
    row_dy, row_dz = (c - yn * s)[:, None], (-yn * c - s)[:, None]  # world ray (xn, dy, dz) per pixel
    with np.errstate(divide="ignore"):
        floor = np.where(row_dz < 0, camera.elevation / -row_dz, np.inf)
    depth = np.broadcast_to(np.fmin(floor, 2 * depth_range[1]).astype(np.float32), (rows, cols)).copy()
    owner = np.full((rows, cols), -1, dtype=np.int16)
    origin = np.array([0.0, 0.0, camera.elevation])
    centres: list[FloatArray] = []
    for index, shape in enumerate(objects):
        reach, top = shape.reach, shape.top
        box = np.array(
            [[shape.x + i * reach, shape.y + j * reach, k * top] for i in (-1, 1) for j in (-1, 1) for k in (0, 1)]
        )
        cam = _to_camera(camera, box)
        if np.all(cam[:, 2] > 0.01):
            u, v = fx * cam[:, 0] / cam[:, 2] + cx, fy * cam[:, 1] / cam[:, 2] + cy
            c0, c1 = max(0, math.floor(u.min())), min(cols, math.ceil(u.max()) + 1)
            r0, r1 = max(0, math.floor(v.min())), min(rows, math.ceil(v.max()) + 1)
        else:
            r0, r1, c0, c1 = 0, rows, 0, cols
        centres.append(_to_camera(camera, np.array([[shape.x, shape.y, top / 2]]))[0])
        if r0 >= r1 or c0 >= c1:
            continue
        t = _hit(shape, origin, xn[None, c0:c1], row_dy[r0:r1], row_dz[r0:r1])
        window = depth[r0:r1, c0:c1]
        closer = t < window
        window[closer] = t[closer]
        owner[r0:r1, c0:c1][closer] = index
    if noise:
        rng = np.random.default_rng(seed)
        sigma = np.float32(0.0012) + np.float32(0.0019) * (depth - np.float32(0.4)) ** 2
        depth += sigma * rng.standard_normal((rows, cols), dtype=np.float32)
    depth[(depth < depth_range[0]) | (depth > depth_range[1])] = 0.0
    counts = np.bincount(owner[depth > 0].ravel() + 1, minlength=len(objects) + 1)[1:]
    truth = [
        Truth(o.name or o.kind, o.kind, float(p[0]), float(p[1]), float(p[2]), int(n))
        for o, p, n in zip(objects, centres, counts, strict=True)
    ]
    return RenderedScene(np.rint(depth * np.float32(1000.0)).astype(np.uint16), truth)
