"""Routes of the Navigation service on the Environment's map (thesis §6.1.2, §7.4; decision D107).

:class:`Routes` wraps the A* planner of plugins/environment/planner.py for one footprint:

- a start inside the inflated obstacles (the robot stood close to the workbench after APPR), or on
  their edge with no straight way out (D210), is
  left by the nearest free A* cell within ``escape`` metres, the robot's position prepended; a
  goal inside them (a pose short of an object on a table) is replaced by the nearest free cell
  within ``goal_escape`` metres, so only a goal deeper in (or walled off) is unreachable;
- scan hits on the path (an obstacle the map does not hold) join the map as avoided areas
  ("scan obstacle N"): :meth:`Routes.avoid` rebuilds the planner with them; :meth:`Routes.forget`
  drops those later scans see through or do not see again (plugins/navigation/obstacles.py, D152)
  and rebuilds it without them; a new goal forgets them all.

:func:`blocking` finds those hits: scan endpoints within ``radius`` of the next ``lookahead``
metres of the path. The map's own obstacles are at least the inflated radius from any planned
path, so only unknown ones (or a localization error larger than the inflation) come that close.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from ckmconf.model.environment import AvoidedArea, Environment, Vertex
from plugins.environment.geometry import Footprint
from plugins.environment.map_model import MapModel
from plugins.environment.planner import Planner, Unreachable

from .frames import Point, Pose
from .obstacles import ScanObstacles

ESCAPE_TRIES = 20
"""Free cells (nearest first) tried as the way out of an inflated obstacle."""


class Routes:
    """A* routes for ``footprint`` on ``env``, with the obstacles scans added since the last reset."""

    def __init__(
        self, env: Environment, footprint: Footprint, resolution: float, escape: float, goal_escape: float = 0.0,
        obstacles: ScanObstacles | None = None,
    ) -> None:
        self.env, self.footprint, self.resolution, self.escape = env, footprint, resolution, escape
        self.goal_escape = goal_escape
        self.model = MapModel.from_environment(env)
        self.static = self.planner = Planner(self.model, footprint, resolution=resolution)
        self.obstacles = ScanObstacles() if obstacles is None else obstacles
        self.extra: list[AvoidedArea] = []
        """The scan obstacles as the planner's avoided areas (rebuilt when they change)."""
        self.excluded: str | None = None
        """The map object the goal is at, left out of the obstacles (:meth:`aim_at`)."""
        self.planned_env = env

    def aim_at(self, name: str | None) -> None:
        """Plan with the map object ``name`` (an object goal's) left out of the obstacles; None: with all."""
        if name == self.excluded:
            return
        self.excluded = name
        self.planned_env = self.env if name is None else dataclasses.replace(
            self.env, objects=tuple(o for o in self.env.objects if o.name != name))
        self.static = Planner(MapModel.from_environment(self.planned_env), self.footprint, resolution=self.resolution)
        self._rebuild()

    def reset(self) -> None:
        """Forget the obstacles scans added (a new goal)."""
        self.obstacles.clear()
        self.extra, self.planner = [], self.static

    def plan(self, here: Point, goal: Point) -> list[Point]:
        """Waypoints from ``here`` to ``goal`` (or the nearest free point within ``goal_escape`` of a goal
        inside an obstacle's inflation); :class:`Unreachable` naming why when there are none."""
        try:
            return self._from(here, goal)
        except Unreachable as refused:
            if not _stuck(refused, "goal") or not self.goal_escape > 0:
                raise
            for near in self._free_near(goal, self.goal_escape):
                try:
                    return self._from(here, near)
                except Unreachable:
                    continue
            raise

    def _from(self, here: Point, goal: Point) -> list[Point]:
        """A plan, leaving a start inside an inflated obstacle by the nearest free cell within ``escape``."""
        try:
            return list(self.planner.plan(here, goal).waypoints)
        except Unreachable as refused:
            if not _stuck(refused, "start") or not self.escape > 0:
                raise
            for exit_point in self._free_near(here, self.escape):
                try:
                    return [here, *self.planner.plan(exit_point, goal).waypoints]
                except Unreachable as again:
                    if _stuck(again, "goal"):  # for plan()'s goal escape: both ends move
                        raise again from None
                    continue
            raise

    def _free_near(self, where: Point, reach: float) -> list[Point]:
        """The free A* cells within ``reach`` of ``where``, nearest first (at most ``ESCAPE_TRIES``)."""
        planner = self.planner
        cells = np.argwhere(planner.free)
        xy = np.stack([planner.xs[cells[:, 0]], planner.ys[cells[:, 1]]], axis=1)
        near = np.hypot(xy[:, 0] - where[0], xy[:, 1] - where[1])
        order = [k for k in np.argsort(near)[:ESCAPE_TRIES] if near[k] <= reach]
        return [(float(xy[k, 0]), float(xy[k, 1])) for k in order]

    def avoid(self, points: Sequence[Point], now: float = 0.0) -> None:
        """Plan around ``points`` (seen at ``now``) from now on: they join the map as avoided areas
        (``merge``, 5 cm, around each)."""
        self.obstacles.add(points, now)
        self._rebuild()

    def forget(self, scan: Mapping[str, Any], laser: Pose, hits: npt.NDArray[np.float64], now: float) -> int:
        """Drop the scan obstacles ``scan`` (from the laser's map pose ``laser``, endpoints ``hits``)
        sees through or that went unseen too long (D152); how many points went (the planner rebuilt)."""
        gone = self.obstacles.update(scan, laser, hits, now)
        if gone:
            self._rebuild()
        return gone

    def areas(self) -> dict[str, Any]:
        """The scan obstacles (for a plugin's state)."""
        return self.obstacles.state()

    def restore(self, state: Mapping[str, Any]) -> None:
        """The scan obstacles of :meth:`areas`, planned around again."""
        self.obstacles.restore(state)
        self._rebuild()

    def _rebuild(self) -> None:
        self.extra = [
            AvoidedArea(name=f"scan obstacle {i + 1}",
                        vertices=tuple(Vertex(x=float(x), y=float(y)) for x, y in list(part.exterior.coords)[:-1]))
            for i, part in enumerate(self.obstacles.shapes())
        ]
        if not self.extra:
            self.planner = self.static
            return
        env = dataclasses.replace(self.planned_env, avoided=self.planned_env.avoided + tuple(self.extra))
        self.planner = Planner(MapModel.from_environment(env), self.footprint, resolution=self.resolution)


def _stuck(refused: Unreachable, end: str) -> bool:
    """Whether the planner refused because ``end`` ("start" or "goal") is inside an obstacle's inflation
    or on its very edge, where every straight way out grazes it ("boxed in": a robot that stopped
    exactly at the footprint's distance from a table, D210)."""
    return f"the {end} collides" in refused.reason or f"the {end} is boxed in" in refused.reason


def blocking(
    plan: Sequence[Point], segment: int, near: Point, hits: npt.NDArray[np.float64], radius: float,
    lookahead: float, count: int,
) -> list[Point]:
    """The ``hits`` (k, 2) within ``radius`` of the path ahead of ``near`` (on ``segment``), if at least ``count``.

    The path ahead runs from ``near`` through the next waypoints until it is ``lookahead`` long
    (the waypoint that crosses it included: a leg is checked whole).
    """
    if not len(hits):
        return []
    ahead, left = [near], lookahead
    for point in plan[segment + 1 :]:
        left -= math.dist(ahead[-1], point)
        ahead.append(point)
        if left <= 0:
            break
    line = shapely.LineString(ahead) if len(ahead) > 1 else shapely.Point(ahead[0])
    close = hits[shapely.distance(line, shapely.points(hits)) < radius]
    return [(float(x), float(y)) for x, y in close] if len(close) >= count else []
