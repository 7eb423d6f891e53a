"""Routes (plugins/navigation/routes.py): a start inside an obstacle's inflation leaves by the nearest
free cell (``escape``), a goal inside one is replaced by the nearest free point (``goalEscape``, D107),
and both at once — the use case's return home, from the workbench where APPR left the robot to the
drop table's edge."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from benchmarks.mission_compact import compact
from ckmconf.loader import load
from plugins.environment.geometry import Footprint
from plugins.environment.planner import Unreachable
from plugins.navigation.obstacles import ScanObstacles
from plugins.navigation.routes import Routes
from tests.conftest import CONFIGS

AT_THE_WORKBENCH = (7.611, 5.823)
"""Where APPR stopped the Turtlebot in a run: 0.28 m from the object, inside the bench's inflation."""
HOME = (1.0, 1.4)
"""NAV_HOME's goal, before the drop table: inside its inflation too."""


def routes(escape: float = 0.6, goal_escape: float = 0.3) -> Routes:
    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    assert environment is not None
    return Routes(environment, Footprint.round(0.2, 0.5), 0.1, escape, goal_escape, ScanObstacles())


def test_a_start_and_a_goal_both_inside_inflations_get_a_path() -> None:
    way = routes().plan(AT_THE_WORKBENCH, HOME)
    assert way[0] == AT_THE_WORKBENCH  # leaves from where the robot is ...
    assert math.dist(way[1], AT_THE_WORKBENCH) <= 0.6  # ... by a free cell within escape
    assert math.dist(way[-1], HOME) <= 0.3  # and ends at a free point near the goal


@pytest.mark.parametrize(("escape", "goal_escape", "end"), [(0.0, 0.3, "start"), (0.6, 0.0, "goal")])
def test_without_the_escape_the_colliding_end_is_named(escape: float, goal_escape: float, end: str) -> None:
    with pytest.raises(Unreachable, match=f"the {end} collides with"):
        routes(escape, goal_escape).plan(AT_THE_WORKBENCH, HOME)


def test_a_start_on_the_edge_of_an_inflation_with_no_straight_way_out_leaves_by_a_free_cell(tmp_path: Path) -> None:
    # A bench run (compact layout, seed 16): driven to HomeArea's centre, the robot stopped 0.2001 m
    # from the drop table, just outside its 0.2 m footprint, where every straight way to a free cell
    # grazes the inflation: "the start is boxed in", and NAV_COOP failed at once (D210).
    environment = load(compact(CONFIGS / "usecase" / "lab.xml", tmp_path / "usecase")).environment
    assert environment is not None
    here = (6.12776, 5.09986)
    stuck = Routes(environment, Footprint.round(0.2, 0.5), 0.1, 0.0, 0.3, ScanObstacles())
    with pytest.raises(Unreachable, match="the start is boxed in"):
        stuck.plan(here, (7.6, 5.501))
    way = Routes(environment, Footprint.round(0.2, 0.5), 0.1, 0.6, 0.3, ScanObstacles()).plan(here, (7.6, 5.501))
    assert way[0] == here and math.dist(way[1], here) <= 0.6 and way[-1] == (7.6, 5.501)


@pytest.mark.parametrize("clearance", [0.0, 0.1])
def test_a_plan_keeps_the_obstacle_clearance_from_scan_points(clearance: float) -> None:
    """D238: scan obstacles show only what the laser saw, placed with the localization's error: the plan
    keeps ``clearance`` more from them than the footprint (0.2) and the points' own 5 cm."""
    import shapely

    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    assert environment is not None
    way = Routes(environment, Footprint.round(0.2, 0.5), 0.1, 0.6, 0.3, ScanObstacles(clearance=clearance))
    face = [(3.0, 2.4 + 0.02 * k) for k in range(26)]  # a crate's face across the way, 0.5 m wide
    way.avoid(face)
    plan = way.plan((2.0, 2.65), (4.0, 2.65))
    gap = shapely.LineString(plan).distance(shapely.MultiPoint(face))
    assert gap >= 0.2 + 0.05 + clearance - 0.01
    if clearance:
        assert gap < 0.2 + 0.05 + clearance + 0.1  # round it, not far off
    with pytest.raises(ValueError, match="clearance"):
        ScanObstacles(clearance=-0.1)
