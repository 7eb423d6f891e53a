"""APPR after a missed grasp, end to end in one process (D207): the real SPOT, APPR and PICK behaviors of
behaviors.xml; the real Displacement service driving the simulated Turtlebot's wheels on its wheel
odometry (the real ``diff-drive-odometry``, the left wheel read 1 % large, as tests/plugins/navigation/loop.py
does: the heading drifts as the use case's odometry does, 0.01-0.03 rad over a drive); the real
RoboticArm.MoveIt plugin in a closed loop with the simulated arm and its grasp (arm_loop.py); the use
case's own RGB and depth recognition and fusion on renders of the simulated lab (benchmarks/fusion_scene.Lab),
a result 0.8 s after its frame (the fusion's period), placed with the pose estimate of that moment. The
estimate is the true pose with a constant bias (3 cm, 0.01 rad: what AMCL showed in the lab).

The robot starts where BACK leaves it after a grasp missed by 5 cm: 0.7 m from the cylinder, 5.7 cm
to its side and turned 11° (the run the decision was made from). The approach must end facing the
cylinder within a centimetre, and PICK must catch it. The normal start (NAV's goal, straight on, 0.6 m)
goes in one move, as before."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Mapping
from typing import Any

import pytest
from ckm_lab.devices import KOBUKI

import ckmconf
from benchmarks.fusion_scene import Lab
from ckmconf.model import Param, System
from plugins.controllers.odometry import DiffDriveOdometry
from plugins.navigation.displacement import BaseDisplacement
from plugins.sim.robots import DiffDriveBase
from runtime.missions.behaviors import Behavior, BehaviorStatus
from runtime.resources.api import Bounds
from runtime.resources.spt import Context
from tests.conftest import REPO
from tests.memory_service import wired_behavior
from tests.plugins.behaviors.test_recovery_in_the_lab import Handle
from tests.plugins.controllers.vector_records import record
from tests.plugins.manipulation.arm_loop import CONTROL_STEPS, SERVICE_STEPS, ArmLoop, arm_plugin
from tests.plugins.navigation.loop import plugin

RED = "cylinder_red_stripes"
CYLINDER = (7.6, 6.1)  # the lab's red-striped cylinder (environment.xml)
BIAS = (0.03, -0.01, 0.01)  # the pose estimate's error (m, m, rad)
ODOM_BIAS = 0.01  # the left wheel's speed read this much too large (a wheel-radius error)
WHEEL_RADIUS = 0.035
FUSION_PERIOD = 0.8


def _relative(pose: tuple[float, float, float], point: tuple[float, float]) -> tuple[float, float]:
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return c * dx + s * dy, -s * dx + c * dy


class BaseHandle(Handle):
    """The Displacement service's handle: a configured ``speed`` reaches the plugin as a float (the service's
    ``<Parameter type="float">``), as the Smart Resource passes it."""

    def __init__(self, base: BaseDisplacement, outputs: Any) -> None:
        super().__init__("MobileBase.Displacement", outputs, dict)
        self.base = base

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        super().configure(parameters, requirements)
        self.base.apply_service_parameters({k: float(v) for k, v in parameters.items()})


class Approacher:
    """The lab, the arm loop, the base loop and the recognition, stepped together in simulated time."""

    def __init__(self, system: System, lab: Lab, start: tuple[float, float, float]) -> None:
        self.system, self.lab = system, lab
        lab.place(*start)
        lab.world.step(24)
        self.arm = arm_plugin()
        self.arm.setup()
        self.loop = ArmLoop(lab.world, lab.robot, self.arm)
        self.wheels = DiffDriveBase(lab.robot, **KOBUKI)
        self.odometer = DiffDriveOdometry(record(
            "diff-drive-odometry", 0.02, [("left_speed", "measure"), ("right_speed", "measure")],
            ["/kobuki/wheel_odom"], wheelBase=0.230,
        ))  # fmt: skip
        self.base = plugin("base-displacement", BaseDisplacement)
        self.base_inputs: dict[str, Any] = {}
        self.base_result: dict[str, Any] = {}
        self.topics: dict[str, Any] = {}
        self.moves: list[dict[str, Any]] = []
        self.pending: Any = None  # the recognition of the last frame, fused at the next period
        self.next_fusion = 0.0
        self.ticks = 0
        self.handles = {
            "RoboticArm.MoveIt": Handle("RoboticArm.MoveIt", lambda: self.loop.result,
                                        lambda: {k: self.loop.result[k] for k in ("active", "holding")}),
            "MobileBase.Displacement": BaseHandle(self.base, lambda: self.base_result),
            "GlobalRecog.Fusion": Handle("GlobalRecog.Fusion", lambda: self.topics.get("/recog/objects") or {}, dict),
            "RGBDCamera.RGBRecog": Handle("RGBDCamera.RGBRecog", dict, dict),
            "RGBDCamera.DepthRecog": Handle("RGBDCamera.DepthRecog", dict, dict),
        }  # fmt: skip
        self.advance(1.0)  # odometry, estimate and a first fused result flowing

    @property
    def time(self) -> float:
        return self.lab.world.time

    def behavior(self, name: str, **params: str) -> Behavior:
        system = self.system
        if params:  # the behavior with these Params changed
            behaviors = tuple(
                b if b.name != name else dataclasses.replace(
                    b, params=tuple(q for q in b.params if q.name not in params)
                    + tuple(Param(name=k, value=v) for k, v in params.items()))
                for b in system.behaviors
            )  # fmt: skip
            system = dataclasses.replace(system, behaviors=behaviors)
        made = wired_behavior(system, name, self.handles.__getitem__, self.topics, self.publish, lambda: self.time)
        made.start()
        return made

    def publish(self, topic: str, message: Any) -> None:
        self.topics[topic] = message
        if topic == "/arm/goal":
            self.loop.goal = dict(message)
        elif topic == "/base/move_goal":
            self.base_inputs["move_goal"] = dict(message)
            self.moves.append(dict(message))

    def truth(self) -> tuple[float, float, float]:
        return self.lab.robot.planar_pose()

    def estimate(self) -> dict[str, Any]:
        x, y, yaw = self.truth()
        return {"stamp": self.time, "pose": {"x": x + BIAS[0], "y": y + BIAS[1], "yaw": yaw + BIAS[2]}}

    def _recognise(self) -> tuple[Any, Any]:
        """The RGB and depth recognition of a frame rendered now (as Lab.observe, without moving the robot)."""
        rgb_image, depth_image, _ = self.lab.render()
        stamp = Context(frame=self.lab.frames, stamp=self.time, resource="RGBDCamera")
        value: Any = rgb_image
        for step in self.lab.rgb:
            value = step.process(value, stamp)
        rgb = value
        value = depth_image
        for step in self.lab.depth:
            value = step.process(value, stamp)
        return rgb, value

    def _fuse(self) -> None:
        """The fusion's period: last period's recognition placed with the estimate of now; a new frame taken."""
        estimate = self.estimate()
        self.topics["/nav/pose"] = estimate
        if self.pending is not None:
            rgb, depth = self.pending
            context = Context(frame=self.lab.frames, stamp=self.time, resource="GlobalRecog")
            self.topics["/recog/objects"] = self.lab.fusion.process({"rgb": rgb, "depth": depth, "pose": estimate},
                                                                    context)  # fmt: skip
        self.pending = self._recognise()

    def _base(self) -> None:
        """The Displacement service's period (0.05 s) on the newest wheel odometry."""
        self.base_result = self.base.process(dict(self.base_inputs), Context(self.ticks, self.time, "MobileBase"))
        command = self.base_result["wheel_cmd"]
        self.wheels.drive(float(command["linear"]), float(command["angular"]))

    def _odometry(self) -> None:
        left = self.lab.robot.joint_state(self.wheels.left)[1] * WHEEL_RADIUS * (1.0 + ODOM_BIAS)
        right = self.lab.robot.joint_state(self.wheels.right)[1] * WHEEL_RADIUS
        (message,) = self.odometer.step_outputs({"measure[0]": left, "measure[1]": right}, CONTROL_STEPS / 240)
        self.base_inputs["wheel_odom"] = message

    def advance(self, seconds: float) -> None:
        """``seconds`` of the loops: arm control and wheel odometry at 60 Hz, arm and base services at 20 Hz."""
        for _ in range(round(seconds * 240 / SERVICE_STEPS)):
            for _ in range(SERVICE_STEPS // CONTROL_STEPS):
                self.loop.control()
                self.lab.world.step(CONTROL_STEPS)
                self._odometry()
            self.loop.service()
            self._base()
            self.ticks += 1
            if self.time + 1e-9 >= self.next_fusion:
                self.next_fusion += FUSION_PERIOD
                self._fuse()

    def run(self, behavior: Behavior, limit: float) -> BehaviorStatus:
        """Step ``behavior`` every 0.1 s until it ends (at most ``limit`` simulated seconds)."""
        end = self.time + limit
        while self.time < end:
            self.advance(0.1)
            status = behavior.step()
            if status.done or status.failed:
                return status
        raise AssertionError(f"{behavior.owner} did not end in {limit} s: {behavior.step()}")

    def close(self) -> None:
        self.arm.stop()


@pytest.fixture(scope="module")
def system() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


@pytest.fixture
def lab() -> Iterator[Lab]:
    made = Lab("VGA", "QVGA", seed=3)
    yield made
    made.close()


def _after_back(side: float, turn: float, back: float = 0.7) -> tuple[float, float, float]:
    """``back`` m in front of the cylinder, ``side`` m to its side (+: right, facing it), turned ``turn`` rad."""
    return CYLINDER[0] + side, CYLINDER[1] - back, math.pi / 2 + turn


def _spot_approach(rig: Approacher) -> tuple[list[dict[str, Any]], BehaviorStatus]:
    spot = rig.behavior("SPOT")
    assert rig.run(spot, 10.0).done
    appr = rig.behavior("APPR")
    status = rig.run(appr, 60.0)
    return list(appr.context.events), status


@pytest.mark.parametrize("start", [(0.057, 0.19), (-0.057, 0.19), (0.057, -0.19)], ids=["right-turned-in",
                                                                                          "left-turned-out",
                                                                                          "right-turned-out"])
def test_after_back_the_approach_ends_facing_the_cylinder_and_pick_catches_it(
    system: System, lab: Lab, start: tuple[float, float]
) -> None:
    rig = Approacher(system, lab, _after_back(*start))
    try:
        events, status = _spot_approach(rig)
        assert status.done, status
        assert [e["message"] for e in events] == ["re-aimed"] and len(rig.moves) == 2
        rig.advance(0.5)
        ahead, lateral = _relative(rig.truth(), CYLINDER)
        assert abs(lateral) < 0.01, (ahead, lateral, rig.moves)
        assert 0.27 < ahead < 0.31
        pick = rig.behavior("PICK")
        assert rig.run(pick, 40.0).done
        assert rig.loop.gripper.held == lab.world.objects[RED]
    finally:
        rig.close()


def test_from_navs_goal_the_approach_is_one_move_as_before(system: System, lab: Lab) -> None:
    """NAV's goal is 0.6 m from the objects, straight on: a 0.31 m drive, shorter than ``reaimAbove``."""
    rig = Approacher(system, lab, _after_back(0.0, 0.0, back=0.6))
    try:
        events, status = _spot_approach(rig)
        assert status.done and events == [] and len(rig.moves) == 1
        rig.advance(0.5)
        ahead, lateral = _relative(rig.truth(), CYLINDER)
        assert abs(lateral) < 0.015 and 0.27 < ahead < 0.31, (ahead, lateral)
        assert rig.run(rig.behavior("PICK"), 40.0).done
        assert rig.loop.gripper.held == lab.world.objects[RED]
    finally:
        rig.close()
