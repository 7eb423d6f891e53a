"""What the HTML run report (:mod:`.html_report`) reads from a run's rosbag2 bags (§7.4–7.5).

``ckm-run --record TOPICS`` leaves a rosbag2 bag (MCAP or sqlite3, :mod:`runtime.ros.bag`) in the
run directory. The report takes from it, by topic (:class:`ReportTopics`: the recorded system's own,
:mod:`.report_topics`, or given on the command line):

- the **estimated trajectory** (a localization's pose estimate) and the **true trajectory** (a
  simulator's ground-truth topic, when recorded) for the Fig. 7.16 picture;
- the **zoom-map areas** (§6.1.3) when a topic carries them (``{x, y, width, depth}``, the shape of
  ``plugins.environment.zoom.Recentring``);
- the **recognition results** (the fused ones, and each source's) for Fig. 7.19;
- the **camera frame nearest** each moment of Fig. 7.22 / 7.24 (:class:`Moment`: an agent entering
  or ending a state): an ``Image`` on a camera topic, or its ``CompressedImage`` on
  ``CAMERA/compressed`` as ``ckm-run --record CAMERA@HZ:jpeg`` records it (runtime.ros.sparse, D197).

Payloads are read by shape, not by type name, so a CKM MessageType recorded as its generated
``ckm_msgs/msg/…`` type and a standard ROS type (``geometry_msgs/msg/PoseStamped``,
``nav_msgs/msg/Odometry``, ``sensor_msgs/msg/Image``) both work. Times are the bag's (seconds since
the epoch, the publication time), which the report puts on the recordings' run time.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Reader

from ..ros.bag import BagSource
from ..ros.convert import IMAGE_ENCODINGS
from ..ros.sparse import decompress

STORAGE_SUFFIXES = (".mcap", ".db3")


@dataclass(frozen=True)
class ReportTopics:
    """The topics the report looks for in the bags, by their names in the bag; empty: none known.

    Nothing is looked for by default: :func:`.report_topics.topics_of` takes them from the recorded
    system, and the command line may name others (:meth:`filled_from` joins the two). An internal
    topic is in the bag under its node's name (``camera_raw`` of node ``robot1`` is
    ``/robot1/camera_raw``, runtime.ros.recording)."""

    estimate: str = ""
    truth: tuple[str, ...] = ()
    fused: str = ""
    recognition: tuple[str, ...] = ()
    cameras: tuple[str, ...] = ()
    zoom: tuple[str, ...] = ()

    def filled_from(self, other: ReportTopics) -> ReportTopics:
        """These topics where they name some, ``other``'s where they name none."""
        return ReportTopics(
            estimate=self.estimate or other.estimate,
            truth=self.truth or other.truth,
            fused=self.fused or other.fused,
            recognition=self.recognition or other.recognition,
            cameras=self.cameras or other.cameras,
            zoom=self.zoom or other.zoom,
        )

    def camera_topics(self) -> tuple[str, ...]:
        """Each camera topic and its compressed stream (``CAMERA/compressed``, image_transport's name)."""
        return tuple(t for c in self.cameras for t in (c, c.rstrip("/") + "/compressed"))

    def wanted(self) -> set[str]:
        """Every topic the report reads, to load only those from the bags."""
        every = {self.estimate, self.fused, *self.truth, *self.recognition, *self.camera_topics(), *self.zoom}
        return every - {""}


@dataclass(frozen=True)
class Moment:
    """A moment of Fig. 7.22 / 7.24: an agent entering or ending a state, at an epoch ``time``
    (``run_time`` on the recordings' clock)."""

    time: float
    run_time: float
    agent: str
    state: str
    path: str
    edge: str  # "entered", "ended" (a transition) or "stopped" (the run ended in it)

    @property
    def label(self) -> str:
        """``robot1 Fetch/Interaction/PICK ended at 80.0 s``."""
        return f"{self.agent} {self.path} {self.edge} at {self.run_time:.1f} s"


@dataclass(frozen=True)
class Sighting:
    """One recognised object in one recognition message."""

    time: float
    name: str
    reliability: float
    x: float | None
    y: float | None


@dataclass
class Frame:
    """The camera frame nearest a moment: the payload is decoded to pixels only for these."""

    topic: str
    moment: Moment
    time: float = math.nan
    payload: Any = None

    @property
    def offset(self) -> float:
        """Seconds from the moment to the frame (negative: taken before it)."""
        return self.time - self.moment.time


@dataclass
class BagData:
    """Everything the report takes from the bags, with notes on what was not there."""

    bags: list[Path] = field(default_factory=list)
    topics: dict[str, str] = field(default_factory=dict)  # topic → ROS type, over every bag
    stored: dict[str, int] = field(default_factory=dict)  # messages per topic, as the bags' metadata counts them
    counts: dict[str, int] = field(default_factory=dict)  # messages read per wanted topic
    poses: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)  # topic → (t, x, y)
    headings: dict[str, list[tuple[float, float]]] = field(default_factory=dict)  # topic → (t, yaw)
    zoom: list[tuple[float, float, float, float, float]] = field(default_factory=list)  # t, x, y, width, depth
    detections: dict[str, list[tuple[float, list[Sighting]]]] = field(default_factory=dict)  # topic → (t, objects)
    frames: list[Frame] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)


def find_bags(run_dir: Path) -> list[Path]:
    """The bag directories of a run: the run directory itself or a folder up to two levels below
    it holding ``metadata.yaml`` or a storage file (``.mcap``/``.db3``); the sqlite3 twin ``BAG-sqlite3``
    of a bag ``BAG`` (``--record-format mcap+sqlite3``) is left out, its messages being BAG's."""
    candidates = [run_dir]
    for child in sorted(p for p in run_dir.iterdir() if p.is_dir()):
        candidates += [child, *sorted(p for p in child.iterdir() if p.is_dir())]
    bags = [c for c in candidates if _is_bag(c)]
    # --record-format mcap+sqlite3 (runtime.ros.recording): BAG-sqlite3 holds BAG's messages again
    return [b for b in bags if not (b.name.endswith("-sqlite3") and b.with_name(b.name[: -len("-sqlite3")]) in bags)]


def _is_bag(folder: Path) -> bool:
    if (folder / "metadata.yaml").is_file():
        return True
    return any(p.suffix in STORAGE_SUFFIXES and p.is_file() for p in folder.iterdir())


def _storage_files(bag: Path) -> str:
    files = sorted(p.name for p in bag.glob("*") if p.suffix in STORAGE_SUFFIXES)
    return ", ".join(str(bag / f) for f in files) or str(bag / "metadata.yaml")


def _first_line(error: Exception) -> str:
    lines = str(error).strip().splitlines()
    return lines[0] if lines else type(error).__name__


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def pose_xy(payload: Any, depth: int = 0) -> tuple[float, float] | None:
    """The planar position a pose-like payload holds: ``{x, y}``, ``{pose: …}``, ``{position: …}``
    (Pose2D, PoseEstimate, Odometry, geometry_msgs Pose/PoseStamped, nav_msgs/Odometry)."""
    if not isinstance(payload, Mapping) or depth > 4:
        return None
    x, y = _number(payload.get("x")), _number(payload.get("y"))
    if x is not None and y is not None:
        return x, y
    for key in ("pose", "position"):
        if key in payload:
            return pose_xy(payload[key], depth + 1)
    return None


def pose_yaw(payload: Any, depth: int = 0) -> float | None:
    """The heading (rad) a pose-like payload holds: ``yaw`` next to ``x``/``y``, or a quaternion
    ``orientation`` ``{x, y, z, w}``, at the top or under ``pose``."""
    if not isinstance(payload, Mapping) or depth > 4:
        return None
    yaw = _number(payload.get("yaw"))
    if yaw is not None and _number(payload.get("x")) is not None:
        return yaw
    quaternion = payload.get("orientation")
    if isinstance(quaternion, Mapping):
        x, y, z, w = (_number(quaternion.get(k)) for k in ("x", "y", "z", "w"))
        if x is not None and y is not None and z is not None and w is not None and (x, y, z, w) != (0, 0, 0, 0):
            return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return pose_yaw(payload.get("pose"), depth + 1) if "pose" in payload else None


def sightings(payload: Any, t: float) -> list[Sighting]:
    """The objects of a recognition result ``{objects: [{name|label, shape, texture, x, y, reliability}]}``."""
    if not isinstance(payload, Mapping) or not isinstance(payload.get("objects"), list | tuple):
        return []
    found = []
    for item in payload["objects"]:
        if not isinstance(item, Mapping):
            continue
        reliability = _number(item.get("reliability"))
        if reliability is None:
            continue
        words = [str(item.get(k) or "") for k in ("name", "label", "shape", "texture")]
        name = " ".join(dict.fromkeys(w for w in words if w))  # name first, no repeats
        found.append(Sighting(t, name, reliability, _number(item.get("x")), _number(item.get("y"))))
    return found


def _zoom_area(payload: Any) -> tuple[float, float, float, float] | None:
    if not isinstance(payload, Mapping):
        return None
    values = [_number(payload.get(k)) for k in ("x", "y", "width", "depth")]
    if all(v is not None for v in values):
        x, y, w, d = values
        return x, y, w, d  # type: ignore[return-value]
    bounds = [_number(payload.get(k)) for k in ("xmin", "ymin", "xmax", "ymax")]
    if all(v is not None for v in bounds):
        x0, y0, x1, y1 = bounds
        return (x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0  # type: ignore[operator]
    return None


def compressed_picture(payload: Any) -> tuple[str, bytes] | None:
    """(media type, bytes) of a ``sensor_msgs/msg/CompressedImage`` payload, None for another payload.

    Raises:
        ValueError: a compressed image whose data is neither JPEG nor PNG.
    """
    if isinstance(payload, Mapping) and "format" in payload and "data" in payload and "width" not in payload:
        return decompress(dict(payload))
    return None


def image_pixels(payload: Any) -> np.ndarray:
    """The pixels of an image payload: an (H, W[, C]) array (``sensor_msgs/msg/Image`` read by
    :mod:`runtime.ros.convert`) or a CKM ``Image`` ``{width, height, encoding, data}``."""
    if isinstance(payload, np.ndarray):
        pixels = payload
        encoding = "rgb8"
    elif isinstance(payload, Mapping) and isinstance(payload.get("data"), bytes | bytearray | np.ndarray):
        encoding = str(payload.get("encoding") or "rgb8")
        if encoding not in IMAGE_ENCODINGS:
            raise ValueError(f"image encoding {encoding!r} is not supported ({', '.join(IMAGE_ENCODINGS)})")
        code, channels = IMAGE_ENCODINGS[encoding]
        width, height = int(payload.get("width") or 0), int(payload.get("height") or 0)
        data = payload["data"]
        if isinstance(data, bytes | bytearray):
            raw = np.frombuffer(bytes(data), dtype=np.uint8)
        else:
            raw = np.asarray(data, dtype=np.uint8).reshape(-1)
        size = width * height * channels * np.dtype(code).itemsize
        if width <= 0 or height <= 0 or raw.size < size:
            raise ValueError(f"image of {width}×{height} {encoding}: {raw.size} bytes do not hold it")
        flat = raw[:size].view(np.dtype("<" + code))
        pixels = flat.reshape((height, width) if channels == 1 else (height, width, channels))
    else:
        raise ValueError(f"not an image payload ({type(payload).__name__})")
    if pixels.ndim == 3 and encoding.startswith("bgr"):
        pixels = pixels[:, :, [2, 1, 0, *range(3, pixels.shape[2])]]
    return pixels


def read_bags(bags: Iterable[Path], topics: ReportTopics, moments: Iterable[Moment]) -> BagData:
    """Read the wanted topics of ``bags``; at each of ``moments`` the nearest frame of every camera.

    A bag that cannot be read (no metadata, a corrupt storage file, an undecodable message) adds
    an error naming its files to :attr:`BagData.errors`; what was read before it is kept.
    """
    data = BagData()
    # one frame per camera and moment over every bag (several --node processes each keep a bag)
    frames = {(c, m): Frame(c, m) for c in topics.camera_topics() for m in moments}
    for bag in bags:
        data.bags.append(bag)
        try:
            if not (bag / "metadata.yaml").is_file():
                raise ValueError(f"{bag}: not a rosbag2 bag (no metadata.yaml)")
            with Reader(bag) as reader:  # the catalogue: types and message counts of metadata.yaml
                types = {c.topic: c.msgtype for c in reader.connections}
                for connection in reader.connections:
                    data.stored[connection.topic] = data.stored.get(connection.topic, 0) + connection.msgcount
        except Exception as error:  # rosbags raises several kinds for a broken bag: name the files
            data.errors.append(f"{_storage_files(bag)}: not a readable rosbag2 bag: {_first_line(error)}")
            continue
        data.topics.update(types)
        wanted = sorted(set(types) & topics.wanted())
        if not wanted:
            continue
        try:
            for message in BagSource(bag, topics=wanted).messages():
                _take(data, topics, message.topic, message.time, message.payload, frames)
        except Exception as error:
            stopped = "reading the rosbag2 bag stopped (corrupt or undecodable)"
            data.errors.append(f"{_storage_files(bag)}: {stopped}: {_first_line(error)}")
    data.frames = sorted((f for f in frames.values() if f.payload is not None), key=lambda f: (f.moment.time, f.topic))
    for track in data.poses.values():  # bags of several processes interleave: time order for lookups
        track.sort()
    for headings in data.headings.values():
        headings.sort()
    for messages in data.detections.values():
        messages.sort(key=lambda message: message[0])
    data.zoom.sort()
    return data


def _take(data: BagData, topics: ReportTopics, topic: str, t: float, payload: Any, frames: dict[Any, Frame]) -> None:
    data.counts[topic] = data.counts.get(topic, 0) + 1
    if topic == topics.estimate or topic in topics.truth:
        xy = pose_xy(payload)
        if xy is not None:
            data.poses.setdefault(topic, []).append((t, *xy))
            yaw = pose_yaw(payload)
            if yaw is not None:
                data.headings.setdefault(topic, []).append((t, yaw))
    if topic in topics.zoom:
        area = _zoom_area(payload)
        if area is not None and (not data.zoom or data.zoom[-1][1:] != area):  # one entry per move
            data.zoom.append((t, *area))
    if topic == topics.fused or topic in topics.recognition:
        data.detections.setdefault(topic, []).append((t, sightings(payload, t)))
    if topic in topics.camera_topics():
        for (camera, moment), frame in frames.items():
            if camera == topic and (frame.payload is None or abs(t - moment.time) < abs(frame.offset)):
                frame.time, frame.payload = t, payload
