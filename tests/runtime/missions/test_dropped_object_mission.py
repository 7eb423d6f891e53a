"""The dropped-object branch of ObjectPlace (issue K point 3d, D226): the real HFSM engine (§5.2)
runs configs/usecase/missions.xml's ObjectPlace with the real behaviors of behaviors.xml, against
services scripted in memory that answer them as the lab's do — Navigation.AMCL's status for the
goal it was given, MobileBase.Displacement's move status by id, RoboticArm.MoveIt's status by id
and its ``holding`` measure, the fused recognition on ``/recog/objects``.

When the holding measure drops while the robot drives home, the mission stops it, looks for the
object, approaches it and picks it off the floor, then drives home again; a second drop ends it;
an object that cannot be found ends it too; with no drop the success path is unchanged."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from runtime.missions.behaviors import Behavior
from runtime.missions.hfsm import MissionEngine
from tests.conftest import REPO
from tests.memory_service import MemoryService, wired_behavior

POSE = {"x": 4.0, "y": 3.0, "yaw": -1.5}
SUCCESS = ["ObjectPlace/NAV", "ObjectPlace/WAIT", "ObjectPlace/DOCK", "ObjectPlace/PLACE", "ObjectPlace/BACK"]


class ScriptedLab:
    """The services the Turtlebot's behaviors use, answering their goals after a short delay."""

    def __init__(self, system: System, *, visible_after: int | None = 3) -> None:
        self.system = system
        self.time = 0.0
        self.services: dict[str, MemoryService] = {}
        self.topics: dict[str, Any] = {"/nav/pose": {"pose": POSE}}
        self.sent: list[tuple[str, Any]] = []  # (topic, message) in order
        self.pending: list[tuple[float, Callable[[], None]]] = []
        self.visible_after = visible_after  # the object is seen once this many turns were made
        self.turns = 0
        self.goal: str | None = None
        self.goals = 0
        self.goal_set = 0.0
        self.around_object = False  # the open fingers are round the object on the floor
        self.service("RoboticArm.MoveIt").values.update(active=1.0, holding=1.0)  # carried off the workbench
        self.service("Navigation.AMCL").values["localization_dispersion"] = 0.1
        self.service("GlobalRecog.Fusion").values["reliability"] = 0.0

    def service(self, ref: str) -> MemoryService:
        return self.services.setdefault(ref, MemoryService(ref))

    def factory(self, behavior: str, path: str, now: Callable[[], float]) -> Behavior:
        """The real behavior of behaviors.xml, wired to these services and topics."""
        return wired_behavior(self.system, behavior, self.service, self.topics, self.publish, now)

    def publish(self, topic: str, message: Any) -> None:
        self.sent.append((topic, message))
        self.topics[topic] = message
        if topic == "/base/move_goal":
            self.pending.append((self.time + 1.0, functools.partial(self._moved, message)))
        elif topic == "/arm/goal":
            self.pending.append((self.time + 0.5, functools.partial(self._reached, message)))

    def _moved(self, move: Mapping[str, Any]) -> None:
        base = self.service("MobileBase.Displacement")
        base.outputs["move_status"] = {"id": move["id"], "state": "done", "remaining": 0.0, "total": 1.0}
        if move["yaw"] != 0.0 and move["x"] == 0.0:
            self.turns += 1

    def _reached(self, goal: Mapping[str, Any]) -> None:
        arm = self.service("RoboticArm.MoveIt")
        holding = False
        if goal["pose"] == "grasp_floor":
            self.around_object = True
        elif goal["group"] == "gripper":
            holding = goal["pose"] == "closed" and self.around_object
            arm.values["holding"] = 1.0 if holding else 0.0
        arm.outputs["status"] = {"id": goal["id"], "group": goal["group"], "pose": goal["pose"],
                                 "state": "reached", "active": True, "error": "", "holding": holding}

    def drop(self) -> None:
        """The object slips out of the gripper: the fingers close on nothing (D169)."""
        self.service("RoboticArm.MoveIt").values["holding"] = 0.0

    def advance(self, step: float) -> None:
        """Time passes: answer due goals; Navigation drives 1 m/s along a 10 m path to its goal."""
        self.time += step
        for due in [d for d in self.pending if d[0] <= self.time]:
            self.pending.remove(due)
            due[1]()
        nav = self.service("Navigation.AMCL")
        goals = [c["goal"] for c, _ in nav.configured if "goal" in c]
        if len(goals) != self.goals:  # a goal set (again: a new navigation) or cancelled
            self.goals, self.goal, self.goal_set = len(goals), goals[-1], self.time
        if self.goal:
            remaining = max(0.0, 10.0 - (self.time - self.goal_set))
            nav.outputs["status"] = {"goal": self.goal, "state": "arrived" if remaining == 0 else "active",
                                     "path_length": 10.0, "remaining": remaining}
        else:
            nav.outputs.pop("status", None)  # a cancelled goal: no status (plugins/navigation/amcl.py)
        if self.visible_after is not None and self.turns >= self.visible_after:
            found = {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "frame": "map",
                     "x": 4.2, "y": 2.4, "z": 0.06, "reliability": 0.9, "sources": ["rgb", "depth"],
                     "observer": [POSE]}
            self.topics["/recog/objects"] = {"objects": [found], "reliability": 0.9}
            self.service("GlobalRecog.Fusion").values["reliability"] = 0.9

    def sent_on(self, topic: str) -> list[Any]:
        return [m for t, m in self.sent if t == topic]


@pytest.fixture(scope="module")
def system() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


def run(
    lab: ScriptedLab, events: Mapping[str, Callable[[], None]] | None = None, until: float = 600.0
) -> tuple[str | None, list[str]]:
    """Run ObjectPlace to its end (simulated time, 0.1 s steps); ``events`` fire once, when the
    named state is first entered (after 2 s in it). The outcome and the states it went through."""
    engine = MissionEngine(lab.system, "ObjectPlace", factory=lab.factory, clock=lambda: lab.time)
    engine.start()
    paths: list[str] = [engine.active_path() or ""]
    entered: dict[str, float] = {paths[0]: 0.0}
    fired: set[str] = set()
    while engine.outcome is None and lab.time < until:
        lab.advance(0.1)
        for state, event in (events or {}).items():
            if state not in fired and state in entered and lab.time - entered[state] >= 2.0:
                fired.add(state)
                event()
        engine.step()
        path = engine.active_path()
        if path is not None and path != paths[-1]:
            paths.append(path)
            entered.setdefault(path, lab.time)
    return engine.outcome, paths


def test_with_no_drop_the_success_path_is_the_one_of_fig_7_12(system: System) -> None:
    outcome, paths = run(ScriptedLab(system))
    assert (outcome, paths) == ("placed", SUCCESS)


def test_a_drop_on_the_way_home_is_detected_and_the_object_picked_off_the_floor_again(system: System) -> None:
    lab = ScriptedLab(system)
    outcome, paths = run(lab, {"ObjectPlace/WAIT": lab.drop})
    recovery = ["HALT", "STOW", "LOOK", "APPR", "PICK"]
    assert paths == ["ObjectPlace/NAV", "ObjectPlace/WAIT", *(f"ObjectPlace/RECOVER/{s}" for s in recovery),
                     "ObjectPlace/RENAV", "ObjectPlace/REWAIT", "ObjectPlace/DOCK", "ObjectPlace/PLACE",
                     "ObjectPlace/BACK"]  # fmt: skip
    assert outcome == "placed"
    nav = lab.service("Navigation.AMCL").configured
    goals = [c["goal"] for c, _ in nav if "goal" in c]
    assert goals == ["1.0 1.3 1.5708", "", "1.0 1.3 1.5708", ""]  # home, HALT's cancel, home, DOCK's cancel (D211)
    moves = lab.sent_on("/base/move_goal")
    assert moves[0] == {**moves[0], "x": 0.0, "y": 0.0, "yaw": 0.0}  # HALT: the zero move that stops the path
    # LOOK turned until it saw it (3), then APPR turned to face it first (D253)
    assert sum(1 for m in moves if m["x"] == 0.0 and m["yaw"] != 0.0) == 4
    arm = [(g["group"], g["pose"]) for g in lab.sent_on("/arm/goal")]
    assert arm == [("arm", "resting"), ("arm", "pre_grasp_floor"), ("gripper", "open"), ("arm", "grasp_floor"),
                   ("gripper", "closed"), ("arm", "carry"),  # the recovery
                   ("arm", "place"), ("gripper", "open"), ("arm", "pre_grasp")]  # PLACE at home  # fmt: skip
    target = lab.topics["/agent1/target"]
    assert target["label"] == "cylinder_red_stripes" and target["observer"] == [POSE]


def test_a_second_drop_ends_the_mission_failed(system: System) -> None:
    lab = ScriptedLab(system)
    outcome, paths = run(lab, {"ObjectPlace/WAIT": lab.drop, "ObjectPlace/REWAIT": lab.drop})
    assert outcome == "failed" and paths[-1] == "ObjectPlace/REWAIT"
    assert "ObjectPlace/RECOVER/PICK" in paths


def test_an_object_not_found_round_the_robot_ends_the_mission_failed(system: System) -> None:
    """LOOK_FLOOR backs off and looks round in 9 views, three rounds, backing off before each: not_found."""
    lab = ScriptedLab(system, visible_after=None)
    outcome, paths = run(lab, {"ObjectPlace/WAIT": lab.drop})
    assert outcome == "failed" and paths[-1] == "ObjectPlace/RECOVER/LOOK"
    moves = lab.sent_on("/base/move_goal")[1:]  # after HALT's
    assert sum(1 for m in moves if m["yaw"] == pytest.approx(0.7)) == 24  # 8 turns per round of 9 views
    assert [m["x"] for m in moves if m["x"] != 0.0] == [-0.4, -0.4, -0.4]  # back first, and between the rounds
