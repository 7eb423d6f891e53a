"""The compact laboratory (benchmarks/mission_compact.py, D205): the same system, a shorter fetch.

The copy keeps every node, service, behavior and mission; only the layout moves, consistently:
the robot starts clear of everything in the new HomeArea, the planner finds the way to the
workbench and back to the drop table, and NAV_HOME and DOCK aim at the moved table."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import pytest

import ckmconf
from benchmarks.mission_compact import DOCK_POSE, DROP_TABLE, NAV_HOME_GOAL, START, compact
from benchmarks.mission_random import footprint_distance
from plugins.environment.geometry import Footprint
from plugins.navigation.obstacles import ScanObstacles
from plugins.navigation.routes import Routes
from tests.conftest import CONFIGS

LAB = CONFIGS / "usecase" / "lab.xml"
ROBOT_RADIUS = 0.2  # the Kobuki base (0.175 m in its URDF) and 2.5 cm of margin
NAV_GOAL = (7.6, 5.5)  # the NAV behavior's goal at the workbench (behaviors.xml), unchanged


def _pose(text: str) -> tuple[float, float, float]:
    x, y, yaw = map(float, text.split())
    return x, y, yaw


@pytest.fixture(scope="module")
def copy(tmp_path_factory: pytest.TempPathFactory) -> ckmconf.model.System:
    return ckmconf.load(compact(LAB, tmp_path_factory.mktemp("compact") / "usecase", ports=(7630, 7640)))


def test_the_copy_keeps_the_system_and_moves_only_the_layout(copy: ckmconf.model.System) -> None:
    lab = ckmconf.load(LAB)
    assert [n.name for n in copy.nodes] == [n.name for n in lab.nodes]
    assert [m.name for m in copy.missions] == [m.name for m in lab.missions]
    assert {b.name for b in copy.behaviors} == {b.name for b in lab.behaviors}
    assert copy.environment is not None and lab.environment is not None
    table = next(o for o in copy.environment.objects if o.name == "drop_table")
    assert (table.pose.x, table.pose.y) == DROP_TABLE
    moved = {o.name for o in copy.environment.objects} - {"drop_table"}
    assert all(o.pose == next(p for p in lab.environment.objects if p.name == o.name).pose
               for o in copy.environment.objects if o.name in moved)  # fmt: skip
    assert copy.network is not None and (copy.network.discovery_port, copy.network.base_port) == (7630, 7640)


def test_the_robot_starts_in_home_area_clear_of_every_object(copy: ckmconf.model.System) -> None:
    assert copy.environment is not None
    x, y, _ = _pose(START)
    home = next(a for a in copy.environment.areas if a.name == "HomeArea")
    xs, ys = [p[0] for p in home.points()], [p[1] for p in home.points()]
    margin = ROBOT_RADIUS
    assert min(xs) + margin <= x <= max(xs) - margin and min(ys) + margin <= y <= max(ys) - margin
    assert all(footprint_distance(o, x, y) >= ROBOT_RADIUS for o in copy.environment.objects)
    starts = {p.value for n in copy.nodes for c in n.channels for p in c.params if p.name == "pose"
              and any(q.name == "body" and q.value == "turtlebot" for q in c.params)}  # fmt: skip
    assert starts == {START}


def test_home_goals_face_the_moved_drop_table_at_the_labs_offsets(copy: ckmconf.model.System) -> None:
    nav_home, dock = copy.behavior("NAV_HOME"), copy.behavior("DOCK")
    assert nav_home is not None and dock is not None
    goal = next(c.value for u in nav_home.uses for c in u.configure if c.parameter == "goal")
    assert goal == NAV_HOME_GOAL and next(p.value for p in dock.params if p.name == "pose") == DOCK_POSE
    front = DROP_TABLE[1] - 0.3  # the table is 0.6 m deep
    assert front - _pose(goal)[1] == pytest.approx(0.30) and front - _pose(DOCK_POSE)[1] == pytest.approx(0.18)


def test_the_planner_finds_the_way_to_the_workbench_and_back_and_it_is_short(copy: ckmconf.model.System) -> None:
    assert copy.environment is not None
    routes = Routes(copy.environment, Footprint.round(0.2, 0.5), 0.1, 0.6, 0.3, ScanObstacles())
    there = routes.plan(_pose(START)[:2], NAV_GOAL)
    back = routes.plan(NAV_GOAL, _pose(NAV_HOME_GOAL)[:2])

    def length(way: list[tuple[float, float]]) -> float:
        return sum(math.dist(a, b) for a, b in itertools.pairwise(way))

    assert length(there) < 2.5 and length(back) < 2.5  # the lab's are over 8 m


def test_a_configuration_without_a_drop_table_is_refused_by_name(tmp_path: Path) -> None:
    system = tmp_path / "src" / "plain.xml"
    system.parent.mkdir()
    system.write_text((CONFIGS / "examples" / "partitions.xml").read_text())
    with pytest.raises(ValueError, match="nothing to move for the compact layout: drop table, start, home goals"):
        compact(system, tmp_path / "copy")
