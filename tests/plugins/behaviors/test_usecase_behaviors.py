"""The use-case behaviors (Tables 7.5, 7.7) against services simulated in memory: what they
configure, what goals they send, how their progress follows the services, when they end."""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext
from runtime.missions.payloads import check_payload
from runtime.registry import default_registry
from tests.memory_service import MemoryService

REPO = Path(__file__).resolve().parents[3]
STANDOFF = 0.29  # APPR's standoff in configs/usecase/behaviors.xml (D188)


class Rig:
    """One behavior of the use case with its services, inputs, outputs and a clock."""

    def __init__(self, system: System, name: str, inputs: dict[str, Any] | None = None,
                 drop: tuple[str, ...] = ()) -> None:
        record = system.behavior(name)
        assert record is not None
        if drop:  # the behavior without these Params (their defaults)
            record = dataclasses.replace(record, params=tuple(p for p in record.params if p.name not in drop))
        self.time = 0.0
        self.services = {u.alias: MemoryService(u.service) for u in record.uses}
        self.inputs = inputs or {}
        self.written: list[tuple[str, Any]] = []
        context = BehaviorContext(
            services=self.services,
            inputs={p.name: functools.partial(self.inputs.get, p.name) for p in record.inputs},
            outputs={p.name: functools.partial(self._write, p.name) for p in record.outputs},
            now=lambda: self.time,
        )
        self.behavior: Behavior = default_registry().resolve("behavior", record.kind, record)(record, context)
        self.behavior.start()

    def _write(self, name: str, value: Any) -> None:
        self.written.append((name, value))

    def last(self, output: str) -> Any:
        return next(v for n, v in reversed(self.written) if n == output)


@pytest.fixture(scope="module")
def lab() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


def test_nav_configures_amcl_and_ends_when_the_path_exists(lab: System) -> None:
    rig = Rig(lab, "NAV")
    ((parameters, requirements),) = rig.services["nav"].configured
    assert parameters == {"goal": "7.6 5.5 1.5708"} and requirements[0].measure == "localization_dispersion"
    assert not rig.behavior.step().done
    rig.services["nav"].outputs["status"] = {"goal": "HomeArea", "state": "active"}  # someone else's goal
    assert not rig.behavior.step().done
    rig.services["nav"].outputs["status"] = {"goal": "7.6 5.5 1.5708", "state": "active"}
    assert rig.behavior.step().done
    rig.services["nav"].outputs["status"] = {"goal": "7.6 5.5 1.5708", "state": "failed"}
    assert rig.behavior.step().failed


STRAIGHT = ("approachHeading",)  # NAV_COOP aiming straight from the robot


def test_nav_coop_waits_for_the_signal_and_aims_short_of_the_object(lab: System) -> None:
    rig = Rig(lab, "NAV_COOP", drop=STRAIGHT)
    assert rig.behavior.step().progress == 0.0  # untraceable until the Nao's position arrives
    rig.inputs["spotted"] = {"position": {"x": 3.0, "y": 4.0, "z": 0.0}}
    rig.behavior.step()
    parameters, _ = rig.services["nav"].configured[-1]
    x, y, _yaw = map(float, parameters["goal"].split())
    assert (x, y) == pytest.approx((3.0 * 4.37 / 5, 4.0 * 4.37 / 5), abs=1e-3)  # 0.63 m short of 5 m
    rig.services["nav"].outputs["status"] = {"goal": parameters["goal"], "state": "active"}
    assert rig.behavior.step().done


def test_wait_progress_is_the_share_of_the_path(lab: System) -> None:
    rig = Rig(lab, "WAIT")
    rig.services["nav"].outputs["status"] = {"state": "active", "path_length": 10.0, "remaining": 2.5}
    assert rig.behavior.step().progress == pytest.approx(0.75)
    rig.services["nav"].outputs["status"] = {"state": "arrived", "path_length": 10.0, "remaining": 0.0}
    assert rig.behavior.step().done


def test_spot_needs_the_target_from_enough_sources(lab: System) -> None:
    rig = Rig(lab, "SPOT_COOP")  # minSources 3
    seen = {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "x": 1.0, "y": 0.2,
            "z": 0.0, "reliability": 0.9, "sources": ["rgb", "depth"]}  # fmt: skip
    rig.inputs["objects"] = {"objects": [seen], "reliability": 0.9}
    assert not rig.behavior.step().done
    rig.inputs["objects"] = {"objects": [{**seen, "sources": ["rgb", "depth", "pantilt"]}], "reliability": 0.9}
    assert rig.behavior.step().done and rig.last("target")["x"] == 1.0
    types = {t.name: t for t in lab.message_types}
    assert check_payload(rig.last("target"), "ObjectPosition", types) is None  # /agent1/target's type


def test_approach_sends_base_and_arm_goals_and_follows_them_by_id(lab: System) -> None:
    rig = Rig(lab, "APPR", {"target": {"x": 1.0, "y": 0.0}})
    assert rig.behavior.step().detail == "raising the arm"  # the base waits for the arm (not through the table)
    arm = rig.last("arm_goal")
    assert arm["pose"] == "pre_grasp" and all(n != "move" for n, _ in rig.written)
    rig.services["arm"].outputs["status"] = {"id": arm["id"], "state": "reached"}
    rig.behavior.step()
    move = rig.last("move")
    assert move["x"] == pytest.approx(1.0 - STANDOFF)
    rig.services["base"].outputs["move_status"] = {"id": move["id"] + 100, "state": "done"}
    assert not rig.behavior.step().done  # a stale status of another goal
    rig.services["base"].outputs["move_status"] = {
        "id": move["id"],
        "state": "moving",
        "total": 0.72,
        "remaining": 0.36,
    }
    assert rig.behavior.step().progress == pytest.approx(0.6)  # 0.8 × half the way + 0.2 for the arm
    rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": "done"}
    assert rig.behavior.step().done


@pytest.mark.parametrize(("name", "tolerance"), [("APPR_FLOOR", 0.01), ("APPR", None)])
def test_the_floor_approach_asks_the_base_for_a_finer_final_heading(
    lab: System, name: str, tolerance: float | None
) -> None:
    """D252: the floor grasp's fingers clear the cylinder by 1 cm a side; APPR_FLOOR's move carries
    Move2D yaw_tolerance 0.01 rad, the table's APPR keeps the base's own."""
    rig = Rig(lab, name, {"target": {"x": 0.8, "y": 0.1}})
    rig.behavior.step()
    rig.services["arm"].outputs["status"] = {"id": rig.last("arm_goal")["id"], "state": "reached"}
    rig.behavior.step()
    move = rig.last("move")
    assert move.get("yaw_tolerance") == tolerance
    assert move["yaw"] == pytest.approx(math.atan2(0.1, 0.8))


def test_approach_fails_when_the_arm_cannot_rise(lab: System) -> None:
    rig = Rig(lab, "APPR", {"target": {"x": 1.0, "y": 0.0}})
    rig.behavior.step()
    rig.services["arm"].outputs["status"] = {"id": rig.last("arm_goal")["id"], "state": "failed"}
    assert rig.behavior.step().failed and all(n != "move" for n, _ in rig.written)


def test_pick_runs_its_arm_sequence_step_by_step(lab: System) -> None:
    rig = Rig(lab, "PICK")
    poses = []
    for _ in range(4):
        goal = rig.last("arm_goal")
        poses.append(f"{goal['group']}:{goal['pose']}")
        rig.services["arm"].outputs["status"] = {"id": goal["id"], "state": "reached"}
        status = rig.behavior.step()
    assert poses == ["gripper:open", "arm:grasp", "gripper:closed", "arm:carry"] and status.done


@pytest.mark.parametrize(("opening", "held"), [(0.77, True), (0.72, True), (0.64, False), (0.56, False)])
def test_pick_floor_fails_before_the_lift_when_the_fingers_closed_across_the_object_s_edge(
    lab: System, opening: float, held: bool
) -> None:
    """PICK_FLOOR's minHold (0.72, D251): round the cylinder's middle the fingers stop at 0.77 of
    their range; across its edge nearer. Such a grasp fails at gripper:closed, before arm:carry."""
    rig = Rig(lab, "PICK_FLOOR")
    for pose in ("gripper:open", "arm:grasp_floor"):
        goal = rig.last("arm_goal")
        assert f"{goal['group']}:{goal['pose']}" == pose
        rig.services["arm"].outputs["status"] = {"id": goal["id"], "state": "reached", "holding": False,
                                                 "opening": 1.0 if pose == "gripper:open" else 0.0}  # fmt: skip
        rig.behavior.step()
    closed = rig.last("arm_goal")
    rig.services["arm"].outputs["status"] = {"id": closed["id"], "state": "reached", "holding": True,
                                             "opening": opening}  # fmt: skip
    status = rig.behavior.step()
    if held:
        assert not status.failed and rig.last("arm_goal")["pose"] == "carry"
    else:
        assert status.failed and rig.last("arm_goal") == closed  # no lift
        assert status.detail == (f"gripper:closed: holds the object at {opening:.2f} of the opening, under 0.72: "
                                 "closed across its edge")
    plain = Rig(lab, "PICK")  # no minHold: any hold lifts
    for _ in range(3):
        goal = plain.last("arm_goal")
        plain.services["arm"].outputs["status"] = {"id": goal["id"], "state": "reached", "holding": True,
                                                   "opening": 0.3}  # fmt: skip
        plain.behavior.step()
    assert plain.last("arm_goal")["pose"] == "carry"


def test_fix_holds_a_reliable_recognition_then_signals_the_position(lab: System) -> None:
    rig = Rig(lab, "OBJ_FIX")
    rig.services["recog"].outputs["objects"] = {
        "objects": [{"name": "cylinder_red_stripes", "x": 2.0, "y": 1.0, "z": 0.3, "reliability": 0.9}]
    }
    for t in (0.0, 1.0):
        rig.time = t
        assert not rig.behavior.step().done
    rig.time = 2.0
    assert not rig.behavior.step().done  # held long enough, but Track has not placed it on the map
    rig.services["track"].outputs["target"] = {"stamp": 1.9, "label": "cylinder_red_stripes", "frame": "map",
                                               "x": 2.5, "y": 1.5, "z": 0.8, "reliability": 0.85}  # fmt: skip
    assert rig.behavior.step().done
    spotted = rig.last("spotted")
    assert spotted == {"stamp": 2.0, "label": "cylinder_red_stripes", "frame": "map", "x": 2.5, "y": 1.5,
                       "z": 0.8, "reliability": 0.85, "observer": []}  # fmt: skip
    types = {t.name: t for t in lab.message_types}
    assert check_payload(spotted, "ObjectPosition", types) is None  # what the signal's type asks for


def test_nav_coop_aims_short_of_a_map_position_from_where_the_robot_is(lab: System) -> None:
    rig = Rig(lab, "NAV_COOP", drop=STRAIGHT)
    rig.inputs["spotted"] = {"frame": "map", "x": 4.0, "y": 5.0, "z": 0.8}
    assert rig.behavior.step().progress == 0.0  # no pose estimate yet: it cannot aim
    rig.services["nav"].outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": 2.0}, "dispersion": 0.1}
    rig.behavior.step()
    parameters, _ = rig.services["nav"].configured[-1]
    x, y, yaw = map(float, parameters["goal"].split())
    assert (x, y) == pytest.approx((1.0 + 3.0 * 4.37 / 5, 1.0 + 4.0 * 4.37 / 5), abs=1e-3)  # 0.63 m short
    assert yaw == pytest.approx(math.atan2(4.0, 3.0), abs=1e-3)  # facing the object


def test_nav_coop_reaches_the_object_square_on_to_the_workbench(lab: System) -> None:
    """D204: along approachHeading (the workbench's free side), whatever side the robot comes from."""
    rig = Rig(lab, "NAV_COOP")
    rig.inputs["spotted"] = {"frame": "map", "x": 7.6, "y": 6.13, "z": 0.36}
    rig.services["nav"].outputs["pose"] = {"pose": {"x": 1.5, "y": 1.5, "yaw": 0.0}, "dispersion": 0.1}
    rig.behavior.step()
    parameters, _ = rig.services["nav"].configured[-1]
    assert tuple(map(float, parameters["goal"].split())) == pytest.approx((7.6, 5.5, math.pi / 2), abs=1e-3)


def test_approach_places_a_map_target_relative_to_the_robot(lab: System) -> None:
    target = {"frame": "map", "x": 2.0, "y": 3.0, "z": 0.8}
    rig = Rig(lab, "APPR", {"target": target})
    rig.behavior.step()
    rig.services["arm"].outputs["status"] = {"id": rig.last("arm_goal")["id"], "state": "reached"}
    assert rig.behavior.step().detail == "waiting for the pose estimate"
    rig.inputs["pose"] = {"pose": {"x": 2.0, "y": 2.0, "yaw": math.pi / 2}}  # facing +y, 1 m short of it
    rig.behavior.step()
    move = rig.last("move")
    assert (move["x"], move["y"]) == pytest.approx((1.0 - STANDOFF, 0.0), abs=1e-6)
    assert move["yaw"] == pytest.approx(0.0, abs=1e-6)


def test_approach_uses_the_pose_the_fusion_placed_the_target_with(lab: System) -> None:
    """A biased pose estimate placed the target; the later estimate differs: the move is the camera's own
    measurement, the observer pose's bias cancels (D172)."""
    observer = [{"x": 2.03, "y": 2.0, "yaw": math.pi / 2}]  # 3 cm off in x: the target is too, by as much
    target = {"frame": "map", "x": 2.03, "y": 3.0, "z": 0.8, "observer": observer}
    rig = Rig(lab, "APPR", {"target": target, "pose": {"pose": {"x": 2.0, "y": 2.0, "yaw": math.pi / 2}}})
    rig.behavior.step()
    rig.services["arm"].outputs["status"] = {"id": rig.last("arm_goal")["id"], "state": "reached"}
    rig.behavior.step()
    move = rig.last("move")
    assert (move["x"], move["y"]) == pytest.approx((1.0 - STANDOFF, 0.0), abs=1e-6)  # straight ahead, as seen


def test_spot_passes_the_observer_pose_on_with_the_target(lab: System) -> None:
    observer = [{"x": 1.0, "y": 2.0, "yaw": 0.5}]
    found = {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "frame": "map",
             "x": 1.5, "y": 2.2, "z": 0.8, "reliability": 0.9, "sources": ["rgb", "depth"], "observer": observer}
    rig = Rig(lab, "SPOT", {"objects": {"objects": [found], "reliability": 0.9}})
    assert rig.behavior.step().done
    assert rig.last("target")["observer"] == observer
    types = {t.name: t for t in lab.message_types}
    assert check_payload(rig.last("target"), "ObjectPosition", types) is None


def test_bad_params_are_refused_naming_the_behavior(lab: System) -> None:
    import dataclasses

    from ckmconf.model import Param

    record = lab.behavior("PICK")
    assert record is not None
    broken = dataclasses.replace(record, params=(Param(name="sequence", value="elbow:up"),))
    context = BehaviorContext(services={}, inputs={}, outputs={}, now=lambda: 0.0)
    with pytest.raises(ParamError, match=r"behavior 'PICK' .*'elbow:up' is not arm:POSE"):
        default_registry().resolve("behavior", "pick", broken)(broken, context)


def _with_goal(system: System, name: str, goal: str) -> System:
    """``system`` with behavior ``name``'s ``nav`` Uses configuring ``goal`` (a WAIT of its own goal)."""
    record = system.behavior(name)
    assert record is not None
    configure = ckmconf.model.missions.Configure(parameter="goal", value=goal)
    uses = tuple(dataclasses.replace(u, configure=(configure,)) if u.alias == "nav" else u for u in record.uses)
    behaviors = tuple(dataclasses.replace(b, uses=uses) if b.name == name else b for b in system.behaviors)
    return dataclasses.replace(system, behaviors=behaviors)


class StaleService(MemoryService):
    """The navigation as a newer goal finds it: the status of the previous goal is still the newest."""

    def __init__(self, ref: str) -> None:
        super().__init__(ref)
        self.outputs["status"] = {"goal": "1.0 1.3 1.5708", "state": "failed", "reason": "no path"}


def test_wait_with_its_own_goal_never_reads_the_previous_goals_status(lab: System) -> None:
    """Issue M: WAIT configuring its own goal ended at once on the previous goal's 'failed'."""
    system = _with_goal(lab, "WAIT", "7.6 5.5 1.5708")
    record = system.behavior("WAIT")
    assert record is not None
    nav = StaleService("Navigation.AMCL")
    stale = nav.outputs["status"]
    context = BehaviorContext(services={"nav": nav, "scan": MemoryService("s"), "base": MemoryService("b")},
                              inputs={}, outputs={}, now=lambda: 0.0)
    wait = default_registry().resolve("behavior", "wait-goal", record)(record, context)
    wait.start()
    assert nav.configured[-1][0] == {"goal": "7.6 5.5 1.5708"}
    status = wait.step()
    assert not status.failed and not status.done and "take the goal" in status.detail
    nav.outputs["status"] = stale  # the same stale message again: still not this goal's
    assert not wait.step().failed
    nav.outputs["status"] = {"goal": "7.6 5.5 1.5708", "state": "active", "path_length": 4.0, "remaining": 1.0}
    assert wait.step().progress == pytest.approx(0.75)
    nav.outputs["status"] = {"goal": "7.6 5.5 1.5708", "state": "failed", "path_length": 4.0, "remaining": 1.0,
                             "reason": "the goal collides with 'parcel_target'"}
    failed = wait.step()
    assert failed.failed and failed.detail == "navigation failed: the goal collides with 'parcel_target'"


def test_wait_at_the_same_goal_again_ignores_the_status_it_entered_with(lab: System) -> None:
    """The same goal set again starts a new navigation: the old 'failed' of that very goal is not its result."""
    system = _with_goal(lab, "WAIT", "1.0 1.3 1.5708")
    record = system.behavior("WAIT")
    assert record is not None
    nav = StaleService("Navigation.AMCL")
    context = BehaviorContext(services={"nav": nav}, inputs={}, outputs={}, now=lambda: 0.0)
    wait = default_registry().resolve("behavior", "wait-goal", record)(record, context)
    wait.start()
    assert not wait.step().failed
    nav.outputs["status"] = {"goal": "1.0 1.3 1.5708", "state": "arrived", "path_length": 2.0, "remaining": 0.0}
    assert wait.step().done


def test_a_navigation_failure_carries_its_reason(lab: System) -> None:
    rig = Rig(lab, "WAIT")
    rig.services["nav"].outputs["status"] = {"goal": "x", "state": "failed", "reason": "no localization for 10 s"}
    assert rig.behavior.step().detail == "navigation failed: no localization for 10 s"
    nav = Rig(lab, "NAV")
    nav.services["nav"].outputs["status"] = {"goal": "7.6 5.5 1.5708", "state": "failed", "reason": "no free cell"}
    assert nav.behavior.step().detail == "no path to the goal: no free cell"
