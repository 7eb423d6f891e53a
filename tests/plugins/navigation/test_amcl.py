"""amcl-navigation (Navigation.AMCL, Table 7.1) on scans ray-cast in the test room's grid: goals by
Area or pose, the path re-anchored in the odom frame, replanning round scan points on the path,
leaving an inflated obstacle, waiting for and failing without a localization, bad input."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import shapely

import ckmconf
from plugins.localization.raster import GridMap, environment_obstacles
from plugins.localization.raycast import cast
from plugins.navigation.amcl import AmclNavigation
from plugins.navigation.frames import Pose, compose, inverse, transform_point
from plugins.navigation.laser_scan import LaserScanService
from runtime.kernel.interfaces import ParamError
from runtime.resources import codec
from runtime.resources.spt import Context

from .loop import TURTLEBOT, plugin, room

LASER = (0.10, 0.0, 0.0)
ANGLES = np.linspace(-4.1888 / 2, 4.1888 / 2, 683)


def grid(path: Path, *extra: shapely.Geometry) -> GridMap:
    env = ckmconf.load(path).environment
    assert env is not None
    bounds = (env.map.xmin, env.map.ymin, env.map.xmax, env.map.ymax)
    return GridMap.from_shapes(bounds, [*environment_obstacles(env, 0.14), *extra], 0.02)


def scan(world: GridMap, truth: Pose, mount: Pose = LASER) -> dict[str, Any]:
    """The LaserScan the laser-scan service makes of the sweep from ``truth`` (the laser at ``mount``)."""
    laser = compose(truth, mount)
    ranges = cast(world, np.array([laser]), ANGLES, 5.6)[0]
    service: LaserScanService = plugin("laser-scan", LaserScanService, fov=4.1888, rangeMin=0.02, rangeMax=5.6)
    return service.process({"stamp": 1.0, "ranges": ranges.astype(np.float32)}, Context(0, 1.0))


def odometry(pose: Pose) -> dict[str, Any]:
    return {"stamp": 1.0, "pose": {"x": pose[0], "y": pose[1], "yaw": pose[2]},
            "twist": {"linear": 0.0, "angular": 0.0}, "dispersion": 0.0}


def navigation(file: Path, **params: object) -> AmclNavigation:
    made: AmclNavigation = plugin("amcl-navigation", AmclNavigation, file,
                                  **{"environment": file.name, "particles": 500, **TURTLEBOT, **params})
    made.setup()
    return made


def frames(nav: AmclNavigation, world: GridMap, truth: Pose, odom: Pose, count: int = 3) -> dict[str, Any]:
    result: dict[str, Any] = {}
    for k in range(count):
        result = nav.process({"scan": scan(world, truth), "odom": odometry(odom)}, Context(k, 0.8 * k))
    return result


@pytest.fixture
def file(tmp_path: Path) -> Path:
    return room(tmp_path)


def test_goals_are_areas_or_poses_and_a_bad_goal_names_the_areas(file: Path) -> None:
    nav = navigation(file, goal="Target")
    assert nav.goal == pytest.approx((4.0, 1.8, None)) and nav.goal_text == "Target"
    nav.apply_service_parameters({"goal": "3.5 2 1.57"})
    assert nav.goal == pytest.approx((3.5, 2.0, 1.57))
    for bad in ("Kitchen", "1 2", "1 2 nan"):
        with pytest.raises(ValueError, match=r"is neither an Area of environment 'nav-room' \(Start, Target, Walled\)"):
            nav.apply_service_parameters({"goal": bad})
    for bad_value in (3, None):
        with pytest.raises(ValueError, match="service parameter 'goal'"):
            nav.apply_service_parameters({"goal": bad_value})
    assert nav.goal == pytest.approx((3.5, 2.0, 1.57))  # a refused goal changes nothing
    nav.apply_service_parameters({"max_sensors": 2})  # not this plugin's
    nav.apply_service_parameters({"goal": " "})  # no goal: navigation cancelled
    assert nav.goal is None


def test_without_a_goal_only_the_pose_is_published_and_a_cancelled_goal_stops_the_base(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.1 0.05")
    result = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0))
    assert set(result) == {"pose", "dispersion", "particles"}  # the room has no <ZoomMap>: no zoom
    nav.apply_service_parameters({"goal": "Target"})
    assert frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)["path"]["points"]
    nav.apply_service_parameters({"goal": ""})  # cancelled: the base is told to stop
    result = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)
    assert result["path"]["points"] == []
    assert result["status"] == {"goal": "Target", "state": "cancelled", "path_length": 0.0, "remaining": 0.0,
                                "reason": "cancelled: the goal was set empty"}  # the goal's result
    nav.apply_service_parameters({"goal": ""})  # nothing left to cancel: no status replaces that result
    assert "status" not in frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)
    pose = result["pose"]
    assert math.hypot(pose["pose"]["x"] - 1.0, pose["pose"]["y"] - 1.8) < 0.1
    assert len(pose["covariance"]) == 9 and pose["dispersion"] == result["dispersion"] > 0


def test_the_path_is_the_plan_re_anchored_in_the_odom_frame(file: Path) -> None:
    truth, odom = (1.0, 1.8, 0.0), (0.5, -0.2, 1.0)  # the odom frame is turned and shifted from the map's
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.1 0.05", goal="4 1.8 1.57")
    result = frames(nav, grid(file), truth, odom)
    status, path = result["status"], result["path"]
    assert status["state"] == "active" and status["goal"] == "4 1.8 1.57" and status["reason"] == ""
    assert status["path_length"] > 3.0 and status["remaining"] == pytest.approx(status["path_length"], abs=0.15)
    assert path["frame"] == "odom" and path["goal"] == "4 1.8 1.57" and path["speed"] == 0.3
    assert path["points"][0] == pytest.approx(list(odom[:2]))  # starts at the robot, in odometry
    correction = compose(truth, inverse(odom))  # the true map→odom
    end = transform_point(correction, tuple(path["points"][-1]))
    assert math.dist(end, (4.0, 1.8)) < 0.1
    assert math.remainder(path["yaw"] + correction[2] - 1.57, 2 * math.pi) == pytest.approx(0.0, abs=0.05)
    for point in path["points"]:  # every waypoint clear of the pillar by the inflated radius
        assert shapely.box(2.3, 1.1, 2.7, 2.9).distance(shapely.Point(transform_point(correction, tuple(point)))) > 0.19


def test_scan_points_on_the_path_ahead_make_it_replan_round_them(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="Target")
    first = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)["path"]
    # the odom frame is the map's shifted by (-1, -1.8): map y = odom y + 1.8
    assert min(p[1] for p in first["points"]) + 1.8 < 1.1  # round the pillar's south end, the shorter way
    truth = (1.7, 0.8, 0.0)  # further on, a box the map does not know closes the south gap
    blocked = grid(file, shapely.box(2.2, 0.1, 2.8, 0.7))
    result = frames(nav, blocked, truth, (0.7, -1.0, 0.0), 2)
    assert result["path"]["id"] == first["id"] + 1
    assert max(p[1] for p in result["path"]["points"]) + 1.8 > 2.9  # now round the north end
    assert result["status"]["state"] == "active"


def test_a_robot_pushed_off_the_path_gets_a_new_plan_and_a_goal_set_again_replans(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="Target")
    first = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)["path"]
    pushed = (1.0, 3.2, 0.0)  # 1.4 m north of where it was, on neither leg of the plan (odometry agrees)
    result = frames(nav, grid(file), pushed, (0.0, 1.4, 0.0), 3)
    assert result["path"]["id"] > first["id"] and result["status"]["state"] == "active"
    assert result["path"]["points"][0] == pytest.approx([0.0, 1.4])
    assert max(p[1] for p in result["path"]["points"]) + 1.8 > 2.9  # now round the north end: nearer
    again = result["path"]["id"]
    nav.apply_service_parameters({"goal": "Target"})  # the same goal again: a fresh plan
    assert frames(nav, grid(file), pushed, (0.0, 1.4, 0.0), 1)["path"]["id"] == again + 1


def test_a_start_inside_the_inflated_pillar_leaves_by_the_nearest_free_point(file: Path) -> None:
    truth = (2.12, 1.5, 0.0)  # 0.18 m from the pillar: inside its 0.2 m inflation
    nav = navigation(file, initialPose="2.12 1.5 0", initialSpread="0.02 0.02", goal="Start")
    result = frames(nav, grid(file), truth, truth, 2)
    assert result["status"]["state"] == "active", result["status"]
    assert math.dist(result["path"]["points"][0], truth[:2]) < 0.05
    nav_strict = navigation(file, initialPose="2.12 1.5 0", initialSpread="0.02 0.02", goal="Start", escape=0.0)
    failed = frames(nav_strict, grid(file), truth, truth, 1)["status"]
    assert failed["state"] == "failed" and "the start collides with 'Pillar'" in failed["reason"]


def test_a_goal_just_inside_an_obstacle_inflation_moves_to_free_space_a_deeper_one_fails(file: Path) -> None:
    goal = "2.15 1.5 0"  # 0.15 m from the pillar, inside its 0.2 m inflation (a pose short of an object)
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.02 0.02", goal=goal)
    result = frames(nav, grid(file), (1.0, 1.8, 0.0), (1.0, 1.8, 0.0), 2)
    assert result["status"]["state"] == "active" and result["status"]["goal"] == goal
    end = tuple(result["path"]["points"][-1])  # the odom frame is the map's here
    assert 0.0 < math.dist(end, (2.15, 1.5)) <= 0.3 and nav.target == pytest.approx(end, abs=0.05)
    assert shapely.box(2.3, 1.1, 2.7, 2.9).distance(shapely.Point(end)) >= 0.2
    strict = navigation(file, initialPose="1 1.8 0", initialSpread="0.02 0.02", goal=goal, goalEscape=0.0)
    failed = frames(strict, grid(file), (1.0, 1.8, 0.0), (1.0, 1.8, 0.0), 1)["status"]
    assert failed["state"] == "failed" and "the goal collides with 'Pillar'" in failed["reason"]


def test_without_a_localization_it_waits_stopped_then_fails_with_the_reason(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", goal="Target", localizeTimeout=2.0)
    result: dict[str, Any] = {}
    for k in range(5):  # odometry but no scan: no estimate
        result = nav.process({"scan": None, "odom": odometry((0.0, 0.0, 0.0))}, Context(k, 0.8 * k))
        if k == 0:
            assert result["status"]["state"] == "planning" and result["path"]["points"] == []
    assert result["status"]["state"] == "failed"
    assert result["status"]["reason"] == "no localization for 2 s (no scan received)"
    assert "pose" not in result


@pytest.mark.parametrize(
    ("inputs", "message"),
    [
        ({"cmd_vel": {}}, r"unknown inputs \['cmd_vel'\]"),
        ({"scan": {"ranges": [1.0]}, "odom": odometry((0, 0, 0))}, "the scan is not a LaserScan"),
        ({"scan": None, "odom": {"pose": {"x": 1}}}, "input 'odom' pose field 'y'"),
        ({"scan": 3, "odom": None}, "input 'scan' must be a message"),
    ],
)
def test_bad_input_is_refused_naming_it(file: Path, inputs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        navigation(file).process(inputs, Context(0, 0.0))


def test_bad_params_and_a_missing_environment_are_refused(file: Path) -> None:
    with pytest.raises(ParamError, match=r"'laserPose' = '0\.1 0' is not 'x y yaw' \(3 finite numbers\)"):
        navigation(file, laserPose="0.1 0")
    with pytest.raises(ParamError, match="filter"):
        navigation(file, filter="ekf")
    with pytest.raises(ValueError, match="'initialPose' = 'Kitchen' is neither an Area"):
        navigation(file, initialPose="Kitchen")
    with pytest.raises(ValueError, match="cannot use environment file"):
        navigation(file, environment="missing.xml")


def same(a: Any, b: Any) -> bool:
    """Equal structures, numbers to 1e-9 (summation order may differ with the arrays' alignment)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):  # the particle cloud's columns: some headings
        return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-9, atol=1e-9))  # are near 0, so 1e-9 m/rad
    return bool(a == b)


@pytest.mark.parametrize("filter_name", ["reliability", "mcl"])
def test_a_copy_restored_from_the_state_goes_on_with_the_same_results(file: Path, filter_name: str) -> None:
    """Delegation (§3.1.2.5–6) ships the state through the codec; the copy's next frames are the original's."""
    params = {"filter": filter_name, "initialPose": "1 1.8 0", "initialSpread": "0.1 0.05", "goal": "Target"}
    nav = navigation(file, **params)
    world = grid(file, shapely.box(2.2, 0.1, 2.8, 0.7))
    frames(nav, world, (1.0, 1.8, 0.0), (0.0, 0.0, 0.0), 1)
    frames(nav, world, (1.7, 0.8, 0.0), (0.7, -1.0, 0.0), 1)  # sees the box: an added obstacle
    assert nav.routes.extra
    copy = navigation(file, **params)
    copy.restore(codec.decode(codec.encode(nav.state())))
    for k, (truth, odom) in enumerate([((1.8, 0.9, 0.1), (0.8, -0.9, 0.1)), ((1.9, 1.0, 0.2), (0.9, -0.8, 0.2))]):
        inputs = {"scan": scan(world, truth), "odom": odometry(odom)}
        mine, theirs = nav.process(inputs, Context(10 + k, 9.0 + k)), copy.process(inputs, Context(10 + k, 9.0 + k))
        assert same(theirs, mine)
    with pytest.raises(ValueError, match="not an amcl-navigation state"):
        copy.restore({"kind": "amcl-navigation", "goal": None})


def test_at_the_goal_the_base_is_stopped_then_arrival_waits_for_it_to_be_still(file: Path) -> None:
    """D128: within tolerance of the goal the path empties (the base stops instead of chasing an end
    point each re-anchoring moves by the localization's jitter); arrived once the odometry is still."""
    truth = (3.95, 1.85, 1.55)  # within 0.15 m and 0.2 rad of the goal
    nav = navigation(file, initialPose="3.95 1.85 1.55", initialSpread="0.05 0.02", goal="4 1.8 1.57")
    moving = {**odometry((0.0, 0.0, 0.0)), "twist": {"linear": 0.1, "angular": 0.3}}
    for k in range(3):
        result = nav.process({"scan": scan(grid(file), truth), "odom": moving}, Context(k, 0.8 * k))
    assert result["status"]["state"] == "active" and result["path"]["points"] == []
    result = nav.process({"scan": scan(grid(file), truth), "odom": odometry((0.0, 0.0, 0.0))}, Context(3, 2.4))
    assert result["status"]["state"] == "arrived" and result["path"]["points"] == []


def test_once_reached_a_heading_moved_off_only_turns_the_base_on_the_spot(file: Path) -> None:
    """D255: after the goal was reached (the path emptied), an estimate whose heading moved more than
    yawTolerance off sends the robot's own spot with the goal's yaw, never the few cm left to the
    plan's end, which the base would first turn to face (half a turn away); back within it, arrived."""
    nav = navigation(file, initialPose="3.95 1.85 1.55", initialSpread="0.05 0.02", goal="4 1.8 1.57")
    moving = {**odometry((0.0, 0.0, 0.0)), "twist": {"linear": 0.1, "angular": 0.3}}
    for k in range(3):
        result = nav.process({"scan": scan(grid(file), (3.95, 1.85, 1.55)), "odom": moving}, Context(k, 0.8 * k))
    assert result["path"]["points"] == []  # reached
    off = (3.95, 1.85, 1.95)  # the heading 0.38 rad off the goal's
    for k in range(3, 8):
        odom = {**odometry((0.0, 0.0, 0.4)), "twist": {"linear": 0.0, "angular": 0.3}}
        result = nav.process({"scan": scan(grid(file), off), "odom": odom}, Context(k, 0.8 * k))
    path, status = result["path"], result["status"]
    assert nav.localizer is not None and nav.localizer.correction is not None
    correction = nav.localizer.correction
    assert status["state"] == "active"
    assert path["points"] == [pytest.approx([0.0, 0.0], abs=1e-9)]  # the robot's spot in odom: turn, do not drive
    assert path["yaw"] == pytest.approx(1.57 - correction[2], abs=1e-9)  # the goal's yaw in odom
    assert math.dist(correction[:2], (3.95, 1.85)) < 0.1  # (the odom origin is the robot's start)
    for k in range(8, 12):  # turned back: within tolerance, empty path, arrived once still
        result = nav.process({"scan": scan(grid(file), (3.95, 1.85, 1.56)), "odom": odometry((0.0, 0.0, 0.01))},
                             Context(k, 0.8 * k))
    assert result["path"]["points"] == [] and result["status"]["state"] == "arrived"


ROVER = {"robotRadius": 0.35, "robotHeight": 0.5, "laserPose": "0.25 0 0", "laserHeight": 0.3}
"""A second robot model (plugins/sim/models/rover.urdf's size): a wider base, its laser further ahead."""


def _clearance(nav: AmclNavigation, world: GridMap, mount: Pose) -> float:
    truth = (1.0, 1.8, 0.0)
    result: dict[str, Any] = {}
    for k in range(3):
        inputs = {"scan": scan(world, truth, mount), "odom": odometry((0.0, 0.0, 0.0))}
        result = nav.process(inputs, Context(k, 0.8 * k))
    assert result["status"]["state"] == "active", result["status"]
    correction = compose(truth, inverse((0.0, 0.0, 0.0)))
    pillar = shapely.box(2.3, 1.1, 2.7, 2.9)
    points = [shapely.Point(transform_point(correction, tuple(p))) for p in result["path"]["points"]]
    return float(min(pillar.distance(point) for point in points))


def test_the_footprint_and_laser_mount_are_the_configured_robots(file: Path) -> None:
    """Two robot models through the same room: each path keeps its own radius from the pillar."""
    start = {"initialPose": "1 1.8 0", "initialSpread": "0.05 0.03", "goal": "4 1.8 0"}
    turtlebot = navigation(file, **start)
    rover = navigation(file, **{**start, **ROVER})
    assert rover.laser == pytest.approx((0.25, 0.0, 0.0)) and turtlebot.laser == pytest.approx(LASER)
    near = _clearance(turtlebot, grid(file), LASER)
    wide = _clearance(rover, grid(file), (0.25, 0.0, 0.0))
    assert 0.18 < near < 0.35 < wide


def test_a_robot_too_wide_for_either_gap_fails_with_the_planners_reason(file: Path) -> None:
    nav = navigation(file, initialPose="1 1.8 0", initialSpread="0.05 0.03", goal="4 1.8 0",
                     **{**ROVER, "robotRadius": 0.6})
    status = frames(nav, grid(file), (1.0, 1.8, 0.0), (0.0, 0.0, 0.0))["status"]
    assert status["state"] == "failed" and status["reason"]


def test_no_footprint_or_map_is_taken_from_any_robot(file: Path) -> None:
    for missing in ("environment", "robotRadius", "laserPose"):
        given = {"environment": file.name, **TURTLEBOT}
        del given[missing]
        with pytest.raises(ParamError, match=f"needs parameter '{missing}'"):
            plugin("amcl-navigation", AmclNavigation, file, **given)
