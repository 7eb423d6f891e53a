"""A flat marking (``<Geometry2D height="0">``, D294) in the navigation room: planning goes straight
through it, the robot drives over it in the real pybullet world (its lidar does not see it, nor
does the localization's map), and an object goal naming it is its centre; without a height the same
footprint is the obstacle it always was."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest
import shapely

from plugins.navigation.amcl import AmclNavigation

from .loop import ROOM, TURTLEBOT, Bench, plugin

START = (1.0, 1.8, 0.0)
PAD = shapely.box(1.2, 0.9, 1.8, 1.5)  # across the straight way from START to GOAL
GOAL = (2.0, 0.6)


def _room(directory: Path, height: str) -> Path:
    pad = (
        f'    <Semantic tag="pad"/>\n    <Object name="pad" tag="pad"><Pose x="1.5" y="1.2"/>'
        f'<Geometry2D{height}><Rectangle width="0.6" depth="0.6"/></Geometry2D></Object>'
    )
    path = directory / "room.xml"
    path.write_text(ROOM.replace("  </Environment>", pad + "\n  </Environment>"))
    return path


@pytest.fixture
def bench(tmp_path: Path) -> Iterator[Bench]:
    nav = {"particles": 800, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"}
    made = Bench(_room(tmp_path, ' height="0"'), START, nav=nav)
    yield made
    made.close()


def _navigate(bench: Bench, goal: str, timeout: float) -> tuple[str, list[tuple[float, float, float]]]:
    """Set ``goal``; run until Navigation arrives or fails: its last state and the true trajectory."""
    bench.services["nav"].plugin.apply_service_parameters({"goal": goal})  # type: ignore[attr-defined]
    trajectory: list[tuple[float, float, float]] = []

    def done() -> bool:
        trajectory.append(bench.truth())
        status = bench.latest("/nav/status")
        return status is not None and status["goal"] == goal and status["state"] in ("arrived", "failed")

    assert bench.run(done, timeout), f"no arrival in {timeout} s, at {bench.truth()}"
    return str(bench.latest("/nav/status")["state"]), trajectory


def test_the_robot_is_planned_and_drives_straight_over_a_marking(bench: Bench) -> None:
    state, trajectory = _navigate(bench, f"{GOAL[0]} {GOAL[1]} 0", 30.0)
    assert state == "arrived", bench.latest("/nav/status")
    assert bench.latest("/base/path")["id"] == 1  # one plan: the lidar saw nothing to replan round
    over = [t for t in trajectory if PAD.contains(shapely.Point(t[:2]))]
    assert len(over) > 100  # it crossed the marking, not round it
    assert math.dist(bench.truth()[:2], GOAL) < 0.15


def test_an_object_goal_naming_a_marking_is_its_centre(bench: Bench) -> None:
    state, _ = _navigate(bench, "pad", 30.0)
    assert state == "arrived", bench.latest("/nav/status")
    nav = bench.services["nav"].plugin
    assert nav.goal is not None and nav.goal[:2] == pytest.approx((1.5, 1.2))  # type: ignore[attr-defined]
    assert math.dist(bench.truth()[:2], (1.5, 1.2)) < 0.15


def test_without_a_height_the_footprint_is_an_obstacle_the_plan_goes_round(tmp_path: Path) -> None:
    file = _room(tmp_path, "")
    nav: AmclNavigation = plugin(
        "amcl-navigation", AmclNavigation, file, **{"environment": file.name, "particles": 300, **TURTLEBOT}
    )
    nav.setup()
    try:
        points = nav.routes.plan(START[:2], GOAL)
        assert len(points) > 2 and shapely.LineString(points).distance(PAD) > 0.17  # round it, a radius off
    finally:
        nav.stop()
    marked = _room(tmp_path, ' height="0"')
    nav = plugin(
        "amcl-navigation", AmclNavigation, marked, **{"environment": marked.name, "particles": 300, **TURTLEBOT}
    )
    nav.setup()
    try:
        assert nav.routes.plan(START[:2], GOAL) == [START[:2], GOAL]  # straight through the marking
    finally:
        nav.stop()
