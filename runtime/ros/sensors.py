"""A kernel Sensor of a vector channel publishing a ROS 2 type itself (issue L point 1, decision D193).

A vector sensor (``runtime.kernel.vectors``, D99) publishes its whole read. On a topic of a ROS 2
type (``sensor_msgs/msg/LaserScan``, ``std_msgs/msg/Float64MultiArray``, a custom ``.msg``) the read
fills the message's **vector field**, the first top-level array of numbers (``ranges``, ``data``,
``position``), and the other fields come from what the kernel knows of the read:

- a ``std_msgs/msg/Header`` field: ``stamp`` the sample's stamp, ``frame_id`` the channel's Param
  ``frame_id``, ``frame`` or ``link`` (the first given; a simulated channel's ``link``);
- a ``builtin_interfaces/msg/Time`` field: the sample's stamp;
- a scalar field named like one of the channel's Params (``range_min`` ← ``rangeMin``): its value;
- ``sensor_msgs/msg/LaserScan``: the angles from Params ``angleMin``/``angleMax`` or else ``fov``
  (beams spanning −fov/2 … fov/2, as the simulated lidar casts them), ``range_min``/``range_max``
  from Params ``rangeMin``/``rangeMax`` or else the channel's ``min``/``max``, ``scan_time`` the
  sensor's period;
- ``sensor_msgs/msg/JointState``: ``name`` the channel's Param ``joints`` (space-separated);
- ``sensor_msgs/msg/Image``: the read is a ``width`` × ``height`` frame (channel Params) of 1, 3 or
  4 channels; the encoding is the channel's ``units`` when it names one (``rgb8``, ``16UC1``), else
  ``mono8``/``rgb8``/``rgba8``; it is published as ``ros-camera`` publishes one, ``{header,
  encoding, data: pixels}``;
- every other field its ROS default (zero, empty).

What is published is the payload a remote subscriber decodes from the CDR (:mod:`runtime.ros.wire`):
every field present, stamps and ``float32`` values as CDR carries them, so a local and a remote
subscriber see equal values. :func:`vector_refusal` says why a type cannot carry the read; the
kernel (at set-up) and ``verify`` report it in one sentence at the ``<Sensor>``
(:func:`runtime.kernel.vectors.refusal`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from ckmconf.model import HWChannel

from .compat import snake_case
from .convert import _DTYPES, IMAGE, IMAGE_ENCODINGS, decode_payload, encode_payload
from .types import RosTypeError, RosTypes

HEADER, TIME = "std_msgs/msg/Header", "builtin_interfaces/msg/Time"
LASER_SCAN, JOINT_STATE = "sensor_msgs/msg/LaserScan", "sensor_msgs/msg/JointState"
FRAME_PARAMS = ("frame_id", "frame", "link")
"""Channel Params naming the frame of a read, the first given wins (a simulated channel's ``link``)."""
_NUMBERS = frozenset(_DTYPES) - {"bool"}
_IMAGE_DEFAULT = {1: "mono8", 3: "rgb8", 4: "rgba8"}
Shaper = Callable[[Any, float], Any]


def cdr_time(stamp: float) -> float:
    """``stamp`` as a ``builtin_interfaces/msg/Time`` carries it and :mod:`.convert` reads it back (ns)."""
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)
    sec, nanosec = sec + nanosec // 1_000_000_000, nanosec % 1_000_000_000
    return (sec * 1_000_000_000 + nanosec) / 1_000_000_000


def _vector_field(ros: RosTypes, ros_type: str) -> tuple[str, str, int] | None:
    """(name, element type, fixed size or 0) of the first top-level array of numbers of ``ros_type``."""
    for name, (kind, detail) in ros.fields(ros_type):
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (element_kind, element), size = detail
            if element_kind == Nodetype.BASE and element[0] in _NUMBERS:
                return name, element[0], size if kind == Nodetype.ARRAY else 0
    return None


def _params(channel: HWChannel) -> dict[str, str]:
    return {p.name: p.value for p in channel.params}


def _image_layout(channel: HWChannel) -> tuple[int, int, str] | str:
    """(height, width, encoding) of a channel read as an Image, or why it cannot be one."""
    params = _params(channel)
    try:
        width, height = int(params.get("width", "")), int(params.get("height", ""))
    except ValueError:
        return "but an Image needs the channel's Params 'width' and 'height' (whole numbers of pixels)"
    if width <= 0 or height <= 0 or channel.size % (width * height):
        return f"but size {channel.size} is not a {width}×{height} frame"
    channels = channel.size // (width * height)
    encoding = channel.units if channel.units in IMAGE_ENCODINGS else _IMAGE_DEFAULT.get(channels, "")
    if encoding not in IMAGE_ENCODINGS or IMAGE_ENCODINGS[encoding][1] != channels:
        return (f"but a {width}×{height} frame of {channels} channels has no image encoding "
                f"(units {channel.units!r}; known: {', '.join(IMAGE_ENCODINGS)})")
    return height, width, encoding


def vector_refusal(ros: RosTypes, ros_type: str, channel: HWChannel) -> str | None:
    """Why a whole read of ``channel`` cannot travel as a ``ros_type``, a clause following the type's
    name ("which has no array of numbers …"); None when it can, or when the type is unknown (the
    topic's own problem, reported there)."""
    if ros_type not in ros:
        return None
    if ros_type == IMAGE:
        layout = _image_layout(channel)
        return layout if isinstance(layout, str) else None
    found = _vector_field(ros, ros_type)
    if found is None:
        names = ", ".join(name for name, _ in ros.fields(ros_type))
        return f"which has no array of numbers to hold them (fields: {names})"
    name, _, size = found
    if size and size != channel.size:
        return f"whose field {name!r} holds exactly {size} numbers, not {channel.size}"
    try:
        _fixed(ros, ros_type, channel, 0.0, name)
    except RosTypeError as error:  # a channel Param that does not convert to its field
        return f"but {error}"
    return None


def _fixed(ros: RosTypes, ros_type: str, channel: HWChannel, period: float, vector: str) -> dict[str, Any]:
    """The fields that do not change from read to read, as CDR carries them (D193's rules)."""
    payload: dict[str, Any] = decode_payload(ros, ros_type, encode_payload(ros, ros_type, {}))
    params = _params(channel)
    by_field = {snake_case(name): value for name, value in params.items()}
    fields = dict(ros.fields(ros_type))
    for name, (kind, detail) in fields.items():
        if kind == Nodetype.BASE and name != vector and name in by_field:
            payload[name] = _converted(by_field[name], detail[0], f"channel Param for field {name!r}")
    if ros_type == LASER_SCAN:
        payload.update(_scan_geometry(channel, params, period))
        for name in ("angle_min", "angle_max", "angle_increment", "scan_time", "range_min", "range_max"):
            payload[name] = float(np.float32(payload[name]))  # as a float32 field travels
    if ros_type == JOINT_STATE and params.get("joints"):
        payload["name"] = params["joints"].split()
    return payload


def _converted(text: str, base: str, what: str) -> Any:
    try:
        if base == "string":
            return text
        if base == "bool":
            return text.strip().lower() in ("1", "true", "yes")
        number = float(text)
        return float(np.float32(number)) if base == "float32" else number if base == "float64" else int(number)
    except ValueError:
        raise RosTypeError(f"{what}: {text!r} is not a {base}") from None


def _scan_geometry(channel: HWChannel, params: dict[str, str], period: float) -> dict[str, float]:
    """A LaserScan's angles and ranges from the channel (see the module docstring)."""
    def number(name: str, default: float) -> float:
        try:
            return float(params[name]) if name in params else default
        except ValueError:
            raise RosTypeError(f"channel Param {name!r} = {params[name]!r} is not a number") from None

    fov = number("fov", 0.0)
    low, high = number("angleMin", -fov / 2), number("angleMax", fov / 2)
    beams = channel.size
    return {
        "angle_min": low,
        "angle_max": high,
        "angle_increment": number("angleIncrement", (high - low) / (beams - 1) if beams > 1 else 0.0),
        "scan_time": period,
        "range_min": number("rangeMin", float(channel.min) if channel.min is not None else 0.0),
        "range_max": number("rangeMax", float(channel.max) if channel.max is not None else 0.0),
    }


def ros_shaper(ros: RosTypes, ros_type: str, channel: HWChannel, period: float, owner: str) -> Shaper:
    """The function turning a whole read and its stamp into the ``ros_type`` payload published.

    Args:
        ros: the configuration's ROS type store (``ConfigRosTypes.ros``).
        ros_type: the topic's type.
        channel: the sensor's HWChannel (size, Params, units, min/max).
        period: the sensor's period (a LaserScan's ``scan_time``).
        owner: the sensor, for messages.

    Raises:
        ValueError: the type cannot carry the read (the clause of :func:`vector_refusal`).
    """
    problem = vector_refusal(ros, ros_type, channel) if ros_type in ros else "which is not a known ROS 2 type"
    if problem is not None:
        raise ValueError(problem)
    params = _params(channel)
    frame = next((params[name] for name in FRAME_PARAMS if params.get(name)), "")
    if ros_type == IMAGE:
        layout = _image_layout(channel)
        assert not isinstance(layout, str)
        return _image_shaper(*layout, frame, owner)
    found = _vector_field(ros, ros_type)
    assert found is not None
    vector, element, _ = found
    fixed = _fixed(ros, ros_type, channel, period, vector)
    fields = dict(ros.fields(ros_type))
    headers = [n for n, (k, d) in fields.items() if k == Nodetype.NAME and d == HEADER]
    times = [n for n, (k, d) in fields.items() if k == Nodetype.NAME and d == TIME]
    as_bytes = isinstance(fixed[vector], bytes)  # uint8[] travels as bytes (runtime.ros.convert)
    dtype = _DTYPES[element]

    def shape(raw: Any, stamp: float) -> dict[str, Any]:
        values = np.asarray(raw, dtype=np.float64).reshape(-1)
        out = dict(fixed)
        when = cdr_time(stamp)
        for name in headers:
            out[name] = {"stamp": when, "frame_id": frame}
        for name in times:
            out[name] = when
        out[vector] = _in_range(values, dtype, owner).tobytes() if as_bytes else values.astype(dtype)
        return out

    return shape


def _in_range(values: np.ndarray[Any, Any], dtype: Any, owner: str) -> np.ndarray[Any, Any]:
    """``values`` as ``dtype``; ValueError when an integer type cannot hold one of them."""
    if np.issubdtype(dtype, np.integer) and values.size:
        info = np.iinfo(dtype)
        if values.min() < info.min or values.max() > info.max:
            raise ValueError(f"{owner}: the read holds values outside {info.min}-{info.max} ({np.dtype(dtype)})")
    return values.astype(dtype)


def _image_shaper(height: int, width: int, encoding: str, frame: str, owner: str) -> Shaper:
    code, channels = IMAGE_ENCODINGS[encoding]
    dtype = np.dtype("<" + code)
    shape = (height, width) if channels == 1 else (height, width, channels)

    def image(raw: Any, stamp: float) -> dict[str, Any]:
        values = np.asarray(raw, dtype=np.float64).reshape(-1)
        pixels = _in_range(values, dtype, owner).reshape(shape)
        return {"header": {"stamp": cdr_time(stamp), "frame_id": frame}, "encoding": encoding, "data": pixels}

    return image
