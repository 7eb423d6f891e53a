"""The ``hardware.sim`` device table (issue N point 1, D295) is what the device code serves: every row
builds a device in a small world whose reads give the row's values, in its order, size and units;
every other kind × direction × device is refused by the backend's checks and by the device code; the
table's Params, modes and sizes are the ones the checks apply."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from ckmconf.errors import Loc
from ckmconf.model import HWChannel, Param
from plugins.hardware.sim import SENSORS, SimBackend
from plugins.hardware.simulation import ManualClock, PlantScope, plant_scope
from plugins.sim.device_table import DEVICES, ROBOT_PARAMS, Device, find, selector_of
from plugins.sim.devices import KINDS, ChannelDevice, SimWorld, Spec
from runtime.kernel.interfaces import read_params
from tests.conftest import REPO

STATION = REPO / "configs" / "examples" / "sim_station.xml"
ROVER = {"body": "rover", "pose": "3 1 0.5"}
ARM = {"body": "station_arm", "pose": "1 1 0"}
CAMERA = {**ARM, "link": "wrist_camera_optical_frame", "width": "8", "height": "6", "fov": "1.2"}
FINGERS = {**ARM, "joint": "left_finger_joint", "mirror": "right_finger_joint", "grasp": "palm_link"}
QUAD = {"body": "quadrotor", "pose": "5.3 1.0 1.0"}
MULTIROTOR = {"actuator": "multirotor", "rotors": "rotor_fl rotor_fr rotor_rl rotor_rr", "spin": "1 -1 -1 1",
              "maxThrust": "6"}  # fmt: skip

EXAMPLES: dict[str, tuple[int, float | None, dict[str, str]]] = {
    "counter in, joint": (1, None, {**ROVER, "joint": "left_wheel_joint", "ticksPerRev": "100"}),
    "pwm out, joint": (1, None, {**ROVER, "joint": "right_wheel_joint", "mode": "velocity"}),
    "analog in, joint": (1, None, {**ARM, "joint": "turret_joint"}),
    "bus in, joint": (1, None, {**ARM, "joint": "shoulder_joint", "mode": "velocity"}),
    "bus in, joints": (2, None, {**ARM, "joints": "turret_joint shoulder_joint"}),
    "analog out, joint": (1, None, {**ARM, "joint": "turret_joint"}),
    "bus out, joint": (1, None, {**ARM, "joint": "elbow_joint", "scale": "0.01", "offset": "100"}),
    "analog out, joint + grasp": (1, None, FINGERS),
    "bus out, joint + grasp": (1, None, FINGERS),
    "digital in, sensor=contact": (1, None, {**ROVER, "sensor": "contact", "link": "bumper_link"}),
    "stream in, sensor=lidar": (31, 5.0, {**ROVER, "sensor": "lidar", "link": "laser_link", "fov": "3"}),
    "stream in, sensor=rgb": (8 * 6 * 3, None, {**CAMERA, "sensor": "rgb"}),
    "stream in, sensor=depth": (8 * 6, None, {**CAMERA, "sensor": "depth"}),
    "analog in, sensor=imu": (6, None, {**ROVER, "sensor": "imu"}),
    "analog in, sensor=altimeter": (1, None, {**ROVER, "sensor": "altimeter", "link": "laser_link"}),
    "bus in, sensor=pose": (3, None, {**ROVER, "sensor": "pose"}),
    "bus in, sensor=flow": (2, None, {**QUAD, "sensor": "flow", "link": "camera_link"}),
    "bus in, sensor=position": (3, None, {**QUAD, "sensor": "position", "noise": "0.05"}),
    "analog in, sensor=compass": (1, None, {**QUAD, "sensor": "compass"}),
    "bus out, actuator=multirotor": (4, None, {**QUAD, **MULTIROTOR}),
    "analog out, actuator=multirotor + axis": (1, None, {**QUAD, **MULTIROTOR, "axis": "vz"}),
    "bus out, actuator=multirotor + axis": (1, None, {**QUAD, **MULTIROTOR, "axis": "yaw_rate"}),
}
"""An example channel of every row (its size, max and Params): a new row needs one here."""


def record(name: str, kind: str, direction: str, size: int, top: float | None, params: dict[str, str]) -> HWChannel:
    """A sim channel record whose world is the example station's workshop."""
    return HWChannel(
        name=name,
        direction=direction,  # type: ignore[arg-type]
        kind=kind,  # type: ignore[arg-type]
        backend="sim",
        size=size,
        max=top,
        loc=Loc(str(STATION), 1, 1, "/System/Node[@name='test']/HWChannel"),
        params=tuple(Param(name=k, value=v) for k, v in params.items()),
    )


def example(device: Device, **changes: str) -> HWChannel:
    size, top, params = EXAMPLES[device.where]
    return record(device.name, device.kind, device.direction, size, top, {**params, **changes})


def messages(channel: HWChannel) -> list[str]:
    return [message for _, message in SimBackend.problems(channel)]


def count(value: Any) -> int:
    return int(value.size) if isinstance(value, np.ndarray) else len(value) if isinstance(value, tuple) else 1


def test_every_row_has_an_example_and_names_the_backend_s_own_params() -> None:
    assert set(EXAMPLES) == {d.where for d in DEVICES}
    assert len({(d.kind, d.direction, d.selector) for d in DEVICES}) == len(DEVICES)  # one row per device
    params = set(SimBackend.PARAMS.specs)
    for device in DEVICES:
        assert device.kind in KINDS and device.direction in ("in", "out")
        assert set(device.params) <= params, device.where
        assert set(device.modes) <= {"position", "velocity", "effort"} and device.values
        assert ("mode" in device.optional) == bool(device.modes), device.where
    # Every sensor the backend's Param offers is a row's, and every row's sensor is offered.
    assert {d.name for d in DEVICES if d.selector.startswith("sensor=")} == set(SENSORS) - {""}


def test_every_row_is_a_device_whose_reads_give_its_values() -> None:
    """Each row's example channel passes the checks, builds in one world and reads as many values as
    the row's size says; the named values are where the row puts them (pose, IMU, camera units)."""
    clock = ManualClock()
    scope = PlantScope(clock, name="device-table")
    channels = {d.where: example(d) for d in DEVICES}
    for where, channel in channels.items():
        assert messages(channel) == [], where
    with plant_scope(scope):
        backends = {where: SimBackend(channel) for where, channel in channels.items()}
    for backend in backends.values():
        backend.setup()
    try:
        written: dict[str, float | tuple[float, ...]] = {
            where: 0.0 if backend.channel.kind == "pwm" else 0.5 for where, backend in backends.items()
        }
        written["bus out, actuator=multirotor"] = (0.0, 0.0, 0.0, 0.0)  # a velocity set-point: stay landed
        written["analog out, actuator=multirotor + axis"] = 0.0
        for where, backend in backends.items():
            if backend.channel.direction == "out":
                backend.write(written[where])  # the rover's wheels stay still: its pose is checked
        clock.advance(1.0)
        reads = {where: backend.read() for where, backend in backends.items()}
    finally:
        for backend in backends.values():
            backend.stop()
    for device in DEVICES:
        value, channel = reads[device.where], channels[device.where]
        expected = device.size.count({**SimBackend(channel).values})
        assert count(value) == (channel.size if expected is None else expected), device.where
        assert count(value) % len(device.values) == 0, device.where
        if device.direction == "out":
            assert value == written[device.where], device.where  # an out channel reads back what was written
    named: dict[str, dict[str, float]] = {}  # a tuple read by the names of the row's values
    for device in DEVICES:
        value = reads[device.where]
        if isinstance(value, tuple) and not device.size.each:  # one group of values: each has its name
            named[device.where] = dict(zip((name for name, _ in device.values), value, strict=True))
    pose = named["bus in, sensor=pose"]
    assert (pose["x"], pose["y"], pose["yaw"]) == pytest.approx((3.0, 1.0, 0.5), abs=0.05)
    assert named["analog in, sensor=imu"]["az"] == pytest.approx(9.81, abs=0.3)  # gravity, m/s²
    rgb, depth = reads["stream in, sensor=rgb"], reads["stream in, sensor=depth"]
    assert isinstance(rgb, np.ndarray) and rgb.min() >= 0 and rgb.max() <= 255
    assert isinstance(depth, np.ndarray) and depth.max() > 50.0  # mm, not m
    speed = reads["counter in, joint"]
    assert isinstance(speed, float) and abs(speed) < 1.0  # ticks/s: the wheel is held at duty 0
    assert reads["digital in, sensor=contact"] in (0.0, 1.0)
    ranges = reads["stream in, sensor=lidar"]
    assert isinstance(ranges, np.ndarray) and ranges.min() > 0.0 and ranges.max() <= 5.0  # m, up to max
    fix, compass = named["bus in, sensor=position"], reads["analog in, sensor=compass"]
    assert (fix["x"], fix["y"]) == pytest.approx((5.3, 1.0), abs=0.3)  # m; noise 0.05
    assert compass == pytest.approx(1.0, abs=0.01)  # rad: the quadrotor spawned at yaw 1
    assert named["bus in, sensor=flow"]["vx"] == pytest.approx(0.0, abs=0.01)  # m/s: it stands landed


def _selectors() -> dict[str, dict[str, str]]:
    """Each device selector of the table with the Params of an example choosing it."""
    return {d.selector: EXAMPLES[d.where][2] for d in DEVICES}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("direction", ["in", "out"])
def test_no_other_combination_is_served(kind: str, direction: str) -> None:
    """A kind × direction × device that is no row is refused by the checks (so verify) and by the device
    code (so the world server, given a spec no backend checked); each that is a row is accepted."""
    sim = SimWorld(ManualClock(), None, 0, "", "")
    for selector, params in _selectors().items():
        channel = record("c", kind, direction, 1, 5.0, params)
        values = SimBackend(channel).values if not messages(channel) else None
        served = find(kind, direction, params)
        assert selector_of(params) == selector
        if served is not None:
            continue  # built and read by test_every_row_is_a_device_whose_reads_give_its_values
        refusal = f"a {kind} {direction} channel cannot be the {selector} device: it is served as"
        assert any(m.startswith(refusal) for m in messages(channel)), (selector, messages(channel))
        assert values is None
        read = read_params(channel.params, SimBackend.PARAMS, owner="c")
        with pytest.raises(ValueError, match=refusal.replace("+", r"\+")):
            ChannelDevice(sim, Spec("c", kind, direction, 1, 5.0, read))


def test_the_checks_apply_the_rows_sizes_modes_and_params() -> None:
    every = set(SimBackend.PARAMS.specs)
    for device in DEVICES:
        size, top, params = EXAMPLES[device.where]
        if device.size.count(params) is not None:  # a size the device cannot give
            wrong = record("c", device.kind, device.direction, size + 1, top, params)
            plural = "" if size == 1 else "s"
            assert f"size is {size + 1}, its {device.name} device gives {size} value{plural}" in messages(wrong)
        for mode in ("position", "velocity", "effort"):
            found = messages(example(device, mode=mode))
            assert (found == []) == (mode in device.modes), (device.where, mode, found)
        for name in sorted(every - set(device.params) - {"mode"}):
            value = {
                "noise": "0.1",
                "holdForce": "5",
                "ticksPerRev": "10",
                "fov": "1",
                "initial": "0",
                "maxVelocity": "2",
                "sensor": "imu",
                "actuator": "multirotor",
                "axis": "vx",
                "arc": "1",
                "width": "4",
                "height": "4",
                "rangeMin": "0.1",
                "latency": "0.1",
                "scale": "2",
                "offset": "1",
                **dict.fromkeys(("maxThrust", "thrustLag", "maxTilt", "maxSpeed", "maxClimb"), "0.1"),
                **dict.fromkeys(("maxYawRate", "drag", "yawMoment", "failsafe"), "0.1"),
            }.get(name, "x")
            found = messages(example(device, **{name: value}))
            assert found, (device.where, name)  # a Param the device does not read is refused
        for name in device.required:
            if name in ("sensor", "actuator", "axis", "joint", "joints", "grasp"):
                continue  # these choose the device: without them it is another row
            _, _, params = EXAMPLES[device.where]
            left_out = record(
                "c", device.kind, device.direction, size, top, {k: v for k, v in params.items() if k != name}
            )
            assert any(f"Param {name!r}" in m for m in messages(left_out)), (device.where, name)


def test_a_param_the_device_does_not_read_is_named_with_what_it_reads() -> None:
    imu = next(d for d in DEVICES if d.where == "analog in, sensor=imu")
    assert messages(example(imu, arc="1")) == [
        "Param 'arc' is not read by the imu device (analog in, sensor=imu), which reads "
        f"{', '.join(p for p in ROBOT_PARAMS if p != 'body')}, sensor, link, noise"
    ]
