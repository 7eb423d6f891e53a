"""Depth recognition plugins of ``RGBDCamera.DepthRecog`` (thesis §7.4.1): depth image → clusters → shapes.

The thesis' "Depth recognition" computes the point clusters of the perceived point cloud and
classifies their shape by "a K-neighbors search into a previously trained KD-tree", thresholded
to accept a match. A profile chains, per resolution (the lab's, for example)::

    depth-acquisition → image-resize (nearest) → euclidean-clustering → kdtree-shape-classifier

- ``plugin.depth-acquisition`` (``DepthAcquisition``): a raw frame → float32 metres, NaN = no return.
- ``plugin.euclidean-clustering`` (``EuclideanClustering``): back-projection, support-plane
  removal, Euclidean clustering → ``list[Cluster]`` (left to right).
- ``plugin.kdtree-shape-classifier`` (``KdTreeShapeClassifier``): the descriptor of each cluster
  (``shapes.describe``) → k-NN vote in a KD-tree of labelled descriptors →
  ``{"objects": [{"name", "reliability", "x", "y", "z", "points"}], "reliability": r}``.

This module holds the plugins; the algorithms they run are in ``clusters.py`` (re-exported here).
The trained model is a PCD file of labelled descriptors (``pcd.py``) that the system names in
Param ``model``; the lab's, for example, is generated from rendered scenes run through this very
pipeline by its own package (``ckm_lab.shape_training``, D272).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from sklearn.neighbors import KDTree

from ckmconf.model import System
from ckmconf.model.resources import Plugin
from plugins.processing.camera_info import (
    CAMERA_INFO,
    IMAGE,
    camera_of_info,
    fed_camera_info,
    is_camera_frame,
    stream_input_problems,
)
from plugins.processing.cameras import Camera, camera_of
from plugins.processing.channel_camera import channel_camera, intrinsics_problems
from plugins.processing.clusters import (
    Cluster,
    Depth,
    Mask,
    Points,
    backproject,
    euclidean_clusters,
    find_support_plane,
    segment,
    solid_centre,
    to_metres,
)
from plugins.processing.descriptor import describe
from plugins.processing.pcd import PcdError, ShapeModel, read_pcd
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ANY, ARRAY, MAPPING, P, Params, Ports

__all__ = [
    "ENCODINGS",
    "Cluster",
    "Depth",
    "DepthAcquisition",
    "EuclideanClustering",
    "KdTreeShapeClassifier",
    "Mask",
    "ModelError",
    "Points",
    "backproject",
    "euclidean_clusters",
    "find_support_plane",
    "segment",
    "to_metres",
]

ENCODINGS: dict[str, np.dtype[Any]] = {"16UC1": np.dtype("<u2"), "mono16": np.dtype("<u2"), "32FC1": np.dtype("<f4")}


class ModelError(ValueError):
    """The classifier's model file is missing or malformed."""


def _decode(message: Mapping[str, Any], owner: str) -> npt.NDArray[Any]:
    """The image in a sensor_msgs/Image-like dict (``width height encoding data``, optional ``step is_bigendian``),
    or in a ``DepthImage``-like dict (``width height`` and ``data`` an array of the
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


INTRINSICS = (
    P("camera", "", "A simulated camera HWChannel whose fov, width and height give the intrinsics (instead of "
      "fx … calibrationHeight).", type=str),
    P("fx", None, "Focal length x at the calibration size (required without camera).", type=float, unit="px",
      above=0.0),
    P("fy", None, "Focal length y at the calibration size (default: fx).", type=float, unit="px", above=0.0),
    P("cx", None, "Principal point x at the calibration size (default: (calibrationWidth - 1) / 2).", type=float,
      unit="px"),
    P("cy", None, "Principal point y at the calibration size (default: (calibrationHeight - 1) / 2).", type=float,
      unit="px"),
    P("calibrationWidth", None, "Image width the intrinsics are given for (required without camera).", type=int,
      unit="px", above=0),
    P("calibrationHeight", None, "Image height the intrinsics are given for (required without camera).",
      type=int, unit="px", above=0),
)
"""The camera's intrinsics: the ``camera`` HWChannel's (:mod:`.channel_camera`), or as Params, ``fx`` and
the calibration size required (the depth images the clustering plugins receive carry none, and no lab's
camera is a default); ``fy``, ``cx``, ``cy`` default to the ideal pinhole's
(:meth:`~plugins.processing.cameras.Camera.pinhole`)."""


class DepthAcquisition(ProcessingPlugin):
    """``plugin.depth-acquisition``: a depth frame as float32 metres (NaN where the sensor saw nothing).

    Accepts an (H, W) array — unsigned raw units scaled by ``scale`` (0.001: millimetres, as OpenNI depth
    cameras give), float already in metres — or an Image-like dict with encoding ``16UC1``/``mono16`` or ``32FC1``.
    ``topic`` only documents where frames come from (the service's Input). With ``cameraInfo``, the
    stream reads two Inputs, the depth image and the ``sensor_msgs/CameraInfo`` the Param names, and each
    result is a camera frame ``{image, camera_info}`` whose intrinsics the clustering kinds use
    (:mod:`.camera_info`); nothing is produced until both have arrived, nor for an image already
    processed (same header stamp) when only its CameraInfo is new. Bad frames raise ValueError naming the
    plugin and the problem.
    """

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": ARRAY})  # a DepthImage-like message (or array bytes)
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("topic", "", "The raw topic the frames come from (informational)."),
        P("scale", 0.001, "Metres per raw unit of unsigned depth images (0.001: millimetres).", unit="m", above=0.0),
        P("cameraInfo", "", "The Input carrying the camera's sensor_msgs/CameraInfo: each frame then carries "
          "its intrinsics (docs/recognition.md).", type=str),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if not (math.isfinite(self.params["scale"]) and self.params["scale"] > 0):
            raise ParamError(f"{self.owner}: parameter 'scale' = {self.params['scale']} must be greater than 0")
        self.info_input: str = self.params["cameraInfo"].strip()
        self._last_stamp: Any = None

    @classmethod
    def problems(cls, record: Plugin, system: System | None) -> list[tuple[Any, str]]:
        """``cameraInfo`` naming no Input of the stream, or a stream of other than two Inputs."""
        return stream_input_problems(record, system)

    def process(self, data: Any, context: Context) -> Any:  # Depth, or with cameraInfo a camera frame or None
        """The frame as float32 metres (NaN where the sensor saw nothing), with ``cameraInfo`` a camera
        frame (None while either input is missing or the image is the one already processed);
        ValueError on a bad frame."""
        if self.info_input:
            return self._paired(data)
        return self._metres(data)

    def _metres(self, data: Any) -> Depth:
        if isinstance(data, Mapping):
            image = _decode(data, self.owner)
        elif isinstance(data, np.ndarray):
            image = data
        else:
            raise ValueError(f"{self.owner} expects a depth image or message, got {type(data).__name__}")
        return to_metres(image, self.params["scale"], self.owner)

    def _paired(self, data: Any) -> dict[str, Any] | None:
        if not isinstance(data, Mapping) or self.info_input not in data or len(data) != 2:
            got = sorted(data) if isinstance(data, Mapping) else type(data).__name__
            raise ValueError(f"{self.owner} expects its two Inputs, the depth image and {self.info_input!r}, got {got}")
        info = data[self.info_input]
        image = next(v for k, v in data.items() if k != self.info_input)
        if info is None or image is None:
            return None
        camera_of_info(info, self.owner)  # refuse an uncalibrated or malformed CameraInfo here, named
        header = image.get("header") if isinstance(image, Mapping) else None
        stamp = header.get("stamp") if isinstance(header, Mapping) else None
        if stamp is not None:
            key = repr(stamp)
            if key == self._last_stamp:
                return None
            self._last_stamp = key
        return {IMAGE: self._metres(image), CAMERA_INFO: info}


class EuclideanClustering(ProcessingPlugin):
    """``plugin.euclidean-clustering``: a depth image (metres) → ``list[Cluster]``, left to right.

    Pixels beyond ``maxRange`` are dropped, then, with ``plane`` on, the dominant near-horizontal
    plane (within ``planeAngle`` degrees of the image's up) is found by RANSAC and only points
    more than ``planeDistance`` above it are kept: the objects standing on the floor or a table,
    not what lies below a table edge. Clusters link points closer than ``tolerance`` and keep at
    least ``minPoints``. The camera's intrinsics (the depth images carry none) are those of the
    ``camera`` HWChannel, or Params: ``fx`` at a ``calibrationWidth`` × ``calibrationHeight`` image, ``fy``
    (default ``fx``), ``cx``, ``cy`` (default the image's centre); either is scaled to the image
    received (a resize profile's).
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ANY})  # a list of Clusters: in-process objects
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("tolerance", 0.02, "Points closer than this are linked into one cluster.", unit="m", above=0.0),
        P("minPoints", 100, "Fewest points of a kept cluster.", min=1),
        P("maxRange", 3.5, "Pixels further than this are dropped.", unit="m", above=0.0),
        P("plane", True, "Remove the dominant near-horizontal plane (floor, table) first."),
        P("planeDistance", 0.015, "Points must stand this far above the plane.", unit="m", above=0.0),
        P("planeAngle", 45.0, "Largest tilt of the plane from the image's up, in (0, 90].", unit="deg"),
        *INTRINSICS,
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        for name in ("tolerance", "maxRange", "planeDistance"):
            if not p[name] > 0:
                raise ParamError(f"{self.owner}: parameter {name!r} = {p[name]} must be greater than 0")
        if p["minPoints"] < 1:
            raise ParamError(f"{self.owner}: parameter 'minPoints' = {p['minPoints']} must be at least 1")
        if not 0 < p["planeAngle"] <= 90:
            raise ParamError(f"{self.owner}: parameter 'planeAngle' = {p['planeAngle']} is not in (0, 90] degrees")
        self.camera: Camera | None = None  # None: each frame's CameraInfo gives it (verify checks one does)
        if p["camera"]:
            self.camera = channel_camera(record, p["camera"], self.owner)
        elif p["fx"] is not None or not intrinsics_problems(record, None):
            if problems := intrinsics_problems(record, None):
                raise ParamError(f"{self.owner}: {problems[0][1]}")
            self.camera = camera_of(p, self.owner)

    @classmethod
    def problems(cls, record: Plugin, system: System | None) -> list[tuple[Any, str]]:
        """Neither intrinsics nor a camera channel, or a camera naming no simulated camera (verify reports
        each at its ``FILE:LINE:COL``)."""
        if fed_camera_info(record, system) and not any(p.name in ("camera", "fx") for p in record.params):
            return []
        return intrinsics_problems(record, system)

    def depth_image(self, data: Any) -> tuple[npt.NDArray[Any], Camera]:
        """``data`` as the float depth image in metres (H, W) this plugin clusters and the camera that
        took it (a camera frame's CameraInfo, else the Params' or channel's), else ValueError."""
        camera = self.camera
        if is_camera_frame(data):
            camera = camera_of_info(data[CAMERA_INFO], self.owner)
            data = data[IMAGE]
        depth = np.asarray(data)
        if depth.ndim != 2 or depth.dtype.kind != "f":
            raise ValueError(
                f"{self.owner} expects a float depth image in metres (H, W), got {depth.dtype} {depth.shape}"
            )
        if camera is None:
            raise ValueError(f"{self.owner}: the frame carries no camera_info and no intrinsics are configured")
        return depth, camera

    def clustering(self) -> dict[str, Any]:
        """The clustering Params as keyword arguments of :func:`segment` (and the tabletop's segmentation)."""
        p = self.params
        return {
            "tolerance": p["tolerance"],
            "min_points": p["minPoints"],
            "max_range": p["maxRange"],
            "plane_distance": p["planeDistance"],
            "plane_angle": p["planeAngle"],
        }

    def process(self, data: Any, context: Context) -> list[Cluster]:
        """The clusters of the depth image, left to right."""
        depth, camera = self.depth_image(data)
        return segment(depth, camera, plane=self.params["plane"], **self.clustering())


ROUND = ("cylinder", "sphere")
"""Recognised shapes placed at their axis rather than at their visible surface's centroid."""


class KdTreeShapeClassifier(ProcessingPlugin):
    """``plugin.kdtree-shape-classifier``: clusters → recognized shapes with their reliability.

    ``model`` is an ASCII PCD file of labelled descriptors, relative to the configuration file
    that declares the plugin; it is read in ``setup()``. Each cluster's ``k`` nearest training
    descriptors vote for their label with weight exp(−(d/``spread``)²), so reliability = the
    winner's weight sum / k: 1 only when all k neighbours agree and sit on the descriptor, low
    for shapes unlike any learned one (``spread`` is in descriptor units, see DESCRIPTOR_FIELDS).
    Below ``threshold`` the object is kept, named "unknown". Each object carries ``x y z`` (camera
    optical frame, metres): a round solid's (cylinder, sphere) axis fitted to its visible arc
    (:func:`~plugins.processing.clusters.solid_centre`), else the cluster's centroid (the visible
    surface's, a few cm in front of the solid's centre); and ``points``. The top-level
    ``reliability`` (the service's quality measure) is the mean over recognized objects, 0 when
    none: furniture in view does not drag it.
    """

    PORTS = Ports(inputs={"*": ANY}, outputs={"*": MAPPING})  # objects, reliability
    PROVIDES = "object-detection"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"objects": (
        "objects[].name", "objects[].reliability", "objects[].x", "objects[].y", "objects[].z", "objects[].points",
        "reliability")}
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
        base = config_dir(record)
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
            name = names[best] if reliability >= self.params["threshold"] else "unknown"
            x, y, z = solid_centre(cluster) if name in ROUND else cluster.centroid
            objects.append({"name": name, "reliability": reliability, "x": x, "y": y, "z": z, "points": cluster.count})
        known = [o["reliability"] for o in objects if o["name"] != "unknown"]
        return {"objects": objects, "reliability": float(np.mean(known)) if known else 0.0}

