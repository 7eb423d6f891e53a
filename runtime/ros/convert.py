"""CKM payloads ⇄ ROS 2 messages (issue L point 1; the ROS MultiPeer architecture of §4.4.1).

CKM topics carry msgpack-able values (:mod:`runtime.resources.codec`): dicts of fields, numbers,
strings, bytes and numpy arrays. A ROS 2 message becomes the CKM payload

- a **numpy array** of shape (H, W) or (H, W, C) for ``sensor_msgs/msg/Image`` (what the image
  plugins take), its encoding chosen by dtype and channels (:data:`IMAGE_ENCODINGS`);
- otherwise a **dict** with the ROS field names, where ``builtin_interfaces`` Time and Duration
  are float seconds, arrays and sequences of numbers are numpy arrays, ``uint8[]``/``byte[]`` are
  bytes, nested messages are dicts and sequences of messages are lists of dicts.

The other way, a dict may leave fields out (they take the ROS default: zero, empty, false) but
may not name a field the type lacks, and Time/Duration also accept ``{"sec", "nanosec"}``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype

from .types import RosTypeError, RosTypes

TIME_TYPES = frozenset({"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})
IMAGE = "sensor_msgs/msg/Image"

IMAGE_ENCODINGS: dict[str, tuple[str, int]] = {
    "mono8": ("u1", 1),
    "8UC1": ("u1", 1),
    "rgb8": ("u1", 3),
    "bgr8": ("u1", 3),
    "8UC3": ("u1", 3),
    "rgba8": ("u1", 4),
    "bgra8": ("u1", 4),
    "8UC4": ("u1", 4),
    "mono16": ("u2", 1),
    "16UC1": ("u2", 1),
    "32FC1": ("f4", 1),
    "32FC3": ("f4", 3),
    "64FC1": ("f8", 1),
}
"""Image encodings understood here: encoding → (little-endian dtype, channels)."""

_DEFAULT_ENCODING = {
    ("u1", 1): "mono8",
    ("u1", 3): "rgb8",
    ("u1", 4): "rgba8",
    ("u2", 1): "16UC1",
    ("f4", 1): "32FC1",
    ("f4", 3): "32FC3",
    ("f8", 1): "64FC1",
}
_DTYPES = {
    "bool": np.bool_,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}
_BYTE_TYPES = frozenset({"uint8", "byte", "char"})


# ---------------------------------------------------------------------- payload → message


def to_message(types: RosTypes, type_name: str, payload: Any, *, where: str = "payload") -> Any:
    """The ``rosbags`` message of ``type_name`` a CKM ``payload`` stands for.

    Raises:
        RosTypeError: naming the field (``payload.header.stamp``) that does not fit.
    """
    if type_name == IMAGE and isinstance(payload, np.ndarray):
        return _image_message(types, payload, {}, where)
    pixels = payload.get("data") if isinstance(payload, Mapping) else None
    if type_name == IMAGE and isinstance(pixels, np.ndarray) and pixels.ndim > 1:  # else raw Image fields
        rest = {k: v for k, v in payload.items() if k != "data"}
        return _image_message(types, payload["data"], rest, where)
    return _struct(types, type_name, payload, where)


def encode_payload(types: RosTypes, type_name: str, payload: Any) -> bytes:
    """``payload`` as the CDR bytes of a ``type_name`` message."""
    return types.encode(type_name, to_message(types, type_name, payload))


def _struct(types: RosTypes, type_name: str, payload: Any, where: str) -> Any:
    if type_name in TIME_TYPES and payload is not None and not isinstance(payload, Mapping):
        return _time(types, type_name, payload, where)
    if payload is None:
        payload = {}
    if not isinstance(payload, Mapping):
        raise RosTypeError(f"{where} is {type(payload).__name__}, not a {type_name} (a dict of its fields)")
    fields = types.fields(type_name)
    declared = {name for name, _ in fields}
    extra = sorted(str(k) for k in payload if k not in declared)
    if extra:
        raise RosTypeError(
            f"{where} has fields {', '.join(extra)} that {type_name} lacks ({', '.join(sorted(declared))})"
        )
    values = {name: _field(types, desc, payload.get(name), f"{where}.{name}") for name, desc in fields}
    return types.message_class(type_name)(**values)


def _field(types: RosTypes, desc: Any, value: Any, where: str) -> Any:
    kind, detail = desc
    if kind == Nodetype.NAME:
        return _struct(types, detail, value, where)
    if kind == Nodetype.BASE:
        return _scalar(detail[0], value, where)
    (element_kind, element), size = detail
    if element_kind == Nodetype.NAME:
        items = [] if value is None else list(value)
        _check_length(kind, size, len(items), where)
        return [_struct(types, element, item, f"{where}[{i}]") for i, item in enumerate(items)]
    base = element[0]
    if base == "string":
        items = [] if value is None else [_scalar("string", v, f"{where}[{i}]") for i, v in enumerate(value)]
        _check_length(kind, size, len(items), where)
        return items
    if value is None:
        value = np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_DTYPES[base])
    if isinstance(value, bytes | bytearray | memoryview):
        value = np.frombuffer(bytes(value), dtype=np.uint8)
    try:
        array: np.ndarray[Any, Any] = np.asarray(value, dtype=_DTYPES[base]).reshape(-1)
    except (TypeError, ValueError) as error:
        raise RosTypeError(f"{where} is not a sequence of {base}: {error}") from error
    _check_length(kind, size, len(array), where)
    return array


def _check_length(kind: Nodetype, size: int, length: int, where: str) -> None:
    if kind == Nodetype.ARRAY and length != size:
        raise RosTypeError(f"{where} has {length} items, the type declares exactly {size}")
    if kind == Nodetype.SEQUENCE and size and length > size:
        raise RosTypeError(f"{where} has {length} items, the type allows at most {size}")


def _scalar(base: str, value: Any, where: str) -> Any:
    if base == "string":
        if value is None:
            return ""
        if not isinstance(value, str):
            raise RosTypeError(f"{where} is {value!r}, not a string")
        return value
    if value is None:
        return False if base == "bool" else 0
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    if base == "bool":
        if not isinstance(value, bool | np.bool_):
            raise RosTypeError(f"{where} is {value!r}, not a bool")
        return bool(value)
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
        raise RosTypeError(f"{where} is {value!r}, not a {base}")
    if base.startswith("float"):
        return float(value)
    if isinstance(value, float | np.floating) and not float(value).is_integer():
        raise RosTypeError(f"{where} is {value!r}, not a whole {base}")
    number, info = int(value), np.iinfo(_DTYPES[base])
    if not info.min <= number <= info.max:
        raise RosTypeError(f"{where} is {number}, outside the range of {base}")
    return number


def _time(types: RosTypes, type_name: str, seconds: Any, where: str) -> Any:
    if isinstance(seconds, bool) or not isinstance(seconds, int | float | np.number) or not math.isfinite(seconds):
        raise RosTypeError(f"{where} is {seconds!r}, not seconds (a number) or {{sec, nanosec}}")
    sec = math.floor(seconds)  # whole seconds first: seconds × 1e9 would round away the nanoseconds of an epoch time
    nanosec = round((float(seconds) - sec) * 1e9)
    sec, nanosec = sec + nanosec // 1_000_000_000, nanosec % 1_000_000_000
    if not -(2**31) <= sec < 2**31:
        raise RosTypeError(f"{where} is {seconds!r} s, outside the int32 seconds of {type_name}")
    return types.message_class(type_name)(sec=sec, nanosec=nanosec)


def _image_message(types: RosTypes, image: np.ndarray, rest: Mapping[str, Any], where: str) -> Any:
    if image.ndim not in (2, 3):
        raise RosTypeError(f"{where} is an array of shape {image.shape}, not an image (H, W) or (H, W, C)")
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    code = image.dtype.newbyteorder("<").str[1:] if image.dtype.kind in "uif" else image.dtype.str
    encoding = rest.get("encoding") or _DEFAULT_ENCODING.get((code, channels))
    if encoding not in IMAGE_ENCODINGS or IMAGE_ENCODINGS[encoding] != (code, channels):
        known = ", ".join(f"{e} ({d}×{c})" for e, (d, c) in IMAGE_ENCODINGS.items())
        raise RosTypeError(
            f"{where}: no image encoding for dtype {image.dtype} with {channels} channels "
            f"(asked: {rest.get('encoding')!r}; known: {known})"
        )
    data = np.ascontiguousarray(image).astype(np.dtype("<" + code), copy=False)
    fields = dict(
        rest,
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=0,
        step=width * channels * data.dtype.itemsize,
        data=np.frombuffer(data.tobytes(), dtype=np.uint8),
    )
    return _struct(types, IMAGE, fields, where)


# ---------------------------------------------------------------------- message → payload


def from_message(types: RosTypes, type_name: str, message: Any) -> Any:
    """The CKM payload of a ``rosbags`` message (see the module docstring for the shapes)."""
    if type_name == IMAGE:
        return image_array(message)
    return _plain(types, type_name, message)


def decode_payload(types: RosTypes, type_name: str, data: bytes | memoryview) -> Any:
    """The CKM payload of the CDR bytes of a ``type_name`` message."""
    return from_message(types, type_name, types.decode(type_name, data))


def image_array(message: Any) -> np.ndarray:
    """The pixels of a ``sensor_msgs/msg/Image`` as an (H, W) or (H, W, C) array."""
    if message.encoding not in IMAGE_ENCODINGS:
        raise RosTypeError(f"image encoding {message.encoding!r} is not supported ({', '.join(IMAGE_ENCODINGS)})")
    code, channels = IMAGE_ENCODINGS[message.encoding]
    dtype = np.dtype((">" if message.is_bigendian else "<") + code)
    row = message.width * channels * dtype.itemsize
    raw = np.asarray(message.data, dtype=np.uint8)
    if message.step < row or len(raw) < message.step * message.height:
        raise RosTypeError(
            f"image of {message.width}×{message.height} {message.encoding}: step {message.step} "
            f"and {len(raw)} bytes do not hold it"
        )
    rows = raw[: message.step * message.height].reshape(message.height, message.step)[:, :row]
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("<"))
    shape = (message.height, message.width) if channels == 1 else (message.height, message.width, channels)
    return pixels.reshape(shape)


def _plain(types: RosTypes, type_name: str, message: Any) -> Any:
    if type_name in TIME_TYPES:
        return (message.sec * 1_000_000_000 + message.nanosec) / 1_000_000_000  # int / int: one rounding
    result: dict[str, Any] = {}
    for name, (kind, detail) in types.fields(type_name):
        value = getattr(message, name)
        if kind == Nodetype.NAME:
            result[name] = _plain(types, detail, value)
        elif kind == Nodetype.BASE:
            result[name] = value
        else:
            (element_kind, element), _ = detail
            if element_kind == Nodetype.NAME:
                result[name] = [_plain(types, element, item) for item in value]
            elif element[0] == "string":
                result[name] = list(value)
            elif element[0] in _BYTE_TYPES and kind == Nodetype.SEQUENCE:
                result[name] = bytes(np.asarray(value, dtype=np.uint8))
            else:
                result[name] = np.array(value, dtype=_DTYPES[element[0]])
    return result
