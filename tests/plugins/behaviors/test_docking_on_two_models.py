"""dock-robot and undock-robot over the docking service (plugin.docking), on the Turtlebot and the rover.

The bench's real navigation and base-drive services move the robot in the pybullet world
(tests/plugins/navigation/loop.py); the docking service sends its moves to the base-drive service as
a behavior would. The robot first navigates to the dock's staging pose (the docking service drives
straight lines only), then docks: what counts is where the robot ends in the world.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import pytest

from plugins.behaviors.docking import DockRobot, UndockRobot
from plugins.behaviors.navigation_goals import SetNavGoal, WaitGoal
from plugins.navigation.docking import Docking
from runtime.missions.behaviors import Behavior
from tests.plugins.behaviors.closed_loop import BenchNavigation, OutputsService, angle, run_states, wired
from tests.plugins.navigation.loop import ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel, Service, plugin, room

MODELS = pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)
CHARGER = (4.6, 2.9, math.pi / 2)  # in front of the room's cabinet, facing it
STAGING = (4.6, 2.3, math.pi / 2)


def docking_bench(tmp_path: Path, model: RobotModel, *, inputs: Mapping[str, str] | None = None,
                  **params: object) -> Bench:
    bench = Bench(room(tmp_path), (1.0, 1.8, 0.0), model=model,
                  nav={"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"})
    docks = f"charger: {CHARGER[0]} {CHARGER[1]} {CHARGER[2]:.4f}"
    given = {"goal": "/dock/goal", "pose": "/nav/pose", "move_status": "/base/move_status", **(inputs or {})}
    bench.services["dock"] = Service(plugin("docking", Docking, docks=docks, **params), given,
                                     {"move_goal": "/base/move_goal", "status": "/dock/status"}, 0.1)
    return bench


def states(bench: Bench, dock: Behavior) -> list[Behavior]:
    goal = " ".join(f"{v:.4f}" for v in STAGING)
    return [wired(bench, SetNavGoal, "NAV", {"nav": BenchNavigation(bench)}, configure={"nav": {"goal": goal}}),
            wired(bench, WaitGoal, "WAIT", {"nav": BenchNavigation(bench)}), dock]


def docker(bench: Bench, cls: type[Behavior] = DockRobot, dock: str = "", pose: str = "") -> Behavior:
    params = {k: v for k, v in (("dock", dock), ("pose", pose)) if v}
    docking = OutputsService("Base.Dock", lambda name: bench.latest(f"/dock/{name}"))
    return wired(bench, cls, cls.__name__.upper(), {"dock": docking}, {},
                 {"dock_goal": "/dock/goal"}, configure=None, **params)


@MODELS
def test_dock_at_a_named_dock_then_undock(tmp_path: Path, model: RobotModel) -> None:
    bench = docking_bench(tmp_path, model)
    try:
        statuses = run_states(bench, states(bench, docker(bench, dock="charger")), 150.0)
        assert statuses[-1][0] == "DOCKROBOT" and statuses[-1][1].done, statuses[-1]
        x, y, yaw = bench.truth()
        assert math.dist((x, y), CHARGER[:2]) < 0.12, (x, y)
        assert angle(yaw, CHARGER[2]) < 0.15, yaw
        status = bench.latest("/dock/status")
        assert status["state"] == "docked" and status["attempt"] >= 1

        _, undocked = run_states(bench, [docker(bench, UndockRobot)], 30.0)[-1]
        assert undocked.done, undocked
        ux, uy, _ = bench.truth()
        assert uy == pytest.approx(y - 0.6, abs=0.08) and ux == pytest.approx(x, abs=0.08), (ux, uy)
    finally:
        bench.close()


@MODELS
def test_docked_needs_contact_when_the_service_reads_one(tmp_path: Path, model: RobotModel) -> None:
    """A charger's contacts: 1 while the robot's front touches the dock's line (the bench has no charger,
    so the contact is read from the world's own pose of the robot)."""
    bench = docking_bench(tmp_path, model, inputs={"contact": "/dock/contact"}, contactTimeout="1.0")
    front = 0.18 if model is TURTLEBOT_MODEL else 0.32

    def contact() -> None:
        x, y, yaw = bench.truth()
        near = abs(y + front * math.sin(yaw) - (CHARGER[1] + front)) < 0.06 and abs(x - CHARGER[0]) < 0.1
        bench.publish("/dock/contact", 1 if near else 0)

    original = bench.step

    def step() -> None:
        original()
        if round(bench.now / 0.005) % 10 == 0:
            contact()

    bench.step = step  # type: ignore[method-assign]
    try:
        statuses = run_states(bench, states(bench, docker(bench, dock="charger")), 150.0)
        assert statuses[-1][1].done, statuses[-1]
        assert bench.latest("/dock/contact") == 1
    finally:
        bench.close()


def test_an_approach_never_within_tolerance_is_retried_then_fails_with_its_reason(tmp_path: Path) -> None:
    bench = docking_bench(tmp_path, TURTLEBOT_MODEL, tolerance="0.0001", retries="1")
    try:
        statuses = run_states(bench, states(bench, docker(bench, pose="4.6 2.9 1.5708")), 200.0)
        name, status = statuses[-1]
        assert name == "DOCKROBOT" and status.failed
        assert status.detail.startswith("the docking failed: ended ") and "(attempt 2 of 2)" in status.detail
        assert bench.latest("/dock/status")["attempt"] == 2
    finally:
        bench.close()


def test_an_unknown_dock_fails_at_once_and_names_the_known_ones(tmp_path: Path) -> None:
    bench = docking_bench(tmp_path, TURTLEBOT_MODEL)
    try:
        _, status = run_states(bench, [docker(bench, dock="station")], 5.0)[-1]
        assert status.failed and "no dock 'station' (docks: charger)" in status.detail
        assert math.dist(bench.truth()[:2], (1.0, 1.8)) < 0.05
    finally:
        bench.close()
