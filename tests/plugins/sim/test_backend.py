"""The ``hardware.sim`` backend: channels read and write simulated devices through the Backend
interface, lock-step with a ManualClock; bad Params are reported; the example system runs."""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator

import numpy as np
import pytest

import ckmconf
from ckmconf.errors import Loc
from ckmconf.model import HWChannel, Param
from plugins.hardware.sim import SimBackend, find_world
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from plugins.sim.devices import ChannelDevice, SimWorld, Spec
from runtime.kernel.interfaces import Backend, ParamError
from runtime.kernel.node import NodeRuntime
from runtime.network import Transport, open_transport
from runtime.registry import default_registry
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

STATION = REPO / "configs" / "examples" / "sim_station.xml"


def channel(name: str, direction: str = "in", kind: str = "analog", size: int = 1, **params: str) -> HWChannel:
    """A sim channel record whose world is the example's workshop."""
    loc = Loc(str(STATION), 1, 1, "/System/Node[@name='test']/HWChannel")
    return HWChannel(
        name=name,
        direction=direction,  # type: ignore[arg-type]
        kind=kind,  # type: ignore[arg-type]
        backend="sim",
        size=size,
        loc=loc,
        params=tuple(Param(name=k, value=v) for k, v in params.items()),
    )


def ranging(record: HWChannel, top: float) -> HWChannel:
    """``record`` with the HWChannel's ``max``: a lidar's range (m)."""
    return dataclasses.replace(record, max=top)


@pytest.fixture
def clock_and_scope() -> tuple[ManualClock, PlantScope]:
    clock = ManualClock()
    return clock, PlantScope(clock, name="sim-test")


def open_all(scope: PlantScope, *records: HWChannel) -> list[Backend]:
    with plant_scope(scope):
        backends: list[Backend] = [SimBackend(record) for record in records]
    for backend in backends:
        backend.setup()
    return backends


def test_sim_is_registered() -> None:
    assert default_registry().resolve("hardware", "sim") is SimBackend


def test_wheel_motor_and_encoder_in_lock_step(clock_and_scope: tuple[ManualClock, PlantScope]) -> None:
    clock, scope = clock_and_scope
    motor, encoder, other = open_all(
        scope,
        channel(
            "m",
            "out",
            "pwm",
            joint="left_wheel_joint",
            mode="velocity",
            maxVelocity="8",
            body="rover",
            pose="3.0 2.0 0",
        ),
        channel("e", "in", "counter", joint="left_wheel_joint", ticksPerRev="1024", body="rover"),
        channel("r", "out", "pwm", joint="right_wheel_joint", mode="velocity", maxVelocity="8", body="rover"),
    )
    motor.write(0.5)
    other.write(0.5)
    clock.advance(1.0)
    speed = encoder.read()
    assert speed == pytest.approx(0.5 * 8 * 1024 / (2 * math.pi), rel=0.05)
    sim = find_world(scope)
    assert sim is not None and sim.world.time == pytest.approx(1.0, abs=sim.world.time_step)
    x, _, _ = sim.robots["rover"].planar_pose()
    assert x - 3.0 == pytest.approx(0.5 * 8 * 0.08 * 1.0, rel=0.2)  # ~ v·t, after the start-up
    assert motor.read() == 0.5  # an out channel reads back the last value written


def test_joint_position_lidar_bumper_camera_imu(clock_and_scope: tuple[ManualClock, PlantScope]) -> None:
    clock, scope = clock_and_scope
    servo, state, laser, bumper, depth, imu, height = open_all(
        scope,
        channel(
            "s", "out", "bus", joint="shoulder_joint", scale="0.01", offset="100", body="station_arm", pose="1.0 1.0 0"
        ),
        channel("j", "in", "bus", size=2, joints="turret_joint shoulder_joint", body="station_arm"),
        ranging(
            channel(
                "l",
                "in",
                "stream",
                size=181,
                body="rover",
                pose="3.0 2.0 0",
                sensor="lidar",
                link="laser_link",
                fov="3.14159",
            ),
            5.0,
        ),
        channel("b", "in", "digital", body="rover", sensor="contact", link="bumper_link"),
        channel(
            "d",
            "in",
            "stream",
            size=80 * 60,
            body="station_arm",
            sensor="depth",
            link="wrist_camera_optical_frame",
            width="80",
            height="60",
            fov="1.5184",
        ),
        channel("i", "in", "analog", size=6, body="rover", sensor="imu"),
        channel("h", "in", "analog", body="rover", sensor="altimeter", link="laser_link"),
    )
    servo.write(150.0)  # (150 − 100) × 0.01 = 0.5 rad
    clock.advance(2.0)
    turret, shoulder = state.read()  # type: ignore[misc]
    assert turret == pytest.approx(0.0, abs=0.01) and shoulder == pytest.approx(0.5, abs=0.02)
    assert servo.read() == 150.0
    ranges = laser.read()
    assert isinstance(ranges, np.ndarray) and ranges.shape == (181,)  # a scan read whole, flat (D243)
    assert ranges[90] == pytest.approx(6.0 - 3.25, abs=0.02)  # straight ahead: the wall at x = 6
    assert bumper.read() == 0.0
    image = depth.read()
    assert isinstance(image, np.ndarray) and image.shape == (80 * 60,) and image.min() > 0.0
    accel = imu.read()
    assert isinstance(accel, tuple) and accel[5] == pytest.approx(9.81, abs=0.3)
    assert height.read() == pytest.approx(0.25, abs=0.01)


def test_bad_params_are_reported() -> None:
    with pytest.raises(ParamError, match="body"):
        SimBackend(channel("x", sensor="lidar"))
    with pytest.raises(ParamError, match="size"):
        SimBackend(channel("x", "in", "stream", size=10, body="rover", sensor="rgb", width="4", height="4", fov="1"))
    # No lab value for a user's sensor (D284): a camera's field of view, a lidar's and its range are its own.
    with pytest.raises(ParamError, match="a depth camera needs its field of view: Param 'fov'"):
        SimBackend(channel("x", "in", "stream", size=16, body="rover", sensor="depth", width="4", height="4"))
    with pytest.raises(ParamError, match="a lidar needs its field of view: Param 'fov'"):
        SimBackend(ranging(channel("x", "in", "stream", size=90, body="rover", sensor="lidar", link="laser_link"), 4.0))
    with pytest.raises(ParamError, match="a lidar needs its range: the HWChannel's max"):
        SimBackend(channel("x", "in", "stream", size=90, body="rover", sensor="lidar", link="laser_link", fov="3"))
    with pytest.raises(ParamError, match="mode"):
        SimBackend(channel("x", "out", "bus", body="rover", joint="left_wheel_joint", mode="torque"))
    backend = SimBackend(channel("x", body="rover", joint="no_such_joint"), scope=PlantScope(ManualClock()))
    with pytest.raises(KeyError, match="no_such_joint"):
        backend.setup()


def test_the_device_refuses_a_lidar_spec_without_its_geometry() -> None:
    """A world server's device, given a spec no backend checked (a client of its own), has no lab value either."""
    sim = SimWorld(ManualClock(), None, 0, "", "")
    values = dict(
        SimBackend(
            ranging(
                channel("l", "in", "stream", size=90, body="rover", sensor="lidar", link="laser_link", fov="4.7"), 5.0
            )
        ).values
    )
    assert ChannelDevice(sim, Spec("l", "stream", "in", 90, 5.0, values)).device.range_max == 5.0
    with pytest.raises(ValueError, match="a lidar needs its range"):
        ChannelDevice(sim, Spec("l", "stream", "in", 90, None, values))
    with pytest.raises(ValueError, match="needs its field of view"):
        ChannelDevice(sim, Spec("l", "stream", "in", 90, 5.0, {**values, "fov": None}))


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="sim-test")
    running.setup()
    running.start()
    yield running
    running.stop()


def test_the_example_system_runs_in_the_simulator(transport: Transport) -> None:
    system = ckmconf.load(STATION)
    scope = PlantScope(time.monotonic, name="example")
    runtime = NodeRuntime(system.nodes[0], system, transport)
    with plant_scope(scope):
        runtime.setup()
    runtime.start()
    try:
        deadline = time.monotonic() + 20.0
        sim = find_world(scope)
        assert sim is not None
        while time.monotonic() < deadline:
            with sim.lock:
                moved = sim.robots["rover"].planar_pose()
                shoulder = sim.robots["station_arm"].joint_state(sim.robots["station_arm"].joint("shoulder_joint"))[0]
            if math.dist(moved[:2], (3.5, 2.0)) > 0.3 and abs(shoulder - 0.9) < 0.05:
                break
            time.sleep(0.1)
        assert math.dist(moved[:2], (3.5, 2.0)) > 0.3  # the rover drove on its constant duties
        assert shoulder == pytest.approx(0.9, abs=0.05)  # the arm reached its set-point
        assert sim.world.time > 0.5
    finally:
        runtime.stop()


def test_gripper_mirror_and_effort_mode(clock_and_scope: tuple[ManualClock, PlantScope]) -> None:
    clock, scope = clock_and_scope
    gripper, fingers, wheel, speed = open_all(
        scope,
        channel("g", "out", "bus", body="turtlebot", pose="3 2 0", joint="gripper_joint", mirror="gripper_right_joint"),
        channel("f", "in", "bus", size=2, body="turtlebot", joints="gripper_joint gripper_right_joint"),
        channel("w", "out", "pwm", body="rover", pose="3 1 0", joint="left_wheel_joint", mode="effort"),
        channel("v", "in", "analog", body="rover", joint="left_wheel_joint", mode="velocity"),
    )
    gripper.write(0.03)
    wheel.write(0.5)  # half the joint's effort limit (10 N·m in rover.urdf) on one wheel
    clock.advance(0.5)
    left, right = fingers.read()  # type: ignore[misc]
    assert left == pytest.approx(0.03, abs=0.002) and right == pytest.approx(0.03, abs=0.002)
    turning = speed.read()
    assert isinstance(turning, float) and turning > 1.0  # the torque turned the wheel


def _lidar_reads(seed: str) -> list[list[float]]:
    clock = ManualClock()
    motor, laser = open_all(
        PlantScope(clock),
        channel("m", "out", "pwm", body="rover", pose="3 2 0.2", joint="left_wheel_joint", mode="velocity", seed=seed),
        ranging(
            channel(
                "l",
                "in",
                "stream",
                size=90,
                body="rover",
                sensor="lidar",
                link="laser_link",
                noise="0.01",
                fov="4.7",
                seed=seed,
            ),
            5.0,
        ),
    )
    motor.write(0.4)
    reads = []
    for _ in range(5):
        clock.advance(0.2)
        value = laser.read()
        assert isinstance(value, np.ndarray) and value.shape == (90,)
        reads.append(value.tolist())
    return reads


def test_same_seed_same_channel_data() -> None:
    assert _lidar_reads("5") == _lidar_reads("5")
    assert _lidar_reads("5") != _lidar_reads("6")


def test_rgb_and_depth_channels_of_one_camera_share_a_render(clock_and_scope: tuple[ManualClock, PlantScope]) -> None:
    clock, scope = clock_and_scope
    xtion = {"body": "turtlebot", "link": "camera_rgb_optical_frame", "width": "40", "height": "30", "fov": "1.0123"}
    rgb, depth = open_all(
        scope,
        channel("c", "in", "stream", size=40 * 30 * 3, sensor="rgb", pose="3 2 0", **xtion),
        channel("d", "in", "stream", size=40 * 30, sensor="depth", **xtion),
    )
    clock.advance(0.1)
    colour, distance = rgb.read(), depth.read()
    assert isinstance(colour, np.ndarray) and isinstance(distance, np.ndarray)  # frames read whole, flat (D243)
    assert colour.shape == (3600,) and colour.dtype == np.uint8 and distance.shape == (1200,)
    cameras = [b.device for b in (rgb, depth)]  # type: ignore[attr-defined]
    assert sum(camera.renders for camera in cameras) == 1
    clock.advance(0.1)
    depth.read()
    assert sum(camera.renders for camera in cameras) == 2  # a new step, a new render


def test_a_front_bumper_feels_a_touch_ahead_but_not_one_behind(clock_and_scope: tuple[ManualClock, PlantScope]) -> None:
    """D236: the Kobuki's bumpers cover its front half (arc π); a contact sensor with no arc feels any touch."""
    import pybullet as p

    clock, scope = clock_and_scope
    front, anywhere = open_all(
        scope,
        channel("f", "in", "digital", body="turtlebot", pose="2.0 2.0 0", sensor="contact", arc="3.1416"),
        channel("a", "in", "digital", body="turtlebot", sensor="contact"),
    )
    clock.advance(0.2)
    assert front.read() == 0.0 and anywhere.read() == 0.0
    sim = find_world(scope)
    assert sim is not None
    cid = sim.world.client
    x, y, _ = sim.robots["turtlebot"].planar_pose()
    wall = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.05, 0.4, 0.1], physicsClientId=cid)
    ahead = p.createMultiBody(0, wall, basePosition=[x + 0.175 + 0.05 - 0.002, y, 0.1], physicsClientId=cid)
    clock.advance(0.02)
    assert front.read() == 1.0 and anywhere.read() == 1.0
    p.resetBasePositionAndOrientation(ahead, [x - 0.175 - 0.05 + 0.002, y, 0.1], [0, 0, 0, 1], physicsClientId=cid)
    clock.advance(0.02)
    assert anywhere.read() == 1.0  # touched on its back ...
    assert front.read() == 0.0  # ... which the front bumper does not cover
