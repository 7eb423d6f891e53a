"""Procedural object textures and the ORB model file of the RGB recognition service (thesis §7.4.1).

Objects are told apart by their printed patterns (the lab objects of Fig. 7.5, for example). No photograph is committed:
each object's texture is drawn from a seed (its base pattern and colours as in the environment's
``<Texture>``, plus seeded shapes and text, like a printed label), so the model file stays small
text and the synthetic scenes (``scenes.py``) show exactly the textures the model learnt.

The model file is a subset of YAML read by ``read_model`` without PyYAML (not a dependency, and
nothing here needs more): top-level ``key: value`` lines, then ``objects:`` and a list of
``- key: value`` items; values are integers, floats, space-separated numbers, or strings (quote
those starting with ``#``); ``#`` after a blank starts a comment. Anything else is an error
naming ``FILE:LINE``. ``build_model`` turns it into the descriptors the matcher searches. Top-level
``views`` names a file of keypoints learnt from rendered views (``views.py``, D175); an object's
``wrap: true`` says its print repeats side by side (round a cylinder), which the matcher unwraps.
Top-level ``words`` lists the words printed in small type (default :data:`WORDS`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from .views import read_views

Image = npt.NDArray[Any]
"""An image as OpenCV and numpy hand it around (uint8 here)."""
Points = npt.NDArray[np.float32]

PATTERNS = ("plain", "stripes", "dots", "checker", "label")
WORDS = ("CKM", "ORB", "RGB", "SPT", "TCM", "BOX", "TEA", "MIX", "MAP", "ROS", "QOS", "HFSM", "FUSION")
"""The words a texture's small print draws from when its model file lists none (``words``)."""
_FONTS = (cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_TRIPLEX, cv2.FONT_HERSHEY_COMPLEX)


@dataclass(frozen=True)
class TextureSpec:
    """One object's texture: base pattern and colours (as the environment's Texture) and a seed."""

    name: str
    pattern: str = "label"
    color: str = "#808080"
    secondary: str = "#FFFFFF"
    seed: int = 0
    width: int = 160
    height: int = 240
    wrap: bool = False
    """The print repeats side by side (a label around a can): a view may show the end of one copy
    and the start of the next, which the matcher unwraps (D175)."""
    words: tuple[str, ...] = WORDS
    """The words its small print draws from (the model file's ``words``)."""


@dataclass(frozen=True)
class ModelSpec:
    """A parsed model file: the objects and the ORB settings their descriptors are extracted with."""

    path: str
    objects: tuple[TextureSpec, ...]
    features: int = 100
    """ORB keypoints kept per object and scale."""
    scale_factor: float = 1.2
    levels: int = 3
    scales: tuple[float, ...] = (0.7, 0.5, 0.35, 0.25)
    """Texture sizes (shares of width × height) the keypoints are extracted at."""
    views: str = ""
    """File of keypoints learnt from rendered views (``views.py``, D175), relative to the model file."""
    words: tuple[str, ...] = WORDS
    """The words the textures' small print draws from."""


def rgb(color: str) -> tuple[int, int, int]:
    """``#RRGGBB`` as an (R, G, B) tuple."""
    text = color.lstrip("#")
    if len(text) != 6:
        raise ValueError(f"colour {color!r} is not #RRGGBB")
    return int(text[0:2], 16), int(text[2:4], 16), int(text[4:6], 16)


def _base(spec: TextureSpec, rng: np.random.Generator) -> Image:
    """The base pattern, its second colour muted halfway to the first.

    A repetitive pattern in full contrast would take most of ORB's keypoint budget with corners
    that all look alike; muted, it leaves the budget to the distinctive print drawn over it.
    """
    h, w = spec.height, spec.width
    main, second = rgb(spec.color), rgb(spec.secondary)
    r, g, b = ((m + s) // 2 for m, s in zip(main, second, strict=True))
    other = (r, g, b)
    image = np.empty((h, w, 3), np.uint8)
    image[:] = other if spec.pattern in ("stripes", "dots") else main
    step = max(8, int(rng.integers(h // 6, h // 4)))
    if spec.pattern == "stripes":
        for y in range(0, h + w, 2 * step):  # diagonal bands
            cv2.fillConvexPoly(image, np.array([[0, y], [0, y + step], [w, y + step - w], [w, y - w]], np.int32), main)
    elif spec.pattern == "dots":
        for y in range(step // 2, h, step):
            for x in range(step // 2 + (y // step % 2) * step // 2, w, step):
                cv2.circle(image, (x, y), step // 3, main, -1, cv2.LINE_AA)
    elif spec.pattern == "checker":
        for y in range(0, h, step):
            for x in range((y // step % 2) * step, w, 2 * step):
                cv2.rectangle(image, (x, y), (x + step - 1, y + step - 1), other, -1)
    elif spec.pattern == "label":
        cv2.rectangle(image, (0, h // 3), (w, 2 * h // 3), other, -1)
    elif spec.pattern != "plain":
        raise ValueError(f"texture {spec.name!r}: unknown pattern {spec.pattern!r} (known: {', '.join(PATTERNS)})")
    return image


def _colour(rng: np.random.Generator) -> tuple[int, int, int]:
    r, g, b = (int(v) for v in rng.integers(0, 256, 3))
    return r, g, b


def _shape(image: Image, rng: np.random.Generator, size: float) -> None:
    """One seeded polygon, disc or bar of about ``size`` pixels, outlined for crisp corners."""
    h, w = image.shape[:2]
    centre = rng.uniform((0, 0), (w, h))
    kind = int(rng.integers(0, 3))
    fill, edge = _colour(rng), _colour(rng)
    if kind == 0:
        angles = np.sort(rng.uniform(0, 2 * np.pi, int(rng.integers(3, 7))))
        radii = rng.uniform(0.5, 1.0, len(angles)) * size
        points = (centre + np.stack([np.cos(angles), np.sin(angles)], 1) * radii[:, None]).astype(np.int32)
        cv2.fillPoly(image, [points], fill, cv2.LINE_AA)
        cv2.polylines(image, [points], True, edge, max(1, round(size / 12)), cv2.LINE_AA)
    elif kind == 1:
        radius = int(rng.uniform(0.4, 0.8) * size)
        cv2.circle(image, (int(centre[0]), int(centre[1])), radius, fill, -1, cv2.LINE_AA)
        cv2.circle(image, (int(centre[0]), int(centre[1])), radius // 2, edge, -1, cv2.LINE_AA)
    else:
        box = ((float(centre[0]), float(centre[1])), (size * 1.6, size * 0.5), float(rng.uniform(0, 180)))
        corners = cv2.boxPoints(box).astype(np.int32)
        cv2.fillConvexPoly(image, corners, fill, cv2.LINE_AA)
        cv2.polylines(image, [corners], True, edge, max(1, round(size / 12)), cv2.LINE_AA)


@functools.lru_cache(maxsize=64)
def render_texture(spec: TextureSpec) -> Image:
    """The object's texture, H×W×3 RGB, the same for the same spec (cached; treat it as read-only).

    Seeded polygons, circles, lines and words over the base pattern make it rich in corners, so ORB
    finds keypoints all over it, and different seeds give different keypoints even for one pattern.
    """
    rng = np.random.default_rng(spec.seed)
    image = _base(spec, rng)
    h, w = image.shape[:2]
    scale = min(h, w)
    # Elements at three sizes, largest first, as on a printed label (logo, pictures, small print):
    # a distant (small) view still resolves the large ones.
    for size, count in ((scale / 4, 4), (scale / 9, 8), (scale / 20, 10)):
        for _ in range(count):
            _shape(image, rng, size)
    for size, count in ((scale / 90, 2), (scale / 200, 3)):
        for _ in range(count):
            word = str(rng.choice(spec.words)) + str(int(rng.integers(0, 100)))
            origin = (int(rng.integers(0, w // 2)), int(rng.integers(h // 8, h)))
            font = _FONTS[int(rng.integers(0, len(_FONTS)))]
            cv2.putText(image, word, origin, font, size, _colour(rng), max(1, round(size * 2)), cv2.LINE_AA)
    cv2.rectangle(image, (0, 0), (w - 1, h - 1), (20, 20, 20), max(2, scale // 60))
    image.setflags(write=False)
    return image


# ---------------------------------------------------------------------- the model file


def _floats(text: str) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split())


def _words(text: str) -> tuple[str, ...]:
    words = tuple(text.split())
    if not words:
        raise ValueError(text)
    return words


def boolean(text: str) -> bool:
    """``true`` or ``false`` (any case); ValueError otherwise."""
    if text.lower() not in ("true", "false"):
        raise ValueError(text)
    return text.lower() == "true"


_TOP: Mapping[str, tuple[str, Callable[[str], Any]]] = {
    "version": ("version", int),
    "features": ("features", int),
    "scaleFactor": ("scale_factor", float),
    "levels": ("levels", int),
    "scales": ("scales", _floats),
    "views": ("views", str),
    "words": ("words", _words),
}
_ITEM: Mapping[str, tuple[str, Callable[[str], Any]]] = {
    "name": ("name", str),
    "pattern": ("pattern", str),
    "color": ("color", str),
    "secondary": ("secondary", str),
    "seed": ("seed", int),
    "width": ("width", int),
    "height": ("height", int),
    "wrap": ("wrap", boolean),
}


def _value(text: str) -> str:
    """A scalar without its comment and quotes."""
    if text[:1] in ("'", '"'):
        end = text.find(text[0], 1)
        if end < 0:
            raise ValueError("unterminated quote")
        rest = text[end + 1 :].strip()
        if rest and not rest.startswith("#"):
            raise ValueError(f"unexpected text after the quoted value: {rest!r}")
        return text[1:end]
    cut = text.find(" #")
    return (text if cut < 0 else text[:cut]).strip()


def _store(into: dict[str, Any], key: str, raw: str, keys: Mapping[str, tuple[str, Callable[[str], Any]]]) -> None:
    if key not in keys:
        raise ValueError(f"unknown key {key!r} (known: {', '.join(keys)})")
    field, kind = keys[key]
    if field in into:
        raise ValueError(f"{key!r} is given twice")
    try:
        into[field] = kind(raw)
    except ValueError:
        names: dict[object, str] = {_floats: "list of numbers", _words: "list of words"}
        name = names.get(kind) or getattr(kind, "__name__", "value")
        raise ValueError(f"{key} = {raw!r} is not a {name}") from None


def parse_model(text: str, path: str = "<memory>") -> ModelSpec:
    """A ModelSpec from model-file text; a problem raises ValueError ``PATH:LINE: message``."""
    top: dict[str, Any] = {}
    items: list[dict[str, Any]] = []
    in_objects = False
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        try:
            item = stripped.startswith("- ")
            key, sep, raw = (stripped[2:] if item else stripped).partition(":")
            key, raw = key.strip(), _value(raw.strip())
            if not sep or not key:
                raise ValueError(f"expected 'key: value', got {stripped!r}")
            if not line[:1].isspace() and not item:
                in_objects = key == "objects"
                if in_objects and raw:
                    raise ValueError("'objects:' takes an indented list, not a value")
                if not in_objects:
                    _store(top, key, raw, _TOP)
            elif not in_objects:
                raise ValueError("indented line outside 'objects:'")
            elif item or items:
                if item:
                    items.append({})
                _store(items[-1], key, raw, _ITEM)
            else:
                raise ValueError("object fields must follow a '- name: ...' item")
        except ValueError as exc:
            raise ValueError(f"{path}:{number}: {exc}") from None
    if top.pop("version", 1) != 1:
        raise ValueError(f"{path}: unsupported model version (this release reads 1)")
    objects = tuple(_texture({"words": top.get("words", WORDS), **fields}, path) for fields in items)
    if not objects:
        raise ValueError(f"{path}: no objects")
    names = [o.name for o in objects]
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: object names repeat: {', '.join(names)}")
    model = ModelSpec(path, objects, **top)
    if model.features < 1 or model.scale_factor <= 1.0 or model.levels < 1:
        raise ValueError(f"{path}: features must be at least 1, scaleFactor more than 1, levels at least 1")
    if not model.scales or not all(0.0 < s <= 4.0 for s in model.scales):
        raise ValueError(f"{path}: scales must be one or more numbers in (0, 4]")
    return model


def _texture(fields: Mapping[str, Any], path: str) -> TextureSpec:
    if "name" not in fields:
        raise ValueError(f"{path}: an object has no name")
    spec = TextureSpec(**fields)
    if spec.width < 32 or spec.height < 32:
        raise ValueError(f"{path}: object {spec.name!r} is smaller than 32 pixels")
    if spec.pattern not in PATTERNS:
        raise ValueError(f"{path}: object {spec.name!r} has unknown pattern {spec.pattern!r}")
    try:
        rgb(spec.color), rgb(spec.secondary)
    except ValueError as exc:
        raise ValueError(f"{path}: object {spec.name!r}: {exc}") from None
    return spec


def read_model(path: str | Path) -> ModelSpec:
    """The model file at ``path``; OSError if it cannot be read, ValueError if it is malformed."""
    with open(path, encoding="utf-8") as stream:
        return parse_model(stream.read(), str(path))


# ---------------------------------------------------------------------- the learnt model


@dataclass(frozen=True)
class Model:
    """Learnt keypoints of all objects, stacked: descriptors, texture positions, object index."""

    names: tuple[str, ...]
    sizes: tuple[tuple[int, int], ...]
    """Each texture's (width, height) in pixels."""
    descriptors: Image
    points: Points
    labels: npt.NDArray[np.intp]
    wraps: tuple[bool, ...] = ()
    """Whether each texture's print repeats side by side (:attr:`TextureSpec.wrap`)."""


_PAD = 32  # grey margin, so that ORB's border exclusion does not hide the texture's own edges


def build_model(path: str | Path) -> Model:
    """The ORB model of a model file: each texture resized to each scale, its keypoints extracted.

    Several scales, because ORB's pyramid only covers sizes its patch (31 pixels) still fits in:
    an object seen small (QVGA, QQVGA, far away) needs descriptors learnt at about its size. The
    model file's ``views`` file (if any) adds keypoints learnt from rendered views (D175).
    """
    spec = read_model(path)
    orb = cv2.ORB.create(nfeatures=spec.features, scaleFactor=spec.scale_factor, nlevels=spec.levels)
    descriptors, points, labels = [], [], []
    for index, obj in enumerate(spec.objects):
        texture, count = render_texture(obj), 0
        for scale in spec.scales:
            small = cv2.resize(texture, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
            canvas = cv2.copyMakeBorder(small, _PAD, _PAD, _PAD, _PAD, cv2.BORDER_CONSTANT, value=(128, 128, 128))
            found, described = orb.detectAndCompute(cv2.cvtColor(canvas, cv2.COLOR_RGB2GRAY), None)
            if described is None:
                continue
            descriptors.append(described)
            points.append((np.array([k.pt for k in found], np.float32).reshape(-1, 2) - _PAD) / scale)
            labels.append(np.full(len(found), index, np.intp))
            count += len(found)
        if count < 4:
            raise ValueError(f"{path}: object {obj.name!r} has {count} keypoints; its texture is too plain")
    names = tuple(o.name for o in spec.objects)
    if spec.views:  # keypoints learnt from rendered views (D175), in the same texture frame
        views = Path(path).parent / spec.views
        try:
            learnt, at, which = read_views(views, names)
        except OSError as exc:
            raise ValueError(f"{path}: cannot read its views file {views}: {exc.strerror}") from None
        descriptors.append(learnt)
        points.append(at)
        labels.append(which)
    return Model(
        names,
        tuple((o.width, o.height) for o in spec.objects),
        np.concatenate(descriptors),
        np.concatenate(points).astype(np.float32),
        np.concatenate(labels),
        tuple(o.wrap for o in spec.objects),
    )
