"""search-object, spot-objects and approach in the pybullet closed loop on the Turtlebot and the rover (issue M,
point 6).

The lab's perception kinds over the bench's real base-drive service (tests/plugins/navigation/loop.py),
a detector seeing from the robot's true pose in the fused recognition's place (closed_loop.SightDetector),
on two robot models. ``approach`` runs without an arm: the rover has none, and the kind then drives the
base alone. What counts is where the robot ends in the world.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import Uses
from plugins.behaviors.approach import Approach
from plugins.behaviors.perception import SpotObjects
from plugins.behaviors.recovery import SearchObject
from tests.plugins.behaviors.closed_loop import BenchBase, SightDetector, angle, run_states, wired
from tests.plugins.navigation.loop import ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel, room

MODELS = pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)
PARCEL = (1.9, 2.6)
"""On the map: ahead and to the left of the start, clear of the pillar."""


def bearing_to(bench: Bench, point: tuple[float, float]) -> float:
    """How far the robot's true heading is from facing ``point`` (rad)."""
    x, y, yaw = bench.truth()
    return angle(math.atan2(point[1] - y, point[0] - x), yaw)


@MODELS
def test_search_object_turns_until_the_target_is_in_view_and_writes_where_it_is(
    tmp_path: Path, model: RobotModel
) -> None:
    bench = Bench(room(tmp_path), (1.0, 1.8, -1.2), model=model)
    try:
        eyes = SightDetector(bench, {"parcel": PARCEL, "box": (1.0, 0.8)})
        assert bearing_to(bench, PARCEL) > 1.5  # out of view at the start
        look = wired(
            bench,
            SearchObject,
            "LOOK",
            {"base": BenchBase(bench), "fusion": eyes},
            outputs={"move": "/base/move_goal", "target": "/target"},
            target="parcel",
            turn="0.6",
            views="11",
            settle="0.5",
            dwell="0.5",
        )
        _, status = run_states(bench, [look], 90.0)[-1]
        assert status.done, status
        assert bearing_to(bench, PARCEL) < eyes.half_fov  # it stopped facing the parcel
        x, y, yaw = bench.truth()
        found = bench.latest("/target")
        assert found["label"] == "parcel"
        on_map = (
            x + math.cos(yaw) * found["x"] - math.sin(yaw) * found["y"],
            y + math.sin(yaw) * found["x"] + math.cos(yaw) * found["y"],
        )
        assert math.dist(on_map, PARCEL) < 0.05, on_map
    finally:
        bench.close()


@MODELS
def test_spot_then_approach_without_an_arm_stops_at_the_standoff_facing_the_target(
    tmp_path: Path, model: RobotModel
) -> None:
    start = (1.0, 1.8, math.atan2(PARCEL[1] - 1.8, PARCEL[0] - 1.0) - 0.3)  # the parcel in view, off-centre
    bench = Bench(room(tmp_path), start, model=model)
    try:
        eyes = SightDetector(bench, {"parcel": PARCEL, "box": (1.0, 0.8)})
        standoff = float(str(model.footprint["robotRadius"])) + 0.15
        spot = wired(bench, SpotObjects, "SPOT", {"fusion": eyes}, outputs={"target": "/target"}, target="parcel")
        approach = wired(
            bench,
            Approach,
            "APPR",
            {"base": BenchBase(bench)},
            inputs={"target": "/target"},
            outputs={"move": "/base/move_goal"},
            standoff=f"{standoff:.2f}",
            yawTolerance="0.03",
        )
        bench.run(lambda: bench.latest("/base/odom") is not None, 1.0)  # the base has its odometry
        statuses = run_states(bench, [spot, approach], 60.0)
        assert statuses[-1][0] == "APPR" and statuses[-1][1].done, statuses[-1]
        x, y, _ = bench.truth()
        # the base drives the move on odometry (its left wheel reads 1 % large): a few centimetres off
        assert math.dist((x, y), PARCEL) == pytest.approx(standoff, abs=0.06)
        assert bearing_to(bench, PARCEL) < 0.15  # the drive's odometry drift (0.04 rad on the Turtlebot)
    finally:
        bench.close()


def test_approach_with_an_arm_but_no_arm_pose_is_a_problem() -> None:
    record = BehaviorRecord(
        name="APPR",
        kind="approach",
        timeout=60.0,
        uses=(Uses(service="Base.Drive", as_="base"), Uses(service="Arm.Motion", as_="arm")),
    )
    ((where, message),) = Approach.problems(record, None)
    assert isinstance(where, Uses) and where.alias == "arm"
    assert message.startswith("an approach with an arm needs the pose to raise it to")
    base_only = BehaviorRecord(
        name="APPR", kind="approach", timeout=60.0, uses=(Uses(service="Base.Drive", as_="base"),)
    )
    assert Approach.problems(base_only, None) == []
