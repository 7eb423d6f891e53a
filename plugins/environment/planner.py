"""Path planning on the map model for a round or rectangular robot (thesis §6.1.2, §7.4).

A grid A* over networkx: the map is cut into square cells of ``resolution`` metres; a cell is
free when its centre is farther than ``r + margin`` from every obstacle, where ``r`` is the
footprint's bounding radius (a rectangle is inflated by its circumscribed circle, so the plan
holds for any heading) and ``margin`` is ``0.75 × resolution``, enough for the straight edge
between two free neighbouring cells (at most ``resolution × √2`` long) to stay clear of the
obstacles inflated by ``r``. The obstacles are the avoided areas, the map's outer edge and the
objects (static ones unless asked) whose parts start below the robot's height.

A* (``networkx.astar_path``, 8-connected, Euclidean heuristic) finds the cell path; the start
and goal are joined to their nearest free cells by straight segments checked exactly. The path
is then smoothed by string pulling: from each kept point, the farthest later point reachable by
a straight segment clear of the inflated obstacles (an exact shapely test) is kept next.

An unreachable goal raises :class:`Unreachable`, naming the start, the goal and why (the start
or the goal collides with a named obstacle, is outside the map, or no free path joins them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import networkx as nx  # type: ignore[import-untyped]
import numpy as np
import shapely
from shapely.geometry import LineString, Point
from shapely.ops import unary_union
from shapely.prepared import prep

from .geometry import Footprint
from .map_model import MapModel

Waypoint = tuple[float, float]
QUAD_SEGS = 8


class Unreachable(ValueError):
    """The planner cannot reach the goal; the message names the start, the goal and the reason."""

    def __init__(self, start: Waypoint, goal: Waypoint, reason: str) -> None:
        super().__init__(f"no path from ({start[0]:g}, {start[1]:g}) to ({goal[0]:g}, {goal[1]:g}): {reason}")
        self.start, self.goal, self.reason = start, goal, reason


@dataclass(frozen=True)
class Plan:
    """A planned path: the smoothed waypoints, the raw grid path and its length (m)."""

    waypoints: list[Waypoint]
    grid_path: list[Waypoint]

    @property
    def length(self) -> float:
        """The length (m) of the smoothed path: the sum of its straight segments."""
        return float(sum(math.dist(a, b) for a, b in zip(self.waypoints, self.waypoints[1:], strict=False)))


class Planner:
    """Grid A* planner for one footprint on one map (the obstacles are read at construction)."""

    def __init__(
        self,
        model: MapModel,
        footprint: Footprint,
        *,
        resolution: float = 0.1,
        include_mobile: bool = False,
    ) -> None:
        if not resolution > 0:
            raise ValueError(f"resolution must be positive, got {resolution}")
        self.model, self.footprint, self.resolution = model, footprint, resolution
        self.radius = footprint.bounding_radius
        self.named = model.obstacles(footprint, include_mobile=include_mobile)
        xmin, ymin, xmax, ymax = model.bounds
        outside = model.outline.buffer(max(xmax - xmin, ymax - ymin)).difference(model.outline)
        # A buffer is a polygon inscribed in the true rounded outline: grow it so it circumscribes it.
        grown = self.radius / math.cos(math.pi / (4 * QUAD_SEGS))
        self.inflated = unary_union([*self.named.values(), outside]).buffer(grown, quad_segs=QUAD_SEGS)
        self._clear = prep(self.inflated)
        margin = self.radius + 0.75 * resolution
        self.xs = np.arange(xmin + resolution / 2, xmax, resolution)
        self.ys = np.arange(ymin + resolution / 2, ymax, resolution)
        grid_x, grid_y = np.meshgrid(self.xs, self.ys, indexing="ij")
        blocked = unary_union([*self.named.values(), outside]).buffer(margin, quad_segs=QUAD_SEGS)
        self.free = ~shapely.contains_xy(blocked, grid_x, grid_y) & ~shapely.intersects_xy(blocked, grid_x, grid_y)
        self.graph = self._graph()

    def _graph(self) -> nx.Graph:
        """8-connected graph of the free cells, edges weighted by their length."""
        graph = nx.Graph()
        free = self.free
        count_x, count_y = free.shape
        graph.add_nodes_from(map(tuple, np.argwhere(free).tolist()))
        diagonal = math.sqrt(2) * self.resolution
        for di, dj, weight in ((1, 0, self.resolution), (0, 1, self.resolution), (1, 1, diagonal), (1, -1, diagonal)):
            j0, j1 = max(0, -dj), count_y - max(0, dj)
            both = free[: count_x - di, j0:j1] & free[di:, j0 + dj : j1 + dj]
            starts = np.argwhere(both) + np.array([0, j0])
            graph.add_weighted_edges_from(((i, j), (i + di, j + dj), weight) for i, j in starts.tolist())
        return graph

    def point(self, cell: tuple[int, int]) -> Waypoint:
        """The map coordinates (m) of the centre of grid cell ``cell`` (its index along x, then along y)."""
        return float(self.xs[cell[0]]), float(self.ys[cell[1]])

    def clear(self, a: Waypoint, b: Waypoint) -> bool:
        """Whether the robot can go straight from ``a`` to ``b`` (exact test on the inflated obstacles)."""
        path = LineString([a, b]) if a != b else Point(a)
        return not self._clear.intersects(path)

    def _blocker(self, where: Waypoint) -> str | None:
        point = Point(where)
        hits = [name for name, g in self.named.items() if g.distance(point) < self.radius]
        if not self.model.outline.contains(point) or self.model.outline.exterior.distance(point) < self.radius:
            hits.append("map bounds")
        return ", ".join(repr(h) for h in hits) if hits else None

    def _entry(self, where: Waypoint) -> tuple[int, int] | None:
        """The nearest free cell joined to ``where`` by a clear straight segment (searching outwards)."""
        i = int(np.clip(np.searchsorted(self.xs, where[0]), 0, len(self.xs) - 1))
        j = int(np.clip(np.searchsorted(self.ys, where[1]), 0, len(self.ys) - 1))
        for reach in range(1, 6):
            window = [
                (a, b)
                for a in range(max(0, i - reach), min(len(self.xs), i + reach + 1))
                for b in range(max(0, j - reach), min(len(self.ys), j + reach + 1))
                if self.free[a, b]
            ]
            window.sort(key=lambda c: (math.dist(self.point(c), where), c))
            for cell in window:
                if self.clear(where, self.point(cell)):
                    return cell
        return None

    def plan(self, start: Sequence[float], goal: Sequence[float]) -> Plan:
        """A smoothed collision-free path from ``start`` to ``goal`` (``(x, y)`` in the map frame)."""
        a, b = (float(start[0]), float(start[1])), (float(goal[0]), float(goal[1]))
        for label, where in (("start", a), ("goal", b)):
            blocker = self._blocker(where)
            if blocker is not None:
                raise Unreachable(a, b, f"the {label} collides with {blocker} (footprint radius {self.radius:g} m)")
        if self.clear(a, b):
            return Plan([a, b], [a, b])
        first, last = self._entry(a), self._entry(b)
        if first is None or last is None:
            label = "start" if first is None else "goal"
            raise Unreachable(a, b, f"the {label} is boxed in: no free cell around it at {self.resolution:g} m")
        try:
            cells = nx.astar_path(
                self.graph, first, last, heuristic=lambda u, v: math.dist(self.point(u), self.point(v)), weight="weight"
            )
        except nx.NetworkXNoPath:
            raise Unreachable(a, b, "the goal's free space is not connected to the start's (walled off)") from None
        raw = [a, *map(self.point, cells), b]
        return Plan(self.smooth(raw), raw)

    def smooth(self, path: list[Waypoint]) -> list[Waypoint]:
        """String pulling: keep a point only when the straight way past it is blocked."""
        kept, index = [path[0]], 0
        while index < len(path) - 1:
            nxt = index + 1
            for later in range(len(path) - 1, index + 1, -1):
                if self.clear(path[index], path[later]):
                    nxt = later
                    break
            kept.append(path[nxt])
            index = nxt
        return kept

    def check(self, waypoints: Sequence[Waypoint]) -> list[str]:
        """The obstacles a path's swept footprint meets (empty for a valid plan): used by tests and callers."""
        line = LineString(waypoints) if len(waypoints) > 1 else Point(waypoints[0])
        hits = [name for name, g in self.named.items() if g.distance(line) < self.radius]
        if not self.model.outline.contains(line) or self.model.outline.exterior.distance(line) < self.radius:
            hits.append("map bounds")
        return hits
