"""A map Object as the Navigation's goal (issue M, point 2): the standoff pose facing it, the object no
obstacle of its own approach, scan points on it not blocking the last leg, and in the closed loop the
robot stopped at the standoff by the world's own evidence."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from plugins.navigation.amcl import AmclNavigation
from plugins.navigation.object_goals import on_object

from .loop import ROOM, Bench
from .test_amcl import frames, grid, navigation

PARCEL = (3.9, 0.9)  # south-east of the pillar, 0.3 m square, 0.3 m tall
AGAINST_WALL = (4.7, 2.5)  # its east side is 0.15 m from the room's east wall


def _object(name: str, x: float, y: float) -> str:
    return (f'    <Object name="{name}" tag="parcel"><Pose x="{x}" y="{y}" z="0" yaw="0"/>'
            '<Geometry3D><Prism zmin="0" zmax="0.3"><Rectangle width="0.3" depth="0.3"/></Prism></Geometry3D>'
            "</Object>")


@pytest.fixture
def file(tmp_path: Path) -> Path:
    objects = "\n".join(['    <Semantic tag="parcel" landmark="free" dynamic="static"/>',
                         _object("parcel", *PARCEL), _object("crate_by_wall", *AGAINST_WALL)])
    path = tmp_path / "room.xml"
    path.write_text(ROOM.replace("  </Environment>", objects + "\n  </Environment>"))
    return path


def _box(centre: tuple[float, float]) -> shapely.Polygon:
    return shapely.box(centre[0] - 0.15, centre[1] - 0.15, centre[0] + 0.15, centre[1] + 0.15)


def test_an_object_goal_is_planned_to_the_standoff_pose_facing_it(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="parcel")
    assert nav.goal_object == "parcel" and "parcel" not in nav.routes.static.named
    status = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0))["status"]
    assert status["state"] == "active" and status["goal"] == "parcel", status
    assert nav.goal is not None
    x, y, yaw = nav.goal
    assert _box(PARCEL).distance(shapely.Point(x, y)) == pytest.approx(0.18 + 0.1, abs=1e-6)  # radius + gap
    assert yaw == pytest.approx(math.atan2(PARCEL[1] - y, PARCEL[0] - x))
    assert x < PARCEL[0] and y > PARCEL[1]  # on the side the robot came from (north-west)


def test_without_the_exclusion_the_object_would_refuse_its_own_goal(file: Path) -> None:
    """What issue M saw: the goal at an object collided with it."""
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal=f"{PARCEL[0]} {PARCEL[1]} 0")
    status = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0))["status"]
    assert status["state"] == "failed" and "'parcel'" in status["reason"]


def test_an_object_against_a_wall_is_approached_from_a_free_side(file: Path) -> None:
    nav = navigation(file, initialPose="4.7 3.0 0", initialSpread="0.05 0.03", goal="crate_by_wall", **{
        "objectStandoff": 0.1})
    frames(nav, grid(file), (4.7, 3.0, 0.0), (0.0, 0.0, 0.0))
    assert nav.goal is not None and nav.phase == "active"
    x, y, _ = nav.goal
    assert _box(AGAINST_WALL).distance(shapely.Point(x, y)) == pytest.approx(0.28, abs=1e-6)
    assert x + 0.18 <= 5.0  # inside the room, not behind the crate


def test_a_wide_robot_with_no_free_side_fails_with_the_reason(file: Path) -> None:
    nav = navigation(file, initialPose="4.0 3.0 0", initialSpread="0.05 0.03", goal="crate_by_wall",
                     robotRadius=1.9)  # no pose 2 m from its outline stays inside the 5 x 4 m room
    status = frames(nav, grid(file), (4.0, 3.0, 0.0), (0.0, 0.0, 0.0))["status"]
    assert status["state"] == "failed"
    assert status["reason"].startswith("no side of object 'crate_by_wall' leaves room for the robot: ")


def test_an_unknown_object_goal_names_the_areas_and_objects(file: Path) -> None:
    nav = navigation(file)
    with pytest.raises(ValueError, match=r"an Object of it \(crate_by_wall, parcel\)"):
        nav.apply_service_parameters({"goal": "parcle"})


def test_scan_points_on_the_goal_object_do_not_block_the_last_leg(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="parcel")
    frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0))
    parcel = nav.routes.model.objects["parcel"]
    hits = np.array([[3.75, 0.9], [3.76, 1.0], [3.9, 1.05], [3.0, 1.0]])  # three on its faces, one off it
    assert on_object(hits, parcel, 0.15).tolist() == [True, True, True, False]


def test_a_newer_goal_brings_the_object_back_as_an_obstacle(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="parcel")
    nav.apply_service_parameters({"goal": "Target"})
    assert nav.goal_object is None and "parcel" in nav.routes.static.named


def test_in_the_closed_loop_the_robot_stops_at_the_standoff_facing_the_parcel(file: Path) -> None:
    """The pybullet world of tests/plugins/navigation/loop.py: the Turtlebot drives round the pillar to
    the parcel (a real box in the world) and stops short of it, facing it."""
    nav_params = {"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"}
    bench = Bench(file, (1.0, 1.8, 0.0), nav=nav_params)
    try:
        nav: AmclNavigation = bench.services["nav"].plugin  # type: ignore[assignment]
        nav.apply_service_parameters({"goal": "parcel"})

        def ended() -> bool:
            return (bench.latest("/nav/status") or {}).get("state") in ("arrived", "failed")

        assert bench.run(ended, 60.0), f"no arrival: {bench.latest('/nav/status')}, at {bench.truth()}"
        assert bench.latest("/nav/status")["state"] == "arrived", bench.latest("/nav/status")
        x, y, yaw = bench.truth()
        gap = _box(PARCEL).distance(shapely.Point(x, y)) - 0.18  # the footprint's edge to the parcel
        assert 0.0 < gap < 0.1 + 0.15 + 0.03  # the standoff, within the arrival tolerance
        facing = math.atan2(PARCEL[1] - y, PARCEL[0] - x)
        assert abs(math.remainder(yaw - facing, 2 * math.pi)) < 0.2 + 0.05
    finally:
        bench.close()
