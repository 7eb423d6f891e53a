"""Routes (plugins/navigation/routes.py): a start inside an obstacle's inflation leaves by the nearest
free cell (``escape``), a goal inside one is replaced by the nearest free point (``goalEscape``, D107),
and both at once — the use case's return home, from the workbench where APPR left the robot to the
drop table's edge."""

from __future__ import annotations

import math

import pytest

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
