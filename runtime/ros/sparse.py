"""Sparse recording for ``ckm-run --record``: rate limits and compressed camera frames (issue K point 2, D197).

A VGA camera frame is 900 kB: recorded at the camera's 2 Hz the bag grows by 1.8 MB/s per camera.
What the run report needs of a camera (the snapshots of Fig. 7.22 / 7.24) is one frame now and
then, so each item of ``--record`` may carry two options, as a ROS user knows them from
``topic_tools throttle`` and ``image_transport``'s ``compressed`` transport:

``NAME[@HZ][:jpeg|:png]``

- ``@HZ``: at most ``HZ`` messages per second of the run's clock (``/nao/camera/image@0.5``: one
  every 2 s at most); the others are not recorded (counted as ``throttled``, not as dropped);
- ``:jpeg`` / ``:png``: an image topic (``sensor_msgs/msg/Image`` or a MessageType with ``width``,
  ``height``, ``encoding`` and ``data``) is recorded as ``sensor_msgs/msg/CompressedImage`` under
  ``BAG_NAME/compressed``, its ``format`` written as ``compressed_image_transport`` does
  (``rgb8; jpeg compressed bgr8``), so rqt, Foxglove and ``ros2 bag play`` show it as any ROS
  camera's compressed stream. JPEG at quality :data:`JPEG_QUALITY` turns a 900 kB frame of the
  simulated laboratory into some 30–60 kB; PNG is lossless.

``all`` may stand with named items: ``all,/nao/camera/image@0.5:jpeg`` records every topic, the
camera sparsely.
"""

from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, Literal

import numpy as np
from PIL import Image as PilImage

from .convert import IMAGE, image_array
from .types import RosTypeError, RosTypes

COMPRESSED = "sensor_msgs/msg/CompressedImage"
Compression = Literal["jpeg", "png"]
COMPRESSIONS: tuple[Compression, ...] = ("jpeg", "png")
JPEG_QUALITY = 85
"""compressed_image_transport's default ``jpeg_quality`` (80) rounded up: snapshots are looked at."""
TOLERANCE = 1e-3
"""s: a message stamped this much before its due time still counts as due (clock rounding)."""
_ITEM = re.compile(r"^(?P<name>[^@:]+?)\s*(?:@\s*(?P<rate>[^@:]+?))?\s*(?::\s*(?P<format>[^@:]+?))?$")


class SpecError(ValueError):
    """An item of ``--record`` that is not ``NAME[@HZ][:jpeg|:png]``."""


@dataclass(frozen=True)
class Item:
    """One item of ``--record``: a topic name (or ``all``), its rate limit in Hz, its compression."""

    name: str
    rate: float | None = None
    compression: Compression | None = None


def parse_spec(spec: str) -> list[Item]:
    """The items of ``--record SPEC`` (comma-separated ``NAME[@HZ][:jpeg|:png]``).

    Raises:
        SpecError: naming the item at fault (a rate that is not a positive number, an unknown format).
    """
    items = []
    for text in (w.strip() for w in spec.split(",")):
        if not text:
            continue
        match = _ITEM.match(text)
        if match is None:
            raise SpecError(f"--record item {text!r}: write NAME, NAME@HZ, NAME:jpeg or NAME@HZ:jpeg")
        rate: float | None = None
        if match["rate"] is not None:
            try:
                rate = float(match["rate"])
            except ValueError:
                rate = math.nan
            if not (math.isfinite(rate) and rate > 0):
                raise SpecError(f"--record item {text!r}: @{match['rate']} is not a rate in Hz (a positive number)")
        compression = match["format"]
        if compression is not None and compression not in COMPRESSIONS:
            raise SpecError(f"--record item {text!r}: :{compression} is not a compression ({', '.join(COMPRESSIONS)})")
        if match["name"] == "all" and (rate is not None or compression is not None):
            raise SpecError(f"--record item {text!r}: 'all' takes no option; name the topics to limit")
        items.append(Item(match["name"], rate, compression))
    return items


def is_image_type(types: RosTypes, ros_type: str) -> bool:
    """Whether messages of ``ros_type`` hold an image: ``sensor_msgs/msg/Image`` or any type with
    ``width``, ``height``, ``encoding`` and ``data`` fields (the use case's ``Image`` MessageType)."""
    if ros_type == IMAGE:
        return True
    try:
        names = {name for name, _ in types.fields(ros_type)}
    except RosTypeError:
        return False
    return {"width", "height", "encoding", "data"} <= names


class Throttle:
    """At most ``rate`` messages per second of the stamps it is shown (``topic_tools throttle``)."""

    def __init__(self, rate: float) -> None:
        self.period = 1.0 / rate
        self._due = -math.inf

    def admit(self, stamp: float) -> bool:
        """Whether the message stamped ``stamp`` (s) is recorded; a stamp that goes back in time
        (another publisher's clock) restarts the limit."""
        if stamp + TOLERANCE < self._due and stamp > self._due - 2 * self.period:
            return False
        self._due = stamp + self.period
        return True


def pixels_of(message: Any, ros_type: str) -> np.ndarray:
    """The pixels of a decoded image message (``sensor_msgs/msg/Image`` or an image-like type)."""
    if ros_type == IMAGE:
        return image_array(message)
    width, height, encoding = int(message.width), int(message.height), str(message.encoding)
    view = SimpleNamespace(width=width, height=height, encoding=encoding, data=message.data,
                           is_bigendian=int(getattr(message, "is_bigendian", 0) or 0),
                           step=int(getattr(message, "step", 0) or 0))  # fmt: skip
    if not view.step:  # a type without a step: rows are packed
        view.step = len(np.asarray(message.data, dtype=np.uint8)) // height if height else 0
    return image_array(view)


def _stamp_and_frame(message: Any) -> tuple[Any, str]:
    header = getattr(message, "header", None)
    if header is not None:
        return header.stamp, str(header.frame_id)
    return getattr(message, "stamp", None), ""


def compress(
    types: RosTypes, message: Any, ros_type: str, compression: Compression, stamp: float, encoding: str | None = None
) -> bytes:
    """The CDR bytes of the ``sensor_msgs/msg/CompressedImage`` of an image message.

    The header keeps the image's stamp and frame (``stamp`` seconds when it has none).

    Raises:
        RosTypeError: the image cannot be compressed so (16-bit or float pixels in JPEG, say).
    """
    pixels = pixels_of(message, ros_type)
    encoding = encoding or str(message.encoding)
    if pixels.ndim == 3 and encoding.startswith("bgr"):
        pixels = pixels[:, :, [2, 1, 0, *range(3, pixels.shape[2])]]
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    if pixels.dtype == np.uint8 and channels in (1, 3, 4):
        picture = PilImage.fromarray(pixels if channels != 1 else pixels.reshape(pixels.shape[:2]))
        target = "mono8" if channels == 1 else "bgr8"
        if compression == "jpeg" and channels == 4:
            picture = picture.convert("RGB")  # JPEG has no alpha
    elif compression == "png" and pixels.dtype == np.uint16 and channels == 1:
        picture, target = PilImage.fromarray(pixels.astype("<u2").reshape(pixels.shape[:2])), "mono16"
    else:
        raise RosTypeError(
            f"a {encoding} image ({pixels.dtype}, {channels} channel(s)) cannot be {compression}-compressed"
        )
    buffer = io.BytesIO()
    if compression == "jpeg":
        picture.save(buffer, format="JPEG", quality=JPEG_QUALITY)
    else:
        picture.save(buffer, format="PNG", compress_level=6)
    head_stamp, frame = _stamp_and_frame(message)
    if head_stamp is None or not hasattr(head_stamp, "sec"):
        sec = math.floor(stamp)
        head_stamp = types.message_class("builtin_interfaces/msg/Time")(
            sec=sec, nanosec=min(999_999_999, round((stamp - sec) * 1e9))
        )
    header = types.message_class("std_msgs/msg/Header")(stamp=head_stamp, frame_id=frame)
    data = np.frombuffer(buffer.getvalue(), dtype=np.uint8)
    image = types.message_class(COMPRESSED)(
        header=header, format=f"{encoding}; {compression} compressed {target}", data=data
    )
    return types.encode(COMPRESSED, image)


def decompress(payload: Any) -> tuple[str, bytes]:
    """The picture a ``CompressedImage`` payload holds: (``image/jpeg`` or ``image/png``, its bytes).

    Raises:
        ValueError: the payload is not a JPEG or PNG picture.
    """
    data = payload.get("data") if isinstance(payload, dict) else None
    if isinstance(data, np.ndarray):
        data = data.astype(np.uint8).tobytes()
    if not isinstance(data, bytes | bytearray):
        raise ValueError(f"not a compressed image payload ({type(payload).__name__})")
    if data[:3] == b"\xff\xd8\xff":
        return "image/jpeg", bytes(data)
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return "image/png", bytes(data)
    raise ValueError(f"compressed image of format {payload.get('format')!r}: neither JPEG nor PNG data")
