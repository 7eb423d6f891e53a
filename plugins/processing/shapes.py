"""Shapes for depth recognition (thesis §7.4.1): a synthetic depth camera, the cluster descriptor, PCD files.

- ``render_depth_scene`` ray-casts a floor and a few lab objects (boxes, cylinders, spheres) into
  a uint16 depth image in millimetres, as an Asus Xtion would deliver it, with the axial noise
  model of Nguyen, Izadi and Lovell (2012): σ(z) = 1.2 mm + 1.9 mm·(z − 0.4 m)².
- ``describe`` turns a point-cloud cluster into the shape descriptor the KD-tree classifier
  searches: sizes measured against the support plane (scale-aware) and profile measures of the
  visible surface (view-robust), see ``DESCRIPTOR_FIELDS``.
- ``read_pcd``/``format_pcd`` read and write the labelled descriptors as an ASCII PCD v0.7 file.

Frames: the camera optical frame has x right, y down, z forward (metres); the world frame of the
renderer has X right, Y forward, Z up, with the camera at (0, 0, ``Camera.elevation``) pitched down
by ``Camera.tilt`` radians.
"""

from __future__ import annotations

import functools
import math
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NoReturn

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
AnyFloats = npt.NDArray[np.floating[Any]]
Plane = tuple[float, float, float, float]
"""A plane n·p + d = 0 in the camera frame, unit normal n pointing up (towards the camera side)."""

ShapeKind = Literal["box", "cylinder", "sphere"]


@dataclass(frozen=True)
class Camera:
    """Pinhole intrinsics given for a ``width`` × ``height`` image (default: Asus Xtion at VGA), and a pose."""

    fx: float = 525.0
    fy: float = 525.0
    cx: float = 319.5
    cy: float = 239.5
    width: int = 640
    height: int = 480
    elevation: float = 0.5  # metres above the floor (renderer only)
    tilt: float = 0.35  # radians pitched down (renderer only)

    def intrinsics(self, rows: int, cols: int) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) for a ``rows`` × ``cols`` image resampled from the reference size.

        Pixel centres map as in the resize plugin: pixel i of the small image sits at
        (i + 0.5)·factor − 0.5 of the reference one.
        """
        sx, sy = cols / self.width, rows / self.height
        return self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5, (self.cy + 0.5) * sy - 0.5


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
    camera: Camera = Camera(),
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


# --------------------------------------------------------------------------- descriptor

DESCRIPTOR_FIELDS = ("height", "width", "depth", "top_ratio", "hinge_residual", "circle_residual", "curvature")
"""The shape descriptor, in the order of the PCD fields. Lengths are in decimetres, so that 1 cm
weighs as much as 0.1 of a ratio in the KD-tree's Euclidean distance:

- ``height``: top of the cluster above the support plane (99th percentile), dm;
- ``width``: extent across the line of sight, horizontally (1st–99th percentile), dm;
- ``depth``: extent along the line of sight of the middle band (25–75 % of the height), dm;
- ``top_ratio``: width of the top band (above 90 % of the height) over ``width``: near 1 for
  boxes and cylinders, lower for spheres;
- ``hinge_residual``, ``circle_residual``, ``curvature``: how the middle band's horizontal
  profile, seen from above, fits straight faces or an arc (see ``_profile_fits``).

The three sizes make it scale-aware (a desk is no box of Fig. 7.5). All are taken against the
support plane and the horizontal line of sight, so they do not depend on the camera's height or
tilt, and the profile is the median of 8 lateral bins, so neither the number of points
(resolution) nor the sensor's noise weighs much.
"""


def describe(points: npt.ArrayLike, plane: Plane | None) -> FloatArray:
    """The descriptor (``DESCRIPTOR_FIELDS``) of a cluster of camera-frame points standing on ``plane``.

    Without a plane, "up" is the image's up (−y) and heights start at the cluster's lowest point.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if plane is None:
        n = np.array([0.0, -1.0, 0.0])
        h = p @ n
        h -= h.min()
    else:
        n = np.asarray(plane[:3], dtype=np.float64)
        h = p @ n + plane[3]
    centre = p.mean(axis=0)
    view = centre - (centre @ n) * n
    view /= max(float(np.linalg.norm(view)), 1e-9)
    u, v = p @ np.cross(view, n), p @ view
    top = float(np.percentile(h, 99))
    u1, u99 = np.percentile(u, [1, 99])
    width = max(float(u99 - u1), 1e-4)
    body = (h > 0.25 * top) & (h < 0.75 * top)
    if np.count_nonzero(body) < 5:
        body = np.ones_like(h, dtype=bool)
    ub, vb = u[body] - u[body].mean(), v[body] - v[body].mean()
    v1, v99 = np.percentile(vb, [1, 99])
    depth = float(v99 - v1)
    upper = u[h > 0.9 * top]
    top_ratio = float(upper.max() - upper.min()) / width if upper.size > 1 else 0.0
    # The horizontal profile seen from above, as medians of 8 lateral bins (sensor noise averages out).
    lo, hi = float(ub.min()), float(ub.max())
    bins = np.minimum(((ub - lo) / max(hi - lo, 1e-9) * 8).astype(np.intp), 7)
    profile = np.stack([_bin_medians(bins, ub), _bin_medians(bins, vb)], axis=1)
    return np.array([10 * top, 10 * width, 10 * depth, min(top_ratio, 1.5), *_profile_fits(profile, width / 2)])


def _bin_medians(bins: npt.NDArray[np.intp], values: FloatArray) -> FloatArray:
    """The (lower) median of ``values`` in each non-empty bin, by increasing bin."""
    counts = np.bincount(bins)
    counts = counts[counts > 0]
    first = np.cumsum(counts) - counts
    ordered = values[np.lexsort((values, bins))]
    medians: FloatArray = ordered[first + (counts - 1) // 2]
    return medians


def _profile_fits(profile: FloatArray, half: float) -> tuple[float, float, float]:
    """Hinge and circle residuals (×10, over ``half``) and the curvature of the horizontal profile.

    A box's visible faces are straight: one line, or two meeting at its corner, fit them (small
    hinge residual). A cylinder's or sphere's side is an arc (small circle residual). A line is a
    circle of infinite radius, which the algebraic fit cannot reach, so the circle residual is at
    most the line residual: a box seen square on is then small on both, and told by its depth.
    """
    u, v = profile[:, 0], profile[:, 1]
    ones = np.ones_like(u)

    def rms(design: AnyFloats, target: AnyFloats) -> tuple[AnyFloats, float]:
        fit, *_ = np.linalg.lstsq(design, target, rcond=None)
        return fit, float(np.sqrt(np.mean((design @ fit - target) ** 2)))

    line = rms(np.stack([ones, u], axis=1), v)[1]
    hinge = min([line, *(rms(np.stack([ones, u, np.maximum(u - knot, 0.0)], axis=1), v)[1] for knot in u[1:-1])])
    # Kåsa fit: u² + v² = 2au + 2bv + c, radius² = c + a² + b².
    (a, b, c), _ = rms(np.stack([2 * u, 2 * v, ones], axis=1), u * u + v * v)
    radius = math.sqrt(max(c + a * a + b * b, 0.0))
    circle = min(float(np.sqrt(np.mean((np.hypot(u - a, v - b) - radius) ** 2))), line)
    # Curvature: the u² coefficient of a parabola fitted with u and v in half-widths.
    curvature = float(rms(np.stack([ones, u / half, (u / half) ** 2], axis=1), v / half)[0][2])
    return 10 * hinge / half, 10 * circle / half, curvature


# --------------------------------------------------------------------------- PCD files

PCD_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
MAX_PCD_BYTES = 16 * 1024 * 1024


class PcdError(ValueError):
    """A malformed model file; the text is ``FILE:LINE: message``."""

    def __init__(self, path: str, line: int, message: str) -> None:
        super().__init__(f"{path}:{line}: {message}")
        self.path, self.line = path, line


@dataclass(frozen=True)
class ShapeModel:
    """Labelled training descriptors: ``descriptors`` (N, F), ``labels`` (N,) indices into ``names``."""

    fields: tuple[str, ...]
    descriptors: FloatArray
    labels: npt.NDArray[np.int64]
    names: Mapping[int, str]


def format_pcd(model: ShapeModel, comments: Sequence[str] = ()) -> str:
    """The model as an ASCII PCD v0.7 text: one point per sample, the label as the last field."""
    n, fields = len(model.labels), (*model.fields, "label")
    lines = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "# labels: " + " ".join(f"{i}={name}" for i, name in sorted(model.names.items())),
        *(f"# {text}" for text in comments),
        "VERSION 0.7",
        "FIELDS " + " ".join(fields),
        "SIZE " + " ".join(["4"] * len(fields)),
        "TYPE " + " ".join(["F"] * len(model.fields) + ["U"]),
        "COUNT " + " ".join(["1"] * len(fields)),
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA ascii",
    ]
    for row, label in zip(model.descriptors, model.labels, strict=True):
        lines.append(" ".join(f"{x:.4f}" for x in row) + f" {int(label)}")
    return "\n".join(lines) + "\n"


def _labels(text: str, fail: Callable[[str], NoReturn]) -> dict[int, str]:
    names: dict[int, str] = {}
    for item in text.split():
        match = re.fullmatch(r"(\d+)=([A-Za-z_][\w-]*)", item)
        if match is None:
            fail(f"bad label {item!r} in '# labels:' (expected INDEX=NAME)")
        index = int(match.group(1))
        if index in names:
            fail(f"label {index} is named twice")
        names[index] = match.group(2)
    if not names:
        fail("'# labels:' names no label")
    return names


def read_pcd(path: str | os.PathLike[str], fields: Sequence[str] = DESCRIPTOR_FIELDS) -> ShapeModel:
    """Read a labelled descriptor model (as written by ``format_pcd``); PcdError names the file and line.

    Only what the model needs is accepted: DATA ascii, one value per field, the given ``fields``
    (type F) then ``label`` (type U or I), labels named in a ``# labels: 0=name …`` comment, finite
    values. Plain string splitting and float()/int(): nothing in the file is evaluated.
    """
    name = os.fspath(path)

    def fail(line: int, message: str) -> NoReturn:
        raise PcdError(name, line, message)

    size = Path(path).stat().st_size
    if size > MAX_PCD_BYTES:
        fail(0, f"file of {size} bytes exceeds {MAX_PCD_BYTES}")
    try:
        lines = Path(path).read_text(encoding="ascii").splitlines()
    except UnicodeDecodeError:
        fail(0, "not an ASCII file")
    header: dict[str, list[str]] = {}
    names: dict[int, str] | None = None
    expected = (*fields, "label")
    number = 0
    for number, raw in enumerate(lines, 1):
        line = raw.strip()
        if line.startswith("#") and line[1:].strip().startswith("labels:"):
            names = _labels(line[1:].strip()[len("labels:") :], functools.partial(fail, number))
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        want = PCD_KEYS[len(header)]
        if key != want:
            fail(number, f"expected {want}, found {key!r}")
        header[key] = values
        if key == "VERSION" and values not in (["0.7"], [".7"]):
            fail(number, f"unsupported VERSION {' '.join(values)!r} (expected 0.7)")
        elif key == "FIELDS" and tuple(values) != expected:
            fail(number, f"FIELDS {' '.join(values)!r} are not the descriptor's ({' '.join(expected)})")
        elif key in ("SIZE", "TYPE", "COUNT") and len(values) != len(expected):
            fail(number, f"{key} has {len(values)} entries for {len(expected)} fields")
        elif key == "TYPE" and (any(t != "F" for t in values[:-1]) or values[-1] not in ("U", "I")):
            fail(number, "TYPE must be F for the descriptor fields and U or I for the label")
        elif key == "COUNT" and any(v != "1" for v in values):
            fail(number, "every COUNT must be 1")
        elif key in ("WIDTH", "HEIGHT", "POINTS") and not (len(values) == 1 and values[0].isdigit()):
            fail(number, f"{key} must be a non-negative integer")
        elif key == "DATA":
            if values != ["ascii"]:
                fail(number, f"DATA {' '.join(values)!r} is not supported (only ascii)")
            break
    else:
        fail(number, "the header ends before DATA" if header else "no PCD header")
    if names is None:
        fail(number, "no '# labels: 0=name …' comment before DATA")
    points = int(header["POINTS"][0])
    if int(header["WIDTH"][0]) * int(header["HEIGHT"][0]) != points:
        fail(number, f"WIDTH × HEIGHT is not POINTS ({points})")
    rows: list[list[float]] = []
    labels: list[int] = []
    for index, raw in enumerate(lines[number:], number + 1):
        values = raw.split()
        if not values:
            continue
        if len(values) != len(expected):
            fail(index, f"{len(values)} values for {len(expected)} fields")
        try:
            row = [float(x) for x in values[:-1]]
            label = int(values[-1])
        except ValueError:
            fail(index, f"not a number in {raw.strip()!r}")
        if not all(math.isfinite(x) for x in row):
            fail(index, "a value is not finite")
        if label not in names:
            fail(index, f"label {label} is not in '# labels:' ({', '.join(map(str, sorted(names)))})")
        rows.append(row)
        labels.append(label)
    if len(rows) != points:
        fail(len(lines), f"{len(rows)} data rows for POINTS {points}")
    if not rows:
        fail(number, "the model has no samples")
    return ShapeModel(tuple(fields), np.array(rows, dtype=np.float64), np.array(labels, dtype=np.int64), names)
