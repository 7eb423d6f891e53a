"""base-displacement (MobileBase.Displacement, Table 7.1) on an ideal unicycle: pure pursuit along a
path with final heading, speed and acceleration limits, relative moves forwards and backwards,
preemption by id, the stale-odometry stop, the odometry dispersion model (D105), bad input."""

from __future__ import annotations

import math
from typing import Any

import pytest

from plugins.navigation.displacement import BaseDisplacement
from runtime.kernel.interfaces import ParamError
from runtime.resources import codec
from runtime.resources.spt import Context

from .loop import plugin

DT = 0.05


class Unicycle:
    """An ideal base integrating the service's wheel_cmd; its Odometry is diff-drive-odometry's shape."""

    def __init__(self, pose: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.x, self.y, self.yaw = pose
        self.twist = (0.0, 0.0)
        self.time = 0.0
        self.frames = 0
        self.commands: list[tuple[float, float]] = []

    def odometry(self) -> dict[str, Any]:
        return {"stamp": 1000.0 + self.time, "pose": {"x": self.x, "y": self.y, "yaw": self.yaw},
                "twist": {"linear": self.twist[0], "angular": self.twist[1]}, "dispersion": 0.0}

    def frame(self, base: BaseDisplacement, odometry: bool = True, **inputs: Any) -> dict[str, Any]:
        """One service period: the service's result, then the base moves by its command for DT."""
        data = {"path": None, "move_goal": None, "wheel_odom": self.odometry() if odometry else None, **inputs}
        if not odometry and base._seen.get("wheel_odom") is not None:
            data["wheel_odom"] = base._seen["wheel_odom"]  # the stream hands the newest, even if old
        result = base.process(data, Context(self.frames, self.time))
        self.frames += 1
        v, w = result["wheel_cmd"]["linear"], result["wheel_cmd"]["angular"]
        self.commands.append((v, w))
        for _ in range(10):  # integrate finely
            self.yaw += w * DT / 20
            self.x += v * math.cos(self.yaw) * DT / 10
            self.y += v * math.sin(self.yaw) * DT / 10
            self.yaw += w * DT / 20
        self.yaw = math.remainder(self.yaw, 2 * math.pi)
        self.twist = (v, w)
        self.time += DT
        return result


def base(**params: object) -> BaseDisplacement:
    made: BaseDisplacement = plugin("base-displacement", BaseDisplacement, **params)
    return made


def path(points: list[list[Any]], path_id: int = 1, yaw: float | None = None, speed: float = 0.3) -> dict[str, Any]:
    return {"id": path_id, "goal": "g", "frame": "odom", "points": points, "yaw": yaw, "speed": speed}


def move(goal_id: int, x: float, y: float = 0.0, yaw: float = 0.0) -> dict[str, Any]:
    return {"id": goal_id, "frame": "robot", "x": x, "y": y, "yaw": yaw}


def test_pure_pursuit_follows_an_l_shaped_path_to_its_end_and_final_heading_within_limits() -> None:
    robot, service = Unicycle(), base(speed=0.4)
    route = path([[0.0, 0.0], [1.5, 0.0], [1.5, 1.0]], yaw=math.pi)
    for _ in range(400):
        result = robot.frame(service, path=route)
        if robot.frames > 20 and robot.twist == (0.0, 0.0):
            break
    assert math.hypot(robot.x - 1.5, robot.y - 1.0) < 0.04
    assert abs(math.remainder(robot.yaw - math.pi, 2 * math.pi)) < 0.04
    speeds = [v for v, _ in robot.commands]
    assert max(speeds) == pytest.approx(0.3)  # the path's speed, below the service's top speed
    steps = [abs(b[0] - a[0]) for a, b in zip(robot.commands, robot.commands[1:], strict=False)]
    assert max(steps) <= 0.5 * DT + 1e-9  # the acceleration limit
    assert max(abs(w) for _, w in robot.commands) <= 1.5 + 1e-9
    assert result["odom"]["pose"] == pytest.approx({"x": robot.x, "y": robot.y, "yaw": robot.yaw}, abs=0.02)
    assert "move_status" not in result


def test_the_speed_parameter_caps_the_path_speed_and_bad_values_are_refused() -> None:
    robot, service = Unicycle(), base()
    service.apply_service_parameters({"speed": 0.1})
    for _ in range(60):
        robot.frame(service, path=path([[0.0, 0.0], [3.0, 0.0]]))
    assert max(v for v, _ in robot.commands) == pytest.approx(0.1)
    for bad in (0.9, 0.0, "fast", True):
        with pytest.raises(ValueError, match="service parameter 'speed'"):
            service.apply_service_parameters({"speed": bad})


@pytest.mark.parametrize(("goal", "backwards"), [(move(1, 0.5), False), (move(2, -0.3), True),
                                                  (move(3, 0.2, 0.4, math.pi / 2), False)])
def test_relative_moves_end_at_the_goal_pose(goal: dict[str, Any], backwards: bool) -> None:
    robot, service = Unicycle((1.0, 1.0, 0.3)), base()
    status: dict[str, Any] = {}
    for _ in range(300):
        status = robot.frame(service, move_goal=goal)["move_status"]
        if status["state"] != "moving":
            break
    assert status["state"] == "done" and status["id"] == goal["id"]
    assert status["total"] == pytest.approx(math.hypot(goal["x"], goal["y"]))
    c, s = math.cos(0.3), math.sin(0.3)
    want = (1.0 + c * goal["x"] - s * goal["y"], 1.0 + s * goal["x"] + c * goal["y"])
    assert math.dist((robot.x, robot.y), want) < 0.035
    assert abs(math.remainder(robot.yaw - 0.3 - goal["yaw"], 2 * math.pi)) < 0.035
    assert (min(v for v, _ in robot.commands) < 0) == backwards  # BACK reverses, it does not turn round


@pytest.mark.parametrize("tolerance", [None, 0.0, 0.01, 0.005])  # 0: a MoveGoal message's "not given"
def test_a_move_with_its_own_yaw_tolerance_ends_aimed_within_it_and_keeps_it_in_its_state(
    tolerance: float | None,
) -> None:
    """APPR_FLOOR's moves (D252): Move2D ``yaw_tolerance`` replaces the service's 0.03 rad for the
    move's final heading (and its first facing, at twice it); a copy restored mid-move keeps it."""
    robot, service = Unicycle((1.0, 1.0, 0.3)), base()
    goal = move(5, 0.25, 0.02, 0.4) | ({} if tolerance is None else {"yaw_tolerance": tolerance})
    status: dict[str, Any] = {}
    for _ in range(300):
        status = robot.frame(service, move_goal=goal)["move_status"]
        if status["state"] != "moving":
            break
        if robot.frames == 20:
            assert service.state()["move"]["yaw_tolerance"] == (tolerance or 0.03)
            copy = base()
            copy.restore(codec.decode(codec.encode(service.state())))
            service = copy
    assert status["state"] == "done"
    error = abs(math.remainder(robot.yaw - 0.3 - 0.4, 2 * math.pi))
    if not tolerance:
        assert 0.01 < error <= 0.03  # the service's own tolerance: the last turn stops early
    else:
        assert error <= tolerance


def test_a_new_goal_preempts_the_running_one_and_a_move_preempts_the_path_for_good() -> None:
    robot, service = Unicycle(), base()
    robot.frame(service, move_goal=move(1, 1.0))
    status = robot.frame(service, move_goal=move(2, 0.2))["move_status"]
    assert (status["id"], status["state"], status["reason"]) == (1, "failed", "preempted by move 2")
    running = robot.frame(service, move_goal=move(2, 0.2))["move_status"]
    assert running.pop("reason") == ""
    assert running == pytest.approx({"id": 2, "state": "moving", "remaining": 0.2, "total": 0.2}, abs=0.02)
    preempted = robot.frame(service, path=path([[0.0, 0.0], [2.0, 0.0]], path_id=5))["move_status"]
    assert (preempted["state"], preempted["reason"]) == ("failed", "preempted by path 5")
    assert service.move_state == "failed" and service.path_id == 5
    robot.frame(service, move_goal=move(3, 0.1))  # a move preempts the path...
    for _ in range(40):
        robot.frame(service, path=path([[robot.x, robot.y], [2.0, 0.5]], path_id=5))  # ...even re-anchored
    assert service.follower is None and service.move_state == "done"
    robot.frame(service, path=path([[robot.x, robot.y], [2.0, 0.0]], path_id=6))  # a new path is followed
    assert service.follower is not None and service.path_id == 6
    robot.frame(service, path=path([], path_id=6))  # no points: stop following
    assert service.follower is None


def test_stale_wheel_odometry_gives_a_zero_command() -> None:
    robot, service = Unicycle(), base()
    for _ in range(20):
        robot.frame(service, path=path([[0.0, 0.0], [3.0, 0.0]]))
    assert robot.twist[0] > 0.2
    commands = [robot.frame(service, odometry=False)["wheel_cmd"] for _ in range(8)]
    assert commands[4]["linear"] > 0  # 0.25 s without odometry: still driving (decelerating is the base's)
    assert commands[-1] == {"linear": 0.0, "angular": 0.0}  # > 0.3 s: stopped


def test_odometry_dispersion_grows_with_distance_and_rotation_and_resets_with_a_new_path() -> None:
    robot, service = Unicycle(), base()
    result: dict[str, Any] = {}
    for _ in range(200):
        result = robot.frame(service, move_goal=move(1, 1.0))
        if result["move_status"]["state"] == "done":
            break
    result = robot.frame(service)
    d = math.hypot(robot.x, robot.y)  # straight: no rotation; α = 0.02 each
    assert result["dispersion"] == pytest.approx(math.sqrt(0.02 * d * d + d * d * 0.02 * d * d / 3), rel=0.02)
    assert result["odom"]["dispersion"] == result["dispersion"]
    for _ in range(200):
        result = robot.frame(service, move_goal=move(2, 0.0, 0.0, math.pi))
        if result["move_status"]["state"] == "done":
            break
    turned = robot.frame(service)["dispersion"]
    assert turned > 0.0 and service.rotation == pytest.approx(math.pi, abs=0.05)
    assert robot.frame(service, path=path([[robot.x, robot.y], [0.0, 0.0]], 4))["dispersion"] == 0.0


@pytest.mark.parametrize(
    ("inputs", "message"),
    [
        ({"cmd_vel": {}}, "unknown inputs \\['cmd_vel'\\]"),
        ({"path": path([[0.0, 0.0]]) | {"frame": "map"}}, "input 'path' must be in the odom frame"),
        ({"path": path([[0.0, "x"]])}, "input 'path' point 0"),
        ({"path": path([[0.0, 0.0]]) | {"id": "one"}}, "input 'path' field 'id' must be an integer"),
        ({"path": path([]) | {"points": 3}}, "field 'points' must be a list"),
        ({"move_goal": move(1, 0.5) | {"frame": "map"}}, "input 'move_goal' must be in the robot frame"),
        ({"move_goal": move(1, math.inf)}, "input 'move_goal' field 'x' must be a finite number"),
        ({"move_goal": move(1, 0.5) | {"yaw_tolerance": 0.001}}, "field 'yaw_tolerance' = 0.001 must be in"),
        ({"move_goal": move(1, 0.5) | {"yaw_tolerance": "fine"}}, "field 'yaw_tolerance' must be a finite number"),
        ({"wheel_odom": {"pose": {"x": 0.0}}}, "input 'wheel_odom' pose field 'y'"),
    ],
)
def test_bad_input_is_refused_once_naming_the_input(inputs: dict[str, Any], message: str) -> None:
    robot, service = Unicycle(), base()
    with pytest.raises(ValueError, match=message):
        robot.frame(service, **inputs)
    if "cmd_vel" not in inputs:  # the same bad message is not refused again at every frame
        assert robot.frame(service, **inputs)["wheel_cmd"] == {"linear": 0.0, "angular": 0.0}


def test_bad_params_are_refused() -> None:
    with pytest.raises(ParamError, match="odometryNoise"):
        base(odometryNoise="0.1 0.1")
    with pytest.raises(ParamError, match="speed"):
        base(speed=2.0)
    with pytest.raises(ValueError, match="the input must be a message"):
        base().process([1, 2], Context(0, 0.0))


def test_a_copy_restored_from_the_state_goes_on_with_the_same_commands() -> None:
    """Delegation (§3.1.2.5–6) ships the state through the codec; the copy's next commands are the original's."""
    robot, service = Unicycle(), base()
    route = path([[0.0, 0.0], [1.5, 0.0], [1.5, 1.0]], yaw=1.0)
    for _ in range(30):
        robot.frame(service, path=route, move_goal=move(4, 0.2))  # the move preempted the path: it ends first
    copy = base()
    copy.restore(codec.decode(codec.encode(service.state())))
    for _ in range(40):
        inputs = {"path": path([[robot.x, robot.y], [1.5, 1.0]], 9), "move_goal": move(4, 0.2),
                  "wheel_odom": robot.odometry()}
        context = Context(robot.frames, robot.time)
        assert copy.process(inputs, context) == robot.frame(service, path=inputs["path"], move_goal=inputs["move_goal"])
    with pytest.raises(ValueError, match="not a base-displacement state"):
        copy.restore({"kind": "base-displacement"})


def test_a_cancelled_navigations_empty_path_leaves_a_running_move_alone() -> None:
    # D211: DOCK cancels the navigation goal; the Navigation then sends an empty path (its last id),
    # which must not preempt DOCK's move, while a new path still would.
    robot, service = Unicycle(), base()
    robot.frame(service, path=path([[0.0, 0.0], [1.0, 0.0]], path_id=3))
    robot.frame(service, move_goal=move(1, 0.2))
    for _ in range(5):
        status = robot.frame(service, path=path([], path_id=3))["move_status"]
    assert status["id"] == 1 and status["state"] == "moving"
    replanned = robot.frame(service, path=path([[robot.x, robot.y], [1.0, 0.0]], path_id=4))
    assert replanned["move_status"]["state"] == "failed"


def test_a_new_path_is_faced_turning_in_place_before_the_base_drives() -> None:
    """D237: the carrot of a new path 45° to the left (within turn_in_place) is faced first, v = 0,
    to within 0.35 rad; then pure pursuit drives. A re-anchored copy (same id) is not faced again."""
    robot, service = Unicycle(), base()
    route = path([[0.0, 0.0], [0.6, 0.6], [2.0, 0.6]])
    while robot.frames < 200:
        robot.frame(service, path=route)
        if robot.commands[-1][0] > 0:
            break
    turning = robot.commands[:-1]
    assert len(turning) >= 5 and all(v == 0.0 and w > 0 for v, w in turning)  # turned left in place ...
    assert robot.yaw > math.pi / 4 - 0.35 - 0.05  # ... until the carrot was within 0.35 rad
    for _ in range(40):
        robot.frame(service, path=route)
    assert all(v > 0 for v, _ in robot.commands[-40:])  # driving, not stopping to face again
    shifted = path([[robot.x, robot.y], [2.0, 0.65]])  # Navigation's re-anchored copy: same id
    robot.frame(service, path=shifted)
    assert robot.commands[-1][0] > 0
    for _ in range(300):
        robot.frame(service, path=shifted)
        if robot.twist == (0.0, 0.0):
            break
    assert math.hypot(robot.x - 2.0, robot.y - 0.65) < 0.05


def test_a_path_of_the_robots_own_spot_only_turns_it_to_the_yaw_and_a_short_rest_behind_is_faced() -> None:
    """D255: the Navigation's path once the goal is reached and only the heading is off is the robot's
    own spot with the yaw: the base turns in place to it and never drives. (The rest of the plan, 4 cm
    behind the robot, would have been faced first: a half turn to drive 4 cm, then a half turn back.)"""
    robot, service = Unicycle((0.5, 0.5, 0.0)), base()
    spot = path([[0.5, 0.5]], path_id=2, yaw=0.4)
    for _ in range(200):
        robot.frame(service, path=spot)
        if robot.twist == (0.0, 0.0) and robot.frames > 5:
            break
    assert all(v == 0.0 for v, _ in robot.commands) and any(w > 0 for _, w in robot.commands)
    assert robot.yaw == pytest.approx(0.4, abs=0.03) and (robot.x, robot.y) == (0.5, 0.5)
    behind, other = Unicycle((0.5, 0.5, 0.0)), base()
    rest = path([[0.5, 0.5], [0.46, 0.5]], path_id=2, yaw=0.4)  # what the Navigation sent before D255
    for _ in range(40):
        behind.frame(other, path=rest)
    assert abs(behind.yaw) > 1.5  # it turned round to face the 4 cm behind it


def test_a_move_before_any_odometry_fails_saying_so() -> None:
    service = base()
    result = service.process({"move_goal": move(7, 0.5)}, Context(0, 0.0, "base"))
    assert result["move_status"] == {"id": 7, "state": "failed", "remaining": 0.0, "total": 0.0,
                                     "reason": "no odometry received yet: no pose to move from"}
