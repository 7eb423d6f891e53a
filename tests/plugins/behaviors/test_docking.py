"""DOCK (D196): the base to the drop table's docking pose, placed relative to the robot by its estimate."""

from __future__ import annotations

import dataclasses
import math

import pytest

from ckmconf.model import Param, System
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from runtime.registry import default_registry
from tests.plugins.behaviors.test_usecase_behaviors import Rig, lab  # noqa: F401  (the fixture)


def test_dock_moves_from_the_estimate_to_the_docking_pose(lab: System) -> None:  # noqa: F811
    rig = Rig(lab, "DOCK")  # behaviors.xml: pose 1.0 1.42 1.5708
    assert rig.behavior.step().detail == "waiting for the pose estimate"
    rig.inputs["pose"] = {"pose": {"x": 0.9, "y": 1.22, "yaw": math.pi / 2 - 0.1}}
    rig.behavior.step()
    move = rig.last("move")
    # the goal 0.2 m up and 0.1 m right in the map; the robot turned 0.1 rad right of up
    ahead, left = 0.2 * math.cos(0.1) + 0.1 * math.sin(0.1), 0.2 * math.sin(0.1) - 0.1 * math.cos(0.1)
    assert move["frame"] == "robot" and move["x"] == pytest.approx(ahead, abs=1e-3)
    assert move["y"] == pytest.approx(left, abs=1e-3)
    assert move["yaw"] == pytest.approx(0.1, abs=1e-3)  # ends facing the table
    rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": "moving", "total": 0.2, "remaining": 0.1}
    assert rig.behavior.step().progress == pytest.approx(0.5)
    rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": "done"}
    assert rig.behavior.step().done
    assert len([n for n, _ in rig.written if n == "move"]) == 1  # one move, from one estimate


def test_a_failed_move_fails_dock(lab: System) -> None:  # noqa: F811
    rig = Rig(lab, "DOCK", {"pose": {"pose": {"x": 1.0, "y": 1.3, "yaw": math.pi / 2}}})
    rig.behavior.step()
    rig.services["base"].outputs["move_status"] = {"id": rig.last("move")["id"], "state": "failed"}
    assert rig.behavior.step().failed


def test_a_bad_pose_is_refused_naming_the_behavior(lab: System) -> None:  # noqa: F811
    record = lab.behavior("DOCK")
    assert record is not None
    broken = dataclasses.replace(record, params=(Param(name="pose", value="by the table"),))
    context = BehaviorContext(services={}, inputs={}, outputs={}, now=lambda: 0.0)
    with pytest.raises(ParamError, match=r"behavior 'DOCK'.*'by the table' is not 'x y yaw'"):
        default_registry().resolve("behavior", "dock", broken)(broken, context)


def test_dock_cancels_the_navigation_goal_before_it_moves(lab: System) -> None:  # noqa: F811
    # D211: WAIT's dispersion check can set NAV_HOME's goal again just before DOCK; a path the
    # Navigation then plans would preempt DOCK's move (a bench run failed so). The empty goal
    # cancels it: the Navigation sends the base an empty path, which stops no move.
    rig = Rig(lab, "DOCK", {"pose": {"pose": {"x": 1.0, "y": 1.3, "yaw": math.pi / 2}}})
    ((parameters, requirements),) = rig.services["nav"].configured
    assert parameters == {"goal": ""} and requirements == ()
    rig.behavior.step()
    assert rig.last("move")["frame"] == "robot"
