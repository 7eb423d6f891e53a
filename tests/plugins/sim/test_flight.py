"""Aerial robots in ``hardware.sim`` (issue N point 2, D293): the multirotor channel flies a velocity
set-point on both shipped airframes (hover, climb, a square, take-off and landing, too weak a motor,
the rotors' lag, bad set-points), lock-step on a ManualClock, through the backend as a configuration
declares it; the flow, position and compass sensors; the example configuration flies through its own
channels, in process and through the world server."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

import ckmconf
from ckmconf.model import HWChannel, Param
from plugins.hardware.sim import SimBackend, find_world
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from plugins.sim.client import ENV_ADDRESS, ENV_KEY
from plugins.sim.devices import SimWorld
from plugins.sim.flight import AXES, GRAVITY, Multirotor
from plugins.sim.session import ServerProcess
from runtime.kernel.interfaces import ParamError
from runtime.kernel.node import NodeRuntime
from runtime.network import open_transport
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

EXAMPLE = REPO / "configs" / "examples" / "sim_multirotor.xml"
AIRFRAMES = {
    "quadrotor": {"rotors": "rotor_fl rotor_fr rotor_rl rotor_rr", "spin": "1 -1 -1 1", "maxThrust": "6"},
    "hexarotor": {"rotors": " ".join(f"rotor_{k}" for k in range(1, 7)), "spin": "1 -1 1 -1 1 -1", "maxThrust": "9"},
}
MASS = {"quadrotor": 1.2, "hexarotor": 2.5}  # kg, the models' links summed
TICK = 0.05  # s between two reads of a flight (the world steps at 240 Hz in between)


def record(name: str, direction: str, kind: str, size: int, **params: str) -> HWChannel:
    """A sim channel record of no file: its world is an empty floor."""
    return HWChannel(
        name=name,
        direction=direction,  # type: ignore[arg-type]
        kind=kind,  # type: ignore[arg-type]
        backend="sim",
        size=size,
        params=tuple(Param(name=k, value=v) for k, v in params.items()),
    )


class Flight:
    """One multirotor in its own lock-step world: its set-point channel and a position fix channel."""

    def __init__(self, model: str, **airframe: str) -> None:
        self.model, self.clock = model, ManualClock()
        scope = PlantScope(self.clock, name=f"flight-{model}")
        frame = {**AIRFRAMES[model], **airframe}
        self.fly = SimBackend(
            record("fly", "out", "bus", 4, body=model, pose="1 1 0", actuator="multirotor", **frame), scope=scope
        )
        self.fix = SimBackend(record("fix", "in", "bus", 3, body=model, sensor="position"), scope=scope)
        self.fly.setup()
        self.fix.setup()
        sim = find_world(scope)
        assert sim is not None
        self.sim: SimWorld = sim
        self.flyer: Multirotor = sim.flyers[model]
        self.go(0.0, 0.0, 0.0, 0.0, 0.2)  # settle on the skids
        self.rest = self.position()[2]

    def position(self) -> np.ndarray:
        value = self.fix.read()
        assert isinstance(value, tuple) and len(value) == 3
        return np.array(value)

    def velocity(self) -> np.ndarray:
        return np.array(p.getBaseVelocity(self.flyer.robot.body, physicsClientId=self.sim.world.client)[0])

    def tilt(self) -> float:
        orientation = self.flyer.robot.link_pose(-1)[1]
        return math.acos(min(1.0, p.getMatrixFromQuaternion(orientation)[8]))

    def go(self, vx: float, vy: float, vz: float, yaw_rate: float, seconds: float) -> list[np.ndarray]:
        """Fly the set-point for ``seconds``, sent every TICK as an offboard stream is; the positions read
        every TICK."""
        track = []
        for _ in range(round(seconds / TICK)):
            self.fly.write((vx, vy, vz, yaw_rate))
            self.clock.advance(TICK)
            track.append(self.position())
        return track

    def climb_to(self, height: float, rate: float = 1.0) -> None:
        """Climb at ``rate`` until ``height`` above the resting height (bounded), then hold 2 s."""
        for _ in range(round(2 * height / rate / TICK) + 40):
            if self.go(0.0, 0.0, rate, 0.0, TICK)[-1][2] - self.rest >= height:
                break
        self.go(0.0, 0.0, 0.0, 0.0, 2.0)

    def close(self) -> None:
        self.fly.stop()
        self.fix.stop()


@pytest.fixture(params=list(AIRFRAMES))
def flight(request: pytest.FixtureRequest) -> Flight:
    return Flight(request.param)


def test_hover_holds_its_altitude(flight: Flight) -> None:
    flight.climb_to(1.0)
    track = np.array(flight.go(0.0, 0.0, 0.0, 0.0, 5.0))
    assert track[:, 2].mean() - flight.rest == pytest.approx(1.0, abs=0.35)  # velocity control: it overshoots
    assert np.ptp(track[:, 2]) < 0.03  # held within a few cm over 5 s
    assert np.ptp(track[:, 0]) < 0.02 and np.ptp(track[:, 1]) < 0.02
    assert flight.tilt() < 0.01
    assert flight.flyer.thrust.sum() == pytest.approx(MASS[flight.model] * GRAVITY, rel=0.01)  # it carries its weight


def test_a_climb_at_a_vz_set_point_reaches_2_m(flight: Flight) -> None:
    track = flight.go(0.0, 0.0, 1.0, 0.0, 3.0)
    heights = np.array([t[2] for t in track]) - flight.rest
    reached = next(i for i, h in enumerate(heights) if h >= 2.0) * TICK
    assert 1.8 < reached < 2.8  # 2 m at 1 m/s, after the take-off's start
    climb = (heights[round(1.8 / TICK)] - heights[round(1.0 / TICK)]) / 0.8
    assert climb == pytest.approx(1.0, abs=0.15)  # the climb rate is the set-point
    held = np.array([t[2] for t in flight.go(0.0, 0.0, 0.0, 0.0, 3.0)]) - flight.rest
    assert held[-1] < 3.0 + 0.4 and np.ptp(held[-20:]) < 0.02  # it stops climbing and holds


def test_a_square_flown_by_velocity_set_points_ends_near_its_start(flight: Flight) -> None:
    flight.climb_to(1.0)
    start = flight.position()
    track = []
    for vx, vy in ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)):
        track += flight.go(vx, vy, 0.0, 0.0, 2.0)
    end = flight.go(0.0, 0.0, 0.0, 0.0, 3.0)[-1]
    path = np.array(track)
    extent = path[:, :2].max(axis=0) - path[:, :2].min(axis=0)
    assert 1.4 < extent[0] < 2.1  # 2 s at 1 m/s, less what the velocity loop takes to get there
    assert extent[1] == pytest.approx(extent[0], abs=0.05)  # a square: y (left) flown as x (ahead)
    assert path[round(2.0 / TICK) - 1][0] - start[0] > 1.2  # the first leg went ahead: +x at yaw 0
    assert math.dist(end[:2], start[:2]) < 0.15
    assert abs(end[2] - start[2]) < 0.05


def test_take_off_and_landing(flight: Flight) -> None:
    flight.go(0.0, 0.0, -1.0, 0.0, 1.0)  # descending on the ground: it stays, motors idle
    assert flight.flyer.landed and flight.flyer.thrust.max() < 1e-3
    assert flight.position()[2] == pytest.approx(flight.rest, abs=0.005)
    flight.go(0.0, 0.0, 1.0, 0.0, 1.5)  # an upward set-point takes off
    assert not flight.flyer.landed and flight.position()[2] - flight.rest > 1.0
    for _ in range(200):  # bounded: 10 s at 0.8 m/s down
        flight.go(0.0, 0.0, -0.8, 0.0, TICK)
        if flight.flyer.landed:
            break
    assert flight.flyer.landed
    flight.go(0.5, 0.0, -0.8, 0.0, 1.0)  # landed: a horizontal set-point does not slide it
    assert flight.position()[2] == pytest.approx(flight.rest, abs=0.005)  # resting on its skids
    assert flight.flyer.thrust.max() < 0.01 and flight.tilt() < 0.01
    assert np.abs(flight.velocity()).max() < 0.01
    flight.go(0.0, 0.0, 0.5, 0.0, 1.0)
    assert flight.position()[2] - flight.rest > 0.3  # and it takes off again


def test_set_points_that_stop_make_it_hover_then_land_where_it_was(flight: Flight) -> None:
    """PX4's offboard loss: no set-point for ``failsafe`` (1 s) → hover 2 s → descend at 0.5 m/s to the ground."""
    flight.climb_to(1.5)
    flight.go(0.8, 0.0, 0.0, 0.0, 1.0)  # flying ahead when its flight computer goes silent
    lost = flight.position()
    track = []
    for _ in range(round(1.0 / TICK)):  # no set-point from here on: the last one flies for 1 s
        flight.clock.advance(TICK)
        track.append(flight.position())
    assert not flight.flyer.failsafe and track[-1][0] - lost[0] > 0.6  # still flying its last command
    for _ in range(round(2.0 / TICK)):
        flight.clock.advance(TICK)
        track.append(flight.position())
    assert flight.flyer.failsafe
    assert np.linalg.norm(flight.velocity()) < 0.15  # hovering
    height = track[-1][2]
    for _ in range(round(8.0 / TICK)):  # bounded: 1.5 m at 0.5 m/s is 3 s
        flight.clock.advance(TICK)
        track.append(flight.position())
        if flight.flyer.landed:
            break
    assert flight.flyer.landed and height - flight.rest > 1.2
    end = flight.position()
    assert end[2] == pytest.approx(flight.rest, abs=0.01)
    assert math.dist(end[:2], track[round(2.2 / TICK)][:2]) < 0.3  # down where it hovered, not blown away
    flight.go(0.0, 0.0, 1.0, 0.0, 1.0)  # a new set-point ends the failsafe: it takes off again
    assert not flight.flyer.failsafe and flight.position()[2] - flight.rest > 0.5


def test_a_zero_failsafe_flies_the_last_set_point_on() -> None:
    flight = Flight("quadrotor", failsafe="0")
    flight.climb_to(1.0)
    flight.fly.write((0.0, 0.0, 0.3, 0.0))
    start = flight.position()
    for _ in range(round(4.0 / TICK)):
        flight.clock.advance(TICK)
    assert not flight.flyer.failsafe and flight.position()[2] - start[2] > 0.9  # still climbing after 4 s


@pytest.mark.parametrize("model", list(AIRFRAMES))
def test_too_weak_a_motor_cannot_climb_and_sinks(model: str) -> None:
    rotors = len(AIRFRAMES[model]["rotors"].split())
    weak = 0.8 * MASS[model] * GRAVITY / rotors  # all rotors together: 80 % of the weight
    flight = Flight(model, maxThrust=f"{weak:.4f}")
    flight.go(0.0, 0.0, 2.0, 0.0, 3.0)
    assert flight.position()[2] == pytest.approx(flight.rest, abs=0.005)  # full throttle, still on the ground
    thrust = flight.flyer.thrust
    assert thrust.max() == pytest.approx(weak, rel=1e-3) and thrust.sum() > 0.97 * rotors * weak  # flat out
    cid, body = flight.sim.world.client, flight.flyer.robot.body
    p.resetBasePositionAndOrientation(body, [1.0, 1.0, 3.0], [0, 0, 0, 1], physicsClientId=cid)
    p.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=cid)
    p.performCollisionDetection(physicsClientId=cid)  # the contacts of where it is now: in the air
    track = flight.go(0.0, 0.0, 0.0, 0.0, 1.0)  # asked to hold 3 m
    drop = 3.0 - track[-1][2]
    free = 0.5 * 0.2 * GRAVITY * 1.0**2  # the fifth of g the rotors cannot hold, for 1 s
    assert drop == pytest.approx(free, rel=0.15)  # it sinks: physics, not a clamp (drag takes a little)
    assert flight.tilt() < 0.02  # upright: roll and pitch keep priority over the collective


@pytest.mark.parametrize("model", list(AIRFRAMES))
def test_the_rotors_lag_ramps_the_climb_rate(model: str) -> None:
    rates = {}
    for lag in (0.02, 0.15):
        flight = Flight(model, thrustLag=str(lag))
        flight.climb_to(0.5)
        flight.fly.write((0.0, 0.0, 1.0, 0.0))
        climbs = []
        for _ in range(round(0.4 / 0.02)):
            flight.clock.advance(0.02)
            flight.fix.read()
            climbs.append(flight.velocity()[2])
        rates[lag] = np.array(climbs)
        flight.go(0.0, 0.0, 1.0, 0.0, 4.0)
        assert flight.velocity()[2] == pytest.approx(1.0, abs=0.1)  # both reach the set-point in the end
    slow, quick = rates[0.15], rates[0.02]
    assert slow[0] < 0.05  # no step: 0.02 s after the command the slow rotors have barely moved it
    assert np.all(np.diff(slow[:10]) > 0)  # the climb rate ramps up
    assert slow[4] < 0.5 * quick[4]  # 0.1 s after: the slow rotors' climb is far behind the quick ones'


def test_a_bad_set_point_is_refused_naming_the_channel() -> None:
    flight = Flight("quadrotor", maxSpeed="3")
    flight.go(0.0, 0.0, 1.0, 0.0, 1.0)
    for bad, why in (
        ((math.nan, 0.0, 0.0, 0.0), "not finite"),
        ((0.0, 0.0, math.inf, 0.0), "not finite"),
        ((3.0, 1.0, 0.0, 0.0), "horizontal speed 3.16 is beyond maxSpeed 3"),
        ((0.0, 0.0, -5.0, 0.0), "climb rate 5 is beyond maxClimb 3"),
        ((0.0, 0.0, 0.0, 9.0), "yaw rate 9 is beyond maxYawRate 2"),
        ((0.0, 0.0, 1.0), "takes 4 values"),
        (0.5, "takes 4 values"),
    ):
        with pytest.raises(ValueError, match=re.escape(why)) as refused:
            flight.fly.write(bad)
        assert "sim channel 'fly'" in str(refused.value)
    assert flight.flyer.setpoint == (0.0, 0.0, 1.0, 0.0)  # still flying the last good one
    assert flight.fly.read() == (0.0, 0.0, 1.0, 0.0)
    device = flight.fly._device  # the world server's path: the device refuses what no backend checked
    assert device is not None
    with pytest.raises(ValueError, match=r"sim channel 'fly'.*not finite"):
        device.write([0.0, math.nan, 0.0, 0.0])


def test_a_multirotor_channel_that_cannot_fly_is_refused_before_setup() -> None:
    """What ckm-validate reports at its line (corpus sim_multirotor_*.xml), the backend refuses alone too."""
    quad = {"body": "quadrotor", "actuator": "multirotor", **AIRFRAMES["quadrotor"]}
    for size, direction, params, why in (
        (3, "out", quad, "size is 3, its multirotor device gives 4 values"),
        (4, "in", quad, "a bus in channel cannot be the actuator=multirotor device: it is served as bus out"),
        (4, "out", {**quad, "spin": "1 -1"}, "Param 'spin' needs one +1 or -1 per rotor (4 rotors)"),
        (4, "out", {k: v for k, v in quad.items() if k != "maxThrust"}, "needs Param 'maxThrust'"),
        (4, "out", {**quad, "rotors": "rotor_fl rotor_fr", "spin": "1 -1"}, "needs 3 rotor links or more, not 2"),
        (4, "out", {**quad, "joint": "rotor_fl_joint"}, "Param 'joint' is not read by the multirotor device"),
    ):
        with pytest.raises(ParamError, match=re.escape(why)):
            SimBackend(record("fly", direction, "bus", size, **params))


def test_the_same_commands_fly_the_same_path() -> None:
    """Lock-step determinism with the force hook: two worlds, one flight, the same positions."""
    paths = []
    for _ in range(2):
        flight = Flight("hexarotor")
        paths.append([*flight.go(0.0, 0.0, 1.0, 0.3, 1.5), *flight.go(1.0, -0.5, 0.0, 0.0, 1.5)])
    assert np.array_equal(np.array(paths[0]), np.array(paths[1]))


def channels_of(path: Path, clock: ManualClock) -> dict[str, SimBackend]:
    """Every sim channel of the file's node as the backend builds it, set up in one lock-step scope."""
    scope = PlantScope(clock, name=path.stem)
    backends = {record.name: SimBackend(record, scope=scope) for record in ckmconf.load(path).nodes[0].channels}
    for backend in backends.values():
        backend.setup()
    return backends


def test_the_example_flies_through_its_channels() -> None:
    """configs/examples/sim_multirotor.xml as a configuration declares it: both robots take off, the
    quadrotor flies ahead turned by its yaw rate, its flow, fix and compass say so, both land."""
    clock = ManualClock()
    ch = channels_of(EXAMPLE, clock)

    commands: dict[str, tuple[float, float, float, float]] = {}

    def run(seconds: float) -> None:
        for _ in range(round(seconds / TICK)):  # the set-points streamed every TICK, as offboard control does
            for name, value in commands.items():
                ch[name].write(value)
            clock.advance(TICK)
            ch["quad_fix"].read()

    start = np.array(ch["hexa_fix"].read())
    commands["quad_velocity"] = (0.0, 0.0, 1.0, 0.0)
    commands["hexa_velocity"] = (0.0, 0.0, 0.8, 0.0)
    run(1.5)
    commands["quad_velocity"] = (0.0, 0.0, 0.0, 0.5)  # turn 0.5 rad
    commands["hexa_velocity"] = (0.0, 0.0, 0.0, 0.0)
    run(1.0)
    sim = find_world(ch["quad_fix"].scope)
    assert sim is not None
    turned = sim.robots["quadrotor"].planar_pose()
    commands["quad_velocity"] = (1.0, 0.0, 0.0, 0.0)  # then ahead, along the new heading
    run(2.0)
    heading = ch["quad_compass"].read()
    assert isinstance(heading, float) and heading == pytest.approx(0.5, abs=0.08)  # noise 0.02
    flow = ch["quad_flow"].read()
    assert isinstance(flow, tuple) and flow == pytest.approx((1.0, 0.0), abs=0.1)  # over ground, heading frame
    fixes = np.array([ch["quad_fix"].read() for _ in range(200)])  # one instant, 200 fixes: their spread
    assert fixes.std(axis=0) == pytest.approx([0.05] * 3, rel=0.2)
    x, y, _ = sim.robots["quadrotor"].planar_pose()
    assert fixes.mean(axis=0)[:2] == pytest.approx((x, y), abs=0.02)
    assert math.atan2(y - turned[1], x - turned[0]) == pytest.approx(0.5, abs=0.05)  # x ahead: along the heading
    assert 1.2 < math.dist((x, y), turned[:2]) < 2.0  # 2 s at 1 m/s, less the velocity loop's rise
    hexa = np.array(ch["hexa_fix"].read())
    assert hexa[2] - start[2] > 0.8 and math.dist(hexa[:2], start[:2]) < 0.1  # it hovers where it rose
    height = ch["hexa_range"].read()
    assert isinstance(height, float) and height == pytest.approx(hexa[2] - 0.2 + 0.145, abs=0.02)
    commands["quad_velocity"] = (0.0, 0.0, -1.0, 0.0)
    commands["hexa_velocity"] = (0.0, 0.0, -1.0, 0.0)
    run(4.0)
    assert sim.flyers["quadrotor"].landed and sim.flyers["hexarotor"].landed
    assert ch["quad_range"].read() == pytest.approx(0.09, abs=0.04)  # the camera's height on the skids
    for backend in ch.values():
        backend.stop()


def test_the_docs_example_is_the_validated_configuration() -> None:
    """docs/simulation.md's aerial-robot XML is quoted from the example, which ckm-validate accepts
    (tests/runtime/test_verify.py verifies every example) and the test above flies."""
    docs = (REPO / "docs" / "simulation.md").read_text(encoding="utf-8")
    section = docs[docs.index("### An aerial robot") :]
    snippet = section[section.index("```xml") + len("```xml") : section.index("```", section.index("```xml") + 6)]
    lines = [line.strip() for line in snippet.strip().splitlines()]
    example = [line.strip() for line in EXAMPLE.read_text(encoding="utf-8").splitlines()]
    first = example.index(lines[0])
    assert example[first : first + len(lines)] == lines


def test_a_multirotor_flies_through_the_world_server(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Client mode (D100): the set-point travels as a list, the server's device flies it; a bad one is
    refused by the channel before it is sent."""
    monkeypatch.delenv(ENV_ADDRESS, raising=False)
    with ServerProcess(EXAMPLE, tmp_path / "server") as server:
        monkeypatch.setenv(ENV_ADDRESS, server.address)
        monkeypatch.setenv(ENV_KEY, server.key.hex())
        records = {r.name: r for r in ckmconf.load(EXAMPLE).nodes[0].channels}
        fly, fix = SimBackend(records["quad_velocity"]), SimBackend(records["quad_fix"])
        fly.setup()
        fix.setup()
        try:
            assert fly.remote is not None
            ground = fix.read()
            assert isinstance(ground, tuple)
            fly.write((0.0, 0.0, 1.0, 0.0))
            deadline = time.monotonic() + 30.0  # real time on the server's clock; bounded on a loaded machine
            height = ground[2]
            while time.monotonic() < deadline and height - ground[2] < 0.5:
                time.sleep(0.1)
                fly.write((0.0, 0.0, 1.0, 0.0))  # streamed: set-points that stop make it hover and land
                value = fix.read()
                assert isinstance(value, tuple)
                height = value[2]
            assert height - ground[2] >= 0.5
            with pytest.raises(ValueError, match=r"sim channel 'quad_velocity'.*not finite"):
                fly.write((0.0, 0.0, math.nan, 0.0))
            fly.write((0.0, 0.0, -1.0, 0.0))
        finally:
            fly.stop()
            fix.stop()


def test_axis_channels_fly_as_the_set_point_channel() -> None:
    """Four size-1 channels (``axis``), one per value, as four CKM Actuators drive them, fly the robot
    exactly as one size-4 channel writing the same set-point."""
    whole = Flight("quadrotor")
    whole.go(0.5, -0.3, 1.0, 0.2, 2.0)
    clock = ManualClock()
    scope = PlantScope(clock, name="axes")
    frame = {"body": "quadrotor", "pose": "1 1 0", "actuator": "multirotor", **AIRFRAMES["quadrotor"]}
    axes = [SimBackend(record(f"v_{axis}", "out", "analog", 1, axis=axis, **frame), scope=scope) for axis in AXES]
    fix = SimBackend(record("fix", "in", "bus", 3, body="quadrotor", sensor="position"), scope=scope)
    for backend in (*axes, fix):
        backend.setup()
    fix.read()  # the world's clock starts at its first use (D88), as Flight's first write starts it
    for _ in range(4):  # as Flight settles its robot
        clock.advance(TICK)
    for _ in range(round(2.0 / TICK)):  # each axis streamed every TICK, as Flight.go streams the whole
        for backend, value in zip(axes, (0.5, -0.3, 1.0, 0.2), strict=True):
            backend.write(value)
        clock.advance(TICK)
        fix.read()
    assert np.array_equal(np.array(fix.read()), whole.position())
    assert axes[2].read() == 1.0  # an axis channel reads back its own value
    with pytest.raises(ValueError, match=re.escape("sim channel 'v_vz': set-point [0.0, 0.0, 5.0, 0.0]: climb rate")):
        axes[2].write(5.0)
    other = SimBackend(record("v2", "out", "analog", 1, axis="vx", **{**frame, "maxThrust": "7"}), scope=scope)
    with pytest.raises(ValueError, match="robot 'quadrotor' is flown by sim channel 'v_vx' with another airframe"):
        other.setup()  # one robot, one set of rotors


NODE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="climb">
  <Node name="air" kind="light">
    <HWChannel name="climb" direction="out" kind="analog" backend="sim" units="m/s" min="-1" max="1">
      <Param name="body" value="quadrotor"/>
      <Param name="pose" value="2 2 0"/>
      <Param name="actuator" value="multirotor"/>
      <Param name="axis" value="vz"/>
      <Param name="rotors" value="rotor_fl rotor_fr rotor_rl rotor_rr"/>
      <Param name="spin" value="1 -1 -1 1"/>
      <Param name="maxThrust" value="6"/>
    </HWChannel>
    <HWChannel name="range" direction="in" kind="analog" backend="sim" units="m">
      <Param name="body" value="quadrotor"/>
      <Param name="sensor" value="altimeter"/>
      <Param name="link" value="camera_link"/>
    </HWChannel>
    <Topic name="height" type="float64" scope="internal"/>
    <Topic name="climb_rate" type="float64" scope="internal"/>
    <Sensor name="altimeter" channel="range" topic="height" period="0.05"/>
    <Controller name="up" kind="constant" period="0.05"><Param name="value" value="0.5"/>
      <Input topic="height" role="measure"/>
      <Output topic="climb_rate"/></Controller>
    <Actuator name="climb_motor" channel="climb" topic="climb_rate" min="-1" max="1" safeValue="0"/>
  </Node>
  <Environment name="hall" frame="map">
    <Map xmin="0" ymin="0" xmax="4" ymax="4" height="3"/>
  </Environment>
</System>
"""


def test_a_ckm_actuator_flies_an_axis_channel(tmp_path: Path) -> None:
    """The kernel's path: a constant controller's 0.5 m/s, an Actuator, the vz channel; the robot climbs."""
    path = tmp_path / "climb.xml"
    path.write_text(NODE, encoding="utf-8")
    system = ckmconf.load(path)
    transport = open_transport(private_network(), name="climb")
    transport.setup()
    transport.start()
    scope = PlantScope(time.monotonic, name="climb")
    runtime = NodeRuntime(system.nodes[0], system, transport)
    try:
        with plant_scope(scope):
            runtime.setup()
        runtime.start()
        sim = find_world(scope)
        assert sim is not None
        deadline, height = time.monotonic() + 30.0, 0.0  # real time; bounded on a loaded machine
        while time.monotonic() < deadline and height < 0.6:
            time.sleep(0.1)
            with sim.lock:
                height = sim.robots["quadrotor"].link_pose(-1)[0][2] - 0.13
        assert height >= 0.6
        assert sim.flyers["quadrotor"].setpoint == (0.0, 0.0, 0.5, 0.0)
    finally:
        runtime.stop()
        transport.stop()
