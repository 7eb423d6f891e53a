"""plugin.arm-poses (RoboticArm.MoveIt, Table 7.1) on its messages alone: goals by id, bad goals and
bad joint states named, IK failures, timeout, preemption, the speed Parameter, the pose file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.manipulation.arm_poses import ArmPoses
from plugins.manipulation.kinematics import parse_poses
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

from .arm_loop import JOINTS, arm_plugin

REST = [0.0, 0.0, 0.0, 0.0, 0.0]


@pytest.fixture
def arm() -> Iterator[ArmPoses]:
    plugin = arm_plugin(timeout=2.0, maxVelocity="")  # the URDF's limits; resources.xml's contactPoses
    plugin.setup()
    yield plugin
    plugin.stop()


def frame(plugin: ArmPoses, goal: Any, positions: Any, stamp: float) -> dict[str, Any]:
    states = None if positions is None else {"stamp": stamp, "name": [], "position": np.asarray(positions, float)}
    return plugin.process({"goal": goal, "joint_states": states}, Context(0, stamp, "RoboticArm"))


def test_a_goal_gets_one_trajectory_from_the_measured_start_and_is_reached_only_at_its_target(arm: ArmPoses) -> None:
    goal = {"id": 7, "group": "arm", "pose": "ready"}
    first = frame(arm, goal, REST, 0.0)
    trajectory = first["trajectory"]
    assert trajectory["joint_names"] == arm.joints[:4]
    start, end = trajectory["points"]
    assert start == {"positions": REST[:4], "time_from_start": 0.0}
    target = list(arm.solutions["ready"].joints)
    assert end["positions"] == target
    # the cubic profile's peak speed (1.5 Δq / T) is the URDF's 3 rad/s × the 0.5 speed scaling
    peak = max(1.5 * abs(q) / end["time_from_start"] for q in target)
    assert peak == pytest.approx(1.5)
    assert first["status"] == {"stamp": 0.0, "id": 7, "group": "arm", "pose": "ready", "state": "moving",
                               "active": True, "error": "", "holding": False, "contact": False, "opening": 0.0}
    assert first["active"] == 1
    halfway = [q / 2 for q in target] + [0.0]
    assert "trajectory" not in frame(arm, goal, halfway, 0.2)  # the same goal is not planned twice
    assert frame(arm, goal, halfway, 0.2)["status"]["state"] == "moving"
    near = [q + 0.015 for q in target] + [0.0]  # within the 0.02 rad tolerance
    assert frame(arm, goal, near, 0.4)["status"]["state"] == "reached"


def test_joint_states_with_names_are_read_by_name(arm: ArmPoses) -> None:
    target = list(arm.solutions["grasp"].joints)
    names = list(reversed(arm.joints))
    states = {"stamp": 0.0, "name": names, "position": list(reversed([*target, 0.01]))}
    result = arm.process({"goal": {"id": 1, "group": "arm", "pose": "grasp"}, "joint_states": states},
                         Context(0, 0.0, ""))
    assert result["status"]["state"] == "reached"


def test_the_gripper_group_moves_only_the_gripper_between_its_urdf_limits(arm: ArmPoses) -> None:
    opened = frame(arm, {"id": 2, "group": "gripper", "pose": "open"}, REST, 0.0)
    assert opened["trajectory"]["joint_names"] == ["gripper_joint"]
    assert opened["trajectory"]["points"][1]["positions"] == [pytest.approx(0.045)]  # the URDF's upper limit
    closed = frame(arm, {"id": 3, "group": "gripper", "pose": "closed"}, [*REST[:4], 0.045], 0.1)
    assert closed["trajectory"]["points"][1]["positions"] == [0.0]


def test_closing_fingers_stopped_by_an_object_count_as_holding_it(arm: ArmPoses) -> None:
    goal = {"id": 4, "group": "gripper", "pose": "closed"}
    duration = frame(arm, goal, [*REST[:4], 0.045], 0.0)["trajectory"]["points"][1]["time_from_start"]
    assert duration > 0.5
    t, opening = 0.0, 0.045
    while t < duration:  # the fingers still closing: moving
        t, opening = t + 0.05, opening - 0.002
        assert frame(arm, goal, [*REST[:4], opening], t)["status"]["state"] == "moving"
    stopped = t
    while t < stopped + 0.45:  # stopped short of closed (an object), not yet for settle = 0.5 s
        t += 0.05
        assert frame(arm, goal, [*REST[:4], opening], t)["status"]["state"] == "moving"
    held = frame(arm, goal, [*REST[:4], opening], t + 0.1)
    assert held["status"]["state"] == "reached" and held["status"]["holding"] is True
    assert held["holding"] == 1  # the gripper's measure: the object is in the hand


def hold_an_object(arm: ArmPoses, goal_id: int, start: float = 0.0) -> tuple[dict[str, Any], float, float]:
    """A closing gripper goal that stops on an object; returns the goal, the time and the opening."""
    goal = {"id": goal_id, "group": "gripper", "pose": "closed"}
    duration = frame(arm, goal, [*REST[:4], 0.045], start)["trajectory"]["points"][1]["time_from_start"]
    t = start + duration + 0.05
    while frame(arm, goal, [*REST[:4], 0.02], t)["holding"] != 1:
        t += 0.05
        assert t < start + duration + 2.0, "never counted as holding"
    return goal, t, 0.02


def test_the_holding_measure_drops_when_the_object_slips_out_or_the_gripper_opens(arm: ArmPoses) -> None:
    goal, t, opening = hold_an_object(arm, 4)
    assert frame(arm, goal, [*REST[:4], opening], t + 1.0)["holding"] == 1  # carried: still held
    assert frame(arm, goal, [*REST[:4], 0.0], t + 1.1)["holding"] == 0  # the fingers closed on nothing: dropped
    goal, t, opening = hold_an_object(arm, 5, t + 2.0)
    released = frame(arm, {"id": 6, "group": "gripper", "pose": "open"}, [*REST[:4], opening], t + 0.1)
    assert released["holding"] == 0  # opening lets it go


def test_the_status_gives_the_measured_opening_of_the_held_object(arm: ArmPoses) -> None:
    """What PICK_FLOOR's minHold reads (D251): 0.02 m of the fingers' 0.045 m range."""
    goal, t, opening = hold_an_object(arm, 4)
    status = frame(arm, goal, [*REST[:4], opening], t + 0.05)["status"]
    assert status["holding"] is True and status["opening"] == pytest.approx(0.02 / 0.045, abs=1e-4)


def _stalled(arm: ArmPoses, goal: dict[str, Any], share: float) -> tuple[list[float], float]:
    """Plan ``goal`` from REST; the joints stopped at ``share`` of the way; its planned duration."""
    duration = frame(arm, goal, REST, 0.0)["trajectory"]["points"][1]["time_from_start"]
    target = list(arm.solutions[goal["pose"]].joints)
    return [q * share for q in target] + [0.0], duration


def test_a_place_stopped_short_by_the_set_down_object_is_reached_with_contact(arm: ArmPoses) -> None:
    """resources.xml's contactPoses: the place ends when the object stands on the table and the
    arm stands still short of the pose for settle (0.5 s) after the planned time (D251)."""
    assert arm.contact_poses == {"place"}
    goal = {"id": 9, "group": "arm", "pose": "place"}
    stopped, duration = _stalled(arm, goal, 0.9)
    t = duration
    while t < duration + 0.45:  # standing still, not yet for settle
        t += 0.05
        assert frame(arm, goal, stopped, t)["status"]["state"] == "moving"
    result = frame(arm, goal, stopped, t + 0.1)
    status = result["status"]
    assert status["state"] == "reached" and status["contact"] is True and status["active"] is True
    # the arm is held where it stopped: it no longer presses the object, the fingers can open
    assert [point["positions"] for point in result["trajectory"]["points"]] == [stopped[:4], stopped[:4]]
    assert "trajectory" not in frame(arm, goal, stopped, t + 0.15)  # once


def test_an_arm_still_creeping_or_stopped_short_of_another_pose_is_not_reached(arm: ArmPoses) -> None:
    """Creeping by more than stillness (5 mrad in settle) is no contact; a pose outside contactPoses
    stopped short fails at its timeout as before."""
    goal = {"id": 10, "group": "arm", "pose": "place"}
    stopped, duration = _stalled(arm, goal, 0.9)
    t, states = duration, []
    for k in range(40):  # 2 s creeping at 6 mrad/s on the elbow (3 mrad per settle window)…
        t = duration + 0.05 * k
        stopped[2] += 0.0003
        states.append(frame(arm, goal, stopped, t)["status"]["state"])
    assert "reached" in states  # …is still: 3 mrad < 5
    goal = {"id": 11, "group": "arm", "pose": "place"}
    stopped, duration = _stalled(arm, goal, 0.9)
    for k in range(40):  # creeping at 20 mrad/s: moving, never contact
        stopped[2] += 0.001
        assert frame(arm, goal, stopped, duration + 0.05 * k)["status"]["state"] == "moving"
    goal = {"id": 12, "group": "arm", "pose": "ready"}
    stopped, duration = _stalled(arm, goal, 0.9)
    assert frame(arm, goal, stopped, duration + 1.0)["status"]["state"] == "moving"
    status = frame(arm, goal, stopped, duration + 2.1)["status"]
    assert status["state"] == "failed" and status["contact"] is False


def test_fingers_closing_on_nothing_never_count_as_holding(arm: ArmPoses) -> None:
    goal = {"id": 7, "group": "gripper", "pose": "closed"}
    duration = frame(arm, goal, [*REST[:4], 0.045], 0.0)["trajectory"]["points"][1]["time_from_start"]
    result = frame(arm, goal, [*REST[:4], 0.0], duration + 0.1)
    assert result["status"]["state"] == "reached" and result["holding"] == 0


def test_a_new_goal_preempts_the_old_one(arm: ArmPoses) -> None:
    frame(arm, {"id": 1, "group": "arm", "pose": "ready"}, REST, 0.0)
    second = frame(arm, {"id": 2, "group": "arm", "pose": "resting"}, REST, 0.1)
    assert second["trajectory"]["points"][1]["positions"] == list(arm.solutions["resting"].joints)
    assert second["status"]["id"] == 2 and second["status"]["pose"] == "resting"


@pytest.mark.parametrize(
    ("goal", "error"),
    [
        ({"id": 5, "group": "arm", "pose": "dance"}, "goal 5: unknown arm pose 'dance' (defined: resting, ready"),
        ({"id": 5, "group": "gripper", "pose": "grasp"}, "unknown gripper pose 'grasp' (defined: open, closed)"),
        ({"id": 5, "group": "legs", "pose": "ready"}, "group 'legs' is not 'arm' or 'gripper'"),
        ({"id": "5", "group": "arm", "pose": "ready"}, "goal id '5' is not an integer"),
        ({"id": 5, "group": "arm", "pose": "ready", "speed": 3}, "goal 5 speed = 3 must be a number in (0, 1]"),
        ("ready", "goal is str, not an ArmGoal mapping"),
    ],
)
def test_a_bad_goal_fails_with_its_reason_and_active_drops(arm: ArmPoses, goal: Any, error: str) -> None:
    result = frame(arm, goal, REST, 0.0)
    assert result["status"]["state"] == "failed"
    assert error in result["status"]["error"]
    assert "trajectory" not in result
    assert result["active"] == 0
    recovered = frame(arm, {"id": 6, "group": "arm", "pose": "ready"}, REST, 0.1)  # a good goal clears it
    assert recovered["active"] == 1


def test_a_goal_not_reached_in_time_fails_naming_the_joint(arm: ArmPoses) -> None:
    goal = {"id": 8, "group": "arm", "pose": "ready"}
    duration = frame(arm, goal, REST, 0.0)["trajectory"]["points"][1]["time_from_start"]
    assert frame(arm, goal, REST, duration + 1.9)["status"]["state"] == "moving"
    status = frame(arm, goal, REST, duration + 2.1)["status"]
    assert status["state"] == "failed" and "not reached in" in status["error"] and "_joint still" in status["error"]


@pytest.mark.parametrize(
    ("states", "error"),
    [
        ({"stamp": 0.0, "name": [], "position": [0.0, 0.0]}, "2 unnamed positions, expected 5"),
        ({"stamp": 0.0, "name": ["a", "b"], "position": [0.0, 0.0]}, "joint_states has no arm_shoulder_pan_joint"),
        ({"stamp": 0.0}, "no 'position'"),
        ({"stamp": 0.0, "name": [], "position": [0, 0, float("nan"), 0, 0]}, "not finite"),
    ],
)
def test_bad_joint_states_clear_active_and_say_why(arm: ArmPoses, states: Any, error: str) -> None:
    result = arm.process({"goal": {"id": 1, "group": "arm", "pose": "ready"}, "joint_states": states},
                         Context(0, 0.0, ""))
    assert result["active"] == 0
    assert error in result["status"]["error"] and result["status"]["state"] == "moving"


def test_the_speed_parameter_scales_the_trajectory_and_bad_values_are_refused(arm: ArmPoses) -> None:
    slow = frame(arm, {"id": 1, "group": "arm", "pose": "ready"}, REST, 0.0)["trajectory"]["points"][1]
    arm.apply_service_parameters({"speed": 1.0})
    fast = frame(arm, {"id": 2, "group": "arm", "pose": "ready"}, REST, 0.1)["trajectory"]["points"][1]
    assert slow["time_from_start"] == pytest.approx(2 * fast["time_from_start"])
    for bad in (0.0, 1.5, "fast", True):
        with pytest.raises(ValueError, match="service parameter 'speed'"):
            arm.apply_service_parameters({"speed": bad})
    arm.apply_service_parameters({"other": 1})  # not this plugin's


def _pose_file(tmp_path: Path, text: str) -> ArmPoses:
    (tmp_path / "poses.yml").write_text("tool: gripper_tool_link\n" + text)  # the Turtlebot's tool point
    loc = Loc(str(tmp_path / "resources.xml"), 1, 1, "/Plugin")
    params = (Param(name="poses", value="poses.yml"), Param(name="model", value="turtlebot"),
              Param(name="joints", value=JOINTS))
    return ArmPoses(Plugin(name="moveit", kind="arm-poses", params=params, loc=loc))


def test_poses_out_of_reach_or_out_of_the_joint_limits_fail_when_asked(tmp_path: Path, arm: ArmPoses) -> None:
    assert arm.model is not None
    # a tool point the arm reaches with the wrist at 2.3 rad, past its 2.0 rad limit
    x, y, z = arm.model.tool_point([0.0, 0.2, 0.3, 2.3])
    plugin = _pose_file(tmp_path, f"arm:\n  far: 0.6 0 0.3 1.57\n  bent: {x} {y} {z} 2.8\ngripper:\n  open: 1\n")
    plugin.setup()
    try:
        far = frame(plugin, {"id": 1, "group": "arm", "pose": "far"}, REST, 0.0)["status"]
        assert far["state"] == "failed" and "arm pose 'far' cannot be reached: out of reach" in far["error"]
        bent = frame(plugin, {"id": 2, "group": "arm", "pose": "bent"}, REST, 0.1)["status"]
        assert bent["state"] == "failed"
        assert "the wrist joint would be at 2.3" in bent["error"] or "wrist joint would be at 2.2" in bent["error"]
        assert "outside its limits [-2.000, 2.000]" in bent["error"]
    finally:
        plugin.stop()


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("arm:\n  ready: 0.2 0\n", ":2: arm pose 'ready' needs x y z [pitch]"),
        ("gripper:\n  open: 2\n", ":2: gripper pose 'open': opening share 2.0 is not in [0, 1]"),
        ("arm:\n  a: 0 0 0 0\n  a: 0 0 0 0\n", ":3: arm pose 'a' is defined twice"),
        ("  ready: 0 0 0 0\n", ":1: an indented line must follow"),
        ("legs:\n", ":1: unknown key 'legs'"),
        ("version: 2\narm:\n  a: 0 0 0 0\n", "unsupported pose file version"),
        ("tool: x\n", "no arm or gripper poses"),
        ("arm:\n  a: 0.2 0 0.35 1.57\n", "no 'tool': the URDF link whose point the arm poses place (tool: LINK)"),
    ],
)
def test_a_bad_pose_file_is_named_with_its_line(text: str, error: str) -> None:
    with pytest.raises(ValueError, match=r"poses\.yml") as caught:
        parse_poses(text, "poses.yml")
    assert error in str(caught.value)


def test_bad_params_and_files_are_reported(tmp_path: Path) -> None:
    with pytest.raises(ParamError, match="'joints' must name 3 or 4 arm joints"):
        arm_plugin(joints="a b c")
    with pytest.raises(ParamError, match="'maxVelocity' needs one or 5 positive numbers"):
        arm_plugin(maxVelocity="1 2")
    missing = _pose_file(tmp_path, "arm:\n  a: 0.2 0 0.35 1.57\n")
    missing.poses_path = tmp_path / "none.yml"
    with pytest.raises(OSError, match="cannot read pose file"):
        missing.setup()
    broken = _pose_file(tmp_path, "arm:\n  a: 0.2\n")
    with pytest.raises(ValueError, match=r"bad pose file: .*poses\.yml:3"):  # line 1 is the tool
        broken.setup()
    with pytest.raises(FileNotFoundError, match="robot model"):
        arm_plugin(model="nowhere.urdf").setup()
    with pytest.raises(RuntimeError, match="not set up"):
        arm_plugin().process({}, Context(0, 0.0, ""))
