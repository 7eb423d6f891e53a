"""The three mobile services closing the loop on the real pybullet world (tests/plugins/navigation/loop.py):
Algorithm 3 and the MCL baseline take the Turtlebot around a pillar to an area 3 m away; an unmapped
box on the way is seen and planned around; relative moves of APPR and BACK end within a few cm; an
unreachable goal is refused with the planner's reason and the robot stays put."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pybullet as p
import pytest
import shapely

from .loop import Bench, room

START = (1.0, 1.8, 0.0)
TARGET = (4.0, 1.8)  # the Target area's centroid, 3 m east, behind the pillar
PILLAR = shapely.box(2.3, 1.1, 2.7, 2.9)


@pytest.fixture
def bench_factory(tmp_path: Path) -> Iterator[type[Bench]]:
    made: list[Bench] = []

    class Made(Bench):
        def __init__(self, *args: object, **kwargs: object) -> None:
            super().__init__(*args, **kwargs)  # type: ignore[arg-type]
            made.append(self)

    yield Made
    for bench in made:
        bench.close()


def _navigate(bench: Bench, goal: str, timeout: float) -> tuple[list[str], list[tuple[float, float, float]]]:
    """Set ``goal`` and run until Navigation arrives or fails: the states seen and the true trajectory."""
    bench.services["nav"].plugin.apply_service_parameters({"goal": goal})  # type: ignore[attr-defined]
    states: list[str] = []
    trajectory: list[tuple[float, float, float]] = []

    def done() -> bool:
        status = bench.latest("/nav/status")
        trajectory.append(bench.truth())
        if status is None or status["goal"] != goal:
            return False
        if not states or states[-1] != status["state"]:
            states.append(status["state"])
        return bool(status["state"] in ("arrived", "failed"))

    assert bench.run(done, timeout), f"no arrival in {timeout} s: states {states}, at {bench.truth()}"
    return states, trajectory


@pytest.mark.parametrize("filter_name", ["reliability", "mcl"])
def test_the_robot_localizing_reaches_the_target_area_around_the_pillar(
    tmp_path: Path, bench_factory: type[Bench], filter_name: str
) -> None:
    # the prior is 0.15 m and 0.05 rad off the truth; the odometry's left wheel reads 1 % fast
    nav = {"filter": filter_name, "particles": 1000, "initialPose": "1.1 1.7 0.05", "initialSpread": "0.2 0.1"}
    bench = bench_factory(room(tmp_path), START, nav=nav)
    states, trajectory = _navigate(bench, "Target", 40.0)
    assert states[-1] == "arrived", states
    assert "active" in states
    bench.run(lambda: False, 1.0)  # the base has stopped: it stays
    x, y, _ = bench.truth()
    assert math.hypot(x - TARGET[0], y - TARGET[1]) < 0.3
    clearance = min(PILLAR.distance(shapely.Point(t[0], t[1])) for t in trajectory)
    assert clearance > 0.18  # around the pillar, never through it (the base's radius is 0.175 m)
    errors = [e for _, e in bench.estimates]
    assert max(errors[1:]) < 0.25, errors  # bounded all along (the first frame is the prior's mean)
    assert errors[-1] < 0.1
    status, pose = bench.latest("/nav/status"), bench.latest("/nav/pose")
    assert status["remaining"] == 0.0 and status["path_length"] > 3.0
    assert 0 < pose["dispersion"] < 0.5 and len(pose["covariance"]) == 9
    assert bench.latest("/base/path")["points"] == []  # arrived: the base is told to stop


def test_an_unmapped_box_on_the_path_is_seen_and_planned_around(tmp_path: Path, bench_factory: type[Bench]) -> None:
    nav = {"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"}
    bench = bench_factory(room(tmp_path), START, nav=nav)
    cid = bench.world.client  # a box the map does not know closes the gap south of the pillar
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.3, 0.3, 0.25], physicsClientId=cid)
    p.createMultiBody(0, shape, -1, [2.5, 0.4, 0.25], physicsClientId=cid)
    states, trajectory = _navigate(bench, "Target", 45.0)
    assert states[-1] == "arrived", states
    assert max(t[1] for t in trajectory) > 2.9  # it went round the north end instead
    assert bench.latest("/base/path")["id"] >= 2  # replanned, around what the scan showed
    assert [a.name for a in bench.services["nav"].plugin.routes.extra][:1] == ["scan obstacle 1"]  # type: ignore[attr-defined]
    assert min(shapely.box(2.2, 0.1, 2.8, 0.7).distance(shapely.Point(t[:2])) for t in trajectory) > 0.15


def test_relative_moves_end_within_a_few_centimetres(tmp_path: Path, bench_factory: type[Bench]) -> None:
    bench = bench_factory(room(tmp_path), START)
    bench.run(lambda: False, 0.2)  # odometry flowing
    moves = [  # APPR's forward move, BACK's backwards move, an APPR move to one side facing the target
        (11, (0.5, 0.0, 0.0)),
        (12, (-0.3, 0.0, 0.0)),
        (13, (0.3, 0.3, math.pi / 4)),
    ]
    for goal_id, (dx, dy, dyaw) in moves:
        x0, y0, yaw0 = bench.truth()
        bench.publish("/base/move_goal", {"id": goal_id, "frame": "robot", "x": dx, "y": dy, "yaw": dyaw})

        def finished(goal_id: int = goal_id) -> bool:
            status = bench.latest("/base/move_status")
            return status is not None and status["id"] == goal_id and status["state"] != "moving"

        assert bench.run(finished, 15.0)
        status = bench.latest("/base/move_status")
        assert status["state"] == "done"
        assert status["total"] == pytest.approx(math.hypot(dx, dy), abs=1e-6)
        bench.run(lambda: False, 0.3)
        x, y, yaw = bench.truth()
        c, s = math.cos(yaw0), math.sin(yaw0)
        want = (x0 + c * dx - s * dy, y0 + s * dx + c * dy)
        assert math.dist((x, y), want) < 0.03, (goal_id, (x, y), want)
        assert abs(math.remainder(yaw - yaw0 - dyaw, 2 * math.pi)) < 0.06
    assert bench.latest("/base/odom")["dispersion"] > 0


def test_an_unreachable_goal_is_refused_with_the_reason_and_the_robot_stays(
    tmp_path: Path, bench_factory: type[Bench]
) -> None:
    bench = bench_factory(room(tmp_path), START, nav={"particles": 500, "initialPose": "1 1.8 0"})
    states, _ = _navigate(bench, "Walled", 5.0)  # an area inside the pillar
    status = bench.latest("/nav/status")
    assert states[-1] == "failed"
    assert "the goal collides with 'Pillar'" in status["reason"]
    assert bench.latest("/base/path")["points"] == []
    states, _ = _navigate(bench, "7 2 0", 5.0)  # outside the 5 × 4 m room
    assert states[-1] == "failed" and "map bounds" in bench.latest("/nav/status")["reason"]
    assert math.dist(bench.truth()[:2], START[:2]) < 0.01


def test_in_the_use_case_lab_the_robot_drives_from_home_to_the_workbench(bench_factory: type[Bench]) -> None:
    """configs/usecase/environment.xml, the sim's start pose (nodes.xml), the Params proposed for the
    use case (docs/navigation.md): 7.8 m between the drop table, the column and the workbench."""
    lab = Path(__file__).resolve().parents[3] / "configs" / "usecase" / "environment.xml"
    nav = {"initialPose": "1.5 1.5 0.785", "initialSpread": "0.2 0.1"}
    bench = bench_factory(lab, (1.5, 1.5, 0.785), nav=nav)
    states, _ = _navigate(bench, "WorkbenchArea", 60.0)
    assert states[-1] == "arrived", states
    x, y, _ = bench.truth()
    assert math.hypot(x - 8.1, y - 5.5) < 0.2  # the area's centroid
    assert max(e for _, e in bench.estimates[1:]) < 0.2
