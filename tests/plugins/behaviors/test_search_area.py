"""``behavior.search-area`` (issue M, point 3; D269): the lawnmower waypoints of a map Area, each a goal
of the navigation followed by its echoed status only, unreachable ones skipped with their reason, the
object's map pose once the detection or the fusion shows it, and a failure once the Area is covered;
in the pybullet closed loop on the Turtlebot and the rover, through the real navigation service."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
import shapely

import ckmconf
from ckmconf.model import Param
from ckmconf.model.environment import Area, Environment, MapBounds, Vertex
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorOutput, Uses
from plugins.behaviors.coverage import lawnmower
from plugins.behaviors.search_area import SearchArea
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext
from tests.memory_service import MemoryService
from tests.plugins.behaviors.closed_loop import BenchNavigation, SightDetector
from tests.plugins.navigation.loop import ROOM, ROVER_MODEL, TURTLEBOT_MODEL, Bench, RobotModel

HALL = Area(name="Hall", vertices=tuple(Vertex(x=x, y=y) for x, y in ((0, 0), (4, 0), (4, 2), (0, 2))))
ENVIRONMENT = Environment(name="room", map=MapBounds(xmin=0, ymin=0, xmax=4, ymax=2), areas=(HALL,))


def record(perception: str = "detection", **params: str) -> BehaviorRecord:
    values = {"area": "Hall", "label": "parcel", "spacing": "1", "margin": "0.5", **params}
    return BehaviorRecord(name="SWEEP", kind="search-area", timeout=600.0,
                          params=tuple(Param(name=k, value=v) for k, v in values.items()),
                          uses=(Uses(service="Base.Nav", as_="nav"), Uses(service="Camera.Detect", as_=perception)),
                          outputs=(BehaviorOutput(name="found", topic="/found"),))


def sweep(nav: Any, eyes: Any, perception: str = "detection", environment: Environment | None = ENVIRONMENT,
          now: list[float] | None = None, **params: str) -> tuple[SearchArea, list[Any]]:
    clock = now if now is not None else [0.0]
    written: list[Any] = []
    context = BehaviorContext(services={"nav": nav, perception: eyes}, inputs={},
                              outputs={"found": written.append}, now=lambda: clock[0], environment=environment)
    made = SearchArea(record(perception, **params), context)
    made.start()
    return made, written


def goal_of(nav: MemoryService) -> str:
    return str(nav.configured[-1][0]["goal"])


def test_the_lawnmower_covers_the_polygon_lane_by_lane_inside_its_margin() -> None:
    waypoints = lawnmower(HALL.points(), 1.0, 0.5, "long")
    assert [(round(x, 3), round(y, 3)) for x, y, _ in waypoints] == [
        (0.5, 0.5), (1.5, 0.5), (2.5, 0.5), (3.5, 0.5), (3.5, 1.5), (2.5, 1.5), (1.5, 1.5), (0.5, 1.5)]
    assert [round(yaw, 3) for _, _, yaw in waypoints[3:5]] == [0.0, round(math.pi, 3)]
    across = lawnmower(HALL.points(), 1.0, 0.5, "y")
    assert {round(x, 3) for x, _, _ in across} == {0.5, 1.5, 2.5, 3.5} and len(across) == 8
    ell = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (3.0, 4.0), (3.0, 1.0), (0.0, 1.0)]  # an L (concave)
    inside = shapely.Polygon(ell)
    points = lawnmower(ell, 0.5, 0.25)
    assert points and all(inside.buffer(1e-6).contains(shapely.Point(x, y)) for x, y, _ in points)
    assert lawnmower([(0.0, 0.0), (0.4, 0.0), (0.4, 0.4), (0.0, 0.4)], 1.0, 0.5) == [(0.2, 0.2, 0.0)]  # too small


def test_each_waypoint_is_a_goal_and_only_its_own_status_moves_the_sweep_on() -> None:
    nav, eyes = MemoryService("Base.Nav"), MemoryService("Camera.Detect")
    nav.outputs["status"] = {"goal": "0.500 0.500 0.000", "state": "arrived"}  # an earlier goal's, same text
    search, _ = sweep(nav, eyes)
    assert goal_of(nav) == "0.500 0.500 0.000"
    assert search.step().progress == 0.0  # the status from before this goal was set
    nav.outputs["status"] = {"goal": "0.500 0.500 0.000", "state": "arrived"}
    status = search.step()
    assert status.progress == pytest.approx(1 / 8) and goal_of(nav) == "1.500 0.500 0.000"


def test_an_unreachable_waypoint_is_skipped_with_its_reason_and_the_covered_area_fails() -> None:
    nav, eyes = MemoryService("Base.Nav"), MemoryService("Camera.Detect")
    search, written = sweep(nav, eyes)
    for k in range(8):
        goal = goal_of(nav)
        if k == 2:
            nav.outputs["status"] = {"goal": goal, "state": "failed", "reason": "the goal collides with 'Pillar'"}
        else:
            nav.outputs["status"] = {"goal": goal, "state": "arrived"}
        status = search.step()
    assert status.failed and status.progress == 1.0 and not written
    assert status.detail.startswith("area Hall covered (8 waypoints, 1 skipped) without seeing parcel; skipped "
                                    "2.500 0.500 0.000: the goal collides with 'Pillar'")
    assert {"message": "waypoint skipped", "waypoint": "2.500 0.500 0.000",
            "reason": "the goal collides with 'Pillar'"} in search.context.events
    assert nav.configured[-1][0] == {"goal": "0.500 1.500 3.142"}  # the last: nothing left to cancel


def test_a_waypoint_not_reached_in_time_is_skipped() -> None:
    nav, eyes, clock = MemoryService("Base.Nav"), MemoryService("Camera.Detect"), [0.0]
    search, _ = sweep(nav, eyes, now=clock, waypointTimeout="20")
    clock[0] = 21.0
    search.step()
    assert search.skipped == [{"waypoint": "0.500 0.500 0.000", "reason": "not reached in 20 s"}]
    assert goal_of(nav) == "1.500 0.500 0.000"


def test_the_object_seen_is_placed_on_the_map_and_the_sweep_cancelled() -> None:
    nav, eyes = MemoryService("Base.Nav"), MemoryService("Camera.Detect")
    search, written = sweep(nav, eyes, sensorPose="0.1 0 0", minReliability="0.6")
    nav.outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": math.pi / 2}}
    eyes.outputs["objects"] = {"objects": [{"name": "parcel", "x": 1.0, "y": 0.0, "z": 0.2, "reliability": 0.5},
                                           {"name": "box", "x": 0.5, "y": 0.0, "z": 0.2, "reliability": 0.9}]}
    assert not search.step().done  # too unreliable, and a box
    eyes.outputs["objects"]["objects"][0]["reliability"] = 0.8
    assert not search.step().done  # placed once, with this pose estimate
    assert not search.step().done  # the same estimate again confirms nothing
    nav.outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": 0.0}}  # a newer estimate: the robot turned
    assert not search.step().done  # 1.56 m from where the older one placed it: not taken
    nav.outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": math.pi / 2}}
    eyes.outputs["objects"]["objects"][0]["y"] = 0.0  # seen again facing it
    assert not search.step().done  # agrees with none placed before with another estimate
    nav.outputs["pose"] = {"pose": {"x": 1.0, "y": 1.0, "yaw": math.pi / 2}}
    status = search.step()
    assert status.done and nav.configured[-1][0] == {"goal": ""}
    (found,) = written
    assert found["frame"] == "map" and found["label"] == "parcel" and found["reliability"] == 0.8
    assert (found["x"], found["y"], found["z"]) == pytest.approx((1.0, 2.1, 0.2))
    assert found["observer"] == [{"x": 1.0, "y": 1.0, "yaw": math.pi / 2}]


def test_a_fused_object_is_on_the_map_already() -> None:
    nav, fusion = MemoryService("Base.Nav"), MemoryService("Fusion.Objects")
    search, written = sweep(nav, fusion, "fusion")
    fusion.outputs["objects"] = {"objects": [{"name": "cylinder", "texture": "parcel", "frame": "map", "x": 3.0,
                                              "y": 1.0, "z": 0.1, "reliability": 0.7}]}
    assert search.step().done and (written[0]["x"], written[0]["y"]) == (3.0, 1.0) and written[0]["observer"] == []


def test_leaving_the_state_mid_sweep_cancels_the_waypoint() -> None:
    nav, eyes = MemoryService("Base.Nav"), MemoryService("Camera.Detect")
    search, _ = sweep(nav, eyes)
    search.stop()
    assert nav.configured[-1][0] == {"goal": ""}


def test_an_area_not_on_the_map_or_no_perception_is_refused() -> None:
    nav = MemoryService("Base.Nav")
    with pytest.raises(ParamError, match=r"parameter 'area' = 'Lobby' is no Area of the map"):
        sweep(nav, MemoryService("c"), area="Lobby")
    with pytest.raises(ParamError, match=r"no Area of the map"):
        sweep(nav, MemoryService("c"), environment=None)
    bare = BehaviorRecord(name="SWEEP", kind="search-area", params=(Param(name="area", value="Hall"),),
                          uses=(Uses(service="Base.Nav", as_="nav"),))
    context = BehaviorContext(services={"nav": nav}, inputs={}, outputs={}, now=lambda: 0.0, environment=ENVIRONMENT)
    with pytest.raises(ParamError, match="it watches one perception service"):
        SearchArea(bare, context)


SWEPT = '    <Area name="Sweep"><Vertex x="2" y="0.5"/><Vertex x="4.6" y="0.5"/><Vertex x="4.6" y="3.3"/>' \
        '<Vertex x="2" y="3.3"/></Area>\n'
"""East of the start, the pillar's east edge inside it: its first lane's waypoints are in or next to it."""


@pytest.mark.parametrize("model", [TURTLEBOT_MODEL, ROVER_MODEL], ids=lambda m: m.urdf)
def test_in_the_closed_loop_the_sweep_skips_the_pillar_and_finds_the_parcel(tmp_path: Path,
                                                                            model: RobotModel) -> None:
    room = tmp_path / "room.xml"
    room.write_text(ROOM.replace('height="1.5"/>\n', 'height="1.5"/>\n' + SWEPT))
    environment = ckmconf.load(room).environment
    bench = Bench(room, (1.0, 1.8, 0.0), model=model,
                  nav={"particles": 1000, "initialPose": "1 1.8 0", "initialSpread": "0.05 0.03"})
    try:
        eyes = SightDetector(bench, {"parcel": (4.4, 2.9), "box": (3.3, 3.2)})
        search, written = sweep(BenchNavigation(bench), eyes, environment=environment, now=[0.0], area="Sweep",
                                spacing="0.9", margin="0.45")
        search.context.now = lambda: bench.now
        statuses: list[Any] = []

        def ended() -> bool:
            statuses.append(search.step())
            return bool(statuses[-1].done or statuses[-1].failed)

        assert bench.run(ended, 240.0), f"not ended: {statuses[-1]}, at {bench.truth()}"
        assert statuses[-1].done, (statuses[-1], search.skipped)
        reasons = [str(s["reason"]) for s in search.skipped]
        assert reasons and all("Pillar" in r or "collides" in r or "no path" in r for r in reasons), reasons
        assert search.visited >= 2 and 0.3 < statuses[-2].progress < 1.0
        (found,) = written
        assert found["label"] == "parcel" and math.dist((found["x"], found["y"]), (4.4, 2.9)) < 0.3
        assert "box" in eyes.sightings  # seen on the way, and not taken for the parcel
    finally:
        bench.close()
