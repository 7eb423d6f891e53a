"""RGB recognition plugins of ``RGBDCamera.RGBRecog`` (thesis §7.2, §7.4.1), for the Smart Plugin Topology.

A profile chains ``camera-acquisition → image-resize → orb-keypoints → keypoint-matching``. The
thesis extracts SURF keypoints; SURF is not in the free OpenCV build, so ORB (binary descriptors,
Hamming distance) plays its part: a texture is recognised when enough of its learnt keypoints are
matched in the frame (Fig. 7.17).

OpenCV threads. ``setup()`` sets OpenCV to one thread (Param ``threads``, 0 keeps OpenCV's own
choice). The setting is process-wide: it makes a profile's CPU share and deadline figures (the
QoC/QoS measures of §7.2, Table 7.3) those of one core, as in the thesis' set-up, and keeps
OpenCV's worker pool from competing with the kernel's own threads.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import cv2
import numpy as np
import numpy.typing as npt

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import ANY, ARRAY, MAPPING, P, Params, Ports

from .textures import Image, Model, Points, build_model

ENCODINGS: Mapping[str, int] = {"rgb8": 3, "bgr8": 3, "mono8": 1}
"""Raw camera encodings accepted, with their channels (the ROS ``sensor_msgs/Image`` names)."""


def _threads(count: int) -> None:
    if count > 0:
        cv2.setNumThreads(count)


class CameraAcquisition(ProcessingPlugin):
    """``plugin.camera-acquisition``: a raw camera message as an image, RGB (H×W×3) or mono (H×W) uint8.

    The message is an array in the Param ``encoding`` (default ``rgb8``), or a mapping with
    ``width``, ``height``, ``data`` (bytes) and optionally ``encoding`` (else the Param's), as a
    ROS Image without its step. ``bgr8`` is reordered to RGB, so the rest of the chain sees one
    colour order. ``topic`` names the raw topic (the service subscribes to it; informational here).
    """

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": ARRAY})  # an Image-like message (or array bytes)
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("topic", "", "The raw topic the frames come from (informational)."),
        P("encoding", "rgb8", "Encoding of array frames and of messages without one: rgb8, bgr8 or mono8."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.encoding: str = self.params["encoding"]
        if self.encoding not in ENCODINGS:
            raise ParamError(f"{self.owner}: parameter 'encoding' = {self.encoding!r} is not one of {_known()}")

    def process(self, data: Any, context: Context) -> Image:
        """The frame as an RGB or mono uint8 image.

        Raises:
            ValueError: ``data`` is neither an image array nor an Image-like message.
        """
        if isinstance(data, np.ndarray):
            return self._convert(data, self.encoding)
        if isinstance(data, Mapping):
            return self._message(data)
        raise ValueError(f"{self.owner} expects an image array or a width/height/data message, got {type(data)}")

    def _message(self, message: Mapping[str, Any]) -> Image:
        missing = [key for key in ("width", "height", "data") if key not in message]
        if missing:
            raise ValueError(f"{self.owner}: the message has no {', '.join(missing)}")
        encoding = str(message.get("encoding") or self.encoding)
        if encoding not in ENCODINGS:
            raise ValueError(f"{self.owner}: unknown encoding {encoding!r} (known: {_known()})")
        width, height, raw = message["width"], message["height"], message["data"]
        if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v > 0 for v in (width, height)):
            raise ValueError(f"{self.owner}: bad image size {width!r} x {height!r}")
        width, height = int(width), int(height)
        channels = ENCODINGS[encoding]
        if not isinstance(raw, (bytes, bytearray, memoryview)):
            raise ValueError(f"{self.owner}: data is {type(raw).__name__}, not bytes")
        expected = width * height * channels
        if len(raw) != expected:
            raise ValueError(
                f"{self.owner}: {encoding} {width}x{height} needs {expected} bytes of data, got {len(raw)}"
            )
        flat = np.frombuffer(raw, np.uint8)
        return self._convert(flat.reshape((height, width, 3) if channels == 3 else (height, width)), encoding)

    def _convert(self, image: npt.NDArray[Any], encoding: str) -> Image:
        wanted = (3,) if ENCODINGS[encoding] == 3 else ()
        if image.dtype != np.uint8 or image.ndim != 2 + len(wanted) or image.shape[2:] != wanted:
            shape = "(H, W, 3)" if wanted else "(H, W)"
            raise ValueError(f"{self.owner}: {encoding} needs a uint8 {shape} array, got {image.dtype} {image.shape}")
        if encoding == "bgr8":
            return np.ascontiguousarray(image[..., ::-1])
        return image


def _known() -> str:
    return ", ".join(ENCODINGS)


@dataclass(frozen=True)
class Keypoints:
    """ORB keypoints of one frame: positions (N×2 x, y pixels), sizes, angles, descriptors (N×32)."""

    points: Points
    sizes: Points
    angles: Points
    descriptors: Image | None
    shape: tuple[int, int]
    """The (rows, columns) of the image they were found in."""

    def __len__(self) -> int:
        return len(self.points)


def orb_keypoints(orb: cv2.ORB, image: npt.NDArray[Any]) -> Keypoints:
    """ORB keypoints and descriptors of an RGB or grey uint8 image."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    found, descriptors = orb.detectAndCompute(np.ascontiguousarray(grey), None)
    points = np.array([k.pt for k in found], np.float32).reshape(-1, 2)
    sizes = np.array([k.size for k in found], np.float32)
    angles = np.array([k.angle for k in found], np.float32)
    return Keypoints(points, sizes, angles, descriptors, (int(image.shape[0]), int(image.shape[1])))


class OrbKeypoints(ProcessingPlugin):
    """``plugin.orb-keypoints``: ORB keypoints of an image (the thesis' SURF step, §7.4.1).

    Params: ``features`` (most keypoints kept, > 0), ``scaleFactor`` (pyramid step, > 1), ``levels``
    (pyramid levels, ≥ 1), ``threads`` (OpenCV threads, see the module doc).
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ANY})  # Keypoints: an in-process object
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("features", 500, "Most keypoints kept.", above=0),
        P("scaleFactor", 1.2, "Scale step of the image pyramid.", above=1.0),
        P("levels", 8, "Pyramid levels.", min=1),
        P("threads", 1, "OpenCV threads (0: OpenCV's default).", min=0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        for name, ok, rule in (
            ("features", p["features"] > 0, "greater than 0"),
            ("scaleFactor", p["scaleFactor"] > 1.0, "greater than 1"),
            ("levels", p["levels"] >= 1, "at least 1"),
            ("threads", p["threads"] >= 0, "at least 0"),
        ):
            if not ok:
                raise ParamError(f"{self.owner}: parameter {name!r} = {p[name]} must be {rule}")
        self._orb: cv2.ORB | None = None

    def setup(self) -> None:
        """Create the ORB detector (and set OpenCV's thread count)."""
        _threads(self.params["threads"])
        p = self.params
        self._orb = cv2.ORB.create(nfeatures=p["features"], scaleFactor=p["scaleFactor"], nlevels=p["levels"])

    def process(self, data: Any, context: Context) -> Keypoints:
        """The ORB keypoints of a uint8 image."""
        if self._orb is None:
            raise RuntimeError(f"{self.owner} is not set up")
        image = np.asarray(data)
        if image.dtype != np.uint8 or image.ndim not in (2, 3) or image.shape[2:] not in ((), (3,)):
            raise ValueError(f"{self.owner} expects a uint8 RGB or grey image, got {image.dtype} {image.shape}")
        return orb_keypoints(self._orb, image)

    def stop(self) -> None:
        """Drop the ORB detector."""
        self._orb = None


class KeypointMatching(ProcessingPlugin):
    """``plugin.keypoint-matching``: which learnt textures a frame's ORB keypoints show (§7.4.1).

    Param ``model``: the model file (``textures.py`` format), relative to the configuration file
    that declares the plugin; loaded and learnt in ``setup()``. Each keypoint's nearest model
    descriptor (Hamming, brute force) is kept if it passes Lowe's ratio test (``ratio``) against
    the nearest descriptor of a *different* model point: the model holds each texture at several
    scales, and the same corner learnt twice must not make itself ambiguous. An object is detected
    when at least ``minMatches`` kept matches point to it and a RANSAC homography (threshold
    ``reprojection`` pixels at 640 columns, scaled to the frame) explains at least half of them,
    mapping its texture to a plausible (convex, not mirrored) quadrilateral.

    Output (msgpack-able): ``{"objects": [{"name", "matches", "inliers", "x", "y",
    "reliability"}], "reliability", "keypoints", "width", "height"}``, objects by decreasing
    reliability, ``x``/``y`` the texture centre in the frame (0..1). An object's reliability
    ``r = inliers / (inliers + support)``: 0.5 at ``support`` inliers, towards 1 with more
    evidence, so it falls with resolution as the thesis' keypoint reliability does (Fig. 7.18).
    The service's ``reliability`` (Table 7.1's measure) is the mean ``r`` of the detected
    objects, 0 when none is seen.
    """

    PORTS = Ports(inputs={"*": ANY}, outputs={"*": MAPPING})  # objects, reliability, keypoints, size
    PROVIDES = "object-detection"  # docs/interfaces.md
    POSITIONS = "image"  # x, y: shares of the frame (plugins.behaviors.upstream)
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"objects": (
        "objects[].name", "objects[].matches", "objects[].inliers", "objects[].x", "objects[].y",
        "objects[].reliability", "reliability", "keypoints", "width", "height")}
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", "", "Texture model file, relative to the configuration file (required)."),
        P("ratio", 0.75, "Lowe's ratio test threshold, in (0, 1]."),
        P("minMatches", 10, "Kept matches needed to detect an object (at least 4)."),
        P("reprojection", 4.0, "RANSAC reprojection threshold at 640 columns.", unit="px", above=0.0),
        P("support", 20.0, "Inliers at which an object's reliability is 0.5.", above=0.0),
        P("threads", 1, "OpenCV threads (0: OpenCV's default).", min=0),
        P("matcher", "brute-force", "Nearest-descriptor search: exhaustive, or a FLANN LSH index of the model "
          "(D200: 2.5x faster on the 9,000-keypoint lab model, nearly the same inliers).",
          choices=("brute-force", "lsh")),
    )
    SAME_POINT = 0.04
    CUTS = 8
    """Places a wrapping print is tried unwrapped at (D175)."""
    """Model points closer than this share of the texture's size are one point (ratio test)."""

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        for name, ok, rule in (
            ("model", bool(p["model"]), "a file name"),
            ("ratio", 0.0 < p["ratio"] <= 1.0, "in (0, 1]"),
            ("minMatches", p["minMatches"] >= 4, "at least 4 (a homography needs 4 points)"),
            ("reprojection", p["reprojection"] > 0.0, "greater than 0"),
            ("support", p["support"] > 0.0, "greater than 0"),
            ("threads", p["threads"] >= 0, "at least 0"),
        ):
            if not ok:
                raise ParamError(f"{self.owner}: parameter {name!r} = {p[name]!r} must be {rule}")
        # Anchored now (no I/O): the file was loaded relative to the current directory.
        base = Path(os.path.abspath(record.loc.file)).parent if record.loc is not None else Path.cwd()
        self.path = base / p["model"]
        self.model: Model | None = None
        self._matcher: Any = cv2.BFMatcher(cv2.NORM_HAMMING)

    def setup(self) -> None:
        """Build the texture model from the model file.

        Raises:
            OSError: the model file cannot be read.
            ValueError: the model file is malformed.
        """
        _threads(self.params["threads"])
        try:
            self.model = build_model(self.path)
        except OSError as exc:  # the same errno, so still a FileNotFoundError, PermissionError…
            raise OSError(exc.errno, f"{self.owner}: cannot read model file {self.path}: {exc.strerror}") from exc
        except ValueError as exc:
            raise ValueError(f"{self.owner}: bad model file: {exc}") from exc
        if self.params["matcher"] == "lsh":  # the index is built once, over the model's descriptors
            lsh: dict[str, bool | int | float | str] = {"algorithm": 6, "table_number": 6, "key_size": 12,
                                                        "multi_probe_level": 1}  # FLANN_INDEX_LSH
            self._matcher = cv2.FlannBasedMatcher(lsh, {"checks": 64})
            self._matcher.add([self.model.descriptors])
            # FLANN draws its hash tables from OpenCV's process-wide RNG: reset it to its start state so the
            # index depends on the model only, not on what the process built before (D206)
            cv2.setRNGSeed(0)
            self._matcher.train()

    def stop(self) -> None:
        """Drop the texture model."""
        self.model = None

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The learnt textures ``data``'s keypoints show, with their positions and reliability (§7.4.1)."""
        if self.model is None:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Keypoints):
            raise ValueError(f"{self.owner} expects the Keypoints of an orb-keypoints plugin, got {type(data)}")
        rows, cols = data.shape
        found: list[dict[str, Any]] = []
        if data.descriptors is not None and len(data) >= 4:
            good, nearest = self._good(data.descriptors)
            for index in range(len(self.model.names)):
                chosen = good & (self.model.labels[nearest] == index)
                if int(chosen.sum()) >= self.params["minMatches"]:
                    hit = self._locate(index, self.model.points[nearest[chosen]], data.points[chosen], cols, rows)
                    if hit is not None:
                        found.append(hit)
        found.sort(key=lambda o: -o["reliability"])
        mean = sum(o["reliability"] for o in found) / len(found) if found else 0.0
        return {"objects": found, "reliability": mean, "keypoints": len(data), "width": cols, "height": rows}

    def _good(self, descriptors: Image) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.intp]]:
        """Which query keypoints pass the ratio test, and each one's nearest model descriptor."""
        assert self.model is not None
        k = 3  # the model has at least 4 descriptors: brute force gives k per row, LSH may give fewer
        if self.params["matcher"] == "lsh":
            rows = self._matcher.knnMatch(descriptors, k=k)
        else:
            rows = self._matcher.knnMatch(descriptors, self.model.descriptors, k=k)
        dist = np.full((len(descriptors), k), np.inf, np.float32)
        index = np.zeros((len(descriptors), k), np.intp)
        for i, row in enumerate(rows):
            for j, m in enumerate(row[:k]):
                dist[i, j], index[i, j] = m.distance, m.trainIdx
        # A query LSH found nothing near keeps distance inf: it fails the ratio test below. A shorter
        # row's missing neighbours repeat its nearest (never "distinct": the ratio test has no second).
        for j in range(1, k):
            short = np.isinf(dist[:, j])
            index[short, j] = index[short, 0]
        nearest = index[:, 0]
        labels, points = self.model.labels, self.model.points
        sizes = np.array([max(size) for size in self.model.sizes], np.float32)[labels[nearest]]
        offset = points[index] - points[nearest][:, None, :]
        apart = np.hypot(offset[..., 0], offset[..., 1]) > self.SAME_POINT * sizes[:, None]
        distinct = (labels[index] != labels[nearest][:, None]) | apart
        distinct[:, 0] = False
        second = np.where(distinct.any(axis=1), dist[np.arange(len(dist)), np.argmax(distinct, axis=1)], np.inf)
        return dist[:, 0] < self.params["ratio"] * second, nearest

    def _locate(self, index: int, model: Points, image: Points, cols: int, rows: int) -> dict[str, Any] | None:
        """The detection of object ``index`` from its matches, or None if no plausible homography explains them.

        A print that repeats side by side (``wrap``: round a cylinder) may show the end of one copy
        and the start of the next. Its texture points are then unwrapped at one of ``CUTS`` cuts
        (those left of the cut move one copy to the right) and the cut whose homography explains
        most matches wins (D175). Each match stands for one point, so no degenerate homography
        gathers a point's several copies.
        """
        assert self.model is not None
        width, height = self.model.sizes[index]
        wraps = bool(self.model.wraps[index]) if self.model.wraps else False
        threshold = max(2.0, self.params["reprojection"] * cols / 640.0)
        best: tuple[int, Image, Image, Points] | None = None
        for cut in np.arange(self.CUTS if wraps else 1) * width / self.CUTS:
            source = model.copy()
            if cut > 0:
                source[source[:, 0] < cut, 0] += width
            found, found_mask = cv2.findHomography(source, image, cv2.RANSAC, threshold)
            if found is not None and found_mask is not None and (best is None or int(found_mask.sum()) > best[0]):
                best = (int(found_mask.sum()), found, found_mask, source)
        if best is None:
            return None
        inliers, homography, mask, source = best
        if 2 * inliers < len(model) or inliers < 4:
            return None
        # The texture's own frame, or for a wrapping print the one-copy span the inliers show.
        left = 0.0
        if wraps:
            used = source[mask.ravel().astype(bool), 0]
            left = float((used.min() + used.max()) / 2 - width / 2)
        right = left + width
        corners = np.array([[[left, 0], [right, 0], [right, height], [left, height]]], np.float32)
        quad = cv2.perspectiveTransform(corners, homography)[0]
        if not _plausible(quad):
            return None
        middle = np.array([[[left + width / 2, height / 2]]], np.float32)
        centre = cv2.perspectiveTransform(middle, homography)[0, 0]
        return {
            "name": self.model.names[index],
            "matches": len(model),
            "inliers": inliers,
            "x": float(np.clip(centre[0] / cols, 0.0, 1.0)),
            "y": float(np.clip(centre[1] / rows, 0.0, 1.0)),
            "reliability": inliers / (inliers + self.params["support"]),
        }


def _plausible(quad: Points) -> bool:
    """A texture's projected corners form a view of a flat print: convex, not mirrored, a few pixels big."""
    if not cv2.isContourConvex(quad.reshape(-1, 1, 2)):
        return False
    area = cv2.contourArea(quad.reshape(-1, 1, 2), oriented=True)  # > 0 for clockwise (y down)
    sides = np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)
    return bool(area > 64.0 and sides.max() < 4.0 * sides.min())
