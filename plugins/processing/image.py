"""Image processing plugins for the Smart Plugin Topology: ``plugin.resize`` and ``plugin.grayscale``.

They serve the recognition services' profiles (VGA, QVGA, QQVGA are resizes of one acquisition).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

import cv2
import numpy as np
import numpy.typing as npt

from ckmconf.model.resources import Plugin
from plugins.processing.camera_info import IMAGE, is_camera_frame
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import ARRAY, P, Params, Ports

Image = npt.NDArray[Any]


def _image(data: Any, owner: str) -> Image:
    image = np.asarray(data)
    if image.ndim not in (2, 3):
        raise ValueError(f"{owner} expects an image of shape (H, W) or (H, W, C), got {image.shape}")
    return image


def resize(image: Image, height: int, width: int, *, area: bool = True) -> Image:
    """``image`` resampled to ``height`` × ``width`` (channels kept, dtype kept).

    With ``area`` and whole factors (VGA → QVGA → QQVGA) it is a block average, an anti-aliased
    downscale (integers rounded half up, as OpenCV's INTER_AREA which computes it); otherwise
    nearest-neighbour sampling at the centres of the target pixels (what depth images need:
    averaging depths across an object's edge invents surfaces).
    """
    rows, cols = image.shape[:2]
    if (rows, cols) == (height, width):
        return image
    if area and rows % height == 0 and cols % width == 0:
        if image.dtype in (np.uint8, np.uint16, np.float32) and (image.ndim == 2 or image.shape[-1] <= 4):
            # OpenCV's area interpolation is this block average, ~20x faster than numpy's float64 mean.
            scaled: Image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
            return scaled.reshape(height, width, *image.shape[2:])
        blocks = image.reshape(height, rows // height, width, cols // width, *image.shape[2:])
        mean: Image = blocks.mean(axis=(1, 3), dtype=np.float64)
        return (np.floor(mean + 0.5) if np.issubdtype(image.dtype, np.integer) else mean).astype(image.dtype)
    pick_rows = ((np.arange(height) + 0.5) * rows / height).astype(np.intp)
    pick_cols = ((np.arange(width) + 0.5) * cols / width).astype(np.intp)
    picked: Image = image[pick_rows][:, pick_cols]
    return picked


class Resize(ProcessingPlugin):
    """``plugin.resize`` / ``plugin.image-resize``: an image resized to ``width`` × ``height`` pixels.

    Params: ``width`` and ``height`` (0: unset; one alone keeps the aspect ratio) or, when neither
    is set, ``scale`` (default 1); ``interpolation``: ``area`` (default: block average for whole
    factors) or ``nearest``. The resolution profiles of the recognition services use it. A camera
    frame ``{image, camera_info}`` (:mod:`.camera_info`) comes out as one, its image resized and its
    CameraInfo passed on: the intrinsics stay at the CameraInfo's size, which its users scale from.
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ARRAY})  # an image in, the resized image out
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("scale", 1.0, "Scale factor when neither width nor height is set.", above=0.0),
        P("width", 0, "Output width (0: unset; one of width/height alone keeps the aspect ratio).", unit="px", min=0),
        P("height", 0, "Output height (0: unset).", unit="px", min=0),
        P("interpolation", "area", "'area' (block average) or 'nearest'."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if not self.params["scale"] > 0.0:
            raise ParamError(f"{self.owner}: parameter 'scale' = {self.params['scale']} must be greater than 0")
        for name in ("width", "height"):
            if self.params[name] < 0:
                raise ParamError(f"{self.owner}: parameter {name!r} = {self.params[name]} must not be negative")
        if self.params["interpolation"] not in ("area", "nearest"):
            value = self.params["interpolation"]
            raise ParamError(f"{self.owner}: parameter 'interpolation' = {value!r} is not 'area' or 'nearest'")
        self.area = self.params["interpolation"] == "area"

    def target(self, rows: int, cols: int) -> tuple[int, int]:
        """The output (height, width) for an input of ``rows`` × ``cols``."""
        width, height, scale = self.params["width"], self.params["height"], self.params["scale"]
        if width and height:
            return height, width
        if width:
            return max(1, round(rows * width / cols)), width
        if height:
            return height, max(1, round(cols * height / rows))
        return max(1, round(rows * scale)), max(1, round(cols * scale))

    def process(self, data: Any, context: Context) -> Image | dict[str, Any]:
        """The image resized to the target size (a camera frame's image, its CameraInfo passed on)."""
        if is_camera_frame(data):
            return {**data, IMAGE: self.process(data[IMAGE], context)}
        image = _image(data, self.owner)
        return resize(image, *self.target(*image.shape[:2]), area=self.area)


class Grayscale(ProcessingPlugin):
    """``plugin.grayscale``: the luma of a colour image (ITU-R BT.601 weights), dtype kept.

    Param ``order``: ``rgb`` (default, the cameras' rgb8) or ``bgr`` (OpenCV's). A 2-D image passes
    through; a fourth (alpha) channel is ignored.
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ARRAY})
    PARAMS: ClassVar[Mapping[str, Any]] = Params(P("order", "rgb", "Channel order of the input: 'rgb' or 'bgr'."))
    WEIGHTS = (0.299, 0.587, 0.114)

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if self.params["order"] not in ("rgb", "bgr"):
            raise ParamError(f"{self.owner}: parameter 'order' = {self.params['order']!r} is not 'rgb' or 'bgr'")
        weights = self.WEIGHTS if self.params["order"] == "rgb" else self.WEIGHTS[::-1]
        self.weights = np.asarray(weights, dtype=np.float64)

    def process(self, data: Any, context: Context) -> Image:
        """The luma of a colour image (a grey image passes unchanged)."""
        image = _image(data, self.owner)
        if image.ndim == 2:
            return image
        if image.shape[2] not in (3, 4):
            raise ValueError(f"{self.owner} expects 3 or 4 channels, got {image.shape[2]}")
        luma = image[..., :3] @ self.weights
        return (np.rint(luma) if np.issubdtype(image.dtype, np.integer) else luma).astype(image.dtype)


class Undistort(ProcessingPlugin):
    """``plugin.undistort``: lens distortion removed with the Brown–Conrady model (OpenCV's).

    Params: the intrinsics ``fx``, ``fy``, ``cx``, ``cy`` in pixels at the input's resolution
    (0: focal = image width, centre = image centre) and the coefficients ``k1 k2 p1 p2 k3``. With
    every coefficient 0 the image passes through untouched; otherwise the remap tables are built
    once per image size and reused, so a frame costs one ``cv2.remap``.
    """

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": ARRAY})
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("fx", 0.0, "Focal length along x at the input's resolution (0: the image width).", unit="px", min=0.0),
        P("fy", 0.0, "Focal length along y (0: the image width).", unit="px", min=0.0),
        P("cx", 0.0, "Principal point x (0: the image centre).", unit="px"),
        P("cy", 0.0, "Principal point y (0: the image centre).", unit="px"),
        P("k1", 0.0, "Radial distortion coefficient k1."),
        P("k2", 0.0, "Radial distortion coefficient k2."),
        P("p1", 0.0, "Tangential distortion coefficient p1."),
        P("p2", 0.0, "Tangential distortion coefficient p2."),
        P("k3", 0.0, "Radial distortion coefficient k3."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        for name in ("fx", "fy"):
            if self.params[name] < 0:
                raise ParamError(f"{self.owner}: parameter {name!r} = {self.params[name]} must not be negative")
        self.coefficients = np.array([self.params[k] for k in ("k1", "k2", "p1", "p2", "k3")], dtype=np.float64)
        self._maps: dict[tuple[int, int], tuple[Image, Image]] = {}

    def _camera(self, rows: int, cols: int) -> Image:
        p = self.params
        fx, fy = p["fx"] or cols, p["fy"] or p["fx"] or cols
        cx, cy = p["cx"] or (cols - 1) / 2, p["cy"] or (rows - 1) / 2
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    def process(self, data: Any, context: Context) -> Image:
        """The image with the lens distortion removed (unchanged when the coefficients are all 0)."""
        image = _image(data, self.owner)
        if not self.coefficients.any():
            return image
        rows, cols = image.shape[:2]
        maps = self._maps.get((rows, cols))
        if maps is None:
            camera = self._camera(rows, cols)
            maps = cv2.initUndistortRectifyMap(camera, self.coefficients, None, camera, (cols, rows), cv2.CV_32FC1)
            self._maps[(rows, cols)] = maps
        undistorted: Image = cv2.remap(image, maps[0], maps[1], cv2.INTER_LINEAR)
        return undistorted
