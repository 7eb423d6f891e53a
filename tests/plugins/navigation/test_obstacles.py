"""Scan obstacles expire (D152): a point a later beam sees through goes at once, one unseen for the
time-out goes too, a standing one stays; the Navigation service plans round a box on its way and,
once the box has gone, takes the shorter way again."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest
import shapely

from plugins.localization.raster import GridMap
from plugins.navigation.amcl import AmclNavigation
from plugins.navigation.frames import Pose
from plugins.navigation.obstacles import ScanObstacles
from runtime.resources.spt import Context

from .loop import Bench, room
from .test_amcl import grid, navigation, odometry, scan

BOX = shapely.box(2.2, 0.1, 2.8, 0.7)
"""A box the map does not know, closing the way south of the pillar."""


def sweep(ranges: dict[int, float], beams: int = 181) -> dict[str, Any]:
    """A LaserScan over [-π/2, π/2] (1° steps), 3 m everywhere but at the given beam indices."""
    values = np.full(beams, 3.0)
    for index, value in ranges.items():
        values[index] = value
    return {"ranges": values, "angle_min": -math.pi / 2, "angle_increment": math.pi / (beams - 1),
            "range_min": 0.05, "range_max": 5.6}


def test_a_point_seen_through_goes_a_hidden_or_hit_one_stays_an_unseen_one_times_out() -> None:
    memory = ScanObstacles(margin=0.1, timeout=5.0)
    ahead, behind = (2.0, 0.0), (-2.0, 0.0)  # the laser at the origin looks along +x; beam 90 points ahead
    cases = [({90: 2.0}, 0), ({90: 1.0}, 0), ({90: float("nan")}, 0), ({90: float("-inf")}, 0),
             ({90: 2.05}, 0), ({90: 2.5}, 1), ({90: float("inf")}, 1), ({90: 5.6}, 1)]
    for ranges, gone in cases:  # hit, hidden by something nearer, unusable, too close, within the margin; free
        memory.clear()
        memory.add([ahead, behind], now=0.0)
        assert memory.update(sweep(ranges), (0.0, 0.0, 0.0), np.zeros((0, 2)), now=1.0) == gone, ranges
        assert len(memory) == 2 - gone and tuple(memory.points[0]) in (ahead, behind)
    memory.clear()
    memory.add([ahead, behind], now=0.0)
    hit = np.array([[2.01, 0.0]])  # the point ahead is hit again at t = 4: refreshed; the one behind is not
    assert memory.update(sweep({90: 2.01}), (0.0, 0.0, 0.0), hit, now=4.0) == 0
    assert memory.update(sweep({90: 2.01}), (0.0, 0.0, 0.0), np.zeros((0, 2)), now=6.0) == 1
    assert memory.points.tolist() == [list(ahead)] and memory.seen.tolist() == [4.0]
    turned = (0.0, 0.0, math.pi / 2)  # facing +y the point lies 90° right: beam 0, seen through there
    assert memory.update(sweep({0: 4.0}), turned, np.zeros((0, 2)), now=7.0) == 1 and len(memory) == 0
    keeper = ScanObstacles(timeout=0.0)  # no time-out: only a beam clears it
    keeper.add([behind], now=0.0)
    assert keeper.update(sweep({}), (0.0, 0.0, 0.0), np.zeros((0, 2)), now=1e6) == 0
    with pytest.raises(ValueError, match="merge"):
        ScanObstacles(merge=0.0)


def run(nav: AmclNavigation, world: GridMap, truth: Pose, odom: Pose, start: int, count: int) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for k in range(start, start + count):
        result = nav.process({"scan": scan(world, truth), "odom": odometry(odom)}, Context(k, 0.8 * k))
    return result


def south(path: dict[str, Any]) -> bool:
    """The path passes south of the pillar, not round its north end (the odom frame is the map's
    shifted by (-1, -1.8))."""
    return bool(max(p[1] for p in path["points"]) + 1.8 < 2.9)


def test_a_box_that_went_away_stops_blocking_and_the_shorter_way_is_taken_again(tmp_path: Path) -> None:
    file = room(tmp_path)
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="Target")
    first = run(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 0, 1)["path"]
    assert south(first)
    truth, odom = (1.7, 0.8, 0.0), (0.7, -1.0, 0.0)  # further on, facing the box
    boxed = run(nav, grid(file, BOX), truth, odom, 1, 2)
    assert boxed["path"]["id"] == first["id"] + 1 and not south(boxed["path"]) and nav.routes.extra
    still = run(nav, grid(file, BOX), truth, odom, 3, 3)  # the box stays: so do its points and the plan
    assert still["path"]["id"] == boxed["path"]["id"] and nav.routes.extra
    assert nav.routes.obstacles.seen.max() == pytest.approx(0.8 * 5)  # refreshed by the hits on it
    free = run(nav, grid(file), truth, odom, 6, 2)  # the box went: its beams reach the wall behind
    assert not nav.routes.extra and len(nav.routes.obstacles) == 0
    assert free["path"]["id"] == boxed["path"]["id"] + 1 and south(free["path"])
    assert free["status"]["state"] == "active" and free["status"]["path_length"] < boxed["status"]["path_length"]


def test_an_obstacle_out_of_view_is_forgotten_after_the_time_out(tmp_path: Path) -> None:
    file = room(tmp_path)
    nav = navigation(file, initialPose="1.7 0.8 0", initialSpread="0.05 0.03", goal="Target", obstacleTimeout=3.0)
    truth, odom = (1.7, 0.8, 0.0), (0.0, 0.0, 0.0)
    boxed = run(nav, grid(file, BOX), truth, odom, 0, 2)
    assert not south(boxed["path"]) and nav.routes.extra
    away = (1.7, 0.8, math.pi)  # turned round (the box now behind the 240° sweep's blind sector)
    run(nav, grid(file, BOX), away, (0.0, 0.0, math.pi), 2, 2)
    assert nav.routes.extra  # not seen, but not for 3 s yet
    run(nav, grid(file, BOX), away, (0.0, 0.0, math.pi), 4, 4)
    assert not nav.routes.extra and len(nav.routes.obstacles) == 0


def test_in_the_closed_loop_the_robot_takes_the_way_a_removed_box_no_longer_blocks(tmp_path: Path) -> None:
    """On the real pybullet world (tests/plugins/navigation/loop.py): the box closing the south gap is
    seen and planned round (north); it is taken away; the beams see through where it stood, and the
    robot turns back to the shorter south way and arrives."""
    nav_params = {"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"}
    bench = Bench(room(tmp_path), (1.0, 1.8, 0.0), nav=nav_params)
    try:
        cid = bench.world.client
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.3, 0.3, 0.25], physicsClientId=cid)
        box = p.createMultiBody(0, shape, -1, [2.5, 0.4, 0.25], physicsClientId=cid)
        nav: AmclNavigation = bench.services["nav"].plugin  # type: ignore[assignment]
        nav.apply_service_parameters({"goal": "Target"})

        def path() -> dict[str, Any]:
            return bench.latest("/base/path") or {"id": 0, "points": []}

        assert bench.run(lambda: bool(nav.routes.extra) and path()["id"] >= 2, 20.0), "the box was never seen"
        detour = path()
        assert not south(detour)
        p.removeBody(box, physicsClientId=cid)
        trajectory: list[tuple[float, float, float]] = []

        def arrived() -> bool:
            trajectory.append(bench.truth())
            return (bench.latest("/nav/status") or {}).get("state") in ("arrived", "failed")

        assert bench.run(arrived, 40.0), f"no arrival: {bench.latest('/nav/status')}, at {bench.truth()}"
        assert bench.latest("/nav/status")["state"] == "arrived"
        assert not nav.routes.extra  # every point of the box was seen through
        assert min(t[1] for t in trajectory) < 1.1 and max(t[1] for t in trajectory) < 2.9  # south, not north
        assert math.dist(bench.truth()[:2], (4.0, 1.8)) < 0.2
    finally:
        bench.close()
