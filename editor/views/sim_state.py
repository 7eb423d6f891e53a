"""The newest values of the live views' topics (issue K.5), filled on the transport's threads.

Network callbacks only store what arrived, under a lock; the Monitor tab's Qt timer takes a
:class:`Snapshot` and redraws from it (the same split as editor/views/live.py). Images are kept as
they arrived and turned into pixels at most once each, on the GUI thread. A recognition result is
shown for its topic's ``lifespan`` after it arrived (``/recog/objects``: 2.4 s), so objects no
longer recognised leave the map.

The zoom-map area (§6.1.3) is the newest one a zoom topic carried (the use case's ``/nav/zoom``, the
area Navigation.AMCL holds: D215); until one has arrived, or when the system publishes none, it is
replayed from the pose estimate with the ``<ZoomMap>`` triggers of plugins/environment/zoom.py —
centred on the robot at the first estimate, again when the robot comes within ``border`` × the size
of the area's edge, and after ``timeout`` s — at its fixed size (D160). The particle cloud is the
newest one a particle topic (``/nav/particles``) or an estimate's ``particles`` field carried. A
malformed cloud or area is not drawn: its FeedError is the topic's entry in ``errors`` until a good
message arrives there.
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ckmconf.model.environment import ZoomMap
from runtime.network import Sample

from .sim_feeds import (
    FeedError,
    Feeds,
    Seen,
    covariance_of,
    number,
    objects_of,
    particles_of,
    plain,
    pose_of,
    zoom_of,
)

Pose = tuple[float, float, float]
TRACK = 5000  # poses kept per trajectory: 1000 s of the use case's ground truth (0.2 s)


@dataclass(frozen=True)
class Zoom:
    """A zoom-map area: centre, size, and whether it was replayed rather than published."""

    x: float
    y: float
    width: float
    depth: float
    replayed: bool
    reason: str = ""  # why a published area last moved (start, border, timeout)
    objects: int | None = None  # the objects a published area manages


def zoom_text(zoom: Zoom) -> str:
    """The map's label of a zoom-map area: replayed, or why it last moved and how many objects it holds."""
    if zoom.replayed:
        return "zoom map (replayed)"
    words = [zoom.reason] if zoom.reason else []
    if zoom.objects is not None:
        words.append(f"{zoom.objects} object{'' if zoom.objects == 1 else 's'}")
    return f"zoom map ({', '.join(words)})" if words else "zoom map"


@dataclass
class Snapshot:
    """What the views draw, as of one refresh."""

    truth: dict[str, Pose] = field(default_factory=dict)
    estimate: dict[str, Pose] = field(default_factory=dict)
    covariance: dict[str, np.ndarray] = field(default_factory=dict)
    head: dict[str, float] = field(default_factory=dict)  # robot → head pan (rad, left of its heading)
    tracks: dict[tuple[str, str], list[tuple[float, float]]] = field(default_factory=dict)  # (robot, kind) → path
    particles: np.ndarray | None = None
    zoom: Zoom | None = None
    objects: list[Seen] = field(default_factory=list)
    images: dict[str, tuple[int, Any]] = field(default_factory=dict)  # topic → (frames so far, newest)
    errors: dict[str, str] = field(default_factory=dict)  # topic → the last unreadable message


class LiveState:
    """The newest sample of every topic of ``feeds``, turned into what the map draws."""

    def __init__(self, feeds: Feeds, zoom: ZoomMap | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.feeds = feeds
        self.clock = clock  # arrival times, for the lifespans
        self.settings = zoom
        self._lock = threading.Lock()
        self._now = Snapshot()
        self._zoom_stamp = 0.0
        self._zoom_heard = False  # a zoom topic has carried an area: no more replaying
        self._by_topic: dict[str, tuple[float, list[Seen]]] = {}  # topic → (arrival, objects)
        self._frames: dict[str, int] = {}
        self._tracks: dict[tuple[str, str], collections.deque[tuple[float, float]]] = {}

    def handlers(self) -> dict[str, Callable[[Sample], None]]:
        """One callback per topic to subscribe (a topic feeding several roles gets one that does all)."""
        roles: dict[str, list[Callable[[str, Any, float], None]]] = {}
        for robot in self.feeds.robots:
            if robot.truth is not None:
                roles.setdefault(robot.truth, []).append(self._truth(robot.name))
            for topic in robot.estimates:
                roles.setdefault(topic, []).append(self._estimate(robot.name))
            if robot.head is not None:
                roles.setdefault(robot.head, []).append(self._head(robot.name))
        for topic in self.feeds.objects:
            roles.setdefault(topic, []).append(self._objects)
        for topic in self.feeds.cameras:
            roles.setdefault(topic, []).append(self._image)
        for topic in self.feeds.zoom:
            roles.setdefault(topic, []).append(self._zoom)
        for topic in self.feeds.particles:
            roles.setdefault(topic, []).append(self._particles)
        return {topic: self._handler(topic, jobs) for topic, jobs in roles.items()}

    def _handler(self, topic: str, jobs: list[Callable[[str, Any, float], None]]) -> Callable[[Sample], None]:
        def arrived(sample: Sample) -> None:
            try:
                value = plain(sample.value)
            except FeedError as exc:
                with self._lock:
                    self._now.errors[topic] = str(exc)
                return
            for job in jobs:
                job(topic, value, sample.stamp)

        return arrived

    def feed(self, topic: str, value: Any, stamp: float) -> None:
        """Hand a value straight in, as if it had arrived on ``topic`` (tests, recordings)."""
        handler = self.handlers().get(topic)
        if handler is None:
            raise KeyError(f"{topic}: not a topic of the live views ({', '.join(sorted(self.handlers()))})")
        handler(Sample(topic, value, stamp, 0, 0, stamp))

    # ------------------------------------------------------------------ roles

    def _truth(self, robot: str) -> Callable[[str, Any, float], None]:
        def take(_: str, value: Any, __: float) -> None:
            pose = pose_of(value)
            if pose is not None:
                with self._lock:
                    self._now.truth[robot] = pose
                    self._track(robot, "truth", pose)

        return take

    def _estimate(self, robot: str) -> Callable[[str, Any, float], None]:
        def take(topic: str, value: Any, stamp: float) -> None:
            pose = pose_of(value)
            if pose is None:
                return
            covariance, cloud, refused = covariance_of(value), None, None
            carried = value.get("particles") if isinstance(value, Mapping) else None
            try:
                cloud = None if carried is None else particles_of(carried)
            except FeedError as exc:  # the pose stays good; its cloud is not drawn
                refused = str(exc)
            with self._lock:
                if refused is not None:
                    self._now.errors[topic] = refused
                else:
                    self._now.errors.pop(topic, None)
                self._now.estimate[robot] = pose
                self._track(robot, "estimate", pose)
                if covariance is not None:
                    self._now.covariance[robot] = covariance
                if cloud is not None:
                    self._now.particles = cloud
                if not self._zoom_heard:
                    self._replay_zoom(pose, stamp)

        return take

    def _track(self, robot: str, kind: str, pose: Pose) -> None:
        self._tracks.setdefault((robot, kind), collections.deque(maxlen=TRACK)).append((pose[0], pose[1]))

    def _head(self, robot: str) -> Callable[[str, Any, float], None]:
        def take(_: str, value: Any, __: float) -> None:
            pan = number(value.get("pan")) if isinstance(value, Mapping) else None
            if pan is not None:
                with self._lock:
                    self._now.head[robot] = pan

        return take

    def _replay_zoom(self, pose: Pose, stamp: float) -> None:
        settings, area = self.settings, self._now.zoom
        if settings is None:
            return
        if area is not None:
            margin_x, margin_y = area.width / 2 - abs(pose[0] - area.x), area.depth / 2 - abs(pose[1] - area.y)
            border = margin_x < settings.border * area.width or margin_y < settings.border * area.depth
            if not border and stamp - self._zoom_stamp < settings.timeout:
                return
        self._zoom_stamp = stamp
        self._now.zoom = Zoom(pose[0], pose[1], settings.width, settings.depth, True)

    def _objects(self, topic: str, value: Any, _: float) -> None:
        seen = objects_of(value, topic)
        with self._lock:
            self._by_topic[topic] = (self.clock(), seen)  # each topic's newest result replaces its last one

    def _image(self, topic: str, value: Any, _: float) -> None:
        if isinstance(value, Mapping):
            with self._lock:
                count = self._frames[topic] = self._frames.get(topic, 0) + 1
                self._now.images[topic] = (count, value)

    def _zoom(self, topic: str, value: Any, __: float) -> None:
        try:
            x, y, width, depth = zoom_of(value)
        except FeedError as exc:
            self._refuse(topic, exc)
            return
        reason = value.get("reason")
        objects = value.get("objects")
        area = Zoom(x, y, width, depth, False, reason if isinstance(reason, str) else "",
                    len(objects) if isinstance(objects, list | tuple) else None)  # fmt: skip
        with self._lock:
            self._now.zoom, self._zoom_heard = area, True
            self._now.errors.pop(topic, None)

    def _particles(self, topic: str, value: Any, __: float) -> None:
        try:
            cloud = particles_of(value)
            if cloud is None:
                raise FeedError("a particle cloud needs x and y arrays (or N rows of x, y)")
        except FeedError as exc:
            self._refuse(topic, exc)
            return
        with self._lock:
            self._now.particles = cloud
            self._now.errors.pop(topic, None)

    def _refuse(self, topic: str, error: FeedError) -> None:
        """A message not drawn: its reason is the topic's error until a good one arrives."""
        with self._lock:
            self._now.errors[topic] = str(error)

    def snapshot(self) -> Snapshot:
        """A copy of the newest values (the arrays and payloads are shared: they are never changed)."""
        moment = self.clock()
        with self._lock:
            now = self._now
            now.objects = [
                s
                for t, (arrived, seen) in sorted(self._by_topic.items())
                if moment - arrived <= self.feeds.lifespans.get(t, math.inf)  # a result past its lifespan is gone
                for s in seen
            ]
            tracks = {key: list(points) for key, points in self._tracks.items()}
            return Snapshot(dict(now.truth), dict(now.estimate), dict(now.covariance), dict(now.head), tracks,
                            now.particles, now.zoom, list(now.objects), dict(now.images), dict(now.errors))  # fmt: skip
