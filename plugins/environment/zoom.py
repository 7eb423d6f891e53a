"""The Zoom Map (thesis §6.1.3, Fig. 6.3, eq. 6.1–6.3; §7.4.1, Fig. 7.16).

An area of interest around the robot: only the objects inside it are managed, so the cost of a
perception update depends on the objects in the area (``ne'``), not on the whole map (``ne``).

- **2D / 2.5D** (Fig. 6.3). A 2D area holds every object whose floor projection meets the
  ``width × depth`` rectangle; a 2.5D area is the box ``width × depth × height`` standing on the
  floor and holds only the objects whose height range meets ``[0, height]`` (a ceiling lamp above
  a 2 m box is left out). 2D objects have no height and are in both.
- **Re-centring.** The area is centred on the robot when it is created, when the robot comes
  closer to its border than ``border`` × its size along that axis (10 % in §7.4.1), and when
  ``timeout`` seconds have passed since the last move.
- **Size from density.** With ``max_objects``, every move starts from ``width × depth`` and
  shrinks the area, keeping its proportions, by ``sqrt(max / found)`` until it holds at most
  ``max_objects`` objects; if it still holds more after a few rounds (a cluster at the robot), it
  keeps the ``max_objects`` nearest. The number of managed objects, hence the worst-case
  management time, is then bounded whatever the map.

A move costs one STRtree query over the map (the ``t_m'`` of eq. 6.2); every perception update
between moves costs ``np × ne'`` comparisons (``t'_i``) instead of ``np × ne`` (``t_i``, eq. 6.1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import box
from shapely.geometry.base import BaseGeometry

from ckmconf.model.environment import ZoomMap as ZoomRecord

from .map_model import MapModel, MapObject
from .perception import manage

SHRINK_ROUNDS = 8


@dataclass(frozen=True)
class ZoomSettings:
    """The ``<ZoomMap>`` settings (§6.1.3); ``height`` is the map height when the record omits it."""

    mode: str = "2D"
    width: float = 4.0
    depth: float = 4.0
    height: float = 3.0
    border: float = 0.1
    timeout: float = 10.0
    max_objects: int | None = None

    @classmethod
    def from_record(cls, record: ZoomRecord, map_height: float) -> ZoomSettings:
        """The settings of a ``<ZoomMap>`` record (environment.xsd ``ZoomMapType``); ``map_height``: the ``<Map>``'s."""
        height = record.height if record.height is not None else map_height
        return cls(record.mode, record.width, record.depth, height, record.border, record.timeout, record.max_objects)


@dataclass(frozen=True)
class Recentring:
    """One move of the area (Fig. 7.16): when, why, where, how large and how many objects it took."""

    time: float
    reason: str  # start, border or timeout
    x: float
    y: float
    width: float
    depth: float
    objects: int

    @property
    def area(self) -> BaseGeometry:
        """The floor rectangle the area covered after this move (map frame)."""
        return box(self.x - self.width / 2, self.y - self.depth / 2, self.x + self.width / 2, self.y + self.depth / 2)


class ZoomMap:
    """The area of interest over a :class:`MapModel` (§6.1.3)."""

    def __init__(self, model: MapModel, settings: ZoomSettings) -> None:
        if settings.mode not in ("2D", "2.5D"):
            raise ValueError(f"zoom mode must be 2D or 2.5D, not {settings.mode!r}")
        self.model = model
        self.settings = settings
        self.history: list[Recentring] = []
        self.rows = np.zeros(0, dtype=np.int64)
        self._area: BaseGeometry | None = None

    @classmethod
    def of(cls, model: MapModel, record: ZoomRecord) -> ZoomMap:
        """The zoom map an ``<Environment>``'s ``<ZoomMap>`` describes."""
        return cls(model, ZoomSettings.from_record(record, model.height))

    @property
    def current(self) -> Recentring | None:
        """The area's last move (Fig. 7.16), or None before the first update."""
        return self.history[-1] if self.history else None

    @property
    def area(self) -> BaseGeometry | None:
        """The current area's floor rectangle (None before the first update)."""
        return self._area

    @property
    def objects(self) -> list[MapObject]:
        """The managed objects (those in the area)."""
        return [self.model.objects[self.model.names[row]] for row in self.rows.tolist()]

    def avoided(self) -> list[str]:
        """The avoided areas meeting the area of interest."""
        area = self._area
        return [] if area is None else sorted(n for n, g in self.model.avoided.items() if g.intersects(area))

    def trigger(self, x: float, y: float, now: float) -> str | None:
        """Why the area must move for a robot at ``(x, y)`` at ``now``, or None."""
        current = self.current
        if current is None:
            return "start"
        if now - current.time >= self.settings.timeout:
            return "timeout"
        margin_x = current.width / 2 - abs(x - current.x)
        margin_y = current.depth / 2 - abs(y - current.y)
        if margin_x < self.settings.border * current.width or margin_y < self.settings.border * current.depth:
            return "border"
        return None

    def update(self, x: float, y: float, now: float) -> str | None:
        """Move the area if :meth:`trigger` says so; returns the reason when it moved."""
        reason = self.trigger(x, y, now)
        if reason is not None:
            self.recentre(x, y, now, reason)
        return reason

    def _select(self, x: float, y: float, width: float, depth: float) -> np.ndarray:
        """Rows of the objects in the area centred at ``(x, y)``: an STRtree query, the 2.5D height test."""
        rows = self.model.candidate_rows(box(x - width / 2, y - depth / 2, x + width / 2, y + depth / 2))
        if self.settings.mode == "2D" or len(rows) == 0:
            return rows
        z = self.model.z_ranges[rows]
        kept: np.ndarray = rows[(z[:, 0] < self.settings.height) & (z[:, 1] >= 0)]  # >=: a marking on the floor
        return kept

    def recentre(self, x: float, y: float, now: float, reason: str = "start") -> Recentring:
        """Centre the area on ``(x, y)``, sized from the objects' density (``max_objects``)."""
        width, depth, bound = self.settings.width, self.settings.depth, self.settings.max_objects
        found = self._select(x, y, width, depth)
        for _ in range(SHRINK_ROUNDS):
            if bound is None or len(found) <= bound:
                break
            scale = math.sqrt(bound / len(found)) * 0.97
            width, depth = width * scale, depth * scale
            found = self._select(x, y, width, depth)
        if bound is not None and len(found) > bound:
            offsets = self.model.xy[found] - (x, y)
            order = np.lexsort((found, np.hypot(offsets[:, 0], offsets[:, 1])))
            found = np.sort(found[order[:bound]])
        self.rows = found.astype(np.int64)
        self._area = box(x - width / 2, y - depth / 2, x + width / 2, y + depth / 2)
        move = Recentring(now, reason, x, y, width, depth, len(found))
        self.history.append(move)
        return move

    def manage(self, perceptions: np.ndarray, *, stamp: float, gate: float = 0.3, **options: object) -> dict[str, int]:
        """One perception update against the managed objects only (the t'_i of eq. 6.2).

        Perceptions outside the area are out of attention: counted as ``outside`` and not applied
        (they would otherwise be taken for new objects). New objects inside the area join it, as
        long as the bound allows.
        """
        before = len(self.model)
        inside = np.ones(len(perceptions), dtype=bool)
        if self._area is not None and len(perceptions):
            xmin, ymin, xmax, ymax = self._area.bounds  # the area is an axis-aligned rectangle
            x, y = perceptions[:, 0], perceptions[:, 1]
            inside = (x >= xmin) & (x <= xmax) & (y >= ymin) & (y <= ymax)
        counts = manage(self.model, perceptions[inside], stamp=stamp, rows=self.rows, gate=gate, **options)  # type: ignore[arg-type]
        counts["outside"] = int(len(perceptions) - inside.sum())
        if len(self.model) > before and self._area is not None:
            bound = self.settings.max_objects
            new_rows = np.arange(before, len(self.model))
            inside_now = self.model.candidate_rows(self._area)
            if self.settings.mode == "2.5D":
                z = self.model.z_ranges[inside_now]
                inside_now = inside_now[(z[:, 0] < self.settings.height) & (z[:, 1] > 0)]
            joining = np.intersect1d(new_rows, inside_now).tolist()
            room = len(joining) if bound is None else max(0, bound - len(self.rows))
            self.rows = np.concatenate([self.rows, np.array(joining[:room], dtype=np.int64)])
        return counts
