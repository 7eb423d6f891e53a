"""``hardware.sim``: HWChannels served by simulated devices of robots in a pybullet world (issue J).

Params (decision D86). ``body`` names the robot; its model is ``plugins/sim/models/<body>.urdf``
unless ``model`` gives a URDF path (relative to the configuration file); ``pose`` "x y yaw" places
it (the first channel of a body to be set up decides; default: the map's centre). One world per
scope (:mod:`plugins.hardware.simulation`: per node under ``ckm-run``), built by the first channel
set up from the ``<Environment>`` of the file its ``world`` Param names (default: its own
configuration file); a later ``world`` naming another file is an error. ``textures`` names the
RGB recognition's model file so objects wear the textures it learnt. A camera's and a lidar's
geometry has no default (D284): ``fov``, and a lidar's range (the HWChannel's ``max``), are the
sensor's own, never the lab's Xtion's or Hokuyo's.
The device is chosen by ``sensor`` (``contact``, ``lidar``, ``rgb``, ``depth``, ``imu``,
``altimeter``, ``pose``, ``flow``, ``position``, ``compass``), by ``joint``/``joints`` (with ``grasp``:
a gripper) or by ``actuator`` (``multirotor``: a velocity set-point flown by the robot's rotors,
:mod:`plugins.sim.flight`, D293), and the channel's kind and direction. Every device — kind ×
direction, the values in order with their units, the size, the ``mode``s it accepts and its Params —
is a row of :data:`plugins.sim.device_table.DEVICES` (D295): ``SimBackend.problems`` (so ``verify``)
refuses a channel no row allows, and ``ckm-plugins show hardware.sim`` prints the table after this
text (:meth:`SimBackend.reference`).

Time (decision D88): the world is a :class:`SimulationHook` of the channel's scope; each read or
write first steps the physics, in fixed steps, up to the scope clock's time — real time under
``ckm-run``, lock-step with a :class:`ManualClock` in tests.

One world per run (decisions D100–D102): when the environment names a world server
(``CKM_SIM_SERVER``, set by ``ckm-run`` for every process of a run, partitions included) a channel
is a client of it (:class:`plugins.sim.client.RemoteDevice`): the same device code
(:mod:`plugins.sim.devices`) runs there, on the server's real-time clock, and every node and
partition sees the same robots. Without it the world is in-process, as above.
"""

from __future__ import annotations

import re
import threading
import weakref
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np

from ckmconf.loader import load
from ckmconf.model import HWChannel, Node, System
from plugins.sim import device_table
from plugins.sim.client import RemoteDevice, server_address
from plugins.sim.devices import ChannelDevice, SimWorld, Spec, to_value
from plugins.sim.flight import AXES, Airframe
from runtime.kernel.interfaces import Backend, ParamError, Value, read_params
from runtime.verification.manifest import NUMBERS, P, Params, Ports

from .sim_checks import device_problems, multirotor_problems, system_problems
from .simulation import PlantScope, scope_for

SENSORS = ("", "contact", "lidar", "rgb", "depth", "imu", "altimeter", "pose", "flow", "position", "compass")
ACTUATORS = ("", "multirotor")
_SPEC = Params(
    P("body", "", "Robot the channel belongs to (model plugins/sim/models/<body>.urdf)."),
    P("model", "", "URDF of the robot, relative to the configuration file (default: from body)."),
    P("pose", "", "Initial pose of the robot: 'x y yaw' (m, m, rad); default the map's centre.", numbers=(3,),
      form="'x y yaw'"),
    P("world", "", "Configuration file whose <Environment> is built (default: the channel's own)."),
    P("textures", "", "RGB recognition model file whose textures paint the objects it names."),
    P("seed", 0, "Seed of the world and of this channel's noise."),
    P("joint", "", "Joint the channel reads or drives."),
    P("joints", "", "Space-separated joints read together (bus in)."),
    P("mirror", "", "A second joint driven like 'joint' (out channels)."),
    P("grasp", "", "Gripper channel: the link an object both fingers close on is held to (D87, D187)."),
    P("holdForce", 0.0, "Force beyond which a held object slips out of the grasp (0: the fingers' friction grip, "
      "2 x 0.75 x their joints' effort limit, D296).", unit="N", min=0.0),
    P("link", "base_link", "Link carrying the sensor."),
    P("sensor", "", "Sensor device.", choices=SENSORS),
    P("mode", "position", "Joint quantity.", choices=("position", "velocity", "effort")),
    P("maxVelocity", 10.0, "Joint speed at duty 1 (pwm, velocity mode).", unit="rad/s", above=0.0),
    P(
        "ticksPerRev",
        None,
        "Encoder ticks per wheel turn (required by a wheel encoder: counter in, joint).",
        type=float,
        above=0.0,
    ),
    P("scale", 1.0, "Joint units per raw unit.", unit="rad"),
    P("offset", 0.0, "Raw value at joint zero."),
    P("initial", "", "Raw value an out channel's joint(s) stand at when the robot is spawned (position mode)."),
    P("noise", 0.0, "Standard deviation of the noise added to each read.", min=0.0),
    P(
        "fov",
        None,
        "Horizontal field of view (required by a camera, sensor rgb or depth, and a lidar: no "
        "default, it is the sensor's own).",
        type=float,
        unit="rad",
        above=0.0,
    ),
    P("rangeMin", 0.0, "Lidar minimum range (0: every return counts).", unit="m", min=0.0),
    P(
        "arc",
        6.2832,
        "Contact sensor: the arc, centred ahead, where a touch presses it (2π: anywhere).",
        unit="rad",
        above=0.0,
    ),
    P("width", 640, "Image width.", unit="px", min=1),
    P("height", 480, "Image height.", unit="px", min=1),
    P("actuator", "", "Actuator device of an out channel other than a joint (multirotor: D293).", choices=ACTUATORS),
    P("axis", "", "Multirotor: the one set-point value a size-1 channel drives (an Actuator's), the others "
                  "kept: vx, vy, vz or yaw_rate.", choices=("", *AXES)),
    P("rotors", "", "Multirotor: its rotor links, space-separated (3 or more; positions and axes from the URDF)."),
    P("spin", "", "Multirotor: one +1 or -1 per rotor, its reaction torque's sense (+1: counter-clockwise "
                  "seen from above, the propeller turning clockwise)."),
    P("maxThrust", None, "Multirotor: the most thrust one rotor gives (required: the motor's own).", type=float,
      unit="N", above=0.0),
    P("thrustLag", 0.05, "Multirotor: the rotors' first-order time constant (slower than 0.2 s cannot hold "
                         "the attitude).", unit="s", min=0.0, max=0.2),
    P("maxTilt", 0.6, "Multirotor: the most the controller tilts the body.", unit="rad", above=0.0, below=1.5),
    P("maxSpeed", 5.0, "Multirotor: the fastest horizontal set-point accepted.", unit="m/s", above=0.0),
    P("maxClimb", 3.0, "Multirotor: the fastest climb or descent set-point accepted.", unit="m/s", above=0.0),
    P("maxYawRate", 2.0, "Multirotor: the fastest yaw-rate set-point accepted.", unit="rad/s", above=0.0),
    P("drag", 0.3, "Multirotor: linear drag of the body.", unit="N/(m/s)", min=0.0),
    P("yawMoment", 0.016, "Multirotor: a rotor's reaction torque per newton of its thrust.", unit="N·m/N",
      above=0.0),
    P("failsafe", 1.0, "Multirotor: simulated seconds without a set-point after which it hovers 2 s, then "
                       "lands at 0.5 m/s, as PX4 does on offboard loss (0: never).", unit="s", min=0.0),
    P(
        "latency",
        0.0,
        "Camera: time from the exposure to the frame's arrival; the world runs on while the "
        "frame renders, in lock-step too (D246).",
        unit="s",
        min=0.0,
    ),
)


_worlds: weakref.WeakValueDictionary[PlantScope, SimWorld] = weakref.WeakValueDictionary()
_lock = threading.Lock()


def find_world(scope: PlantScope) -> SimWorld | None:
    """The world of ``scope`` while a backend holds it (tests, consoles)."""
    with _lock:
        return _worlds.get(scope)


class SimBackend(Backend):
    """A channel served by a device of a simulated robot (see the module docstring)."""

    PARAMS = _SPEC
    PORTS = Ports(outputs={"*": NUMBERS})

    @classmethod
    def reference(cls, form: str) -> str:
        """The device table (D295) for ``ckm-plugins``: ``form`` "text" (``show``) or "markdown" (docs/plugins.md)."""
        return device_table.markdown() if form == "markdown" else device_table.text()

    @classmethod
    def problems(cls, channel: HWChannel, system: System | None = None) -> list[tuple[Any, str]]:
        """What is wrong across the channel's Params (each alone is checked by its manifest entry), as
        ``(the Param or the channel, message)``: ``verify`` reports each at its ``FILE:LINE:COL`` before
        anything starts, and the backend refuses the first."""
        try:
            v = read_params(channel.params, _SPEC, owner=f"sim channel {channel.name!r}")
        except ParamError:
            return []  # the manifest check reports the Param itself
        named = {p.name: p for p in channel.params}
        found: list[tuple[Any, str]] = []

        def problem(param: str | None, message: str) -> None:
            found.append((named.get(param, channel) if param else channel, message))

        if not v["body"]:
            problem(None, "Param 'body' (the robot) is required")
        if not (v["sensor"] or v["joint"] or v["joints"] or v["actuator"]):
            problem(None, "give Param 'sensor', 'joint'/'joints' or 'actuator' to choose the device")
        if v["actuator"]:
            multirotor_problems(v, problem)
        if v["latency"] and v["sensor"] not in ("rgb", "depth"):
            problem("latency", f"Param 'latency' is a camera's (sensor rgb or depth), not {v['sensor'] or 'a joint'}'s")
        if v["initial"]:
            if channel.direction != "out" or v["mode"] != "position":
                problem("initial", "Param 'initial' places a joint: only for an out channel in mode 'position'")
            try:
                float(v["initial"])
            except ValueError:
                problem("initial", f"Param 'initial' is {v['initial']!r}, not a number")
        if channel.kind == "counter" and channel.direction == "in" and v["joint"] and v["ticksPerRev"] is None:
            problem(
                None,
                "a wheel encoder (counter in, joint) needs Param 'ticksPerRev', its encoder's ticks per "
                "wheel turn (no default: it is the encoder's own)",
            )
        if system is not None:  # the robot's URDF and its spawn: against the rest of the system
            found.extend(system_problems(channel, v, named, system))
        sensor = v["sensor"]
        # A camera's or a lidar's geometry is its own: no default, so no user's sensor silently gets
        # the lab's Xtion or Hokuyo (issue M, D284).
        what = {"rgb": "camera", "depth": "depth camera", "lidar": "lidar"}.get(sensor)
        if what and v["fov"] is None:
            problem(
                None,
                f"a {what} needs its field of view: Param 'fov' (rad), its horizontal angle of view "
                f"(no default: it is the {what}'s own)",
            )
        if sensor == "lidar" and channel.max is None:
            problem(
                None,
                "a lidar needs its range: the HWChannel's max (m), the farthest distance it measures "
                "(no default: it is the lidar's own)",
            )
        # The device table's checks (D295), each Param reported once: a specific message above wins.
        told = {name for name, param in named.items() if any(target is param for target, _ in found)}
        told |= set(re.findall(r"Param '(\w+)'", " ".join(message for _, message in found)))
        found.extend(
            (target, message) for param, target, message in device_problems(channel, v, named) if param not in told
        )
        return found

    def __init__(self, channel: HWChannel, *, scope: PlantScope | None = None) -> None:
        super().__init__(channel)
        self.owner = f"sim channel {channel.name!r}"
        self.values = read_params(channel.params, _SPEC, owner=self.owner)
        v = self.values
        problems = self.problems(channel)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.latency = float(v["latency"])
        if v["initial"]:
            v["initial"] = float(v["initial"])
        here = Path(channel.loc.file) if channel.loc and channel.loc.file != "<memory>" else None
        self.base_dir = here.parent if here else Path.cwd()
        own = str(here.resolve()) if here else ""
        self.world_file = str((self.base_dir / v["world"]).resolve()) if v["world"] else own
        self.scope = scope if scope is not None else scope_for(channel)
        self.sim: SimWorld | None = None
        self._device: ChannelDevice | None = None
        self.device: Any = None  # in-process: the simulated device itself (a Camera, a Lidar, joints…)
        self.remote: RemoteDevice | None = None  # client mode: the device in the world server
        self.last: Value = 0.0  # the last raw value written (what reading an out channel gives, as loopback's)
        self.airframe = Airframe.from_values(v, self.owner) if v["actuator"] == "multirotor" else None

    def _path(self, text: str) -> str:
        return str((self.base_dir / text).resolve()) if text else ""

    def setup(self) -> None:
        """Attach the channel's device: in the run's world server, else in the scope's world (built from
        the ``<Environment>`` of the ``world`` file by the first channel of the scope)."""
        v = self.values
        address = server_address()
        if address is not None:  # client mode (D100): the run's world server holds the world
            self.remote = RemoteDevice(address, self.spec())
            return
        with _lock:
            sim = _worlds.get(self.scope)
            if sim is None:
                environment = load(self.world_file).environment if self.world_file else None
                textures = self._path(v["textures"])
                sim = SimWorld(self.scope.clock, environment, v["seed"], textures, self.world_file)
                _worlds[self.scope] = sim
            elif v["world"] and sim.source != self.world_file:
                raise ParamError(
                    f"{self.owner}: Param 'world' names {self.world_file}, but the simulated world of "
                    f"this scope was built from {sim.source}"
                )
        with sim.lock:
            self._device = ChannelDevice(sim, self.spec())
        self.sim, self.device = sim, self._device.device

    def spec(self) -> Spec:
        """What the device needs of this channel (sent to the world server in client mode)."""
        values = dict(self.values)
        values["model"] = self._path(values["model"]) if values["model"] else ""
        values["world"] = self.world_file if values["world"] else ""  # the server refuses another world
        ch = self.channel
        return Spec(ch.name, ch.kind, ch.direction, ch.size, None if ch.max is None else float(ch.max), values)

    def _require(self) -> tuple[SimWorld, ChannelDevice]:
        if self.sim is None or self._device is None:
            raise RuntimeError(f"{self.owner} is used before setup() or after stop()")
        return self.sim, self._device

    def read(self) -> Value:
        """The device's raw value once the world is advanced to the clock's time (an output: the last written)."""
        if self.channel.direction == "out":
            return self.last
        if self.remote is not None:
            return to_value(self.remote.read())
        sim, device = self._require()
        with sim.lock:
            sim.sync()
            return to_value(device.read())

    def request(self) -> Any:
        """A camera's frame of the world now (D246): ordered from the world server, rendered while the
        world runs on; in process, rendered now."""
        if self.remote is not None:
            return self.remote.order()
        return self.read()

    def collect(self, token: Any) -> Value:
        """The frame :meth:`request` ordered (the world server's ticket), waiting for it if need be."""
        if self.remote is not None:
            return to_value(self.remote.collect(token))
        value: Value = token
        return value

    def write(self, value: Value) -> None:
        """Drive the device (joint target, wheel duty…) with one raw value, at the clock's time."""
        if self.channel.direction != "out":
            raise RuntimeError(f"{self.owner} is an input channel")
        if self.airframe is not None:
            self._fly(self.airframe, value)
            return
        raw = float(value[0] if isinstance(value, tuple) else value)
        if self.remote is not None:
            self.remote.write(raw)
            self.last = raw
            return
        sim, device = self._require()
        self.last = raw
        with sim.lock:
            sim.sync()
            device.write(raw)

    def _fly(self, airframe: Airframe, value: Value) -> None:
        """A multirotor's set-point (D293), or one value of it (``axis``), refused here if bad; the device
        checks it again (with the other axes' values) wherever it runs."""
        given = np.asarray(value, dtype=float).ravel().tolist()
        axis = self.values["axis"]
        setpoint: float | list[float]
        if axis:
            if len(given) != 1:
                raise ValueError(f"{self.owner} drives the multirotor's {axis}: one value, got {len(given)}")
            alone = [0.0] * len(AXES)
            alone[AXES.index(axis)] = given[0]
            airframe.setpoint(alone, self.owner)
            setpoint = float(given[0])
        else:
            setpoint = list(airframe.setpoint(given, self.owner))
        if self.remote is not None:
            self.remote.write(setpoint)
        else:
            sim, device = self._require()
            with sim.lock:
                sim.sync()
                device.write(setpoint)
        self.last = setpoint if isinstance(setpoint, float) else tuple(setpoint)

    @classmethod
    def run_session(
        cls, system: System, config: Path, run_dir: Path, nodes: Sequence[Node], failed: Callable[[str], None]
    ) -> AbstractContextManager[None]:
        """ckm-run's hook around a run (runtime.sessions): the world server every sim channel of the
        run's processes talks to (D102)."""
        from plugins.sim.session import world_session  # the launcher is loaded only by ckm-run

        return world_session(system, config, run_dir, nodes, failed)

    def stop(self) -> None:
        """Detach from the device (closing the connection to the world server in client mode)."""
        if self.remote is not None:
            self.remote.close()
        self.sim, self._device, self.device, self.remote = None, None, None, None

