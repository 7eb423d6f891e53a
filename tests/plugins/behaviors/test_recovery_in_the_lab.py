"""ObjectRecovery (issue K point 3d, D225–D227) end to end in one process: the real HFSM runs the
mission of missions.xml with the real behaviors of behaviors.xml; the arm is the real
RoboticArm.MoveIt plugin in a closed loop with the simulated arm and its grasp (arm_loop.py), the
recognition is the use case's own RGB and depth pipelines and fusion on renders of the simulated lab
(benchmarks/fusion_scene.Lab). Only the base is kinematic — a move goal puts the robot at its goal
after the time the move takes at the speed the behavior configured, 1 cm beyond it along the way
(the overshoot D188 measured) — and the pose estimate is the true pose. The camera gives a frame a
second while the base stands (LOOK_FLOOR ignores what it saw while moving).

The robot stopped with the cylinder on the floor beside it, 0.3 m to its left (the dropped-object
scenario puts it 0.35 m ahead and 0.3 m left when it falls; the robot drives on until it stops):
the mission must back off, look round, approach and take the cylinder off the floor."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from typing import Any

import pytest

import ckmconf
from benchmarks.fusion_scene import Lab
from ckmconf.model import System
from plugins.sim.disturbances import Disturbances
from runtime.missions.behaviors import Behavior
from runtime.missions.hfsm import MissionEngine
from runtime.resources.api import Bounds
from tests.conftest import REPO
from tests.memory_service import wired_behavior
from tests.plugins.manipulation.arm_loop import ArmLoop, arm_plugin

START = (3.0, 3.0, 0.0)
OVERSHOOT = 0.01
RED = "cylinder_red_stripes"


class Handle:
    """A service handle reading a service's outputs and measures from the simulation."""

    def __init__(self, ref: str, outputs: Callable[[], Mapping[str, Any]], measures: Callable[[], Mapping[str, float]]):
        self.ref, self._outputs, self._measures = ref, outputs, measures
        self.configured: list[dict[str, Any]] = []

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        self.configured.append(dict(parameters))

    def output(self, name: str) -> Any:
        return self._outputs().get(name)

    def measures(self) -> dict[str, float]:
        return dict(self._measures())

    def samples(self, measure: str) -> list[float]:
        value = self._measures().get(measure)
        return [] if value is None else [value]

    def running(self) -> bool:
        return True


class Recovery:
    """The lab, the arm loop, the kinematic base and the services the recovery's behaviors use."""

    def __init__(self, system: System, lab: Lab) -> None:
        self.system, self.lab = system, lab
        self.time = 0.0
        self.pose = START
        lab.place(*START)
        self.plugin = arm_plugin()
        self.plugin.setup()
        self.loop = ArmLoop(lab.world, lab.robot, self.plugin)
        self.topics: dict[str, Any] = {}
        self.move: dict[str, Any] | None = None
        self.move_status: dict[str, Any] = {}
        self.arrive = 0.0
        self.goal_at: tuple[float, float, float] = START
        self.fused: dict[str, Any] = {}
        self.next_frame = 0.0
        self.moves: list[dict[str, Any]] = []
        empty: Callable[[], Mapping[str, Any]] = dict
        self.handles = {
            "RoboticArm.MoveIt": Handle("RoboticArm.MoveIt", lambda: self.loop.result,
                                        lambda: {k: self.loop.result[k] for k in ("active", "holding")}),
            "MobileBase.Displacement": Handle("MobileBase.Displacement", lambda: {"move_status": self.move_status},
                                              dict),
            "Navigation.AMCL": Handle("Navigation.AMCL", empty, dict),
            "GlobalRecog.Fusion": Handle("GlobalRecog.Fusion", lambda: self.fused,
                                         lambda: {"reliability": float(self.fused.get("reliability", 0.0))}),
            "RGBDCamera.RGBRecog": Handle("RGBDCamera.RGBRecog", empty, dict),
            "RGBDCamera.DepthRecog": Handle("RGBDCamera.DepthRecog", empty, dict),
        }  # fmt: skip

    def factory(self, behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        return wired_behavior(self.system, behavior, self.handles.__getitem__, self.topics, self.publish, now)

    def publish(self, topic: str, message: Any) -> None:
        self.topics[topic] = message
        if topic == "/arm/goal":
            self.loop.goal = dict(message)
        elif topic == "/base/move_goal":
            self._start_move(message)

    def _start_move(self, move: Mapping[str, Any]) -> None:
        """The goal pose, and when the base gets there (at the configured speed, turning at 1 rad/s)."""
        speeds = [float(c["speed"]) for c in self.handles["MobileBase.Displacement"].configured if "speed" in c]
        speed = speeds[-1] if speeds else 0.07
        x, y, yaw = (float(move[k]) for k in ("x", "y", "yaw"))
        distance = math.hypot(x, y)
        if distance > 0:
            x, y = x * (1 + OVERSHOOT / distance), y * (1 + OVERSHOOT / distance)
        px, py, pyaw = self.pose
        self.goal_at = (px + math.cos(pyaw) * x - math.sin(pyaw) * y, py + math.sin(pyaw) * x + math.cos(pyaw) * y,
                        pyaw + yaw)  # fmt: skip
        self.move, self.arrive = dict(move), self.time + distance / speed + abs(yaw) + 0.5
        self.moves.append(dict(move))
        self.move_status = {"id": move["id"], "state": "moving", "remaining": distance, "total": distance}

    def advance(self, step: float) -> None:
        self.loop.run(step)
        self.time += step
        if self.move is not None and self.time >= self.arrive:
            self.pose = self.goal_at
            self.lab.place(*self.pose)
            self.lab.world.step(12)
            self.move_status = {**self.move_status, "state": "done", "remaining": 0.0}
            self.move = None
        self.topics["/nav/pose"] = {"pose": dict(zip(("x", "y", "yaw"), self.pose, strict=True))}
        if self.move is None and self.time >= self.next_frame:  # camera and fusion at 1 Hz (lab: 2 Hz, 0.8 s)
            self.next_frame = self.time + 1.0
            view = self.lab.observe(self.pose)
            self.fused = view.fused
            self.topics["/recog/objects"] = view.fused

    def close(self) -> None:
        self.plugin.stop()


@pytest.fixture(scope="module")
def system() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


@pytest.fixture
def recovery(system: System) -> Iterator[Recovery]:
    lab = Lab("VGA", "QVGA", seed=3)
    made = Recovery(system, lab)
    yield made
    made.close()
    lab.close()


@pytest.mark.parametrize("where", [(0.0, 0.3), (0.1, -0.3)])
def test_the_recovery_backs_off_finds_approaches_and_picks_the_cylinder_off_the_floor(
    recovery: Recovery, where: tuple[float, float]
) -> None:
    """The cylinder beside the robot (x ahead, y to the left, m): 0.3 m to the left (the scenario's
    side), or to the right, where the first views show its print from a side the RGB recognition
    does not know: LOOK_FLOOR looks at it again from round it (`probe`)."""
    lab, loop = recovery.lab, recovery.loop
    for number, (group, pose) in enumerate([("arm", "carry"), ("gripper", "closed")], 1):  # closed on nothing
        assert loop.reach({"id": -number, "group": group, "pose": pose})["state"] == "reached"
    assert loop.result["holding"] == 0
    cylinder = lab.world.objects[RED]
    Disturbances._set_down(cylinder, START[0] + where[0], START[1] + where[1], 0.0, lab.world)  # START's yaw is 0
    lab.world.step(24)
    engine = MissionEngine(recovery.system, "ObjectRecovery", factory=recovery.factory, clock=lambda: recovery.time)
    engine.start()
    paths = [engine.active_path()]
    while engine.outcome is None and recovery.time < 200.0:
        recovery.advance(0.1)
        engine.step()
        if engine.active_path() not in (None, paths[-1]):
            paths.append(engine.active_path())
    assert engine.outcome == "picked", (paths, recovery.time)
    assert [path.split("/")[-1] for path in paths if path] == ["HALT", "STOW", "LOOK", "APPR", "PICK"]
    assert loop.gripper.held == cylinder and loop.result["holding"] == 1
    assert lab.world.pose(cylinder)[0][2] > 0.3  # lifted to the carry pose
    assert recovery.moves[1] == {**recovery.moves[1], "x": -0.4, "yaw": 0.0}  # LOOK backed off first
