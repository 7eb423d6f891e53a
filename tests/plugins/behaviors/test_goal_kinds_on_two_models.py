"""set-nav-goal, wait-goal, dock, back-off and stop-nav on the Turtlebot and the rover (issue M, point 6).

The kinds the lab's missions are made of, each driving the bench's real navigation and base-drive
services in the pybullet world (tests/plugins/navigation/loop.py), on two robot models whose footprint,
wheels and laser mount differ. The states are stepped as the mission engine steps them: start, step
until done or failed, then the next state. What counts is where the robot ends in the world, not what
a behavior says.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from plugins.behaviors.docking import Dock
from plugins.behaviors.manipulation import BackOff
from plugins.behaviors.navigation_goals import SetNavGoal, WaitGoal
from plugins.behaviors.recovery import StopNavigation
from runtime.missions.behaviors import Behavior
from tests.plugins.behaviors.closed_loop import BenchBase, BenchNavigation, angle, run_states, wired
from tests.plugins.navigation.loop import ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel, room

MODELS = pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)


def behavior(bench: Bench, cls: type[Behavior], name: str, *, goal: str | None = None, nav: bool = False,
             base: bool = False, pose_input: bool = False, **params: str) -> Behavior:
    """A behavior on the bench's services: ``nav`` (configured with ``goal``, if given) and ``base``; a
    ``pose`` input on the navigation's estimate and a ``move`` output on the base's goal topic."""
    services: dict[str, Any] = {}
    if nav:
        services["nav"] = BenchNavigation(bench)
    if base:
        services["base"] = BenchBase(bench)
    return wired(bench, cls, name, services, {"pose": "/nav/pose"} if pose_input else {},
                 {"move": "/base/move_goal"} if base else {},
                 configure={"nav": {"goal": goal}} if goal is not None else None, **params)


def navigation_bench(tmp_path: Path, model: RobotModel) -> Bench:
    return Bench(
        room(tmp_path),
        (1.0, 1.8, 0.0),
        model=model,
        nav={"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"},
    )


@MODELS
def test_nav_wait_dock_and_back_off_end_where_they_say(tmp_path: Path, model: RobotModel) -> None:
    bench = navigation_bench(tmp_path, model)
    try:
        states = [
            behavior(bench, SetNavGoal, "NAV", nav=True, goal="4 1.8 0"),
            behavior(bench, WaitGoal, "WAIT", nav=True),
            behavior(bench, Dock, "DOCK", base=True, pose_input=True, pose="4.3 2.0 1.5708"),
        ]
        statuses = run_states(bench, states, 120.0)
        assert statuses[-1][0] == "DOCK" and statuses[-1][1].done, statuses[-1]
        assert any(name == "NAV" and s.done for name, s in statuses)
        assert [s.progress for name, s in statuses if name == "WAIT"][-1] == 1.0
        x, y, yaw = bench.truth()
        # the base drives the dock move on odometry from a pose estimate a few centimetres off
        assert math.dist((x, y), (4.3, 2.0)) < 0.2, (x, y)
        assert angle(yaw, math.pi / 2) < 0.2, yaw

        back = behavior(bench, BackOff, "BACK", base=True, distance="0.3")
        _, status = run_states(bench, [back], 30.0)[-1]
        assert status.done, status
        bx, by, _ = bench.truth()
        # backwards from facing north: south, by the distance
        assert by == pytest.approx(y - 0.3, abs=0.06) and bx == pytest.approx(x, abs=0.06), (bx, by)
    finally:
        bench.close()


@MODELS
def test_stop_nav_cancels_the_goal_and_the_robot_stays_where_it_stopped(tmp_path: Path, model: RobotModel) -> None:
    bench = navigation_bench(tmp_path, model)
    try:
        nav = behavior(bench, SetNavGoal, "NAV", nav=True, goal="4 1.8 0")
        wait = behavior(bench, WaitGoal, "WAIT", nav=True)
        run_states(bench, [nav], 30.0)
        wait.start()
        driven = bench.run(lambda: wait.step().progress > 0.25, 60.0)
        assert driven, f"the robot did not get a quarter of the way: {bench.truth()}"
        halt = behavior(bench, StopNavigation, "HALT", nav=True, base=True, goal="")
        _, status = run_states(bench, [halt], 10.0)[-1]
        assert status.done, status
        bench.run(lambda: False, 1.0)  # the base brakes
        stopped = bench.truth()
        bench.run(lambda: False, 4.0)
        x, y, _ = bench.truth()
        assert math.dist((x, y), stopped[:2]) < 0.02, "the robot drove on after HALT"
        assert math.dist((x, y), (4.0, 1.8)) > 0.5, "HALT came too late to tell"
        # the cancelled goal's result, as an action's: a WAIT still following it ends, with the reason
        status_now = bench.latest("/nav/status")
        assert isinstance(status_now, Mapping), status_now
        assert (status_now["goal"], status_now["state"]) == ("4 1.8 0", "cancelled"), status_now
        ended = wait.step()
        assert ended.failed and ended.detail == "navigation failed: cancelled: the goal was set empty", ended
    finally:
        bench.close()


@MODELS
def test_wait_goal_fails_with_the_navigation_s_reason_for_an_unreachable_goal(
    tmp_path: Path, model: RobotModel
) -> None:
    bench = navigation_bench(tmp_path, model)
    try:
        states = [behavior(bench, WaitGoal, "WAIT", nav=True, goal="Walled")]
        _, status = run_states(bench, states, 30.0)[-1]
        assert status.failed, status
        assert status.detail.startswith("navigation failed: "), status.detail
        x, y, _ = bench.truth()
        assert math.dist((x, y), (1.0, 1.8)) < 0.1  # it never drove
    finally:
        bench.close()
