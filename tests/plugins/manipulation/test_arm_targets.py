"""plugin.arm-poses with Cartesian targets (issue M, point 2) on its messages alone, on two robot models:
the Turtlebot's 4-DOF arm (a target needs its pitch) and the station arm's turret and two pitch joints
(the pitch optional, D264); refusals with their reason; a newer goal preempting an older one."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from plugins.manipulation.arm_poses import ArmPoses
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

from .arm_loop import arm_plugin
from .manipulator_loop import STATION, TURTLEBOT, arm_service


def frame(plugin: ArmPoses, goal: Any, positions: list[float], stamp: float) -> dict[str, Any]:
    states = {"stamp": stamp, "name": [], "position": np.asarray(positions, float)}
    return plugin.process({"goal": goal, "joint_states": states}, Context(0, stamp, "Arm"))


@pytest.fixture
def turtlebot() -> Any:
    made = arm_plugin()  # the lab's service: its four arm joints and the gripper
    made.setup()
    yield made
    made.stop()


@pytest.fixture
def station() -> Any:
    made = arm_service(STATION)
    made.setup()
    yield made
    made.stop()


def test_a_target_is_solved_to_a_trajectory_and_its_tool_point_is_the_target(turtlebot: ArmPoses) -> None:
    target = {"x": 0.25, "y": 0.05, "z": 0.33, "pitch": 1.6}
    result = frame(turtlebot, {"id": 1, "group": "arm", "target": target}, [0.0] * 5, 0.0)
    end = result["trajectory"]["points"][1]["positions"]
    assert result["trajectory"]["joint_names"] == turtlebot.joints[:4]
    assert turtlebot.model is not None
    assert math.dist(turtlebot.model.tool_point(end), (0.25, 0.05, 0.33)) < 0.005
    assert turtlebot.model.tool_pitch(end) == pytest.approx(1.6, abs=1e-3)
    status = result["status"]
    assert status["pose"] == "" and status["target"] == target and status["state"] == "moving"


@pytest.mark.parametrize(
    ("goal", "error"),
    [
        ({"target": {"x": 0.25, "y": 0.0, "z": 0.33}}, "target (0.250, 0.000, 0.330) cannot be reached: this arm "
                                                       "sets the tool's pitch: the target needs one"),
        ({"target": {"x": 0.9, "y": 0.0, "z": 0.33, "pitch": 1.57}}, "cannot be reached: out of reach: the nearest "
                                                                     "tool point is"),
        ({"target": {"x": "a", "y": 0.0, "z": 0.3}}, "target x = 'a' is not a finite number"),
        ({"target": [0.2, 0.0, 0.3]}, "target is list, not {x, y, z, pitch}"),
        ({"target": {"x": 0.2, "y": 0.0, "z": 0.3, "pitch": 1.5}, "pose": "ready"}, "a target is an arm goal's, "
                                                                                    "instead of a pose"),
    ],
)
def test_a_bad_or_unreachable_target_fails_with_its_reason(turtlebot: ArmPoses, goal: dict[str, Any],
                                                           error: str) -> None:
    result = frame(turtlebot, {"id": 2, "group": "arm", **goal}, [0.0] * 5, 0.0)
    assert result["status"]["state"] == "failed" and error in result["status"]["error"]
    assert result["status"]["error"].startswith("goal 2: ") and "trajectory" not in result


def test_the_station_arm_takes_targets_without_pitch_and_refuses_a_pitch_it_cannot_set(station: ArmPoses) -> None:
    assert station.solutions["home"].error == "" and station.solutions["inspect"].error == ""
    result = frame(station, {"id": 1, "group": "arm", "target": {"x": 0.5, "y": 0.2, "z": 0.9}}, [0.0] * 3, 0.0)
    assert station.model is not None
    end = result["trajectory"]["points"][1]["positions"]
    assert math.dist(station.model.tool_point(end), (0.5, 0.2, 0.9)) < 0.005
    assert result["status"]["opening"] is None  # its gripper is a service of its own
    tilted = frame(station, {"id": 2, "group": "arm", "target": {"x": 0.5, "y": 0.0, "z": 0.8, "pitch": 1.0}},
                   [0.0] * 3, 0.1)
    assert tilted["status"]["error"] == ("goal 2: target (0.500, 0.000, 0.800, pitch 1.000) cannot be reached: this "
                                         "arm cannot set the pitch at that point: the tool points at 2.648 rad there, "
                                         "not 1.000")
    gripper = frame(station, {"id": 3, "group": "gripper", "pose": "open"}, [0.0] * 3, 0.2)
    assert gripper["status"]["error"] == "goal 3: this arm moves no gripper (its gripper is a service of its own)"


def test_a_newer_target_preempts_the_older_without_a_stale_status(station: ArmPoses) -> None:
    frame(station, {"id": 5, "group": "arm", "target": {"x": 0.5, "y": 0.0, "z": 0.8}}, [0.0] * 3, 0.0)
    newer = frame(station, {"id": 6, "group": "arm", "target": {"x": 0.4, "y": -0.2, "z": 1.0}}, [0.0] * 3, 0.05)
    assert newer["status"]["id"] == 6 and "trajectory" in newer
    end = newer["trajectory"]["points"][1]["positions"]
    for step in range(10):
        status = frame(station, {"id": 6, "group": "arm", "target": {"x": 0.4, "y": -0.2, "z": 1.0}},
                       [q * step / 9 for q in end], 0.1 + 0.3 * step)["status"]
        assert status["id"] == 6
    assert status["state"] == "reached"


def test_the_joints_param_counts_the_gripper_only_when_there_is_one() -> None:
    with pytest.raises(ParamError, match="must name 3 or 4 arm joints, each once"):
        arm_service(STATION, joints="turret_joint shoulder_joint")
    four = arm_service(TURTLEBOT)
    assert four.arm_count == 4 and not four.has_gripper
