"""The map shared between robots as a Smart Resource service (thesis §6.1.1 time marks, §4.3 service API).

Each robot's :class:`MapShare` announces its map on the service directory
(:data:`runtime.resources.api.DIRECTORY_TOPIC`, an entry of ``type`` ``service`` with
``function`` :data:`FUNCTION` and one output, ``objects``), publishes its objects on that output
and subscribes to the ``objects`` output of every other map it discovers (a
:class:`~runtime.resources.client.ServiceDirectory`). Every published object carries its time
mark; a received one replaces the local copy only when newer (:meth:`MapModel.replace`: later
stamp, ties broken by the larger source name), so robots exchanging updates in any order end
with the same object list.

Every ``period`` seconds a share publishes the objects changed since it last published, and every
``full_every`` periods all of them, in chunks of :data:`CHUNK` (robots that join late catch up).
The map service takes no requests: it has no config, quality or alarm topics, and clients read
its output directly. Received messages are untrusted: a malformed object is counted in
:attr:`MapShare.rejected` and dropped, never applied in part.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Mapping
from typing import Any

import shapely

from runtime.network.api import Publisher, Sample, Subscription, TopicQoS, Transport
from runtime.resources.api import DIRECTORY_TOPIC
from runtime.resources.client import ServiceDirectory

from .geometry import Part
from .map_model import MapModel, MapObject

FUNCTION = "environment-map"
CHUNK = 256
MESSAGE_TYPE = "ckm/environment-objects"
DIMENSIONS = ("2D", "2.5D", "3D")


def encode_object(obj: MapObject) -> dict[str, Any]:
    """A map object as a msgpack-able dict (parts as WKB)."""
    return {
        "name": obj.name,
        "tag": obj.tag,
        "pose": [obj.x, obj.y, obj.z, obj.yaw],
        "dimension": obj.dimension,
        "texture": obj.texture,
        "area": obj.area,
        "stamp": obj.stamp,
        "reliability": obj.reliability,
        "source": obj.source,
        "parts": [[shapely.to_wkb(p.local), p.zmin, p.zmax] for p in obj.parts],
    }


def _text(value: Any, field: str, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str) or not 0 < len(value) <= 256:
        raise ValueError(f"{field} must be a string of 1-256 characters")
    return value


def _real(value: Any, field: str, finite: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise ValueError(f"{field} must be a number")
    if finite and not math.isfinite(value):
        raise ValueError(f"{field} must be finite")
    return float(value)


def decode_object(item: Any) -> MapObject:
    """A map object from a received dict; a ValueError names the first bad field."""
    if not isinstance(item, Mapping):
        raise ValueError("an object must be a map")
    pose = item.get("pose")
    if not isinstance(pose, list | tuple) or len(pose) != 4:
        raise ValueError("pose must be [x, y, z, yaw]")
    x, y, z, yaw = (_real(v, "pose") for v in pose)
    if item.get("dimension") not in DIMENSIONS:
        raise ValueError(f"dimension must be one of {', '.join(DIMENSIONS)}")
    raw_parts = item.get("parts")
    if not isinstance(raw_parts, list | tuple) or len(raw_parts) > 64:
        raise ValueError("parts must be a list of at most 64 [wkb, zmin, zmax]")
    parts = []
    for raw in raw_parts:
        if not isinstance(raw, list | tuple) or len(raw) != 3 or not isinstance(raw[0], bytes) or len(raw[0]) > 65536:
            raise ValueError("a part must be [wkb bytes, zmin, zmax]")
        try:
            local = shapely.from_wkb(raw[0])
        except shapely.errors.GEOSException as exc:
            raise ValueError(f"a part's geometry is not WKB: {exc}") from None
        parts.append(Part(local, _real(raw[1], "zmin", False), _real(raw[2], "zmax", False)))
    reliability = _real(item.get("reliability"), "reliability")
    if not 0.0 <= reliability <= 1.0:
        raise ValueError("reliability must be within [0, 1]")
    return MapObject(
        name=str(_text(item.get("name"), "name")),
        tag=str(_text(item.get("tag"), "tag")),
        x=x,
        y=y,
        z=z,
        yaw=yaw,
        parts=tuple(parts),
        dimension=item["dimension"],
        texture=_text(item.get("texture"), "texture", True),
        area=_text(item.get("area"), "area", True),
        stamp=_real(item.get("stamp"), "stamp"),
        reliability=reliability,
        source=str(_text(item.get("source"), "source")),
    )


class MapShare:
    """One robot's map offered to, and completed by, the other robots' maps (newer time mark wins)."""

    def __init__(
        self,
        transport: Transport,
        model: MapModel,
        robot: str,
        *,
        period: float = 0.2,
        full_every: int = 10,
    ) -> None:
        self.transport, self.model, self.robot = transport, model, robot
        self.period, self.full_every = period, full_every
        self.resource, self.service = f"{robot}Map", "Map"
        self.topic = f"/{self.resource}/{self.service}/objects"
        self.lock = threading.RLock()
        """Hold it while changing :attr:`model` from another thread (received updates are applied under it)."""
        self.received = 0
        self.applied = 0
        self.rejected = 0
        self._sent: dict[str, tuple[float, str]] = {}
        self._peers: dict[str, Subscription] = {}
        self._publisher: Publisher | None = None
        self._announcer: Publisher | None = None
        self._directory: ServiceDirectory | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def entry(self) -> dict[str, Any]:
        """The directory entry of this map service."""
        return {
            "type": "service",
            "resource": self.resource,
            "service": self.service,
            "node": self.robot,
            "function": FUNCTION,
            "inputs": {},
            "outputs": {"objects": self.topic},
            "parameters": [],
            "measures": [],
            "scenarios": [],
        }

    def setup(self) -> None:
        """Create the ``objects`` output, the service-directory announcer and the directory of other maps (§4.3)."""
        self._publisher = self.transport.publisher(TopicQoS(self.topic, MESSAGE_TYPE, history=8))
        self._announcer = self.transport.publisher(TopicQoS(DIRECTORY_TOPIC, "ckm/service", history=64))
        self._directory = ServiceDirectory(self.transport)

    def start(self) -> None:
        """Start announcing, publishing every ``period`` s and subscribing to the maps discovered (after setup)."""
        self._thread = threading.Thread(target=self._loop, name=f"map-share-{self.robot}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the thread (waiting at most 5 s) and close the subscriptions to the other maps and the directory."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for subscription in self._peers.values():
            subscription.close()
        if self._directory is not None:
            self._directory.close()

    def __enter__(self) -> MapShare:
        self.setup()
        self.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()

    def _loop(self) -> None:
        rounds = 0
        while not self._stop.wait(self.period):
            assert self._announcer is not None
            self._announcer.publish(self.entry())
            self._follow_peers()
            self.publish(full=rounds % self.full_every == 0)
            rounds += 1

    def _follow_peers(self) -> None:
        assert self._directory is not None
        for entry in self._directory.services().values():
            node, topic = entry.get("node"), (entry.get("outputs") or {}).get("objects")
            if entry.get("function") != FUNCTION or node == self.robot or not isinstance(topic, str):
                continue
            if topic not in self._peers:
                qos = TopicQoS(topic, MESSAGE_TYPE, history=8)
                self._peers[topic] = self.transport.subscribe(qos, self._on_objects)

    @property
    def peers(self) -> list[str]:
        """The other maps' output topics this share follows."""
        return sorted(self._peers)

    def publish(self, *, full: bool = False) -> int:
        """Publish the objects changed since the last call (all of them with ``full``); returns how many."""
        assert self._publisher is not None
        with self.lock:
            changed = [
                o for o in self.model.objects.values() if full or self._sent.get(o.name) != (o.stamp, o.source)
            ]
            encoded = [encode_object(o) for o in changed]
            self._sent.update((o.name, (o.stamp, o.source)) for o in changed)
        for start in range(0, len(encoded), CHUNK):
            self._publisher.publish({"type": "objects", "map": self.robot, "objects": encoded[start : start + CHUNK]})
        return len(encoded)

    def _on_objects(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, Mapping) or message.get("type") != "objects":
            self.rejected += 1
            return
        items = message.get("objects")
        if not isinstance(items, list) or len(items) > CHUNK:
            self.rejected += 1
            return
        self.apply(items)

    def apply(self, items: Iterable[Any]) -> int:
        """Apply received encoded objects (newer wins); returns how many changed the map."""
        decoded = []
        for item in items:
            self.received += 1
            try:
                decoded.append(decode_object(item))
            except ValueError:
                self.rejected += 1
        with self.lock:
            applied = 0
            for obj in decoded:
                if self.model.replace(obj):
                    applied += 1
                    self._sent[obj.name] = (obj.stamp, obj.source)  # the sender has it: no echo
        self.applied += applied
        return applied
