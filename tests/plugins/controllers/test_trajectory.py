"""joint-trajectory: cubic and linear segments timed by the velocity limits, predefined poses and
their status, trajectories with joint names and times, joint limits, and the stored future."""

from __future__ import annotations

import itertools
from typing import Any

import pytest

from plugins.controllers.trajectory import JointTrajectory
from runtime.kernel.interfaces import ParamError
from tests.plugins.controllers.vector_records import record

DT = 0.02
POSES = "resting: 0 0 0; ready: 0.5 -0.5 0.2; open: 0 0 0.8"


def arm(status: bool = False, /, **params: object) -> JointTrajectory:
    params = {"joints": "shoulder elbow gripper_joint", **params}
    outputs: list[Any] = ["pan_cmd", "lift_cmd", "gripper_cmd"] + ([("/arm/status", "status")] if status else [])
    inputs = [("/arm/joint_trajectory", "setpoint"), ("/arm/joint_states", "measure")]
    return JointTrajectory(record("joint-trajectory", DT, inputs, outputs, 50, **params))


def play(c: JointTrajectory, setpoint: Any, steps: int, start: tuple[float, ...] = (0.0, 0.0, 0.0)) -> list[Any]:
    """Runs ``steps`` periods on ideal servos (the measure is the last command)."""
    measure: Any = list(start)
    rows = []
    for _ in range(steps):
        row = c.step_outputs({"setpoint": setpoint, "measure": measure}, DT)
        measure = [v for v in row if isinstance(v, float)]
        rows.append(row)
    return rows


def test_cubic_segment_is_timed_by_the_slowest_joint() -> None:
    c = arm(maxVelocity="1.0 0.5 1.0")
    rows = play(c, [1.0, 1.0, 0.0], 160)  # T = 1.5·1/0.5 = 3 s
    assert rows[75][:2] == pytest.approx((0.5, 0.5))  # row k is at t = k·DT: half way at 1.5 s
    assert rows[150][:2] == pytest.approx((1.0, 1.0)) and rows[-1][:2] == pytest.approx((1.0, 1.0))
    speeds = [abs(b[1] - a[1]) / DT for a, b in itertools.pairwise(rows)]
    assert max(speeds) <= 0.5 + 1e-9 and max(speeds) > 0.49  # the limit is reached, never passed


def test_linear_segment_moves_at_the_limit() -> None:
    rows = play(arm(maxVelocity="2", interpolation="linear"), [0.5, -1.0, 0.0], 60)  # T = 1/2 s
    assert rows[0][:2] == pytest.approx((0.0, 0.0)) and rows[1][:2] == pytest.approx((0.02, -0.04))
    assert rows[25][:2] == pytest.approx((0.5, -1.0))


def test_predefined_pose_with_status() -> None:
    c = arm(True, poses=POSES, maxVelocity="1.0")
    rows = play(c, {"group": "arm", "pose": "ready", "speed": 0.5}, 120)  # arm joints only; T = 1.5·0.5/0.5
    moving, reached = rows[10][3], rows[-1][3]
    assert moving["active"] and moving["pose"] == "" and moving["error"] == ""
    assert reached["active"] and reached["pose"] == "ready"
    assert rows[-1][:3] == pytest.approx((0.5, -0.5, 0.0))  # the gripper stayed
    assert rows[74][:2] != pytest.approx((0.5, -0.5)) and rows[76][:2] == pytest.approx((0.5, -0.5))
    rows = play(c, {"group": "gripper", "pose": "open", "speed": 1.0}, 80, start=(0.5, -0.5, 0.0))
    assert rows[-1][:3] == pytest.approx((0.5, -0.5, 0.8)) and rows[-1][3]["pose"] == "open"


def test_unknown_pose_reports_an_error_and_holds() -> None:
    c = arm(True, poses=POSES)
    rows = play(c, {"group": "arm", "pose": "dance", "speed": 1.0}, 3, start=(0.1, 0.2, 0.3))
    assert rows[-1][:3] == pytest.approx((0.1, 0.2, 0.3))
    assert not rows[-1][3]["active"] and "unknown pose 'dance'" in rows[-1][3]["error"]


def test_trajectory_by_joint_names_with_times_and_limits() -> None:
    c = arm(maxVelocity="1.0", lowerLimits="-1 -1 0", upperLimits="1 1 0.5")
    trajectory = {
        "joint_names": ["elbow", "shoulder"],
        "points": [
            {"positions": [0.3, 0.0], "time_from_start": 2.0},  # slower than the limit asks: 2 s
            {"positions": [0.3, 3.0], "time_from_start": 2.5},  # beyond the limit: to 1.0, in 1.5 s
        ],
    }
    rows = play(c, trajectory, 200)
    assert rows[50][1] == pytest.approx(0.15)  # half of the first segment at t = 1 s
    assert rows[100][:2] == pytest.approx((0.0, 0.3))
    assert rows[-1][:2] == pytest.approx((1.0, 0.3)) and c.remaining == 0.0


def test_future_samples_the_rest_of_the_plan_and_state_round_trips() -> None:
    c = arm(maxVelocity="1.0", interpolation="linear")
    play(c, [1.0, 0.0, 0.0], 11)  # 0.2 s into a 1 s segment
    future = c.future_outputs()
    assert len(future) == 50 and future[0][0] == pytest.approx(0.22) and future[-1][0] == pytest.approx(1.0)
    other = arm(maxVelocity="1.0", interpolation="linear")
    other.restore(c.state())
    assert other.future_outputs() == future


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"joints": ""}, "each joint once"),
        ({"maxVelocity": "1 2"}, "one per joint"),
        ({"maxVelocity": "0"}, "greater than 0"),
        ({"poses": "ready 1 2 3"}, "is not 'name: q1 q2"),
        ({"lowerLimits": "1 1 1", "upperLimits": "0 2 2"}, "lower limit must be less"),
    ],
)
def test_param_errors(params: dict[str, str], message: str) -> None:
    with pytest.raises(ParamError, match=message):
        arm(**params)


def test_a_joint_state_naming_no_joint_is_read_in_joints_order() -> None:
    """The arm_joints sensor's JointState carries positions only (D99): ``joints`` orders them."""
    c = arm()
    assert c.measured({"name": [], "position": [0.1, 0.2, 0.3]}) == [0.1, 0.2, 0.3]
    assert c.measured({"name": ["gripper_joint", "elbow", "shoulder"], "position": [3, 2, 1]}) == [1, 2, 3]
