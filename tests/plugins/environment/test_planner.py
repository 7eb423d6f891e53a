"""Path planning (grid A* over networkx, footprint inflation, smoothing) with known answers."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import shapely
from shapely.geometry import LineString, box

from benchmarks.zoom_tour import LAB_GOALS
from plugins.environment.geometry import Footprint
from plugins.environment.map_model import MapModel, small_object
from plugins.environment.planner import Planner, Unreachable
from plugins.environment.semantics import SemanticDictionary

ROUND = Footprint.round(0.18, height=0.45)
RECTANGLE = Footprint.rectangle(0.5, 0.36, height=0.45)


def assert_avoids_everything(model: MapModel, footprint: Footprint, waypoints: list[tuple[float, float]]) -> None:
    """Independent check with shapely: the swept footprint stays in the map and off every obstacle."""
    path, radius = LineString(waypoints), footprint.bounding_radius
    assert model.outline.contains(path) and model.outline.exterior.distance(path) >= radius
    for name, area in model.avoided.items():
        assert path.distance(area) >= radius, f"the path comes within {path.distance(area):.4f} m of {name}"
    for obj in model.objects.values():
        if model.semantics.is_mobile(obj.tag):
            continue
        obstacle = obj.obstacle(footprint.height)
        assert obstacle is None or path.distance(obstacle) >= radius, f"the path hits {obj.name}"


@pytest.mark.parametrize("footprint", [ROUND, RECTANGLE], ids=["round", "rectangle"])
def test_paths_through_the_lab_avoid_every_avoided_area_and_object(lab: MapModel, footprint: Footprint) -> None:
    planner = Planner(lab, footprint)
    for start, goal in itertools.pairwise(LAB_GOALS):
        plan = planner.plan(start, goal)
        assert plan.waypoints[0] == start and plan.waypoints[-1] == goal
        assert planner.check(plan.waypoints) == [] and planner.check(plan.grid_path) == []
        assert_avoids_everything(lab, footprint, plan.waypoints)
        # smoothing only shortens, and never below the straight line
        raw = sum(math.dist(a, b) for a, b in itertools.pairwise(plan.grid_path))
        assert math.dist(start, goal) - 1e-9 <= plan.length <= raw + 1e-9


def test_a_path_around_the_partition_wall_is_smoothed_to_few_waypoints(lab: MapModel) -> None:
    # From the shelf area (left of the wall at x 3.4-3.6, y >= 4.6) to the Nao area (right of it).
    plan = Planner(lab, ROUND).plan((2.0, 5.6), (5.0, 5.6))
    assert len(plan.waypoints) <= 4 < len(plan.grid_path)
    assert min(y for _, y in plan.waypoints) < 4.6 - 0.18  # goes round the wall's end
    assert_avoids_everything(lab, ROUND, plan.waypoints)


def generated_floor(seed: int) -> MapModel:
    """A 30 x 20 m floor with random pillars (avoided areas) and random static crates."""
    rng = np.random.default_rng(seed)
    avoided = {}
    for i in range(40):
        x, y = rng.uniform(2, 28), rng.uniform(2, 18)
        w, d = rng.uniform(0.3, 2.5), rng.uniform(0.3, 2.5)
        avoided[f"pillar{i}"] = box(x - w / 2, y - d / 2, x + w / 2, y + d / 2)
    model = MapModel((0, 0, 30, 20), avoided=avoided, semantics=SemanticDictionary(), name="generated")
    crates = []
    for i in range(60):
        x, y = rng.uniform(1, 29), rng.uniform(1, 19)
        if not any(area.distance(shapely.Point(x, y)) < 0.3 for area in avoided.values()):
            crates.append(small_object(f"crate{i}", "crate", x, y, radius=0.2, z=0.2))
    model.semantics = SemanticDictionary([_static("crate")])
    model.add_many(crates)
    return model


def _static(tag: str):  # type: ignore[no-untyped-def]
    from ckmconf.model.environment import Semantic

    return Semantic(tag=tag, dynamic="static")


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_paths_on_a_generated_floor_avoid_every_obstacle(seed: int) -> None:
    model = generated_floor(seed)
    planner = Planner(model, ROUND, resolution=0.15)
    free = [(x, y) for x in np.linspace(0.5, 29.5, 12) for y in np.linspace(0.5, 19.5, 8)
            if not model.collisions(ROUND, x, y)]
    planned = 0
    for start, goal in zip(free[::3], free[::-3], strict=False):
        try:
            plan = planner.plan(start, goal)
        except Unreachable as refused:
            assert "walled off" in str(refused) or "boxed in" in str(refused)
            continue
        assert_avoids_everything(model, ROUND, plan.waypoints)
        planned += 1
    assert planned >= 8


def test_an_unreachable_goal_is_refused_with_its_reason(lab: MapModel) -> None:
    planner = Planner(lab, ROUND)
    with pytest.raises(Unreachable) as inside:
        planner.plan((1.5, 1.0), (4.5, 3.5))
    assert str(inside.value) == (
        "no path from (1.5, 1) to (4.5, 3.5): the goal collides with 'Column1' (footprint radius 0.18 m)"
    )
    with pytest.raises(Unreachable, match=r"the start collides with 'map bounds'"):
        planner.plan((0.05, 3.0), (2.0, 3.0))
    with pytest.raises(Unreachable, match=r"the goal collides with 'desk'"):
        planner.plan((1.5, 1.0), (5.4, 0.6))


def test_a_walled_off_room_and_a_too_narrow_door_are_unreachable() -> None:
    walls = {
        "north": box(2, 4, 5, 4.2), "south": box(2, 1, 5, 1.2), "west": box(2, 1, 2.2, 4.2),
        "east-low": box(4.8, 1, 5, 2.5), "east-high": box(4.8, 2.8, 5, 4.2),  # a 0.3 m door at y 2.5-2.8
    }
    model = MapModel((0, 0, 6, 5), avoided=walls)
    with pytest.raises(Unreachable) as refused:
        Planner(model, ROUND).plan((0.6, 2.6), (3.5, 2.6))
    assert str(refused.value) == (
        "no path from (0.6, 2.6) to (3.5, 2.6): the goal's free space is not connected to the start's (walled off)"
    )
    slim = Footprint.round(0.08)
    plan = Planner(model, slim, resolution=0.02).plan((0.6, 2.6), (3.5, 2.6))  # 0.16 m across fits the door
    assert_avoids_everything(model, slim, plan.waypoints)
    assert any(4.8 <= x <= 5.0 and 2.5 < y < 2.8 for x, y in plan.waypoints)


def test_mobile_objects_are_left_to_the_navigation_unless_asked(lab: MapModel) -> None:
    # the chair (mobile) stands at (5.3, 1.35), radius 0.3
    assert "chair" not in Planner(lab, ROUND).named
    with pytest.raises(Unreachable, match="the goal collides with 'chair'"):
        Planner(lab, ROUND, include_mobile=True).plan((3.0, 1.0), (5.3, 1.5))
