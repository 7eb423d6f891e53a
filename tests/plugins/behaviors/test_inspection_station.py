"""The inspection station (issue N point 2, D296): plugins/sim/models/inspection_arm.urdf through the
real pick-object and place-object behaviors over its arm-motion (plugin.arm-poses on turret, shoulder,
elbow and wrist pitch) and gripper (plugin.parallel-gripper) services, its wrist roll under a
controller.joint-trajectory. It picks a 0.3 m parcel off its work table, turns it before its camera
— the camera's pixels show the parcel's other end face — and puts it down where asked. Evidence is
the world's own poses and the rendered frames, not the commands sent."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import numpy.typing as npt
import pybullet as p
import pytest

from plugins.sim.sensors import Camera

from .inspection_cell import InspectionLoop, in_base, parcel, run_behavior, station, table

PICK = {"approach": "0.6 0 1.1 3.1416", "grasp": "0.6 0 0.9 3.1416", "lift": "0.6 0 1.15 3.1416"}
PLACE_AT = (0.5, -0.45)
"""Where the parcel is asked to be set down (base frame, m): another spot of the table."""
PLACE = {
    "above": f"{PLACE_AT[0]} {PLACE_AT[1]} 1.15 3.1416",
    "place": f"{PLACE_AT[0]} {PLACE_AT[1]} 0.9 3.1416",
    "retreat": "home",
}
TABLE_TOP = 0.70


@pytest.fixture
def cell() -> Iterator[tuple[InspectionLoop, int]]:
    """The station, its work table (top at 0.70 m) and a 0.3 m, 2 kg parcel on it 0.6 m ahead."""
    for loop in station():
        table(loop, (0.55, -0.2, TABLE_TOP / 2), (0.3, 0.5, TABLE_TOP / 2))
        body = parcel(loop, (0.6, 0.0, TABLE_TOP + 0.151), 0.15, 2.0)
        loop.world.step(60)
        yield loop, body


def _colour(camera: Camera) -> npt.NDArray[np.float64]:
    """The mean colour of the centre of a 160 x 120 frame (where the inspection point appears)."""
    frame = camera.render(160, 120)
    centre: npt.NDArray[np.float64] = frame.rgb[40:80, 60:100].reshape(-1, 3).mean(axis=0)
    return centre


def _facing(loop: InspectionLoop, body: int) -> npt.NDArray[np.float64]:
    """The parcel's own x axis (its red face's normal) in the station's base frame."""
    rotation = np.array(
        p.getMatrixFromQuaternion(p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[1])
    ).reshape(3, 3)
    base = np.array(p.getMatrixFromQuaternion(loop.robot.link_pose(-1)[1])).reshape(3, 3)
    facing: npt.NDArray[np.float64] = base.T @ rotation[:, 0]
    return facing


def test_the_station_picks_the_parcel_turns_it_before_its_camera_and_puts_it_down_where_asked(
    cell: tuple[InspectionLoop, int],
) -> None:
    loop, body = cell
    resting = in_base(loop, body)
    picked = run_behavior(loop, "pick-object", PICK)
    assert picked.done, picked
    assert loop.grasp.held == body and in_base(loop, body)[2] - resting[2] > 0.2  # lifted off the table
    assert loop.move({"id": 100, "group": "arm", "pose": "inspect"}, 20.0)["state"] == "reached"
    camera = Camera(loop.robot, "inspection_camera_optical_frame", fov=1.0)
    held_at = in_base(loop, body)
    assert math.dist(held_at, (0.0, 0.45, 1.2)) < 0.02  # at the inspection point, 0.65 m before the camera
    before, facing = _colour(camera), _facing(loop, body)
    assert before[0] > 120 and before[2] < 60, before  # the red end face towards the camera
    loop.turn(math.pi)  # the wrist roll turns the held parcel half a turn about the vertical
    after = _colour(camera)
    assert after[2] > 120 and after[0] < 60, after  # now its blue end face
    assert float(np.dot(_facing(loop, body), facing)) < -0.98  # the world's pose: turned by pi
    assert math.dist(in_base(loop, body), held_at) < 0.01  # about the tool axis: still at the point
    assert loop.grasp.held == body
    assert loop.move({"id": 101, "group": "arm", "pose": "home"}, 20.0)["state"] == "reached"
    placed = run_behavior(loop, "place-object", PLACE)
    assert placed.done, placed
    assert loop.grasp.held is None and loop.gripper_result["holding"] == 0
    loop.run(1.0)
    x, y, z = in_base(loop, body)
    assert math.hypot(x - PLACE_AT[0], y - PLACE_AT[1]) < 0.02  # set down where asked
    assert z == pytest.approx(TABLE_TOP + 0.15, abs=0.01)  # standing on the table
    up = p.getMatrixFromQuaternion(p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[1])[8]
    assert up > 0.999  # upright


def test_a_parcel_heavier_than_the_fingers_grip_slips_out_as_it_is_lifted(cell: tuple[InspectionLoop, int]) -> None:
    """The hold force is the fingers' friction grip (2 x 0.75 x 60 N = 90 N, D296): a 15 kg parcel
    (147 N) is caught as they close on it, and slips out when the arm lifts: it stays on the table."""
    loop, light = cell
    p.removeBody(light, physicsClientId=loop.world.client)
    heavy = parcel(loop, (0.6, 0.0, TABLE_TOP + 0.151), 0.15, 15.0)
    loop.world.step(60)
    resting = in_base(loop, heavy)
    assert loop.grasp.gripper.hold_force == pytest.approx(90.0)
    picked = run_behavior(loop, "pick-object", PICK)
    assert loop.grasp.held is None  # let go: it slipped out
    assert in_base(loop, heavy)[2] - resting[2] < 0.03  # still on the table
    assert loop.tool_in_base()[2] > 1.1 or picked.failed  # the arm rose (or could not) without it
