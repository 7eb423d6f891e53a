"""``plugin.colour-detection``: objects recognised by their colour (the ``object-detection`` interface's
colour recogniser, issue M point 2; thesis §4.3's processing plugin, ``<Plugin kind="colour-detection">``).

Each frame (an RGB or BGR image, H × W × 3 uint8, as camera-acquisition delivers it) is converted to
HSV; every colour of Param ``colours`` selects the pixels within its hue range and above its saturation
and value floors; the selection is opened (one 3 × 3 erosion then dilation, so single noisy pixels do
not count) and split into connected blobs (8-connectivity). A blob of at least ``minArea`` of the frame
is an object named after its colour: ``x``, ``y`` are its centroid as a share of the frame's width and
height (as the texture recogniser gives its detections), ``points`` its pixel count. Its reliability
is its solidity (area over its convex hull's: a ragged blob of scattered pixels is a poor object)
times ``1 − exp(−area / (4 · minArea))`` (a blob just over the floor is not yet sure), in [0, 1]. At
most ``maxObjects`` blobs per colour are kept, the largest first; the result's ``reliability`` is the
mean of its objects' (0 when none is seen), as for the other recognisers (Table 7.1).

``colours``: ``"label: hueMin-hueMax satMin valMin; …"`` with hue in degrees (0–360; ``hueMin >
hueMax`` wraps through red, ``350-10``) and saturation and value in [0, 1].
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import cv2
import numpy as np
import numpy.typing as npt

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import ARRAY, MAPPING, REQUIRED, P, Params, Ports

Image = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class ColourRange:
    """One colour of Param ``colours``: a hue range (degrees) and the saturation and value floors (0–1)."""

    label: str
    hue_min: float
    hue_max: float
    saturation: float
    value: float

    def mask(self, hsv: Image) -> Image:
        """The pixels of an OpenCV HSV image (hue 0–179) within this colour, as 0/255."""
        hue = hsv[..., 0].astype(np.float32) * 2.0  # OpenCV halves the hue to fit a byte
        low, high = self.hue_min % 360.0, self.hue_max % 360.0
        in_hue = (hue >= low) & (hue <= high) if low <= high else (hue >= low) | (hue <= high)
        strong = (hsv[..., 1] >= self.saturation * 255.0) & (hsv[..., 2] >= self.value * 255.0)
        return np.where(in_hue & strong, 255, 0).astype(np.uint8)


def parse_colours(text: str, owner: str) -> tuple[ColourRange, ...]:
    """The colours of Param ``colours`` (module docstring); ParamError naming the bad entry."""
    found: list[ColourRange] = []
    for entry in (e.strip() for e in text.split(";")):
        if not entry:
            continue
        label, _, spec = (part.strip() for part in entry.partition(":"))
        words = spec.split()
        hues = words[0].split("-") if words else []
        try:
            numbers = [float(v) for v in (*hues, *words[1:])]
        except ValueError:
            numbers = []
        if not label or len(words) != 3 or len(hues) != 2 or len(numbers) != 4 \
                or not all(math.isfinite(v) for v in numbers):
            raise ParamError(f"{owner}: parameter 'colours' entry {entry!r} is not 'label: hueMin-hueMax "
                             "satMin valMin' (hue in degrees, saturation and value in [0, 1])")
        hue_min, hue_max, saturation, value = numbers
        if not (0 <= hue_min <= 360 and 0 <= hue_max <= 360 and 0 <= saturation <= 1 and 0 <= value <= 1):
            raise ParamError(f"{owner}: parameter 'colours' entry {entry!r}: hue must be in [0, 360] degrees, "
                             "saturation and value in [0, 1]")
        if any(c.label == label for c in found):
            raise ParamError(f"{owner}: parameter 'colours' names {label!r} twice")
        found.append(ColourRange(label, hue_min, hue_max, saturation, value))
    if not found:
        raise ParamError(f"{owner}: parameter 'colours' names no colour")
    return tuple(found)


class ColourDetection(ProcessingPlugin):
    """``plugin.colour-detection``: an image in, ``{objects: [{name, label, x, y, points, reliability}],
    reliability, width, height}`` out (module docstring)."""

    PORTS = Ports(inputs={"*": ARRAY}, outputs={"*": MAPPING})
    PROVIDES = "object-detection"  # docs/interfaces.md
    POSITIONS = "image"  # x, y: shares of the frame (plugins.behaviors.upstream)
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"objects": (
        "objects[].name", "objects[].label", "objects[].x", "objects[].y", "objects[].points",
        "objects[].reliability", "reliability", "width", "height")}
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("colours", REQUIRED, "The colours looked for: 'label: hueMin-hueMax satMin valMin; …' (hue in degrees, "
          "wrapping when hueMin > hueMax; saturation and value in [0, 1]).", type=str),
        P("minArea", 0.0005, "Smallest blob kept, as a share of the frame.", above=0.0, max=1.0),
        P("maxObjects", 5, "Most blobs kept per colour, the largest first.", min=1),
        P("encoding", "rgb8", "Channel order of the frames: 'rgb8' or 'bgr8'.", choices=("rgb8", "bgr8")),
    )

    @classmethod
    def labels(cls, record: Plugin) -> set[str] | None:
        """The colour names of Param ``colours``: the labels it can report (None when they do not parse)."""
        text = next((p.value for p in record.params if p.name == "colours"), "")
        try:
            return {c.label for c in parse_colours(text, record.name)}
        except ParamError:
            return None

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.colours = parse_colours(self.params["colours"], self.owner)
        self.kernel = np.ones((3, 3), np.uint8)

    def _blobs(self, mask: Image, label: str, floor: float, rows: int, cols: int) -> list[dict[str, Any]]:
        """The blobs of ``mask`` (0/255) of at least ``floor`` pixels, largest first, as detections."""
        opened = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self.kernel)
        count, labels, stats, centroids = cv2.connectedComponentsWithStats(opened, connectivity=8)
        found: list[dict[str, Any]] = []
        for blob in range(1, count):  # 0 is the background
            area = int(stats[blob, cv2.CC_STAT_AREA])
            if area < floor:
                continue
            points = cv2.findNonZero(np.where(labels == blob, 255, 0).astype(np.uint8))
            hull = float(cv2.contourArea(cv2.convexHull(points)))
            solidity = min(1.0, area / hull) if hull > 0 else 1.0
            reliability = solidity * (1.0 - math.exp(-area / (4.0 * floor)))
            x, y = centroids[blob]
            found.append({"name": label, "label": label, "x": float(x) / cols, "y": float(y) / rows,
                          "points": area, "reliability": float(reliability)})
        found.sort(key=lambda o: -o["points"])
        return found[: self.params["maxObjects"]]

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The objects of every colour seen in the frame ``data``."""
        image = np.asarray(data)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
            raise ValueError(f"{self.owner} expects an H x W x 3 uint8 colour image, got {image.shape} "
                             f"{image.dtype}")
        rows, cols = image.shape[:2]
        order = cv2.COLOR_RGB2HSV if self.params["encoding"] == "rgb8" else cv2.COLOR_BGR2HSV
        hsv: Image = cv2.cvtColor(np.ascontiguousarray(image), order).astype(np.uint8, copy=False)
        floor = max(1.0, self.params["minArea"] * rows * cols)
        objects = [o for colour in self.colours for o in self._blobs(colour.mask(hsv), colour.label, floor, rows, cols)]
        objects.sort(key=lambda o: -o["reliability"])
        mean = sum(o["reliability"] for o in objects) / len(objects) if objects else 0.0
        return {"objects": objects, "reliability": float(mean), "width": cols, "height": rows}
