"""A tour of goal positions with the zoom map following the robot (thesis §7.4.1, Fig. 7.16).

The experiment of §7.4.1: the robot reaches a group of goal positions in sequence while the area
of interest is moved whenever the robot comes within 10 % of its border (or on time-out). Here
the path between goals comes from the :class:`~plugins.environment.planner.Planner`, the robot
follows it at a constant speed, and every perception period the zoom map is updated; the result
holds the driven positions and every move of the area, and :func:`draw_tour` draws Fig. 7.16.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from plugins.environment.geometry import Footprint
from plugins.environment.map_model import MapModel
from plugins.environment.planner import Planner
from plugins.environment.zoom import Recentring, ZoomMap

TURTLEBOT = Footprint.round(0.18, height=0.45)
"""A Turtlebot 2 base: 0.354 m across, about 0.42 m tall with its sensors."""
LAB_GOALS = [(1.6, 1.0), (5.0, 2.6), (8.0, 5.3), (5.5, 4.0), (2.0, 5.4), (8.6, 3.0), (1.6, 1.0)]
"""Goal positions through the use-case lab (configs/usecase/environment.xml), start first."""


@dataclass
class Tour:
    """What a tour produced: the driven positions, the planned legs and the zoom map's moves."""

    positions: list[tuple[float, float]] = field(default_factory=list)
    legs: list[list[tuple[float, float]]] = field(default_factory=list)
    moves: list[Recentring] = field(default_factory=list)


def drive(
    model: MapModel,
    zoom: ZoomMap,
    goals: Sequence[tuple[float, float]],
    *,
    footprint: Footprint = TURTLEBOT,
    speed: float = 0.3,
    period: float = 0.1,
) -> Tour:
    """Plan and follow the legs between consecutive goals, updating ``zoom`` every ``period`` s."""
    planner = Planner(model, footprint)
    tour = Tour()
    now = 0.0
    for start, goal in itertools.pairwise(goals):
        waypoints = planner.plan(start, goal).waypoints
        tour.legs.append(waypoints)
        for a, b in itertools.pairwise(waypoints):
            steps = max(1, math.ceil(math.dist(a, b) / (speed * period)))
            for k in range(steps):
                x, y = a[0] + (b[0] - a[0]) * k / steps, a[1] + (b[1] - a[1]) * k / steps
                zoom.update(x, y, now)
                tour.positions.append((x, y))
                now += period
    tour.positions.append(tuple(goals[-1]))  # type: ignore[arg-type]
    tour.moves = list(zoom.history)
    return tour


def draw_tour(model: MapModel, tour: Tour, goals: Sequence[tuple[float, float]], path: Path) -> None:
    """Fig. 7.16: the map, the trajectory, the goals and the successive areas of interest (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon as PatchPolygon
    from matplotlib.patches import Rectangle

    xmin, ymin, xmax, ymax = model.bounds
    figure, axes = plt.subplots(figsize=(10, 10 * (ymax - ymin) / (xmax - xmin) + 0.8))
    axes.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, linewidth=2, color="black"))
    for name, area in model.avoided.items():
        axes.add_patch(PatchPolygon(np.asarray(area.exterior.coords), color="dimgray", label=None))
        axes.annotate(name, area.centroid.coords[0], fontsize=6, ha="center", color="white")
    for obj in model.objects.values():
        for part in getattr(obj.shape, "geoms", [obj.shape]):
            if hasattr(part, "exterior"):
                axes.add_patch(PatchPolygon(np.asarray(part.exterior.coords), color="peru", alpha=0.7))
    colours = plt.get_cmap("tab10")
    for index, move in enumerate(tour.moves):
        colour = colours(index % 10)
        corner = (move.x - move.width / 2, move.y - move.depth / 2)
        axes.add_patch(Rectangle(corner, move.width, move.depth, fill=False, linestyle="--", color=colour))
        axes.annotate(f"{index + 1} ({move.reason})", corner, fontsize=7, color=colour, va="bottom")
    driven = np.asarray(tour.positions)
    axes.plot(driven[:, 0], driven[:, 1], color="navy", linewidth=1.5, label="trajectory")
    marks = np.asarray(goals)
    axes.plot(marks[:, 0], marks[:, 1], "r*", markersize=12, label="goals")
    axes.set_xlim(xmin - 2.5, xmax + 2.5)
    axes.set_ylim(ymin - 2.5, ymax + 2.5)
    axes.set_aspect("equal")
    axes.set_title(f"Zoom map areas along the trajectory ({len(tour.moves)} areas, Fig. 7.16)")
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    axes.legend(loc="upper right", fontsize=8)
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
