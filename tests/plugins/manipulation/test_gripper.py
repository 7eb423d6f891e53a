"""plugin.parallel-gripper on its messages alone, on two robot models (the Turtlebot's fingers and the
station arm's jaw): commands by id, the range and speed from the URDF, holding and stalled by
stillness, bad commands and joint states with their reason, a newer command preempting an older."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from plugins.manipulation.gripper import ParallelGripper
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

from .manipulator_loop import STATION, TURTLEBOT, Model, gripper_service


@pytest.fixture(params=[TURTLEBOT, STATION], ids=lambda m: m.name)
def gripper(request: pytest.FixtureRequest) -> Iterator[ParallelGripper]:
    model: Model = request.param
    made = gripper_service(model, settle=0.2)
    made.setup()
    yield made


def frame(plugin: ParallelGripper, command: Any, position: float | None, stamp: float,
          effort: float | None = None) -> dict[str, Any]:
    states = None if position is None else {"stamp": stamp, "name": [], "position": [position],
                                            **({"effort": [effort]} if effort is not None else {})}
    return plugin.process({"command": command, "joint_states": states}, Context(0, stamp, "Gripper"))


def test_the_range_speed_and_force_are_the_urdf_s() -> None:
    turtlebot, station = gripper_service(TURTLEBOT), gripper_service(STATION)
    turtlebot.setup()
    station.setup()
    assert (turtlebot.lower, turtlebot.upper) == pytest.approx((0.0, 0.045))
    assert (station.lower, station.upper) == pytest.approx((0.0, 0.17))
    assert station.speed == pytest.approx(0.2) and station.force == pytest.approx(40.0)
    given = gripper_service(STATION, speed=0.05, force=12)
    given.setup()
    assert (given.speed, given.force) == (0.05, 12.0)


def test_a_command_gets_one_trajectory_and_is_reached_at_its_target(gripper: ParallelGripper) -> None:
    command = {"id": 3, "action": "position", "position": 0.5, "max_effort": 5.0}
    first = frame(gripper, command, 0.0, 0.0, effort=0.2)
    target = 0.5 * gripper.upper
    trajectory = first["trajectory"]
    assert trajectory["joint_names"] == gripper.joints
    start, end = trajectory["points"]
    assert start["positions"] == [0.0] and end["positions"] == [pytest.approx(target)]
    assert end["time_from_start"] == pytest.approx(max(0.1, 1.5 * target / gripper.speed))
    assert end["effort"] == [5.0]  # the command's max_effort, under the force limit
    assert first["status"] == {"stamp": 0.0, "id": 3, "action": "position", "state": "moving", "position": 0.0,
                               "opening": 0.0, "holding": False, "effort": 0.2, "max_effort": 5.0, "reason": ""}
    assert "trajectory" not in frame(gripper, command, target / 2, 0.1)  # the same command is not planned twice
    reached = frame(gripper, command, target * 1.01, end["time_from_start"])
    assert reached["status"]["state"] == "reached" and reached["status"]["opening"] == pytest.approx(0.505)
    assert reached["holding"] == 0 and reached["active"] == 1


def test_closing_fingers_that_stand_still_short_hold_and_an_object_slipping_out_ends_it(
    gripper: ParallelGripper,
) -> None:
    close = {"id": 1, "action": "close"}
    open_at, on_object = gripper.upper, 0.4 * gripper.upper
    planned = frame(gripper, close, open_at, 0.0)["trajectory"]["points"][1]["time_from_start"]
    t = planned
    while t < planned + 0.3:  # stopped on the object, past the planned time, for settle (0.2 s)
        result = frame(gripper, close, on_object, t)
        t += 0.05
    assert result["status"]["state"] == "holding" and result["status"]["holding"] is True
    assert result["holding"] == 1
    slipped = frame(gripper, close, 0.0, t)  # the fingers reach closed: nothing between them any more
    assert slipped["status"]["state"] == "reached" and slipped["holding"] == 0


def test_opening_fingers_blocked_short_stall_with_where_they_stopped(gripper: ParallelGripper) -> None:
    opening = {"id": 2, "action": "open"}
    planned = frame(gripper, opening, 0.0, 0.0)["trajectory"]["points"][1]["time_from_start"]
    blocked = 0.3 * gripper.upper
    for step in range(8):
        result = frame(gripper, opening, blocked, planned + 0.05 * step)
    status = result["status"]
    assert status["state"] == "stalled" and status["holding"] is False
    assert status["reason"].startswith(f"command 2: the fingers stopped at {blocked:.4f}")


def test_fingers_that_never_arrive_fail_after_the_timeout(gripper: ParallelGripper) -> None:
    close = {"id": 4, "action": "close"}
    planned = frame(gripper, close, gripper.upper, 0.0)["trajectory"]["points"][1]["time_from_start"]
    moving = gripper.upper
    t = 0.0
    while t < planned + 3.5:  # creeping on, never still, never there
        moving -= gripper.upper * 0.008
        result = frame(gripper, close, moving, t)
        t += 0.05
    assert result["status"]["state"] == "failed" and "close not reached in" in result["status"]["reason"]
    assert result["active"] == 0


@pytest.mark.parametrize(
    ("command", "reason"),
    [
        ("close", "command is str, not a GripperCommand"),
        ({"id": "a", "action": "open"}, "command id 'a' is not an integer"),
        ({"id": 5, "action": "squeeze"}, "command 5: action 'squeeze' is not one of open, close, position"),
        ({"id": 5, "action": "position", "position": 1.5}, "command 5: position 1.5 is outside the share of the "
                                                           "range [0, 1]"),
        ({"id": 5, "action": "position"}, "command 5: position None is not a number"),
        ({"id": 5, "action": "close", "max_effort": -1}, "command 5: max_effort -1 is not a positive number"),
    ],
)
def test_a_bad_command_fails_with_its_reason(gripper: ParallelGripper, command: Any, reason: str) -> None:
    result = frame(gripper, command, 0.01, 0.0)
    assert result["status"]["state"] == "failed" and result["status"]["reason"] == reason
    assert "trajectory" not in result and result["active"] == 0


def test_a_newer_command_preempts_the_older_without_a_stale_status(gripper: ParallelGripper) -> None:
    frame(gripper, {"id": 7, "action": "open"}, 0.0, 0.0)
    newer = frame(gripper, {"id": 8, "action": "close"}, 0.3 * gripper.upper, 0.1)
    assert newer["trajectory"]["points"][1]["positions"] == [0.0]
    for step in range(20):
        status = frame(gripper, {"id": 8, "action": "close"}, 0.3 * gripper.upper * (1 - step / 20), 0.2 + 0.1 * step)
        assert status["status"]["id"] == 8


def test_joint_positions_in_metres_and_bad_joint_states_and_params() -> None:
    metres = gripper_service(STATION, positionUnit="joint")
    metres.setup()
    result = frame(metres, {"id": 1, "action": "position", "position": 0.16}, 0.0, 0.0)
    assert result["trajectory"]["points"][1]["positions"] == [0.16]
    refused = frame(metres, {"id": 2, "action": "position", "position": 0.3}, 0.0, 0.1)
    assert refused["status"]["reason"] == "command 2: position 0.3 is outside the joint position [0, 0.17]"
    broken = frame(metres, {"id": 3, "action": "open"}, None, 0.2)
    assert broken["status"]["state"] == "moving"  # no joint states yet: nothing planned
    bad = metres.process({"command": {"id": 3, "action": "open"}, "joint_states": {"stamp": 0.3}}, Context(0, 0.3, ""))
    assert bad["active"] == 0 and "no 'position'" in bad["status"]["reason"]
    with pytest.raises(ParamError, match="each finger joint once"):
        gripper_service(STATION, joints="a a")
    with pytest.raises(ValueError, match="has no joint nowhere_joint"):
        gripper_service(STATION, joints="nowhere_joint").setup()
    with pytest.raises(RuntimeError, match="not set up"):
        gripper_service(STATION).process({}, Context(0, 0.0, ""))
