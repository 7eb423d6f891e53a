"""Every device ``hardware.sim`` serves, as data (issue N point 1, decision D295): for each HWChannel
kind × direction × device (thesis §3.1.5.1), the values a read gives or a write takes and their order
and units, how many (the channel's ``size``), the ``mode`` values it accepts and the Params it reads.

One table feeds everything that used to repeat it by hand: ``SimBackend.problems`` (via
:mod:`plugins.hardware.sim_checks`) refuses a channel whose kind, direction, size, mode or Params no
row allows; :class:`plugins.sim.devices.ChannelDevice` refuses a combination no row names (the world
server too); ``ckm-plugins show hardware.sim`` and ``docs/plugins.md`` print :func:`text` and
:func:`markdown`; ``docs/simulation.md`` holds :func:`markdown` between :data:`BEGIN` and :data:`END`,
rewritten by ``python -m plugins.sim.device_table docs/simulation.md``.

To add a device: add its :class:`Device` row to :data:`DEVICES` (and its code to
:mod:`plugins.sim.devices`), an example channel to ``tests/plugins/sim/test_device_table.py``, then
regenerate ``docs/simulation.md`` as above and ``docs/plugins.md`` with ``ckm-plugins markdown``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROBOT_PARAMS = ("body", "model", "pose", "world", "textures", "seed")
"""The Params every device reads: its robot (``body``, required), where it comes from and its world."""


@dataclass(frozen=True)
class Size:
    """How many values a device gives or takes: ``text`` for the docs; ``count`` from the channel's
    Params as ``hardware.sim`` read them (None: any size, the device takes the channel's own)."""

    text: str
    count: Callable[[Mapping[str, Any]], int | None]
    each: str = ""
    """What one group of the device's values is about (a beam, a pixel, a joint); "": one group."""


def fixed(n: int) -> Size:
    """A device of ``n`` values whatever its Params."""
    return Size(str(n), lambda values: n)


ANY_SIZE = Size("any: the beams", lambda values: None, "beam")
PER_JOINT = Size("the joints named", lambda values: len(str(values.get("joints", "")).split()), "joint of `joints`")
RGB_FRAME = Size("width × height × 3", lambda values: int(values["width"]) * int(values["height"]) * 3, "pixel")
DEPTH_FRAME = Size("width × height", lambda values: int(values["width"]) * int(values["height"]), "pixel")


@dataclass(frozen=True)
class Device:
    """One device: a channel of ``kind`` and ``direction`` whose Params choose it by ``selector``
    (``joint``, ``joints``, ``joint + grasp``, ``sensor=NAME`` or ``actuator=NAME``).

    ``values`` are (name, unit) in the order a read gives them (a write takes the first), repeated
    for ``size`` when it is a rule; ``modes`` are the ``mode`` values accepted, the first being what
    applies when none is given (empty: the device takes no mode); ``required`` and ``optional`` are
    the Params it reads besides :data:`ROBOT_PARAMS`."""

    kind: str
    direction: str
    selector: str
    summary: str
    values: tuple[tuple[str, str], ...]
    size: Size
    modes: tuple[str, ...] = ()
    required: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()
    typical_noise: float | None = None
    """A typical ``noise`` s.d. (the device's units) for a channel that gives none: what ``ckm-bench mission``
    scales per seed (D301); None where no figure fits every robot (a joint's raw units depend on its scale)."""

    @property
    def name(self) -> str:
        """What messages call the device: its sensor or actuator, ``joint``, ``joints`` or ``gripper``."""
        if self.selector.startswith(("sensor=", "actuator=")):
            return self.selector.partition("=")[2].replace(" + ", " ")
        return "gripper" if self.selector == "joint + grasp" else self.selector

    @property
    def params(self) -> tuple[str, ...]:
        """Every Param the device reads, the robot's included."""
        return (*ROBOT_PARAMS, *self.required, *self.optional)

    @property
    def where(self) -> str:
        """``kind direction, selector``: the row's key as the docs print it."""
        return f"{self.kind} {self.direction}, {self.selector}"


_JOINT_READ = (("q", "raw = q / scale + offset"),)
_JOINT_TARGET = (("q target", "raw; q = (raw − offset) × scale"),)
_JOINT_MODES = ("position", "velocity", "effort")
_READ_JOINT = "q, the joint's position, velocity or effort (`mode`; rad, rad/s, N·m, or m, m/s, N if prismatic)"
_CAMERA_OPTIONAL = ("link", "width", "height", "latency")


def _joint_in(kind: str) -> Device:
    return Device(
        kind=kind,
        direction="in",
        selector="joint",
        summary=f"{_READ_JOINT}, plus `noise` (s.d., raw)",
        values=_JOINT_READ,
        size=fixed(1),
        modes=_JOINT_MODES,
        required=("joint",),
        optional=("mode", "scale", "offset", "noise"),
    )


def _joint_out(kind: str) -> Device:
    return Device(
        kind=kind,
        direction="out",
        selector="joint",
        summary="drives the joint to a target q, its position, velocity or effort (`mode`); `mirror`: a second "
        "joint driven alike (a gripper's other finger); `initial`: the raw value the joint(s) stand at when "
        "the robot is spawned (mode position)",
        values=_JOINT_TARGET,
        size=fixed(1),
        modes=_JOINT_MODES,
        required=("joint",),
        optional=("mode", "scale", "offset", "mirror", "initial"),
    )


def _gripper(kind: str) -> Device:
    return Device(
        kind=kind,
        direction="out",
        selector="joint + grasp",
        summary="a gripper: `joint` and `mirror` are its fingers (closing towards their lower limit); an object "
        "both touch while closing is held to link `grasp` until a command opens them or `holdForce` (N; default "
        "the fingers' friction grip, 2 x 0.75 x their effort limit) is exceeded and it slips out (D87, D187, D296)",
        values=_JOINT_TARGET,
        size=fixed(1),
        modes=("position",),
        required=("joint", "mirror", "grasp"),
        optional=("mode", "scale", "offset", "holdForce", "initial"),
    )


MULTIROTOR = ("actuator", "rotors", "spin", "maxThrust")
AIRFRAME = ("thrustLag", "maxTilt", "maxSpeed", "maxClimb", "maxYawRate", "drag", "yawMoment", "failsafe")


def _axis(kind: str) -> Device:
    return Device(
        kind=kind,
        direction="out",
        selector="actuator=multirotor + axis",
        summary="one value of a multirotor's velocity set-point (`axis`: vx, vy, vz or yaw_rate), the others "
        "kept: one CKM Actuator per axis; every channel of the robot gives the same rotor Params (D293)",
        values=(("the axis' set-point", "m/s, or rad/s for yaw_rate"),),
        size=fixed(1),
        required=(*MULTIROTOR, "axis"),
        optional=AIRFRAME,
    )


DEVICES: tuple[Device, ...] = (
    Device(
        kind="counter",
        direction="in",
        selector="joint",
        summary="a wheel encoder: the joint's speed in ticks/s, plus `noise` (s.d., ticks/s)",
        values=(("speed", "ticks/s"),),
        size=fixed(1),
        required=("joint", "ticksPerRev"),
        optional=("noise",),
        typical_noise=20.0,  # ~0.25 % of a Kobuki wheel's top speed
    ),
    Device(
        kind="pwm",
        direction="out",
        selector="joint",
        summary="a motor: duty × the joint's effort limit (mode effort) or × `maxVelocity` (mode velocity); "
        "`mirror`: a second joint driven alike",
        values=(("duty", "−1 … 1"),),
        size=fixed(1),
        modes=("effort", "velocity"),  # effort first: a pwm channel without `mode` drives the effort
        required=("joint",),
        optional=("mode", "maxVelocity", "mirror"),
    ),
    _joint_in("analog"),
    _joint_in("bus"),
    Device(
        kind="bus",
        direction="in",
        selector="joints",
        summary=f"each named joint's value, in the order `joints` names them: {_READ_JOINT}",
        values=_JOINT_READ,
        size=PER_JOINT,
        modes=_JOINT_MODES,
        required=("joints",),
        optional=("mode", "scale", "offset", "noise"),
    ),
    _joint_out("analog"),
    _joint_out("bus"),
    _gripper("analog"),
    _gripper("bus"),
    Device(
        kind="digital",
        direction="in",
        selector="sensor=contact",
        summary="a bumper: 1 while `link` touches an obstacle within `arc` (rad, centred ahead) of its heading "
        "(the Kobuki's three cover the front half, π; D236)",
        values=(("pressed", "0 or 1"),),
        size=fixed(1),
        required=("sensor",),
        optional=("link", "arc"),
    ),
    Device(
        kind="stream",
        direction="in",
        selector="sensor=lidar",
        summary="a planar lidar on `link`: one range per beam, counter-clockwise from −fov/2 to +fov/2, from "
        "`rangeMin` up to the HWChannel's `max` (required: the lidar's range; a beam hitting nothing reads it), "
        "plus `noise` (s.d., m)",
        values=(("range", "m"),),
        size=ANY_SIZE,
        required=("sensor", "fov"),
        optional=("link", "rangeMin", "noise"),
        typical_noise=0.01,  # a Hokuyo URG's ±1 cm
    ),
    Device(
        kind="stream",
        direction="in",
        selector="sensor=rgb",
        summary="a colour camera on `link`: one `width`×`height` frame over `fov` (its horizontal field of "
        "view), pixels row-major from the top left; `latency`: exposure to arrival (D246)",
        values=(("red", "0–255"), ("green", "0–255"), ("blue", "0–255")),
        size=RGB_FRAME,
        required=("sensor", "fov"),
        optional=_CAMERA_OPTIONAL,
    ),
    Device(
        kind="stream",
        direction="in",
        selector="sensor=depth",
        summary="a depth camera on `link`: one `width`×`height` frame over `fov`, row-major from the top left "
        "(shares the render of an rgb channel of the same camera, D240)",
        values=(("depth", "mm"),),
        size=DEPTH_FRAME,
        required=("sensor", "fov"),
        optional=_CAMERA_OPTIONAL,
    ),
    Device(
        kind="analog",
        direction="in",
        selector="sensor=imu",
        summary="an IMU on `link`: angular velocity and linear acceleration (with gravity) in the link's frame, "
        "plus `noise` (s.d., each value)",
        values=(("wx", "rad/s"), ("wy", "rad/s"), ("wz", "rad/s"), ("ax", "m/s²"), ("ay", "m/s²"), ("az", "m/s²")),
        size=fixed(6),
        required=("sensor",),
        optional=("link", "noise"),
        typical_noise=0.01,
    ),
    Device(
        kind="analog",
        direction="in",
        selector="sensor=altimeter",
        summary="the height of `link` above the floor, plus `noise` (s.d., m)",
        values=(("height", "m"),),
        size=fixed(1),
        required=("sensor",),
        optional=("link", "noise"),
        typical_noise=0.01,
    ),
    Device(
        kind="bus",
        direction="in",
        selector="sensor=pose",
        summary="the true planar pose of `link` on the map: ground truth for reports and benchmarks, as Gazebo's "
        "p3d plugin gives; no robot has it, never noisy",
        values=(("x", "m"), ("y", "m"), ("yaw", "rad")),
        size=fixed(3),
        required=("sensor",),
        optional=("link",),
    ),
    Device(
        kind="bus",
        direction="in",
        selector="sensor=flow",
        summary="optical flow: `link`'s velocity over the ground in the robot's heading frame (x ahead, y left), "
        "plus `noise` (s.d., m/s; D293)",
        values=(("vx", "m/s"), ("vy", "m/s")),
        size=fixed(2),
        required=("sensor",),
        optional=("link", "noise"),
        typical_noise=0.05,
    ),
    Device(
        kind="bus",
        direction="in",
        selector="sensor=position",
        summary="a position fix (UWB, GNSS, motion capture): `link`'s position in the map, plus `noise` (s.d., "
        "m; D293); unlike `pose`, a sensor a robot has",
        values=(("x", "m"), ("y", "m"), ("z", "m")),
        size=fixed(3),
        required=("sensor",),
        optional=("link", "noise"),
        typical_noise=0.03,  # UWB
    ),
    Device(
        kind="analog",
        direction="in",
        selector="sensor=compass",
        summary="a compass: `link`'s heading, counter-clockwise from the map's x axis, in (−π, π], plus `noise` "
        "(s.d., rad; D293)",
        values=(("yaw", "rad"),),
        size=fixed(1),
        required=("sensor",),
        optional=("link", "noise"),
        typical_noise=0.01,
    ),
    Device(
        kind="bus",
        direction="out",
        selector="actuator=multirotor",
        summary="a multirotor flown by a velocity set-point (as PX4 offboard, MAVROS `setpoint_velocity`): "
        "`rotors` (links) with `spin` (±1 each) and `maxThrust` (N per rotor) push the robot; landed on the "
        "ground while vz ≤ 0 (plugins/sim/flight.py, D293)",
        values=(("vx", "m/s, ahead"), ("vy", "m/s, left"), ("vz", "m/s, up"), ("yaw_rate", "rad/s")),
        size=fixed(4),
        required=MULTIROTOR,
        optional=AIRFRAME,
    ),
    _axis("analog"),
    _axis("bus"),
)
"""Every device ``hardware.sim`` serves, one row per kind × direction × device."""

OUT_READ = "Reading an out channel gives the last raw value written (as `hardware.loopback`)."


def selector_of(values: Mapping[str, Any]) -> str:
    """The device a channel's Params choose, as :attr:`Device.selector` names it ("" if none):
    ``sensor`` first, then ``actuator``, ``joints``, then ``joint`` (with ``grasp``: a gripper), as the
    device code."""
    if values.get("sensor"):
        return f"sensor={values['sensor']}"
    if values.get("actuator"):
        return f"actuator={values['actuator']}" + (" + axis" if values.get("axis") else "")
    if values.get("joints"):
        return "joints"
    if values.get("joint"):
        return "joint + grasp" if values.get("grasp") else "joint"
    return ""


def find(kind: str, direction: str, values: Mapping[str, Any]) -> Device | None:
    """The row serving a channel of ``kind`` and ``direction`` whose Params are ``values`` (None: none)."""
    selector = selector_of(values)
    return next((d for d in DEVICES if (d.kind, d.direction, d.selector) == (kind, direction, selector)), None)


def unserved(kind: str, direction: str, values: Mapping[str, Any]) -> str:
    """Why no row serves the channel: the kinds and directions its device is served as."""
    selector = selector_of(values)
    serving = [f"{d.kind} {d.direction}" for d in DEVICES if d.selector == selector]
    if not serving:
        sensors = ", ".join(sorted({d.name for d in DEVICES if d.selector.startswith("sensor=")}))
        return f"no sim device is {selector!r} (the sensors: {sensors}; or Param 'joint'/'joints')"
    return (
        f"a {kind} {direction} channel cannot be the {selector} device: it is served as "
        f"{' or '.join(serving)} (ckm-plugins show hardware.sim lists every device)"
    )


def _values_text(device: Device, unit: Callable[[str], str]) -> str:
    values = ", ".join(f"{name} {unit(u)}" for name, u in device.values)
    return f"{values}, per {device.size.each}" if device.size.each else values


def _params_text(device: Device, code: Callable[[str], str]) -> str:
    return ", ".join([*(f"{code(p)} (required)" for p in device.required), *(code(p) for p in device.optional)])


def _modes_text(device: Device) -> str:
    if not device.modes:
        return "none"
    return f"{' | '.join(device.modes)} (none given: {device.modes[0]})"


def text() -> str:
    """The device table as ``ckm-plugins show hardware.sim`` prints it."""
    lines = [
        "Devices (generated from plugins/sim/device_table.py): a channel's kind, direction and device; what a",
        "read gives or a write takes, in order, with units; its size; the modes it accepts; its Params.",
        f"Every device also reads body (required: the robot) and {', '.join(ROBOT_PARAMS[1:])}.",
        OUT_READ.replace("`", ""),
    ]
    for device in DEVICES:
        lines += [
            "",
            f"{device.where}: {device.summary.replace('`', '')}",
            f"    values: {_values_text(device, lambda u: f'[{u}]').replace('`', '')}",
            f"    size: {device.size.text.replace('`', '')}; mode: {_modes_text(device)}",
            f"    Params: {_params_text(device, str)}",
        ]
    return "\n".join(lines)


def _cell(value: str) -> str:
    return value.replace("|", "\\|")


def markdown() -> str:
    """The device table as a markdown table (docs/plugins.md, docs/simulation.md)."""
    out = [
        "| kind, direction, device | values in order (unit) | size | `mode` | Params | what it is |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for device in DEVICES:
        selector = " + ".join(f"`{part}`" for part in device.selector.split(" + "))
        cells = [
            f"{device.kind} {device.direction}, {selector}",
            _values_text(device, lambda u: f"({u})"),
            device.size.text,
            _modes_text(device),
            _params_text(device, lambda p: f"`{p}`"),
            device.summary,
        ]
        out.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    out += [
        "",
        f"Every device also reads `body` (required: the robot) and "
        f"{', '.join(f'`{p}`' for p in ROBOT_PARAMS[1:])}. {OUT_READ}",
    ]
    return "\n".join(out)


BEGIN = (
    "<!-- BEGIN generated by python -m plugins.sim.device_table docs/simulation.md "
    "(from plugins/sim/device_table.py): do not edit -->"
)
END = "<!-- END generated device table -->"


def regenerated(page: str) -> str:
    """``page`` with the region between :data:`BEGIN` and :data:`END` replaced by :func:`markdown`."""
    head, begin, rest = page.partition(BEGIN)
    _, end, tail = rest.partition(END)
    if not begin or not end:
        raise ValueError(f"the page has no region between {BEGIN!r} and {END!r}")
    return f"{head}{BEGIN}\n{markdown()}\n{END}{tail}"


def main(argv: Sequence[str] | None = None) -> int:
    """Rewrite the generated device table of each page named (``docs/simulation.md``)."""
    for name in argv if argv is not None else sys.argv[1:]:
        path = Path(name)
        path.write_text(regenerated(path.read_text(encoding="utf-8")), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
