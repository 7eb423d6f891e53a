"""Synthetic RGB camera frames of the lab objects, with ground truth, for tests and benchmarks.

Stands in for the Xtion's RGB stream of §7.4.1: the objects' textures (the same ones the ORB
model learns, :mod:`plugins.processing.textures`) are pasted with scale, rotation and perspective jitter on a
cluttered, slightly out-of-focus background, then lit with a random gain and sensor noise.
Textures, backgrounds and noise fields are rendered once and cached, so a VGA frame costs a few
milliseconds: fast enough to feed a 30 Hz camera from the benchmark process itself.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from plugins.processing.textures import Image, ModelSpec, read_model, render_texture

from . import MODELS

USECASE_MODEL = MODELS / "lab_objects_orb.yml"
"""The lab's model file (RGBDCamera's match_* plugins): the default texture catalogue."""

BACKGROUNDS = 8
"""Distinct clutter backgrounds per resolution; a scene uses ``seed % BACKGROUNDS`` by default."""


@dataclass(frozen=True)
class Placement:
    """Where an object's texture landed: its centre (normalized x, y in 0..1) and corners (pixels)."""

    name: str
    centre: tuple[float, float]
    corners: npt.NDArray[np.float32] = field(repr=False)
    """Texture corners top-left, top-right, bottom-right, bottom-left, as (x, y) in the image."""


@dataclass(frozen=True)
class Scene:
    """A rendered frame (H×W×3 RGB uint8) and the ground truth of the objects in it."""

    image: Image
    objects: dict[str, Placement]


@functools.lru_cache(maxsize=8)
def load_catalog(path: str) -> ModelSpec:
    """The model file at ``path``, read once."""
    return read_model(path)


@functools.lru_cache(maxsize=3 * BACKGROUNDS)
def background(height: int, width: int, index: int) -> Image:
    """Clutter background ``index``: a shaded wall with blurred shapes and text (cached, read-only).

    Blurred like an out-of-focus backdrop, so it yields fewer and weaker ORB corners than the
    objects in focus, but enough to test that clutter is not reported as objects.
    """
    rng = np.random.default_rng(1_000_003 + index)
    ramp = np.linspace(0.0, 1.0, width, dtype=np.float32)[None, :] * rng.uniform(-40, 40)
    ramp = ramp + np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None] * rng.uniform(-40, 40)
    base = rng.uniform(90, 170, 3).astype(np.float32)
    image: Image = np.clip(base[None, None, :] + ramp[..., None], 0, 255).astype(np.uint8)
    size = min(height, width)
    for _ in range(30):
        colour = tuple(int(v) for v in rng.integers(30, 226, 3))
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        a, b = (int(v) for v in rng.integers(size // 30, size // 6, 2))
        if rng.random() < 0.5:
            cv2.rectangle(image, (x, y), (x + a, y + b), colour, -1)
        else:
            angle = float(rng.uniform(0, 180))
            cv2.ellipse(image, (x, y), (a, b), angle, 0, 360, colour, -1, cv2.LINE_AA)
    for _ in range(6):
        colour = tuple(int(v) for v in rng.integers(0, 256, 3))
        origin = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        cv2.putText(image, "lab", origin, cv2.FONT_HERSHEY_SIMPLEX, size / 300, colour, max(1, size // 160))
    image = cv2.GaussianBlur(image, (0, 0), max(1.0, size / 240))
    image.setflags(write=False)
    return image


@functools.lru_cache(maxsize=3)
def _noise(height: int, width: int) -> tuple[Image, Image]:
    """Unit Gaussian noise split in its positive and negative parts (uint8, ×16), 64 pixels oversized."""
    rng = np.random.default_rng(42)
    field_ = rng.normal(0.0, 16.0, (height + 64, width + 64, 3))
    return np.clip(field_, 0, 255).astype(np.uint8), np.clip(-field_, 0, 255).astype(np.uint8)


def _placements(
    specs: Sequence[tuple[str, int, int]],
    rows: int,
    cols: int,
    rng: np.random.Generator,
    scale: tuple[float, float],
    rotation: float,
    perspective: float,
) -> list[npt.NDArray[np.float32]]:
    """Destination quads for textures of (name, width, height), inside the frame, boxes disjoint."""
    for _ in range(20):  # restarts: an early placement may leave no room for the last object
        boxes: list[tuple[float, float, float, float]] = []
        quads: list[npt.NDArray[np.float32]] = []
        for _name, w, h in specs:
            for _ in range(100):
                height = rng.uniform(*scale) * rows
                half = np.array([w, h], np.float64) * (height / h) / 2.0
                corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64) * half
                corners += rng.uniform(-perspective, perspective, (4, 2)) * half * 2.0
                angle = math.radians(rng.uniform(-rotation, rotation))
                turn = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
                corners = corners @ turn.T
                low, high = corners.min(axis=0), corners.max(axis=0)
                if high[0] - low[0] >= cols - 2 or high[1] - low[1] >= rows - 2:
                    continue
                cx = rng.uniform(1 - low[0], cols - 1 - high[0])
                cy = rng.uniform(1 - low[1], rows - 1 - high[1])
                box = (cx + low[0], cy + low[1], cx + high[0], cy + high[1])
                if all(box[2] < b[0] or b[2] < box[0] or box[3] < b[1] or b[3] < box[1] for b in boxes):
                    boxes.append(box)
                    quads.append((corners + np.array([cx, cy])).astype(np.float32))
                    break
            else:
                break
        else:
            return quads
    names = ", ".join(name for name, _, _ in specs)
    raise ValueError(f"cannot place {names} without overlap: use fewer objects or a smaller scale")


def render_rgb_scene(
    objects: Sequence[str] = (),
    resolution: tuple[int, int] = (480, 640),
    seed: int = 0,
    *,
    noise: float = 3.0,
    lighting: float = 0.15,
    scale: tuple[float, float] = (0.3, 0.42),
    rotation: float = 20.0,
    perspective: float = 0.06,
    background_index: int | None = None,
    model: str | Path | ModelSpec = USECASE_MODEL,
) -> Scene:
    """A camera frame showing ``objects`` (names in ``model``) and where each landed.

    Args:
        objects: the objects to show, each once, none overlapping.
        resolution: (rows, columns) of the frame.
        seed: draws the placements, lighting and noise window; the same seed gives the same frame.
        noise: standard deviation of the sensor noise, in grey levels (0: none).
        lighting: the frame's brightness gain is drawn in 1 ± ``lighting``.
        scale: an object's height as a share of the frame's, drawn in this range. The default
            fits four objects in a frame (a view of the workbench); QQVGA's keypoints resolve
            only close views, about (0.55, 0.7).
        rotation: in-plane rotation drawn in ± this many degrees.
        perspective: corner jitter as a share of the object's size (a tilted view).
        background_index: which clutter background; ``seed % BACKGROUNDS`` if None.
        model: the model file (or parsed ModelSpec) whose textures are drawn.
    """
    rows, cols = resolution
    catalog = model if isinstance(model, ModelSpec) else load_catalog(str(model))
    specs = {spec.name: spec for spec in catalog.objects}
    unknown = [name for name in objects if name not in specs]
    if unknown:
        raise ValueError(f"no object {unknown[0]!r} in {catalog.path} (objects: {', '.join(specs)})")
    if len(set(objects)) != len(objects):
        raise ValueError(f"objects repeat: {', '.join(objects)}")
    rng = np.random.default_rng(seed)
    index = seed % BACKGROUNDS if background_index is None else background_index
    image = background(rows, cols, index).copy()
    chosen = [specs[name] for name in objects]
    quads = _placements([(s.name, s.width, s.height) for s in chosen], rows, cols, rng, scale, rotation, perspective)
    truth: dict[str, Placement] = {}
    for spec, quad in zip(chosen, quads, strict=True):
        texture = render_texture(spec)
        shrink = float(np.max(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1))) / max(spec.width, spec.height)
        if shrink < 0.8:  # as a lens integrates light: area-average first, then warp (no aliasing)
            texture = cv2.resize(texture, None, fx=shrink, fy=shrink, interpolation=cv2.INTER_AREA)
        tw, th = texture.shape[1], texture.shape[0]
        source = np.array([[0, 0], [tw, 0], [tw, th], [0, th]], np.float32)
        x0, y0 = (int(v) for v in np.floor(quad.min(axis=0)))
        x1, y1 = (int(v) + 1 for v in np.ceil(quad.max(axis=0)))
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, cols), min(y1, rows)
        local = quad - np.array([x0, y0], np.float32)
        warp = cv2.getPerspectiveTransform(source, local)
        patch = cv2.warpPerspective(texture, warp, (x1 - x0, y1 - y0), borderMode=cv2.BORDER_REPLICATE)
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        cv2.fillConvexPoly(mask, np.rint(local).astype(np.int32), 255)
        region = image[y0:y1, x0:x1]
        np.copyto(region, patch, where=mask[..., None].astype(bool))
        middle = cv2.perspectiveTransform(np.array([[[tw / 2, th / 2]]], np.float32), warp)[0, 0]
        centre = ((float(middle[0]) + x0) / cols, (float(middle[1]) + y0) / rows)
        truth[spec.name] = Placement(spec.name, centre, quad)
    gain = float(rng.uniform(1.0 - lighting, 1.0 + lighting))
    if gain != 1.0:
        image = cv2.convertScaleAbs(image, alpha=gain)
    if noise > 0.0:
        up, down = _noise(rows, cols)
        dy, dx = (int(v) for v in rng.integers(0, 64, 2))
        factor = noise / 16.0
        image = cv2.add(image, cv2.convertScaleAbs(up[dy : dy + rows, dx : dx + cols], alpha=factor))
        image = cv2.subtract(image, cv2.convertScaleAbs(down[dy : dy + rows, dx : dx + cols], alpha=factor))
    return Scene(image, truth)
