"""Obstacles the Navigation service learnt from its scans, and how it forgets them (thesis §6.1.1, §7.4; D107, D152).

Scan hits on the path ahead that the map does not explain become obstacles of the plan (D107).
A person or a chair that moves away must not block the way for ever, so :class:`ScanObstacles`
keeps each hit point with the time it was last seen and forgets it (decision D152):

- **seen through** — a later beam aimed at the point (the scan's beam nearest its bearing from
  the laser, passing within ``merge`` of it) reaches more than ``margin`` beyond it, or returns
  nothing (free up to the range maximum): the space is free now, the point goes at once. Beams that
  stop short of the point (something nearer hides it), too-close or unusable readings (REP 117
  −inf, NaN) and points outside the field of view say nothing;
- **not seen again** — no scan hit within ``merge`` of the point for ``timeout`` seconds (it is
  out of view, e.g. behind the robot): it goes too; ``timeout`` 0 keeps such points.

A still standing obstacle is not seen through: the beam aimed at a point of its surface stops on
it (or on its near side, seen from elsewhere), and its hits keep refreshing the points in view.

The plan keeps ``clearance`` more from these points than from the map's obstacles (D238): they show
only the faces the laser saw (a corner lies up to a beam's spacing beyond the last hit), and they
are placed with the localization's few centimetres of error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from shapely.geometry import MultiPoint, Polygon

from .frames import Point, Pose
from .laser_scan import NO_RETURN

Array = npt.NDArray[np.float64]


class ScanObstacles:
    """Hit points (map frame) with the time each was last seen; cleared by ray casting or a time-out."""

    def __init__(self, merge: float = 0.05, margin: float = 0.1, timeout: float = 30.0, clearance: float = 0.0) -> None:
        if not merge > 0 or margin < 0 or timeout < 0 or clearance < 0:
            raise ValueError(f"scan obstacles: merge {merge} must be > 0, margin {margin}, timeout {timeout} and "
                             f"clearance {clearance} >= 0")
        self.merge, self.margin, self.timeout, self.clearance = merge, margin, timeout, clearance
        self.points: Array = np.zeros((0, 2))
        self.seen: Array = np.zeros(0)

    def __len__(self) -> int:
        return len(self.points)

    def clear(self) -> None:
        """Forget every point."""
        self.points, self.seen = np.zeros((0, 2)), np.zeros(0)

    def add(self, points: Sequence[Point], now: float) -> None:
        """Remember ``points`` as seen at ``now``."""
        if len(points):
            self.points = np.concatenate([self.points, np.asarray(points, dtype=np.float64).reshape(-1, 2)])
            self.seen = np.concatenate([self.seen, np.full(len(points), float(now))])

    def update(self, scan: Mapping[str, Any], laser: Pose, hits: Array, now: float) -> int:
        """Refresh the points near ``hits`` (the scan's endpoints, map frame), then drop those this scan
        (taken from ``laser``, the laser's map-frame pose) sees through and those unseen for ``timeout``;
        returns how many went."""
        if not len(self.points):
            return 0
        if len(hits):
            near = np.min(np.hypot(*(self.points[:, None, :] - hits[None, :, :]).transpose(2, 0, 1)), axis=1)
            self.seen[near <= self.merge] = float(now)
        gone = self._seen_through(scan, laser)
        if self.timeout > 0:
            gone |= now - self.seen > self.timeout
        if gone.any():
            self.points, self.seen = self.points[~gone], self.seen[~gone]
        return int(gone.sum())

    def _seen_through(self, scan: Mapping[str, Any], laser: Pose) -> npt.NDArray[np.bool_]:
        """Per point: does the beam aimed at it reach farther than it (free space where it was)?"""
        ranges = np.asarray(scan["ranges"], dtype=np.float64)
        start, step = float(scan["angle_min"]), float(scan["angle_increment"])
        lo, hi = float(scan["range_min"]), float(scan["range_max"])
        dx, dy = self.points[:, 0] - laser[0], self.points[:, 1] - laser[1]
        distance = np.hypot(dx, dy)
        bearing = np.arctan2(dy, dx) - laser[2]
        bearing = (bearing - start + math.pi) % (2 * math.pi) - math.pi + start  # nearest turn to the sweep's start
        index = np.rint((bearing - start) / step).astype(np.int64)
        inside = (index >= 0) & (index < ranges.size)
        index = np.clip(index, 0, ranges.size - 1)
        r = ranges[index]
        aimed = inside & (distance * np.abs(bearing - (start + step * index)) <= self.merge) & (distance > lo)
        with np.errstate(invalid="ignore"):
            beyond = np.isfinite(r) & (r >= lo) & (r < hi - NO_RETURN) & (r > distance + self.margin)
            nothing = (np.isposinf(r) | (np.isfinite(r) & (r >= hi - NO_RETURN))) & (distance < hi - self.margin)
        result: npt.NDArray[np.bool_] = aimed & (beyond | nothing)
        return result

    def shapes(self) -> list[Polygon]:
        """The points as polygons (``merge`` + ``clearance`` around each, touching ones merged): avoided areas
        for the planner."""
        if not len(self.points):
            return []
        blob = MultiPoint([tuple(p) for p in self.points]).buffer(self.merge + self.clearance, quad_segs=4)
        parts = [blob] if isinstance(blob, Polygon) else list(getattr(blob, "geoms", []))
        return [g for g in parts if isinstance(g, Polygon)]

    def state(self) -> dict[str, Any]:
        """The points and their times (codec-able)."""
        return {"points": self.points.tolist(), "seen": self.seen.tolist()}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Go on from :meth:`state`; ValueError if it is not one."""
        points = np.asarray(state["points"], dtype=np.float64).reshape(-1, 2)
        seen = np.asarray(state["seen"], dtype=np.float64).reshape(-1)
        if len(points) != len(seen):
            raise ValueError(f"{len(points)} obstacle points but {len(seen)} times")
        self.points, self.seen = points, seen
