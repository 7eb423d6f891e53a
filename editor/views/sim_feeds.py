"""What the Monitor tab's live map and camera views read from a running system (issue K.5; the
Fig. 7.16 picture of §7.4.1, drawn as the run goes).

:func:`feeds_of` finds the topics in the configuration, by what produces them and by their types:

- each **robot** is a simulated body placed by the ``pose`` Param of a ``sim`` channel (the first
  channel of its node names the world and places the robot, configs/usecase/nodes.xml); its
  **true pose** is the topic of a sensor on a ``sim`` channel of that body with ``sensor=pose``
  (the simulator's ground truth, ``/sim/turtlebot/pose``), a body without one stays where it was
  placed (the Nao); its **estimate** is a ``PoseEstimate`` topic (``/nav/pose``): the one naming
  the body, else the only robot with a ground truth gets them all; its **head** is a ``PanTilt``
  topic naming the body that no controller takes as its set-point (the angles, not the goal:
  ``/nao/head_state``, not ``/nao/head_goal``);
- **recognised objects**: every ``Detections`` topic (only objects in the ``map`` frame, the fused
  ``/recog/objects``, have a place on the map) and every ``ObjectPosition`` topic in that frame
  (the Nao's spotted target);
- **camera images**: every external ``Image`` topic (a MessageType of that name or
  ``sensor_msgs/msg/Image``; likewise ``ckm_interfaces/msg/…`` for the other CKM types named here),
  and the node-internal ones (under their wire name ``/NODE/~NAME``) of a node that publishes none:
  the Turtlebot's Xtion frames are internal to its node, the Nao's are on the network as
  ``/nao/camera/image``;
- **zoom-map areas** and **particles**: topics whose name or type says ``zoom`` or ``particle``,
  and a ``particles`` field of a pose estimate. The use case's Navigation.AMCL publishes both
  (``/nav/zoom`` ZoomArea, ``/nav/particles`` ParticleCloud: D215); until an area arrives (or in a
  system without one) the view replays it from the estimate with the ``<ZoomMap>`` rules (D160).
  A malformed cloud or area (other shapes, NaN, another frame) is refused with a FeedError, not drawn.

Values arrive as the runtime's codec leaves them on the wire (arrays and numpy scalars as tagged
one-key dicts, runtime/resources/codec.py); :func:`plain` rebuilds them with the same checks. The
editor may not import that module (the editor-protocols contract of pyproject.toml), see D160.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ckmconf.model import HWChannel, System, Topic

MAX_BYTES = 16 * 1024 * 1024  # the CKMultiPeer frame limit, as the codec's
MAX_PARTICLES = 100_000  # AMCL's clouds are a few thousand particles at most; Navigation.AMCL sends 200
DTYPES = frozenset(["|b1", "|i1", "|u1", "<i2", "<u2", "<i4", "<u4", "<i8", "<u8", "<f2", "<f4", "<f8"])
"""The codec's numeric dtypes (its complex ones have no place on a map)."""


class FeedError(ValueError):
    """A message the live view cannot read: what was wrong with it."""


def plain(value: Any, depth: int = 0) -> Any:
    """``value`` with the codec's tagged arrays (``~nd``), scalars (``~sc``), tuples (``~tu``) and maps
    (``~map``) rebuilt; FeedError on a malformed or oversized one."""
    if depth > 64:
        raise FeedError("the value is nested deeper than 64 levels")
    if isinstance(value, list):
        return [plain(v, depth + 1) for v in value]
    if not isinstance(value, dict):
        return value
    if len(value) == 1:
        tag, payload = next(iter(value.items()))
        if isinstance(tag, str) and tag.startswith("~"):
            return _tagged(tag, payload, depth)
    return {k: plain(v, depth + 1) for k, v in value.items()}


def _tagged(tag: str, payload: Any, depth: int) -> Any:
    if tag == "~nd" and isinstance(payload, list) and len(payload) == 3:
        code, shape, raw = payload
        if code not in DTYPES or not isinstance(raw, bytes) or not isinstance(shape, list):
            raise FeedError(f"an array of dtype {code!r} and data {type(raw).__name__} is not readable")
        if not all(isinstance(n, int) and n >= 0 for n in shape):
            raise FeedError(f"an array shape must hold non-negative integers, got {shape!r:.80}")
        dtype = np.dtype(code)
        if math.prod(shape) * dtype.itemsize != len(raw) or len(raw) > MAX_BYTES:
            raise FeedError(f"an array of shape {tuple(shape)} and dtype {code} does not fit {len(raw)} bytes")
        return np.frombuffer(raw, dtype=dtype).reshape(shape)
    if tag == "~sc" and isinstance(payload, list) and len(payload) == 2:
        code, raw = payload
        if code not in DTYPES or not isinstance(raw, bytes) or len(raw) != np.dtype(code).itemsize:
            raise FeedError(f"a scalar of dtype {code!r} is not readable")
        return np.frombuffer(raw, dtype=np.dtype(code))[0].item()
    if tag == "~tu" and isinstance(payload, list):
        return tuple(plain(v, depth + 1) for v in payload)
    if tag == "~map" and isinstance(payload, list):
        pairs = [p for p in payload if isinstance(p, list) and len(p) == 2]
        return {_key(plain(k, depth + 1)): plain(v, depth + 1) for k, v in pairs}
    raise FeedError(f"a value tagged {tag!r} is not readable")


def _key(key: Any) -> Any:
    return key if isinstance(key, str | int | float | bool | tuple) else str(key)


def number(value: Any) -> float | None:
    """A finite float, or None."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        return None
    result = float(value)
    return result if math.isfinite(result) else None


def pose_of(payload: Any) -> tuple[float, float, float] | None:
    """``(x, y, yaw)`` of a Pose2D ``{x, y, yaw}`` or of a message holding one under ``pose``."""
    if not isinstance(payload, Mapping):
        return None
    if "x" not in payload and isinstance(payload.get("pose"), Mapping):
        payload = payload["pose"]
    x, y, yaw = (number(payload.get(k)) for k in ("x", "y", "yaw"))
    return None if x is None or y is None else (x, y, yaw or 0.0)


def covariance_of(payload: Any) -> np.ndarray | None:
    """The 2×2 position block of a PoseEstimate's 3×3 ``covariance`` (9 numbers, row-major)."""
    values = payload.get("covariance") if isinstance(payload, Mapping) else None
    try:
        matrix = np.asarray(values, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        return None
    block = matrix[:2, :2]
    return block if bool(np.all(np.isfinite(block))) else None


def particles_of(payload: Any) -> np.ndarray | None:
    """The (N, 2) positions of a particle cloud: a ParticleCloud's parallel ``x`` and ``y`` arrays (what
    Navigation.AMCL publishes, D215), or an (N, ≥2) array or list, alone or as a ``particles`` field.

    None when ``payload`` carries no cloud (a pose estimate without one); FeedError, naming what is
    wrong, for a cloud that is not one: arrays of other shapes or lengths, values that are not finite
    numbers, more than :data:`MAX_PARTICLES`, or a frame other than the map's."""
    if isinstance(payload, Mapping):
        _in_map(payload, "a particle cloud")
        if "particles" in payload:
            payload = payload["particles"]
        elif "x" in payload and "y" in payload:
            x, y = (_numbers(payload[k], f"a particle cloud's {k}") for k in ("x", "y"))
            if x.ndim != 1 or x.shape != y.shape:
                raise FeedError(f"a particle cloud's x and y must be two arrays of one length, got shapes "
                                f"{x.shape} and {y.shape}")  # fmt: skip
            payload = np.stack([x, y], axis=1)
        else:
            return None
    if payload is None:
        return None
    cloud = _numbers(payload, "a particle cloud")
    if cloud.ndim != 2 or cloud.shape[1] < 2:
        raise FeedError(f"a particle cloud must be N rows of x, y[, yaw, weight], got an array of shape {cloud.shape}")
    if len(cloud) > MAX_PARTICLES:
        raise FeedError(f"a particle cloud of {len(cloud)} particles is more than the {MAX_PARTICLES} drawn")
    bad = int(np.count_nonzero(~np.all(np.isfinite(cloud[:, :2]), axis=1)))
    if bad:
        raise FeedError(f"a particle cloud holds {bad} of {len(cloud)} positions that are not finite (NaN or inf)")
    return cloud[:, :2]


def _numbers(value: Any, what: str) -> np.ndarray:
    """``value`` as a float64 array; FeedError naming ``what`` when it is not numbers."""
    if isinstance(value, str | bytes | Mapping):
        raise FeedError(f"{what} must be numbers, got {type(value).__name__}")
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise FeedError(f"{what} must be numbers, got {str(value)[:60]!r}") from None


def _in_map(payload: Mapping[str, Any], what: str) -> None:
    frame = payload.get("frame")
    if frame not in (None, "", "map"):
        raise FeedError(f"{what} in frame {frame!r}, not the map's: it has no place on the map")


def zoom_of(payload: Any) -> tuple[float, float, float, float]:
    """``(x, y, width, depth)`` of a zoom-map area ``{x, y, width, depth}`` (a ZoomArea, D215) or
    ``{xmin, ymin, xmax, ymax}``; FeedError naming what is missing or wrong (not finite, an empty size,
    another frame than the map's)."""
    if not isinstance(payload, Mapping):
        raise FeedError(f"a zoom-map area must be a message, got {type(payload).__name__}")
    _in_map(payload, "a zoom-map area")
    for keys in (("x", "y", "width", "depth"), ("xmin", "ymin", "xmax", "ymax")):
        if not all(k in payload for k in keys):
            continue
        values = [number(payload[k]) for k in keys]
        bad = [k for k, v in zip(keys, values, strict=True) if v is None]
        if bad:
            raise FeedError(f"a zoom-map area's {', '.join(bad)} must be finite numbers, got "
                            f"{', '.join(repr(payload[k]) for k in bad)}")  # fmt: skip
        a, b, c, d = (float(v) for v in values)  # type: ignore[arg-type]
        x, y, width, depth = (a, b, c, d) if keys[0] == "x" else ((a + c) / 2, (b + d) / 2, c - a, d - b)
        if not (width > 0 and depth > 0):
            raise FeedError(f"a zoom-map area of {width:g} × {depth:g} m is empty")
        return x, y, width, depth
    raise FeedError("a zoom-map area needs x, y, width and depth (or xmin, ymin, xmax and ymax)")


@dataclass(frozen=True)
class Seen:
    """A recognised object with a place on the map: a point, or a lone camera ray (Algorithm 4 keeps a 2D
    observation as a ray until another source places it): from ``(x, y)`` along ``ray``, a unit vector
    of the map plane."""

    label: str
    x: float
    y: float
    reliability: float
    sources: int
    topic: str
    ray: tuple[float, float] | None = None
    chosen: bool = False  # an ObjectPosition: the one object a behavior or a robot singled out


def objects_of(payload: Any, topic: str) -> list[Seen]:
    """The map-frame objects of a recognition result (``{objects: [...]}``) or an ObjectPosition."""
    if not isinstance(payload, Mapping):
        return []
    items = payload.get("objects") if "objects" in payload else [payload]
    found = []
    for item in items if isinstance(items, list | tuple) else ():
        if not isinstance(item, Mapping) or item.get("frame", payload.get("frame")) != "map":
            continue
        x, y, r = number(item.get("x")), number(item.get("y")), number(item.get("reliability"))
        ray = None
        if x is None or y is None:
            x, y, ray = _ray(item.get("origin"), item.get("direction"))
        if x is None or y is None:
            continue
        words = [str(item.get(k) or "") for k in ("name", "label", "shape", "texture")]
        label = " ".join(dict.fromkeys(w for w in words if w)) or "object"
        sources = item.get("sources")
        count = len(sources) if isinstance(sources, list) else 1
        found.append(Seen(label, x, y, r if r is not None else 0.0, count, topic, ray, "objects" not in payload))
    return found


def _ray(origin: Any, direction: Any) -> tuple[float | None, float | None, tuple[float, float] | None]:
    """The map-plane start and unit direction of a ray ``origin``, ``direction`` (3 numbers each)."""
    try:
        start, along = np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64)
    except (TypeError, ValueError):
        return None, None, None
    if start.shape != (3,) or along.shape != (3,) or not np.all(np.isfinite(start)) or not np.all(np.isfinite(along)):
        return None, None, None
    norm = math.hypot(along[0], along[1])
    if norm < 1e-9:  # straight up or down, or no direction at all: nothing to draw on a map
        return None, None, None
    return float(start[0]), float(start[1]), (float(along[0] / norm), float(along[1] / norm))


@dataclass(frozen=True)
class Robot:
    """A simulated robot: its body name, where the configuration places it, and its pose topics."""

    name: str
    placed: tuple[float, float, float]
    truth: str | None = None
    estimates: tuple[str, ...] = ()
    head: str | None = None


@dataclass(frozen=True)
class Feeds:
    """The topics (wire names) the live views subscribe to, and their message types."""

    robots: tuple[Robot, ...]
    objects: tuple[str, ...]
    cameras: tuple[str, ...]
    zoom: tuple[str, ...]
    particles: tuple[str, ...]
    types: Mapping[str, str]
    lifespans: Mapping[str, float]  # topic → its <Topic lifespan>: older results are no longer shown


def _wire(topic: Topic, node: str | None) -> str:
    """The name a topic travels under (runtime/kernel/node.py gives internal topics a node-local one)."""
    return f"/{node}/~{topic.name.lstrip('/')}" if node is not None and topic.scope == "internal" else topic.name


def _pose_param(text: str) -> tuple[float, float, float] | None:
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        return None
    if len(values) == 2:
        values.append(0.0)
    return (values[0], values[1], values[2]) if len(values) == 3 and all(map(math.isfinite, values)) else None


def _of_type(kind: str, name: str) -> bool:
    """Whether a topic's type is ``name``: a configuration's own MessageType of that name, or the ROS
    type of that name (``sensor_msgs/msg/Image``, ``ckm_interfaces/msg/Detections``), same fields."""
    return kind == name or kind.endswith(f"/msg/{name}")


def feeds_of(system: System) -> Feeds:
    """The robots, recognition, camera, zoom and particle topics of ``system`` (see the module docstring)."""
    every = [(_wire(t, None), t) for t in system.topics]
    every += [(_wire(t, n.name), t) for n in system.nodes for t in n.topics]
    topics = {name: t.type for name, t in every}
    placed: dict[str, tuple[float, float, float]] = {}
    truth: dict[str, str] = {}
    for node in system.nodes:
        local = {t.name: t for t in node.topics}
        body = ""
        channels: dict[str, tuple[HWChannel | None, dict[str, str], str]] = {}
        for channel in node.channels:
            params = {p.name: p.value for p in channel.params}
            body = params.get("body", body)  # a channel without one is on the node's body so far
            channels[channel.name] = (channel, params, body)
            pose = _pose_param(params.get("pose", "")) if channel.backend == "sim" else None
            if body and pose is not None and body not in placed:
                placed[body] = pose
        for sensor in node.sensors:
            source, params, on = channels.get(sensor.channel, (None, {}, ""))
            if source is not None and source.backend == "sim" and params.get("sensor") == "pose" and on:
                found = local.get(sensor.topic)
                truth.setdefault(on, _wire(found, node.name) if found is not None else sensor.topic)
    cameras = [n for n, kind in topics.items() if _of_type(kind, "Image") and "/~" not in n]
    for node in system.nodes:  # a node's raw frames when it publishes none on the network
        if not any(_of_type(t.type, "Image") and t.scope == "external" for t in node.topics):
            cameras += [_wire(t, node.name) for t in node.topics if _of_type(t.type, "Image")]
    estimates = [name for name, kind in topics.items() if _of_type(kind, "PoseEstimate")]
    setpoints = {i.topic for n in system.nodes for c in n.controllers for i in c.inputs if i.role == "setpoint"}
    pan_tilt = [name for name, kind in topics.items() if _of_type(kind, "PanTilt") and name not in setpoints]
    moving = [body for body in placed if body in truth]
    robots = []
    for body, pose in placed.items():
        mine = [t for t in estimates if body in t.lower()]
        if not mine and moving == [body]:
            mine = [t for t in estimates if not any(other in t.lower() for other in placed if other != body)]
        heads = sorted(t for t in pan_tilt if body in t.lower())
        robots.append(Robot(body, pose, truth.get(body), tuple(mine), heads[0] if heads else None))

    def named(word: str) -> tuple[str, ...]:
        return tuple(sorted(n for n, kind in topics.items() if word in n.lower() or word in kind.lower()))

    return Feeds(
        robots=tuple(robots),
        objects=tuple(sorted(n for n, kind in topics.items()
                             if _of_type(kind, "Detections") or _of_type(kind, "ObjectPosition"))),
        cameras=tuple(sorted(cameras)),
        zoom=named("zoom"),
        particles=named("particle"),
        types=topics,
        lifespans={name: t.lifespan for name, t in every if t.lifespan is not None},
    )
