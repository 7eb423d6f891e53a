"""Depth recognition plugins of ``RGBDCamera.DepthRecog`` (thesis §7.4.1): depth image → clusters → shapes.

The thesis' "Depth recognition" computes the point clusters of the perceived point cloud and
classifies their shape by "a K-neighbors search into a previously trained KD-tree", thresholded
to accept a match. The use case's profiles chain, per resolution::

    depth-acquisition → image-resize (nearest) → euclidean-clustering → kdtree-shape-classifier

- ``plugin.depth-acquisition`` (``DepthAcquisition``): a raw frame → float32 metres, NaN = no return.
- ``plugin.euclidean-clustering`` (``EuclideanClustering``): back-projection, support-plane
  removal, Euclidean clustering → ``list[Cluster]`` (left to right).
- ``plugin.kdtree-shape-classifier`` (``KdTreeShapeClassifier``): the descriptor of each cluster
  (``shapes.describe``) → k-NN vote in a KD-tree of labelled descriptors →
  ``{"objects": [{"name", "reliability", "x", "y", "z", "points"}], "reliability": r}``.

The trained model ``configs/usecase/models/lab_objects_shapes.pcd`` is generated from rendered
synthetic scenes run through this very pipeline; regenerate it with::

    .venv/bin/python -m plugins.processing.depth configs/usecase/models/lab_objects_shapes.pcd
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from sklearn.cluster import DBSCAN
from sklearn.neighbors import KDTree

from ckmconf.model.resources import Plugin
from plugins.processing.image import resize
from plugins.processing.shapes import (
    DESCRIPTOR_FIELDS,
    Camera,
    PcdError,
    Plane,
    Shape,
    ShapeKind,
    ShapeModel,
    describe,
    format_pcd,
    read_pcd,
    render_depth_scene,
)
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import ANY, ARRAY, MAPPING, P, Params, Ports

Depth = npt.NDArray[np.float32]
Points = npt.NDArray[np.float32]
Mask = npt.NDArray[np.bool_]
ENCODINGS: dict[str, np.dtype[Any]] = {"16UC1": np.dtype("<u2"), "mono16": np.dtype("<u2"), "32FC1": np.dtype("<f4")}


class ModelError(ValueError):
    """The classifier's model file is missing or malformed."""


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


def _decode(message: Mapping[str, Any], owner: str) -> npt.NDArray[Any]:
    """The image in a sensor_msgs/Image-like dict (``width height encoding data``, optional ``step is_bigendian``),
    or in a ``DepthImage`` (configs/usecase/network.xml: ``width height`` and ``data`` an array of the
    ``width × height`` raw depths, row-major, as a simulated or real sensor publishes it)."""
    data = message.get("data")
    if "encoding" not in message and isinstance(data, np.ndarray):
        width, height = message.get("width"), message.get("height")
        if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (width, height)):
            raise ValueError(f"{owner}: depth message size {width!r} x {height!r} is not two positive integers")
        assert isinstance(width, int) and isinstance(height, int)
        if data.size != width * height or data.dtype.kind not in "uif":
            shape = f"({data.dtype}, {data.size} values)"
            raise ValueError(f"{owner}: depth message data {shape} is not {width} x {height} depths")
        return data.reshape(height, width)
    missing = [key for key in ("width", "height", "encoding", "data") if key not in message]
    if missing:
        raise ValueError(f"{owner}: depth message has no {', '.join(map(repr, missing))}")
    width, height, encoding, data = (message[k] for k in ("width", "height", "encoding", "data"))
    for key, value in (("width", width), ("height", height)):
        if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
            raise ValueError(f"{owner}: depth message {key} {value!r} is not a positive integer")
    dtype = ENCODINGS.get(encoding) if isinstance(encoding, str) else None
    if dtype is None:
        raise ValueError(f"{owner}: depth encoding {encoding!r} is not one of {', '.join(ENCODINGS)}")
    if message.get("is_bigendian"):
        dtype = dtype.newbyteorder(">")
    if not isinstance(data, bytes | bytearray | memoryview):
        raise ValueError(f"{owner}: depth message data is {type(data).__name__}, not bytes")
    step = message.get("step", width * dtype.itemsize)
    if not isinstance(step, int) or step < width * dtype.itemsize:
        raise ValueError(f"{owner}: depth message step {step!r} is shorter than a row of {width} pixels")
    if len(data) != step * height:
        raise ValueError(f"{owner}: depth message has {len(data)} bytes of data, expected {height} rows of {step}")
    return np.ndarray((height, width), dtype=dtype, buffer=data, strides=(step, dtype.itemsize))


class DepthAcquisition(ProcessingPlugin):
    """``plugin.depth-acquisition``: a depth frame as float32 metres (NaN where the sensor saw nothing).

    Accepts an (H, W) array — unsigned raw units scaled by ``scale`` (0.001: the Xtion's mm), float
    already in metres — or an Image-like dict with encoding ``16UC1``/``mono16`` or ``32FC1``.
    ``topic`` only documents where frames come from (the service's Input). Bad frames raise
    ValueError naming the plugin and the problem.
    """

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": ARRAY})  # a DepthImage-like message (or array bytes)
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("topic", "", "The raw topic the frames come from (informational)."),
        P("scale", 0.001, "Metres per raw unit of unsigned depth images (0.001: millimetres).", unit="m", above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if not (math.isfinite(self.params["scale"]) and self.params["scale"] > 0):
            raise ParamError(f"{self.owner}: parameter 'scale' = {self.params['scale']} must be greater than 0")

    def process(self, data: Any, context: Context) -> Depth:
        """The frame as float32 metres (NaN where the sensor saw nothing); ValueError on a bad frame."""
        if isinstance(data, Mapping):
            image = _decode(data, self.owner)
        elif isinstance(data, np.ndarray):
            image = data
        else:
            raise ValueError(f"{self.owner} expects a depth image or message, got {type(data).__name__}")
        return to_metres(image, self.params["scale"], self.owner)


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


class EuclideanClustering(ProcessingPlugin):
    """``plugin.euclidean-clustering``: a depth image (metres) → ``list[Cluster]``, left to right.

    Pixels beyond ``maxRange`` are dropped, then, with ``plane`` on, the dominant near-horizontal
    plane (within ``planeAngle`` degrees of the image's up) is found by RANSAC and only points
    more than ``planeDistance`` above it are kept: the objects standing on the floor or a table,
    not what lies below a table edge. Clusters link points closer than ``tolerance`` and keep at
    least ``minPoints``. ``fx fy cx cy`` are given for a ``calibrationWidth`` ×
    ``calibrationHeight`` image (the Xtion's at VGA) and scaled to the image received.
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ANY})  # a list of Clusters: in-process objects
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("tolerance", 0.02, "Points closer than this are linked into one cluster.", unit="m", above=0.0),
        P("minPoints", 100, "Fewest points of a kept cluster.", min=1),
        P("maxRange", 3.5, "Pixels further than this are dropped.", unit="m", above=0.0),
        P("plane", True, "Remove the dominant near-horizontal plane (floor, table) first."),
        P("planeDistance", 0.015, "Points must stand this far above the plane.", unit="m", above=0.0),
        P("planeAngle", 45.0, "Largest tilt of the plane from the image's up, in (0, 90].", unit="deg"),
        P("fx", 525.0, "Focal length x at the calibration size.", unit="px", above=0.0),
        P("fy", 525.0, "Focal length y at the calibration size.", unit="px", above=0.0),
        P("cx", 319.5, "Principal point x at the calibration size.", unit="px"),
        P("cy", 239.5, "Principal point y at the calibration size.", unit="px"),
        P("calibrationWidth", 640, "Image width the intrinsics are given for.", unit="px", above=0),
        P("calibrationHeight", 480, "Image height the intrinsics are given for.", unit="px", above=0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        for name in ("tolerance", "maxRange", "planeDistance", "fx", "fy", "calibrationWidth", "calibrationHeight"):
            if not p[name] > 0:
                raise ParamError(f"{self.owner}: parameter {name!r} = {p[name]} must be greater than 0")
        if p["minPoints"] < 1:
            raise ParamError(f"{self.owner}: parameter 'minPoints' = {p['minPoints']} must be at least 1")
        if not 0 < p["planeAngle"] <= 90:
            raise ParamError(f"{self.owner}: parameter 'planeAngle' = {p['planeAngle']} is not in (0, 90] degrees")
        self.camera = Camera(p["fx"], p["fy"], p["cx"], p["cy"], p["calibrationWidth"], p["calibrationHeight"])

    def depth_image(self, data: Any) -> npt.NDArray[Any]:
        """``data`` as the float depth image in metres (H, W) this plugin clusters, else ValueError."""
        depth = np.asarray(data)
        if depth.ndim != 2 or depth.dtype.kind != "f":
            raise ValueError(
                f"{self.owner} expects a float depth image in metres (H, W), got {depth.dtype} {depth.shape}"
            )
        return depth

    def process(self, data: Any, context: Context) -> list[Cluster]:
        """The clusters of the depth image, left to right."""
        depth = self.depth_image(data)
        p = self.params
        return segment(
            depth,
            self.camera,
            tolerance=p["tolerance"],
            min_points=p["minPoints"],
            max_range=p["maxRange"],
            plane=p["plane"],
            plane_distance=p["planeDistance"],
            plane_angle=p["planeAngle"],
        )


class KdTreeShapeClassifier(ProcessingPlugin):
    """``plugin.kdtree-shape-classifier``: clusters → recognized shapes with their reliability.

    ``model`` is an ASCII PCD file of labelled descriptors, relative to the configuration file
    that declares the plugin; it is read in ``setup()``. Each cluster's ``k`` nearest training
    descriptors vote for their label with weight exp(−(d/``spread``)²), so reliability = the
    winner's weight sum / k: 1 only when all k neighbours agree and sit on the descriptor, low
    for shapes unlike any learned one (``spread`` is in descriptor units, see DESCRIPTOR_FIELDS).
    Below ``threshold`` the object is kept, named "unknown". Each object carries its cluster's
    centroid ``x y z`` (camera optical frame, metres; the visible surface's, so a few cm in front
    of the solid's centre) and ``points``. The top-level ``reliability`` (the service's quality
    measure) is the mean over recognized objects, 0 when none: furniture in view does not drag it.
    """

    PORTS = Ports(inputs={"*": ANY}, outputs={"*": MAPPING})  # objects, reliability
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", "", "ASCII PCD file of labelled descriptors, relative to the configuration file (required)."),
        P("k", 5, "Nearest training descriptors that vote.", min=1),
        P("threshold", 0.75, "Reliability below which an object is named 'unknown', in [0, 1]."),
        P("spread", 1.0, "Distance scale of the vote weights, in descriptor units.", above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        if not p["model"]:
            raise ParamError(f"{self.owner}: parameter 'model' must name a PCD file")
        if p["k"] < 1:
            raise ParamError(f"{self.owner}: parameter 'k' = {p['k']} must be at least 1")
        if not 0 <= p["threshold"] <= 1:
            raise ParamError(f"{self.owner}: parameter 'threshold' = {p['threshold']} is not in [0, 1]")
        if not p["spread"] > 0:
            raise ParamError(f"{self.owner}: parameter 'spread' = {p['spread']} must be greater than 0")
        base = Path(record.loc.file).parent if record.loc is not None else Path()
        self.path = base / p["model"]
        self.model: ShapeModel | None = None
        self.tree: KDTree | None = None

    def setup(self) -> None:
        """Read the PCD model and build its k-d tree; ModelError when it is missing, malformed or too small."""
        try:
            model = read_pcd(self.path)
        except PcdError as exc:
            raise ModelError(f"{self.owner}: bad model file {exc}") from None
        except OSError as exc:
            raise ModelError(f"{self.owner}: cannot read model file {self.path}: {exc.strerror}") from None
        if len(model.labels) < self.params["k"]:
            raise ModelError(f"{self.owner}: model file {self.path} has {len(model.labels)} samples, fewer than k")
        self.model, self.tree = model, KDTree(model.descriptors)

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The recognized shapes of ``data``'s clusters and their mean reliability (§7.4.1)."""
        if self.model is None or self.tree is None:
            raise RuntimeError(f"{self.owner}: setup() was not called")
        clusters = list(data)
        if not all(isinstance(c, Cluster) for c in clusters):
            raise ValueError(f"{self.owner} expects the clusters of a euclidean-clustering plugin")
        if not clusters:
            return {"objects": [], "reliability": 0.0}
        k, names = self.params["k"], self.model.names
        features = np.stack([describe(c.points, c.plane) for c in clusters])
        distances, neighbours = self.tree.query(features, k=k)
        weights = np.exp(-((distances / self.params["spread"]) ** 2))
        objects = []
        for cluster, votes, weight in zip(clusters, self.model.labels[neighbours], weights, strict=True):
            scores = np.bincount(votes, weights=weight, minlength=max(names) + 1) / k
            best = int(np.argmax(scores))
            reliability = float(scores[best])
            x, y, z = cluster.centroid
            name = names[best] if reliability >= self.params["threshold"] else "unknown"
            objects.append({"name": name, "reliability": reliability, "x": x, "y": y, "z": z, "points": cluster.count})
        known = [o["reliability"] for o in objects if o["name"] != "unknown"]
        return {"objects": objects, "reliability": float(np.mean(known)) if known else 0.0}


# --------------------------------------------------------------------------- the trained model

# (rows, cols, tolerance, minPoints) of the use case's cluster_vga/qvga/qqvga plugins.
TRAINING_PROFILES = ((480, 640, 0.02, 400), (240, 320, 0.03, 100), (120, 160, 0.04, 25))
SHAPE_LABELS = {0: "box", 1: "cylinder", 2: "sphere"}


def _training_scene(rng: np.random.Generator) -> tuple[list[Shape], Camera]:
    """Three random objects (one per class, sizes around the lab's of Fig. 7.5) on the floor ahead."""
    camera = Camera(elevation=float(rng.uniform(0.4, 0.7)), tilt=float(rng.uniform(0.25, 0.5)))
    near = camera.elevation / math.tan(camera.tilt + 0.4) + 0.2  # the floor's first visible metres
    ahead = max(float(rng.uniform(0.7, 1.8)), near)
    ranges: dict[ShapeKind, list[tuple[float, float]]] = {
        "box": [(0.04, 0.1), (0.04, 0.1), (0.08, 0.18)],  # width, depth, height
        "cylinder": [(0.025, 0.045), (0.08, 0.16)],  # radius, height
        "sphere": [(0.03, 0.06)],  # radius
    }
    kinds: list[ShapeKind] = ["box", "cylinder", "sphere"]
    shapes = []
    for slot, pick in enumerate(rng.permutation(3)):  # left, centre, right
        kind = kinds[int(pick)]
        x = (slot - 1) * 0.25 * ahead + float(rng.uniform(-0.03, 0.03))
        y = ahead + float(rng.uniform(-0.1, 0.1))
        size = tuple(float(rng.uniform(lo, hi)) for lo, hi in ranges[kind])
        shapes.append(Shape(kind, x, y, size, yaw=float(rng.uniform(0, math.pi / 2)), name=kind))
    return shapes, camera


def generate_model(scenes: int = 80, seed: int = 7) -> ShapeModel:
    """Labelled descriptors of rendered scenes run through this pipeline at the three resolutions.

    Deterministic for given arguments. A cluster is labelled by the rendered object whose centre
    is nearest to its centroid (within 15 cm); clusters matching no object are left out.
    """
    rng = np.random.default_rng(seed)
    label_of = {name: index for index, name in SHAPE_LABELS.items()}
    rows: list[npt.NDArray[np.float64]] = []
    labels: list[int] = []
    for scene in range(scenes):
        shapes, camera = _training_scene(rng)
        rendered = render_depth_scene(shapes, seed=seed * 1000 + scene, camera=camera)
        metres = to_metres(rendered.depth, 0.001, "generate_model")
        for height, width, tolerance, min_points in TRAINING_PROFILES:
            image = resize(metres, height, width, area=False)
            clusters = segment(image, Camera(), tolerance=tolerance, min_points=min_points)
            for truth in rendered.truth:
                gaps = [math.dist(c.centroid, (truth.x, truth.y, truth.z)) for c in clusters]
                if gaps and min(gaps) < 0.15:
                    cluster = clusters.pop(int(np.argmin(gaps)))
                    rows.append(describe(cluster.points, cluster.plane))
                    labels.append(label_of[truth.kind])
    descriptors = np.array(rows, dtype=np.float64).round(4)  # what the file keeps
    return ShapeModel(DESCRIPTOR_FIELDS, descriptors, np.array(labels, dtype=np.int64), SHAPE_LABELS)


def write_model(path: str | Path, scenes: int = 80, seed: int = 7) -> ShapeModel:
    """Generate the model and write it as an ASCII PCD file (the committed use-case model)."""
    model = generate_model(scenes, seed)
    notes = [
        f"descriptor: {' '.join(DESCRIPTOR_FIELDS)} (plugins/processing/shapes.py DESCRIPTOR_FIELDS)",
        f"generated by plugins.processing.depth.generate_model(scenes={scenes}, seed={seed})",
    ]
    Path(path).write_text(format_pcd(model, notes), encoding="ascii")
    return model


if __name__ == "__main__":
    write_model(sys.argv[1] if len(sys.argv) > 1 else "configs/usecase/models/lab_objects_shapes.pcd")
