"""plugin.flight-control (the ``flight`` interface): goals flown on a point-mass airframe with a lagging
velocity loop and a noisy position fix; the same service on the simulator's multirotors is tested in
tests/plugins/sim."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from ckmconf import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.flight.service import FlightControl
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

from .point_mass import Loop, PointMass, flight_control


def status(out: dict[str, object]) -> dict[str, object]:
    value = out.get("status")
    assert isinstance(value, dict)
    return value


def test_take_off_fly_to_a_point_and_land_where_it_is() -> None:
    loop = Loop(flight_control(speed=1.5), PointMass(x=1.0, y=2.0), noise=0.02)
    takeoff = loop.send("takeoff", z=2.0)
    out = loop.run(20.0, until="arrived")
    assert status(out)["id"] == takeoff and status(out)["state"] == "arrived"
    assert loop.body.z == pytest.approx(2.0, abs=0.25) and math.hypot(loop.body.x - 1.0, loop.body.y - 2.0) < 0.2
    goto = loop.send("goto", frame="map", x=6.0, y=-1.0, z=3.0, yaw=1.2)
    out = loop.run(30.0, until="arrived")
    assert status(out)["id"] == goto and status(out)["state"] == "arrived", status(out)
    assert math.dist((loop.body.x, loop.body.y, loop.body.z), (6.0, -1.0, 3.0)) < 0.3
    assert loop.body.yaw == pytest.approx(1.2, abs=0.2)
    land = loop.send("land")
    out = loop.run(30.0, until="landed")
    assert status(out)["id"] == land and status(out)["state"] == "landed", status(out)
    assert loop.body.z == 0.0 and math.hypot(loop.body.x - 6.0, loop.body.y + 1.0) < 0.3
    assert out["cmd_vel"]["linear"]["z"] < 0  # landed, it keeps asking to descend: the rotors idle


def test_the_horizontal_speed_stays_within_the_speed_and_the_service_parameter_lowers_it() -> None:
    service = flight_control(speed=2.0)
    loop = Loop(service, PointMass(z=1.0))
    service.apply_service_parameters({"speed": 0.5})
    loop.send("goto", frame="map", x=10.0, y=0.0, z=1.0)
    speeds = []
    for _ in range(40):
        out = loop.run(0.5)
        speeds.append(math.hypot(out["cmd_vel"]["linear"]["x"], out["cmd_vel"]["linear"]["y"]))
    assert max(speeds) == pytest.approx(0.5, abs=1e-6)
    with pytest.raises(ValueError, match="service parameter 'speed'"):
        service.apply_service_parameters({"speed": 0})


def test_a_robot_frame_goal_is_ahead_left_and_up_of_where_it_is() -> None:
    loop = Loop(flight_control(), PointMass(x=2.0, y=2.0, z=1.0, yaw=math.pi / 2))
    loop.send("goto", frame="robot", x=2.0, y=1.0, z=0.5)
    out = loop.run(30.0, until="arrived")
    assert status(out)["state"] == "arrived"
    assert math.dist((loop.body.x, loop.body.y, loop.body.z), (1.0, 4.0, 1.5)) < 0.25  # ahead is +y, left is −x


def test_a_goto_while_landed_fails_and_says_take_off_first() -> None:
    loop = Loop(flight_control(), PointMass())
    loop.send("goto", frame="map", x=3.0, y=0.0, z=2.0)
    out = loop.run(0.5)
    assert status(out)["state"] == "failed" and "take off first" in str(status(out)["reason"])
    assert loop.body.z == 0.0


@pytest.mark.parametrize(
    ("goal", "reason"),
    [
        ({"id": "7", "action": "goto"}, "goal id '7' is not an integer"),
        ({"id": 3, "action": "loop"}, "action 'loop' is not one of takeoff, goto, land, hold"),
        ({"id": 3, "action": "takeoff", "z": -1.0}, "a takeoff needs z"),
        ({"id": 3, "action": "goto", "frame": "odom", "x": 1, "y": 1, "z": 1}, "frame 'odom'"),
        ({"id": 3, "action": "goto", "frame": "map", "x": 1, "y": 1}, "a goto needs finite x, y and z"),
    ],
)
def test_a_bad_goal_fails_with_its_reason_and_the_robot_holds(goal: dict[str, object], reason: str) -> None:
    loop = Loop(flight_control(), PointMass(z=1.5))
    loop.goal = goal
    out = loop.run(1.0)
    assert status(out)["state"] == "failed" and reason in str(status(out)["reason"])
    assert loop.body.z == pytest.approx(1.5, abs=0.01) and abs(loop.body.x) < 0.01


def test_a_lost_position_fix_fails_the_goal_and_the_command_is_to_hold() -> None:
    loop = Loop(flight_control(staleAfter=0.5), PointMass(z=1.0))
    loop.send("goto", frame="map", x=5.0, y=0.0, z=1.0)
    loop.run(1.0)
    loop.fixes = False  # the same fix over and over: no new one
    out = loop.run(1.0)
    assert status(out)["state"] == "failed" and "no position fix for 0.5 s" in str(status(out)["reason"])
    assert out["cmd_vel"]["linear"] == {"x": 0.0, "y": 0.0, "z": 0.0}


def test_a_goal_the_airframe_cannot_reach_in_time_fails_by_its_deadline() -> None:
    loop = Loop(flight_control(speed=1.0, timeoutMargin=2.0), PointMass(z=1.0, top=0.2))  # a headwind: 0.2 m/s
    loop.send("goto", frame="map", x=10.0, y=0.0, z=1.0)
    out = loop.run(40.0, until="failed")
    assert status(out)["state"] == "failed" and "by its deadline" in str(status(out)["reason"])
    x = loop.body.x
    loop.run(2.0)
    assert abs(loop.body.x - x) < 0.3  # it hovers where it ended


def test_a_newer_goal_preempts_and_the_status_names_the_newest() -> None:
    loop = Loop(flight_control(), PointMass(z=1.0))
    loop.send("goto", frame="map", x=10.0, y=0.0, z=1.0)
    loop.run(2.0)
    hold = loop.send("hold")
    out = loop.run(3.0)
    assert status(out)["id"] == hold and status(out)["action"] == "hold"
    x = loop.body.x
    loop.run(3.0)
    assert abs(loop.body.x - x) < 0.3


def test_pose_messages_and_a_range_finder_are_read_and_a_bad_input_names_itself() -> None:
    service = flight_control()
    pose_stamped = {"header": {"stamp": 0.0, "frame_id": "map"},
                    "pose": {"position": {"x": 1.0, "y": 2.0, "z": 0.05},
                             "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(0.3), "w": math.cos(0.3)}}}
    out = service.process({"position": pose_stamped, "altitude": {"range": 0.05}}, Context(0, 0.0))
    assert out["pose"]["pose"] == {"x": 1.0, "y": 2.0, "z": 0.05, "yaw": pytest.approx(0.6, abs=1e-4)}
    assert service.landed is True
    with pytest.raises(ValueError, match="input 'position' must give finite x, y and z"):
        service.process({"position": {"x": 1.0, "y": "two"}}, Context(1, 0.05))
    with pytest.raises(ValueError, match="input 'altitude'"):
        service.process({"position": {"x": 1, "y": 2, "z": 0}, "altitude": "high"}, Context(2, 0.1))


RACKS = """<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0" description="two racks in a hall">
  <Environment name="hall" frame="map">
    <Map xmin="0" ymin="0" xmax="12" ymax="8" height="5"/>
    <AvoidedArea name="rack_low" height="2.0">
      <Vertex x="4" y="1"/><Vertex x="5" y="1"/><Vertex x="5" y="7"/><Vertex x="4" y="7"/>
    </AvoidedArea>
    <AvoidedArea name="rack_high" height="4.5">
      <Vertex x="8" y="1"/><Vertex x="9" y="1"/><Vertex x="9" y="7"/><Vertex x="8" y="7"/>
    </AvoidedArea>
  </Environment>
</Part>
"""


def test_a_goto_is_flown_up_level_and_down_and_refused_when_a_leg_meets_a_solid(tmp_path: Path) -> None:
    path = tmp_path / "hall.xml"
    path.write_text(RACKS)
    given = {"environment": "hall.xml", "radius": "0.3", "speed": "1.5"}
    params = tuple(Param(name=k, value=v) for k, v in given.items())
    record = Plugin(name="flight", kind="flight-control", params=params, loc=Loc(str(path), 1, 1, "/Plugin"))
    service = FlightControl(record)
    service.setup()
    loop = Loop(service, PointMass(x=2.0, y=4.0, z=1.0))
    heights = []
    loop.send("goto", frame="map", x=6.5, y=4.0, z=1.0)  # over the 2 m rack: up to 1 m is not enough
    out = loop.run(0.2)
    assert status(out)["state"] == "failed" and "meets 'rack_low'" in str(status(out)["reason"])
    loop.send("goto", frame="map", x=6.5, y=4.0, z=3.0)  # at 3 m it clears the rack (2 m + margins)
    for _ in range(300):
        out = loop.run(0.1)
        heights.append((loop.body.x, loop.body.z))
        if status(out)["state"] != "active":
            break
    assert status(out)["state"] == "arrived"
    assert all(z > 2.9 for x, z in heights if 3.5 <= x <= 5.5)  # it climbed before it crossed the rack
    loop.send("goto", frame="map", x=10.5, y=4.0, z=3.0)
    out = loop.run(0.2)
    assert "meets 'rack_high'" in str(status(out)["reason"])
    with pytest.raises(ParamError, match="needs parameter 'radius'"):
        FlightControl(Plugin(name="f", kind="flight-control", params=(Param(name="environment", value="hall.xml"),)))
