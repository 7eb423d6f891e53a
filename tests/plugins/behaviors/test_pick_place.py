"""``behavior.pick-object`` / ``behavior.place-object`` (issue M, point 3): their goals by fresh id over
``arm-motion`` + ``gripper``, a refusal's reason in the detail, a stale status never advancing a step,
and in the pybullet closed loop on two robot models (the Turtlebot's arm and the station arm) a real
pick and place through the real arm-poses and parallel-gripper services; the lab's ``pick`` and ``place``
(named-pose sequences) on the same two arms."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator, Mapping
from typing import Any

import pybullet as p
import pytest

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorOutput, Uses
from plugins.behaviors.manipulation import ArmSequence
from plugins.behaviors.pick_place import PickObject, PlaceObject
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.resources.api import Bounds
from tests.memory_service import MemoryService
from tests.plugins.manipulation.manipulator_loop import STATION, TURTLEBOT, ManipulatorLoop, Model
from tests.plugins.manipulation.test_gripper_closed_loop import _box, _height, _loop

KINDS: dict[str, type[Behavior]] = {"pick-object": PickObject, "place-object": PlaceObject}


def record(kind: str, **params: str) -> BehaviorRecord:
    return BehaviorRecord(name=kind.split("-")[0].upper(), kind=kind, timeout=60.0,
                          params=tuple(Param(name=k, value=v) for k, v in params.items()),
                          uses=(Uses(service="Arm.Motion", as_="arm"), Uses(service="Arm.Gripper", as_="gripper")),
                          outputs=(BehaviorOutput(name="arm_goal", topic="/arm/goal"),
                                   BehaviorOutput(name="gripper_command", topic="/gripper/command")))


def behavior(kind: str, services: Mapping[str, Any], written: list[tuple[str, Any]], **params: str) -> Behavior:
    context = BehaviorContext(services=services, inputs={},
                              outputs={n: functools.partial(lambda n, v: written.append((n, v)), n)
                                       for n in ("arm_goal", "gripper_command")}, now=lambda: 0.0)
    made = KINDS[kind](record(kind, **params), context)
    made.start()
    return made


PICK = {"approach": "0.22 0 0.36 1.5708", "grasp": "0.28 0 0.36 1.5708", "lift": "carry"}


@pytest.fixture
def memory() -> dict[str, MemoryService]:
    return {"arm": MemoryService("Arm.Motion"), "gripper": MemoryService("Arm.Gripper")}


def test_pick_sends_its_goals_in_turn_each_after_its_own_status(memory: dict[str, MemoryService]) -> None:
    written: list[tuple[str, Any]] = []
    pick = behavior("pick-object", memory, written, effort="15", **PICK)
    name, command = written[-1]
    assert name == "gripper_command" and command["action"] == "open"
    memory["gripper"].outputs["status"] = {"id": command["id"] - 1, "state": "reached"}  # an earlier command's
    assert pick.step() == BehaviorStatus(progress=0.0)
    memory["gripper"].outputs["status"] = {"id": command["id"], "state": "reached"}
    assert pick.step().progress == pytest.approx(0.2)
    name, goal = written[-1]
    assert name == "arm_goal" and goal["target"] == {"x": 0.22, "y": 0.0, "z": 0.36, "pitch": 1.5708}
    memory["arm"].outputs["status"] = {"id": goal["id"], "state": "reached"}
    pick.step()
    memory["arm"].outputs["status"] = {"id": written[-1][1]["id"], "state": "reached"}
    pick.step()
    name, close = written[-1]
    assert close == {"id": close["id"], "action": "close", "max_effort": 15.0}
    memory["gripper"].outputs["status"] = {"id": close["id"], "state": "reached", "holding": False}
    failed = pick.step()
    assert failed.failed and failed.detail == "close the gripper: the gripper closed on nothing"
    assert failed.progress == pytest.approx(0.6)


def test_a_refused_arm_target_s_reason_reaches_the_detail(memory: dict[str, MemoryService]) -> None:
    written: list[tuple[str, Any]] = []
    pick = behavior("pick-object", memory, written, **PICK)
    memory["gripper"].outputs["status"] = {"id": written[-1][1]["id"], "state": "reached"}
    pick.step()
    reason = "goal 9: target (0.220, 0.000, 0.360, pitch 1.571) cannot be reached: out of reach: the nearest " \
             "tool point is 3.1 cm away"
    memory["arm"].outputs["status"] = {"id": written[-1][1]["id"], "state": "failed", "error": reason}
    failed = pick.step()
    assert failed.failed and failed.detail == f"approach (0.22 0 0.36 1.5708): {reason}"


def test_a_newer_goal_preempts_an_older_one_without_a_stale_status(memory: dict[str, MemoryService]) -> None:
    written: list[tuple[str, Any]] = []
    first = behavior("pick-object", memory, written, **PICK)
    older = written[-1][1]["id"]
    second = behavior("pick-object", memory, written, **PICK)  # a newer pick preempts the older's command
    newer = written[-1][1]["id"]
    assert newer > older
    memory["gripper"].outputs["status"] = {"id": older, "state": "reached"}  # the preempted command's, late
    assert second.step().progress == 0.0 and not second.step().failed
    memory["gripper"].outputs["status"] = {"id": newer, "state": "reached"}
    assert second.step().progress == pytest.approx(0.2)
    assert first.step().progress == 0.0  # the older never reads the newer's status as its own


def test_place_fails_when_nothing_is_held_and_a_stalled_jaw_says_where(memory: dict[str, MemoryService]) -> None:
    written: list[tuple[str, Any]] = []
    place = behavior("place-object", memory, written, above="0.2 0 0.4 1.3", place="place", retreat="ready")
    memory["gripper"].values["holding"] = 0.0
    assert place.step().detail == "the gripper holds nothing to place"
    memory["gripper"].values["holding"] = 1.0
    place = behavior("place-object", memory, written, above="0.2 0 0.4 1.3", place="place", retreat="ready")
    for _ in range(2):
        memory["arm"].outputs["status"] = {"id": written[-1][1]["id"], "state": "reached"}
        place.step()
    memory["gripper"].outputs["status"] = {"id": written[-1][1]["id"], "state": "stalled",
                                           "reason": "command 4: the fingers stopped at 0.0100, 0.0350 short of 0.0450"}
    stalled = place.step()
    assert stalled.failed and stalled.detail.startswith("open the gripper: command 4: the fingers stopped at 0.0100")


@pytest.mark.parametrize("value", ["0.2 0.3", "1 2 3 4 5", "0.2 nan 0.3"])
def test_a_bad_arm_step_param_is_refused_with_the_behavior_s_name(memory: dict[str, MemoryService],
                                                                  value: str) -> None:
    with pytest.raises(ParamError, match=r"behavior 'PICK' \(pick-object\): parameter 'grasp' = .* is neither"):
        behavior("pick-object", memory, [], **{**PICK, "grasp": value})


# ---------------------------------------------------------------- closed loop, two robot models


class LoopService:
    """A service handle on one of a ManipulatorLoop's services: its newest outputs and measures."""

    def __init__(self, loop: ManipulatorLoop, result: str) -> None:
        self.ref, self.loop, self.result = result, loop, result

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        return None

    def output(self, name: str) -> Any:
        return getattr(self.loop, self.result).get(name)

    def measures(self) -> dict[str, float]:
        return {k: float(v) for k, v in getattr(self.loop, self.result).items() if isinstance(v, int | float)}

    def samples(self, measure: str) -> list[float]:
        return [self.measures().get(measure, 0.0)]

    def running(self) -> bool:
        return True


def run(loop: ManipulatorLoop, kind: str, params: Mapping[str, str], limit: float = 30.0) -> BehaviorStatus:
    """The behavior stepped every 0.05 s of simulated time with the loop, until it ends."""

    def publish(name: str, value: Any) -> None:
        if name == "arm_goal":
            loop.arm_goal = value
        else:
            loop.command = value

    services = {"arm": LoopService(loop, "arm_result"), "gripper": LoopService(loop, "gripper_result")}
    context = BehaviorContext(services=services, inputs={}, now=lambda: loop.world.time,
                              outputs={n: functools.partial(publish, n) for n in ("arm_goal", "gripper_command")})
    made = KINDS[kind](record(kind, **params), context)
    made.start()
    start, progress = loop.world.time, []
    while loop.world.time - start < limit:
        loop.run(0.05)
        status = made.step()
        progress.append(status.progress)
        if status.done or status.failed:
            assert progress == sorted(progress)  # progress only grows
            return status
    raise AssertionError(f"{kind} did not end in {limit} s")


@pytest.fixture(params=[TURTLEBOT, STATION], ids=lambda m: m.name)
def cell(request: pytest.FixtureRequest) -> Iterator[tuple[ManipulatorLoop, int, dict[str, str], dict[str, str]]]:
    """A loop, the object to pick, and the pick's and place's Params on that robot model."""
    model: Model = request.param
    pose = (2.0, 2.0, 0.4) if model is TURTLEBOT else (1.0, 1.0, 0.0)
    for loop in _loop(model, pose):
        if model is TURTLEBOT:  # a 4 cm part on a post, its centre at 0.28 m ahead, 0.36 m up
            _box(loop, (0.29, 0.0, 0.17), (0.03, 0.03, 0.17), 0.0)
            body = _box(loop, (0.28, 0.0, 0.36), (0.02, 0.02, 0.02), 0.1)
            pick = {"approach": "0.22 0 0.36 1.5708", "grasp": "0.28 0 0.36 1.5708", "lift": "0.22 0 0.40 1.3"}
            # the caught part stays where the fingers took it, at the tool point (D296): set down there
            place = {"above": "0.26 0 0.38 1.5708", "place": "0.28 0 0.37 1.5708", "retreat": "0.20 0 0.37 1.5708"}
        else:  # a 0.3 m parcel on the work table, named poses and targets without pitch (D264)
            _box(loop, (0.55, 0.0, 0.35), (0.2, 0.25, 0.35), 0.0)
            body = _box(loop, (0.5, 0.0, 0.776), (0.1, 0.15, 0.075), 0.5)
            pick = {"approach": "0.5 0 0.95", "grasp": "0.5 0 0.80", "lift": "home", "effort": "30"}
            place = {"above": "0.5 0 0.95", "place": "0.5 0 0.81", "retreat": "home"}
        loop.world.step(60)
        yield loop, body, pick, place


def test_pick_then_place_on_two_robot_models(cell: tuple[ManipulatorLoop, int, dict[str, str], dict[str, str]]) -> None:
    loop, body, pick, place = cell
    resting = p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[0]
    picked = run(loop, "pick-object", pick)
    assert picked.done and picked.progress == 1.0, picked
    assert loop.grasp.held == body and _height(loop, body) - resting[2] > 0.03
    placed = run(loop, "place-object", place)
    assert placed.done, placed
    assert loop.grasp.held is None and loop.gripper_result["holding"] == 0
    loop.run(1.0)
    back = p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[0]
    assert math.dist(back, resting) < 0.03  # set down where it was picked, standing
    assert run(loop, "place-object", place).detail == "the gripper holds nothing to place"


ARM_SEQUENCES = {  # model: (the named-pose sequence, where its last pose puts the tool point, base frame)
    "turtlebot": ("arm:ready arm:carry arm:pre_grasp", (0.22, 0.0, 0.36)),
    "station_arm": ("arm:inspect arm:home", (0.35, 0.0, 1.35)),
}


def arm_sequence(loop: ManipulatorLoop, kind: str, sequence: str) -> BehaviorStatus:
    """The lab's ``kind`` (pick or place) with ``sequence``, stepped with the loop until it ends."""
    record = BehaviorRecord(name=kind.upper(), kind=kind, timeout=60.0,
                            params=(Param(name="sequence", value=sequence),),
                            uses=(Uses(service="Arm.Motion", as_="arm"),),
                            outputs=(BehaviorOutput(name="arm_goal", topic="/arm/goal"),))

    def publish(value: Any) -> None:
        loop.arm_goal = value

    context = BehaviorContext(services={"arm": LoopService(loop, "arm_result")}, inputs={},
                              outputs={"arm_goal": publish}, now=lambda: loop.world.time)
    made = ArmSequence(record, context)
    made.start()
    status, end = made.step(), loop.world.time + 30.0
    while not (status.done or status.failed) and loop.world.time < end:
        loop.run(0.05)
        status = made.step()
    return status


@pytest.mark.parametrize("model", [TURTLEBOT, STATION], ids=lambda m: m.name)
def test_the_lab_s_pick_and_place_kinds_run_a_named_pose_sequence_on_two_arms(model: Model) -> None:
    """``pick`` and ``place`` (the lab's arm sequences over arm-motion) on each arm's own named poses:
    the tool ends at the last pose; a pose the arm does not know fails with the arm's reason."""
    sequence, tool = ARM_SEQUENCES[model.name]
    pose = (2.0, 2.0, 0.4) if model is TURTLEBOT else (1.0, 1.0, 0.0)
    for loop in _loop(model, pose):
        for kind in ("pick", "place"):
            status = arm_sequence(loop, kind, sequence)
            assert status.done, (kind, status)
            assert loop.tool_in_base() == pytest.approx(tool, abs=0.02), kind
        status = arm_sequence(loop, "pick", "arm:wave")
        assert status.failed and status.detail.startswith("arm:wave: "), status
        assert "wave" in status.detail[len("arm:wave: "):], status.detail
