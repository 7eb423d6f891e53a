"""``hardware.sim``: HWChannels served by simulated devices of robots in a pybullet world (issue J).

Params (decision D86). ``body`` names the robot; its model is ``plugins/sim/models/<body>.urdf``
unless ``model`` gives a URDF path (relative to the configuration file); ``pose`` "x y yaw" places
it (the first channel of a body to be set up decides; default: the map's centre). One world per
scope (:mod:`plugins.hardware.simulation`: per node under ``ckm-run``), built by the first channel
set up from the ``<Environment>`` of the file its ``world`` Param names (default: its own
configuration file); a later ``world`` naming another file is an error. ``textures`` names the
RGB recognition's model file so objects wear the textures it learnt.
The device is chosen by ``sensor`` (``contact``, ``lidar``, ``rgb``, ``depth``, ``imu``,
``altimeter``) or by ``joint``/``joints``, and the channel's kind and direction:

======================  ===========================================================================
counter in, joint       wheel encoder speed, ticks/s (``ticksPerRev``), plus ``noise`` (s.d.)
pwm out, joint          duty × ``maxVelocity`` (``mode`` velocity) or × max effort (``mode`` effort)
analog/bus in, joint    joint position (``mode`` velocity/effort: those), raw = value / scale + offset
bus in, joints          a tuple of the named joints' positions, each as above
analog/bus out, joint   joint target (``mode``), value = (raw − offset) × scale; ``mirror``: a second
                        joint driven alike (the gripper's other finger)
digital in, contact     1 while ``link`` touches an obstacle (bumper)
stream in, lidar        ``size`` ranges (m) over ``fov`` from ``link``
stream in, rgb/depth    one frame ``width``×``height`` (RGB bytes, or depth in mm) flattened row-major
analog in, imu/alt.     (wx, wy, wz, ax, ay, az) of ``link`` (size 6) / the link's height (m)
out, read               the last raw value written (as ``hardware.loopback``)
======================  ===========================================================================

Time (decision D88): the world is a :class:`SimulationHook` of the channel's scope; each read or
write first steps the physics, in fixed steps, up to the scope clock's time — real time under
``ckm-run``, lock-step with a :class:`ManualClock` in tests.
"""

from __future__ import annotations

import math
import threading
import weakref
from pathlib import Path
from typing import Any

import numpy as np

from ckmconf.loader import load
from ckmconf.model import Environment, HWChannel
from plugins.processing.textures import read_model
from plugins.sim.robots import Robot
from plugins.sim.sensors import Bumper, Camera, Frame, Imu, Lidar
from plugins.sim.world import World
from runtime.kernel.interfaces import Backend, ParamError, Value, read_params
from runtime.verification.manifest import NUMBERS, P, Params, Ports

from .simulation import Clock, PlantScope, SimulationHook, scope_for

SENSORS = ("", "contact", "lidar", "rgb", "depth", "imu", "altimeter")
_SPEC = Params(
    P("body", "", "Robot the channel belongs to (model plugins/sim/models/<body>.urdf)."),
    P("model", "", "URDF of the robot, relative to the configuration file (default: from body)."),
    P("pose", "", "Initial pose of the robot: 'x y yaw' (m, m, rad); default the map's centre."),
    P("world", "", "Configuration file whose <Environment> is built (default: the channel's own)."),
    P("textures", "", "RGB recognition model file whose textures paint the objects it names."),
    P("seed", 0, "Seed of the world and of this channel's noise."),
    P("joint", "", "Joint the channel reads or drives."),
    P("joints", "", "Space-separated joints read together (bus in)."),
    P("mirror", "", "A second joint driven like 'joint' (out channels)."),
    P("link", "base_link", "Link carrying the sensor."),
    P("sensor", "", "Sensor device.", choices=SENSORS),
    P("mode", "position", "Joint quantity.", choices=("position", "velocity", "effort")),
    P("maxVelocity", 10.0, "Joint speed at duty 1 (pwm, velocity mode).", unit="rad/s", above=0.0),
    P("ticksPerRev", 2578.33, "Encoder ticks per wheel turn.", above=0.0),
    P("scale", 1.0, "Joint units per raw unit.", unit="rad"),
    P("offset", 0.0, "Raw value at joint zero."),
    P("noise", 0.0, "Standard deviation of the noise added to each read.", min=0.0),
    P("fov", 1.0123, "Horizontal field of view (camera, lidar).", unit="rad", above=0.0),
    P("rangeMin", 0.02, "Lidar minimum range.", unit="m", min=0.0),
    P("width", 640, "Image width.", unit="px", min=1),
    P("height", 480, "Image height.", unit="px", min=1),
)


class SimWorld(SimulationHook):
    """The pybullet world shared by the sim channels of a scope, built from the ``<Environment>`` of
    ``source`` (a configuration file) by the first channel set up."""

    def __init__(self, clock: Clock, environment: Environment | None, seed: int, textures: str, source: str) -> None:
        super().__init__(clock)
        self.source = source
        self.world = World(environment, seed=seed, catalog=read_model(textures) if textures else None)
        self.environment = environment
        self.robots: dict[str, Robot] = {}
        self.origin = 0.0
        self._frames: dict[tuple[int, int, float, int, int], tuple[int, Frame]] = {}

    def frame(self, camera: Camera, width: int, height: int) -> Frame:
        """A render of ``camera`` at this world step: the RGB and the depth channels of one camera
        (same link, field of view and size) read at the same step share one render (D89)."""
        key = (camera.robot.body, camera.link, camera.fov, width, height)
        cached = self._frames.get(key)
        if cached is not None and cached[0] == self.world.steps:
            return cached[1]
        frame = camera.render(width, height)
        self._frames[key] = (self.world.steps, frame)
        return frame

    def robot(self, name: str, model: str, pose: str) -> Robot:
        """The robot ``name``, loaded on first use."""
        if name not in self.robots:
            if pose:
                at = [float(v) for v in pose.split()]
            elif self.environment is not None:
                bounds = self.environment.map
                at = [(bounds.xmin + bounds.xmax) / 2 + len(self.robots), (bounds.ymin + bounds.ymax) / 2, 0.0]
            else:
                at = [float(len(self.robots)), 0.0, 0.0]
            self.robots[name] = Robot(self.world, name, self.world.load_robot(name, model or name, at))
        return self.robots[name]

    def start(self, now: float) -> None:
        self.origin = now

    def advance(self, start: float, end: float) -> None:
        self.world.run_until(end - self.origin)

    def __del__(self) -> None:
        self.world.close()


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

    def __init__(self, channel: HWChannel, *, scope: PlantScope | None = None) -> None:
        super().__init__(channel)
        self.owner = f"sim channel {channel.name!r}"
        self.values = read_params(channel.params, _SPEC, owner=self.owner)
        v = self.values
        if not v["body"]:
            raise ParamError(f"{self.owner}: Param 'body' (the robot) is required")
        if not (v["sensor"] or v["joint"] or v["joints"]):
            raise ParamError(f"{self.owner}: give Param 'sensor' or 'joint'/'joints' to choose the device")
        if channel.direction == "out" and not v["joint"]:
            raise ParamError(f"{self.owner}: an out channel drives a joint: give Param 'joint'")
        here = Path(channel.loc.file) if channel.loc and channel.loc.file != "<memory>" else None
        self.base_dir = here.parent if here else Path.cwd()
        own = str(here.resolve()) if here else ""
        self.world_file = str((self.base_dir / v["world"]).resolve()) if v["world"] else own
        self._check_size()
        self.scope = scope if scope is not None else scope_for(channel)
        self.sim: SimWorld | None = None
        self.device: Any = None
        self._rng = np.random.default_rng(v["seed"])
        self.last = 0.0  # the last raw value written (what reading an out channel gives, as loopback's)

    def _check_size(self) -> None:
        v, size, sensor = self.values, self.channel.size, self.values["sensor"]
        expected = {
            "rgb": v["width"] * v["height"] * 3, "depth": v["width"] * v["height"], "imu": 6,
            "contact": 1, "altimeter": 1,
        }.get(sensor)
        if v["joints"]:
            expected = len(v["joints"].split())
        if expected is not None and size != expected:
            raise ParamError(f"{self.owner}: size is {size}, its {sensor or 'joints'} device gives {expected} values")

    def _path(self, text: str) -> str:
        return str((self.base_dir / text).resolve()) if text else ""

    def setup(self) -> None:
        v = self.values
        with _lock:
            sim = _worlds.get(self.scope)
            if sim is None:
                environment = load(self.world_file).environment if self.world_file else None
                textures = self._path(v["textures"])
                sim = SimWorld(self.scope.clock, environment, v["seed"], textures, self.world_file)
                _worlds[self.scope] = sim
            elif v["world"] and sim.source != self.world_file:
                raise ParamError(f"{self.owner}: Param 'world' names {self.world_file}, but the simulated world of "
                                 f"this scope was built from {sim.source}")
        with sim.lock:
            model = self._path(v["model"]) if v["model"] else ""
            robot = sim.robot(v["body"], model, v["pose"])
            self.device = self._device(sim, robot)
        self.sim = sim

    def _device(self, sim: SimWorld, robot: Robot) -> Any:
        v, sensor = self.values, self.values["sensor"]
        if sensor == "lidar":
            return Lidar(robot, v["link"], beams=self.channel.size, fov=v["fov"], range_min=v["rangeMin"],
                         range_max=self.channel.max or 5.6, noise=v["noise"], seed=v["seed"])
        if sensor in ("rgb", "depth"):
            return Camera(robot, v["link"], fov=v["fov"])
        if sensor == "imu":
            return Imu(robot, v["link"], noise=v["noise"], seed=v["seed"])
        if sensor == "contact":
            return Bumper(robot, v["link"], sim.world.floor)
        if sensor == "altimeter":
            return robot.link(v["link"])
        if v["joints"]:
            return [robot.joint(name) for name in v["joints"].split()]
        joints = [robot.joint(v["joint"])] + ([robot.joint(v["mirror"])] if v["mirror"] else [])
        return joints

    def _require(self) -> tuple[SimWorld, Robot]:
        if self.sim is None:
            raise RuntimeError(f"{self.owner} is used before setup() or after stop()")
        return self.sim, self.sim.robots[self.values["body"]]

    def _joint_value(self, robot: Robot, joint: int) -> float:
        v = self.values
        position, velocity, effort = robot.joint_state(joint)
        if self.channel.kind == "counter":
            return float(velocity * v["ticksPerRev"] / (2 * math.pi))
        value = {"position": position, "velocity": velocity, "effort": effort}[v["mode"]]
        return float(value / v["scale"] + v["offset"])

    def read(self) -> Value:
        sim, robot = self._require()
        v, sensor = self.values, self.values["sensor"]
        if self.channel.direction == "out":
            return self.last
        with sim.lock:
            sim.sync()
            if sensor == "lidar":
                return tuple(self.device.scan().tolist())
            if sensor in ("rgb", "depth"):
                frame = sim.frame(self.device, v["width"], v["height"])
                data = frame.rgb if sensor == "rgb" else np.round(frame.depth * 1000.0)
                return tuple(data.ravel().tolist())
            if sensor == "imu":
                return self.device.read()  # type: ignore[no-any-return]
            if sensor == "contact":
                return 1.0 if self.device.pressed() else 0.0
            if sensor == "altimeter":
                value = robot.link_pose(self.device)[0][2]
            elif self.channel.direction == "in" and v["joints"]:
                return tuple(self._noisy(self._joint_value(robot, j)) for j in self.device)
            else:
                value = self._joint_value(robot, self.device[0])
            return self._noisy(value)

    def _noisy(self, value: float) -> float:
        noise = self.values["noise"]
        return float(value + self._rng.normal(0.0, noise)) if noise > 0.0 else float(value)

    def write(self, value: Value) -> None:
        sim, robot = self._require()
        if self.channel.direction != "out":
            raise RuntimeError(f"{self.owner} is an input channel")
        raw = float(value[0] if isinstance(value, tuple) else value)
        self.last = raw
        v = self.values
        with sim.lock:
            sim.sync()
            for joint in self.device:
                if self.channel.kind == "pwm":
                    limit = robot.max_effort(joint)
                    target = raw * (v["maxVelocity"] if v["mode"] == "velocity" else limit)
                    robot.command(joint, "velocity" if v["mode"] == "velocity" else "effort", target)
                else:
                    robot.command(joint, v["mode"], (raw - v["offset"]) * v["scale"])

    def stop(self) -> None:
        self.sim, self.device = None, None
