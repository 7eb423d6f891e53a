"""Heights of the environment model (D294): a ``<Geometry2D height="0">`` marking is in the map but
nobody's obstacle (collisions, planning, the laser's segments), a ``<Geometry2D height>`` bounds the
block, no height keeps the 2D object an obstacle at every height; an ``<AvoidedArea height>`` leaves
ground planning unchanged; :class:`Airspace` answers what a flight at an altitude meets."""

from __future__ import annotations

import math

import pytest
import shapely

import ckmconf
from ckmconf.model.environment import Environment
from plugins.environment.airspace import BOUNDS, FLOOR, Airspace
from plugins.environment.geometry import Footprint
from plugins.environment.map_model import MapModel
from plugins.environment.planner import Planner
from plugins.environment.zoom import ZoomMap, ZoomSettings

ROBOT = Footprint.round(0.18, height=0.45)

ROOM = """<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0" description="heights">
  <Environment name="heights">
    <Map xmin="0" ymin="0" xmax="10" ymax="6" height="4"/>
    <AvoidedArea name="rack" height="2">
      <Vertex x="6" y="1"/><Vertex x="7" y="1"/><Vertex x="7" y="5"/><Vertex x="6" y="5"/>
    </AvoidedArea>
    <AvoidedArea name="column">
      <Vertex x="8.5" y="2.5"/><Vertex x="9" y="2.5"/><Vertex x="9" y="3"/><Vertex x="8.5" y="3"/>
    </AvoidedArea>
    <Semantic tag="pad"/>
    <Semantic tag="furniture"/>
    <Object name="pad" tag="pad">
      <Pose x="3" y="3"/>
      <Geometry2D height="0"><Rectangle width="1.2" depth="1.2"/></Geometry2D>
    </Object>
    <Object name="desk" tag="furniture">
      <Pose x="3" y="0.8"/>
      <Geometry2D><Rectangle width="1" depth="0.6"/></Geometry2D>
    </Object>
    <Object name="step" tag="furniture">
      <Pose x="1" y="5"/>
      <Geometry2D height="0.3"><Circle radius="0.3"/></Geometry2D>
    </Object>
    <Object name="sign" tag="furniture">
      <Pose x="4.5" y="5" z="0.6"/>
      <Geometry2D height="0.1"><Circle radius="0.3"/></Geometry2D>
    </Object>
    <Object name="shelf" tag="furniture">
      <Pose x="8" y="0.6"/>
      <Geometry25D><Prism zmin="1" zmax="1.2"><Rectangle width="0.8" depth="0.4"/></Prism></Geometry25D>
    </Object>
  </Environment>
</Part>
"""


@pytest.fixture(scope="module")
def env(tmp_path_factory: pytest.TempPathFactory) -> Environment:
    path = tmp_path_factory.mktemp("heights") / "room.xml"
    path.write_text(ROOM)
    loaded = ckmconf.load(path).environment
    assert loaded is not None
    return loaded


@pytest.fixture
def model(env: Environment) -> MapModel:
    return MapModel.from_environment(env)


def test_a_marking_is_in_the_map_but_nobodys_obstacle(model: MapModel) -> None:
    pad = model.get("pad")
    assert (pad.zmin, pad.zmax) == (0.0, 0.0) and pad.obstacle() is None
    assert model.collisions(ROBOT, 3.0, 3.0) == []  # standing on it
    assert [o.name for o in model.in_region(shapely.Point(3, 3).buffer(0.1))] == ["pad"]  # still seen there
    assert "pad" not in model.obstacles(ROBOT)
    assert model.clearance(3.0, 3.0) > 0.5  # the nearest obstacle is not the marking under the point
    on_laser = shapely.MultiLineString([list(row.reshape(2, 2)) for row in model.segments(0.0)])
    assert on_laser.distance(shapely.Point(3.0, 3.0)) > 1.0  # not even a laser at floor level meets its outline


def test_a_geometry2d_without_height_still_obstructs_at_every_height(model: MapModel) -> None:
    desk = model.get("desk")
    assert (desk.zmin, desk.zmax) == (-math.inf, math.inf)
    assert model.collisions(Footprint.round(0.18, height=0.05), 3.0, 0.8) == ["desk"]


def test_a_geometry2d_height_bounds_the_block(model: MapModel) -> None:
    step, sign = model.get("step"), model.get("sign")
    assert (step.zmin, step.zmax) == (0.0, 0.3) and (sign.zmin, sign.zmax) == pytest.approx((0.6, 0.7))
    assert model.collisions(ROBOT, 1.0, 5.0) == ["step"]
    assert model.collisions(ROBOT, 4.5, 5.0) == []  # the 0.45 m robot passes under the sign at 0.6 m
    assert model.collisions(Footprint.round(0.18, height=0.8), 4.5, 5.0) == ["sign"]


def test_the_planner_goes_straight_through_a_marking_and_around_a_block(model: MapModel) -> None:
    planner = Planner(model, ROBOT)
    across = planner.plan((1.5, 3.0), (4.5, 3.0))  # the marking lies across the whole way
    assert across.waypoints == [(1.5, 3.0), (4.5, 3.0)] and planner.check(across.waypoints) == []
    around = planner.plan((1.5, 0.8), (4.5, 0.8))  # the desk, no height given, stands in the way
    assert len(around.waypoints) > 2 and around.length > 3.0 + 0.05


def test_an_avoided_area_of_any_height_is_still_avoided_on_the_ground(model: MapModel) -> None:
    assert model.collisions(ROBOT, 6.5, 3.0) == ["rack"]
    planner = Planner(model, ROBOT)
    plan = planner.plan((5.0, 3.0), (7.8, 3.0))
    assert planner.check(plan.waypoints) == [] and plan.length > 2.8 + 1.0  # round the 4 m long rack


def test_a_2_5d_zoom_map_holds_a_marking_on_the_floor(model: MapModel) -> None:
    zoom = ZoomMap(model, ZoomSettings(mode="2.5D", width=3.0, depth=3.0, height=1.0))
    zoom.recentre(3.0, 3.0, 0.0)
    assert "pad" in [o.name for o in zoom.objects]


# ---------------------------------------------------------------- the airspace


@pytest.fixture
def air(env: Environment) -> Airspace:
    return Airspace(env)


def top(air: Airspace, points: list[tuple[float, float]]) -> tuple[float, str | None]:
    """:meth:`Airspace.highest`, its height rounded to the millimetre."""
    height, name = air.highest(points)
    return round(height, 3), name


def test_the_highest_solid_under_a_point_or_path(air: Airspace) -> None:
    assert air.highest([(3.0, 3.0)]) == (0.0, None)  # over the marking: bare floor
    assert top(air, [(3.0, 0.8)]) == (0.75, "desk")  # no height: the sim's 0.75 m block
    assert top(air, [(1.0, 5.0)]) == (0.3, "step")
    assert air.highest([(5.0, 3.0), (7.5, 3.0)]) == (2.0, "rack")
    assert air.highest([(7.5, 2.75), (9.5, 2.75)]) == (4.0, "column")  # no height: the map's
    assert top(air, [(8.0, 0.6)]) == (1.2, "shelf")
    assert air.highest([(8.0, 0.6)], below=0.5) == (0.0, None)  # the shelf board is above a 0.5 m flight
    assert air.highest([(5.0, 3.0)], radius=1.2) == (2.0, "rack")  # the body's radius reaches it
    assert air.highest([(9.5, 3.0), (11.0, 3.0)]) == (4.0, BOUNDS)


def test_an_avoided_area_2_m_tall_lets_a_flight_at_3_m_pass_and_stops_one_at_1_m(air: Airspace) -> None:
    assert air.clears((5.0, 3.0), (7.5, 3.0), 3.0, radius=0.2, half_height=0.1)
    assert air.blockers((5.0, 3.0), (7.5, 3.0), 1.0, radius=0.2, half_height=0.1) == ["rack"]
    assert air.blockers((5.0, 3.0), (7.5, 3.0), 1.95, half_height=0.1) == ["rack"]  # its bottom would scrape


def test_a_flight_meets_walls_blocks_and_the_floor_in_the_order_met(air: Airspace) -> None:
    assert air.blockers((0.5, 0.8), (9.5, 0.8), 0.5, radius=0.1) == ["desk"]  # under the shelf board at 1 m
    assert air.blockers((0.5, 0.8), (9.5, 0.8), 0.5, radius=0.3) == ["desk", "rack"]  # 0.3 m: the rack's corner
    assert air.blockers((0.5, 0.8), (9.5, 0.8), 1.1) == ["shelf"]  # over the desk, into the shelf board
    assert air.blockers((5.0, 3.0), (9.5, 2.75), 1.0) == ["rack", "column"]
    assert air.blockers((9.0, 4.0), (12.0, 4.0), 1.0) == [BOUNDS]  # through the east wall
    assert air.blockers((1.0, 3.0), (2.0, 3.0), 3.95, half_height=0.1) == [BOUNDS]  # above the mapped space
    assert air.blockers((1.0, 3.0), (2.0, 3.0), 0.05, half_height=0.1) == [FLOOR]
    assert air.clears((1.5, 3.0), (4.5, 3.0), 0.1, radius=0.3, half_height=0.05)  # low over the marking
    assert air.clears((3.0, 0.8), (3.0, 0.8), 1.0)  # hovering over the desk


def test_a_climbing_or_descending_flight_is_checked_at_the_heights_it_has_over_each_solid(air: Airspace) -> None:
    # from 1 m at x = 5 up to 3 m at x = 8: over the rack (x 6..7) it is at 1.67..2.33 m, into its 2 m top
    assert air.path_blockers((5.0, 3.0, 1.0), (8.0, 3.0, 3.0)) == ["rack"]
    assert air.path_clear((5.0, 3.0, 1.5), (5.8, 3.0, 3.0))  # climbs short of it
    # from 3 m at x = 5 down to 2.2 m at x = 7.5: over the rack (5.9..7.1 with its 0.1 m radius) at 2.33..2.71 m
    assert air.path_clear((5.0, 3.0, 3.0), (7.5, 3.0, 2.2), radius=0.1, half_height=0.3)  # its bottom 2.03 m up
    assert air.path_blockers((5.0, 3.0, 3.0), (7.5, 3.0, 2.2), radius=0.1, half_height=0.4) == ["rack"]
    assert air.path_blockers((5.0, 3.0, 3.0), (7.5, 3.0, 1.0)) == ["rack"]  # lands behind it: through it
    assert air.path_blockers((3.0, 0.8, 2.0), (3.0, 0.8, 0.5)) == ["desk"]  # straight down onto the desk
    assert air.path_clear((3.0, 3.0, 2.0), (3.0, 3.0, 0.2))  # straight down onto the marking
    assert air.blockers((5.0, 3.0), (7.5, 3.0), 1.0) == air.path_blockers((5.0, 3.0, 1.0), (7.5, 3.0, 1.0))


def test_bad_flight_arguments_are_refused(air: Airspace) -> None:
    with pytest.raises(ValueError, match="radius"):
        air.blockers((1.0, 1.0), (2.0, 2.0), 1.0, radius=-0.1)
    with pytest.raises(ValueError, match="half height"):
        air.blockers((1.0, 1.0), (2.0, 2.0), 1.0, half_height=-0.1)
    with pytest.raises(ValueError, match="finite"):
        air.blockers((1.0, 1.0), (2.0, 2.0), math.nan)
    with pytest.raises(ValueError, match=r"\(x, y, z\)"):
        air.path_blockers((1.0, 1.0), (2.0, 2.0, 1.0))  # type: ignore[arg-type]
