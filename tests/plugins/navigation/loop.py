"""The closed-loop test bench: the real pybullet world and the three mobile services at their rates.

The bench, not the services, touches the simulator, as the kobuki light node and the lidar sensor
do in the use case (configs/usecase/nodes.xml):

- every 0.02 s the wheel rim speeds (the left one ``odom_bias`` too large: a wheel-radius error,
  so odometry drifts) feed the real ``diff-drive-odometry`` controller, whose Odometry goes on
  ``/kobuki/wheel_odom``; the newest ``/kobuki/cmd_vel`` (zero once older than 0.3 s, the
  kobuki's ``cmd_stale``) drives the wheels;
- every 0.1 s the Hokuyo's sweep goes on ``hokuyo_raw`` shaped as the lidar sensor publishes it
  (runtime/kernel/vectors.py on the LaserScan type of configs/usecase/network.xml);
- each service runs at its rate with the newest value of each input, only when one is fresh (the
  Smart Resource stream's acquisition), and every message crosses the codec, as on the network.

Time is simulated: the physics is stepped (5 ms), nothing sleeps.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from ckm_lab.devices import HOKUYO

import ckmconf
from ckmconf.model import Environment, MessageType, Param
from ckmconf.model.kernel import HWChannel, Sensor
from ckmconf.model.resources import Plugin
from plugins.controllers.odometry import DiffDriveOdometry
from plugins.navigation.amcl import AmclNavigation
from plugins.navigation.displacement import BaseDisplacement
from plugins.navigation.laser_scan import LaserScanService
from plugins.sim.robots import DiffDriveBase, Robot
from plugins.sim.sensors import Lidar
from plugins.sim.world import World
from runtime.kernel.vectors import shaper
from runtime.resources import codec
from runtime.resources.spt import Context, ProcessingPlugin
from tests.plugins.controllers.vector_records import record

ROOT = Path(__file__).resolve().parents[3]
STEP = 0.005
WHEEL_RADIUS = 0.035

REGIONS = {  # name: (element, xmin, ymin, xmax, ymax)
    "Start": ("Area", 0.6, 1.4, 1.4, 2.2),
    "Target": ("Area", 3.6, 1.4, 4.4, 2.2),
    "Walled": ("Area", 2.35, 1.9, 2.65, 2.1),
    "Pillar": ("AvoidedArea", 2.3, 1.1, 2.7, 2.9),
    "Crate": ("AvoidedArea", 0.0, 0.0, 0.6, 0.5),
    "Cabinet": ("AvoidedArea", 4.2, 3.4, 5.0, 4.0),
}
"""A 5 × 4 m room: the Target area lies 3 m east of Start behind a 1.8 m pillar (the way round
its south end is the shorter); two corner blocks break the room's symmetry. ``Walled`` lies
inside the pillar (an unreachable goal)."""


def _region(name: str, tag: str, x0: float, y0: float, x1: float, y1: float) -> str:
    corners = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    vertices = "".join(f'<Vertex x="{x:g}" y="{y:g}"/>' for x, y in corners)
    return f'    <{tag} name="{name}">{vertices}</{tag}>'


ROOM = "\n".join([
    '<?xml version="1.0" encoding="UTF-8"?>',
    '<Part xmlns="urn:ckm:1" version="1.0" description="navigation test room">',
    '  <Environment name="nav-room" frame="map">',
    '    <Map xmin="0" ymin="0" xmax="5" ymax="4" height="1.5"/>',
    *(_region(name, *spec) for name, spec in REGIONS.items()),
    "  </Environment>",
    "</Part>",
])


def room(directory: Path) -> Path:
    """The room's Environment file in ``directory``."""
    path = directory / "room.xml"
    path.write_text(ROOM)
    return path


LIDAR = Sensor(name="lidar", channel="hokuyo", topic="hokuyo_raw", period=0.1)
"""nodes.xml's lidar sensor, whose reads the shaper turns into a LaserScan."""


def _no_ros() -> Any:
    raise AssertionError("the use case's LaserScan is a CKM type: no ROS type store is needed")


@cache
def _laser_types() -> dict[str, MessageType]:
    system = ckmconf.load(ROOT / "configs" / "usecase" / "network.xml")
    return {m.name: m for m in system.message_types}


TURTLEBOT = {"robotRadius": 0.18, "robotHeight": 0.45, "laserPose": "0.10 0 0", "laserHeight": 0.14}
"""The Turtlebot's footprint and laser mount, as configs/usecase/resources.xml gives them to the navigation."""


@dataclass(frozen=True)
class RobotModel:
    """A differential-drive model of plugins/sim/models/: its wheels, laser link and navigation Params."""

    urdf: str
    left: str
    right: str
    wheel_radius: float
    wheel_base: float
    laser_link: str
    footprint: Mapping[str, object]
    laser: Mapping[str, Any]
    """The scanner's data sheet, as plugins.sim.sensors.Lidar takes it."""


TURTLEBOT_MODEL = RobotModel("turtlebot", "wheel_left_joint", "wheel_right_joint", WHEEL_RADIUS, 0.230,
                             "hokuyo_link", TURTLEBOT, HOKUYO)
ROVER_MODEL = RobotModel("rover", "left_wheel_joint", "right_wheel_joint", 0.08, 0.40, "laser_link",
                         {"robotRadius": 0.35, "robotHeight": 0.5, "laserPose": "0.25 0 0", "laserHeight": 0.25},
                         {"beams": 541, "fov": 4.7124, "range_min": 0.05, "range_max": 8.0})
"""rover.urdf: a wider base (0.6 × 0.45 m, half diagonal 0.37), larger wheels, its laser 0.25 m ahead: a
270° scanner of 541 beams reaching 8 m (not the Turtlebot's Hokuyo)."""


def plugin(kind: str, cls: type[ProcessingPlugin], file: Path | None = None, /, **params: object) -> Any:
    """A service plugin built from a ``<Plugin>`` record (declared in ``file``, for relative Params)."""
    loc = None if file is None else ckmconf.Loc(str(file), 1, 1, "/Plugin")
    return cls(Plugin(name=kind, kind=kind, params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
                      loc=loc))


@dataclass
class Service:
    """One service of the bench: its plugin, its Inputs and Outputs (name → topic) and its period."""

    plugin: ProcessingPlugin
    inputs: dict[str, str]
    outputs: dict[str, str]
    period: float
    due: float = 0.0
    taken: dict[str, int] = field(default_factory=dict)
    frames: int = 0
    cpu: list[float] = field(default_factory=list)


class Bench:
    """The world, the robot, its odometry and lidar, and the services (see the module docstring)."""

    def __init__(
        self, environment: Path, start: tuple[float, float, float], *, nav: Mapping[str, object] | None = None,
        seed: int = 0, odom_bias: float = 0.01, lidar_noise: float = 0.01, speed: float = 0.3,
        model: RobotModel = TURTLEBOT_MODEL,
    ) -> None:
        env: Environment | None = ckmconf.load(environment).environment
        assert env is not None
        self.model = model
        self.world = World(env, seed=seed, time_step=STEP)
        self.robot = Robot(self.world, model.urdf, self.world.load_robot(model.urdf, model.urdf, start))
        self.world.step(24)
        self.base = DiffDriveBase(self.robot, left=model.left, right=model.right, wheel_radius=model.wheel_radius,
                                  wheel_base=model.wheel_base)
        self.lidar = Lidar(self.robot, model.laser_link, **model.laser, noise=lidar_noise, seed=seed)
        channel = HWChannel(name="hokuyo", direction="in", kind="stream", backend="sim", units="m", min=0.0,
                            max=self.lidar.range_max, size=self.lidar.beams)
        self.shape = shaper(LIDAR, "LaserScan", channel, _laser_types(), _no_ros)
        inputs = [("left_speed", "measure"), ("right_speed", "measure")]
        self.odometer = DiffDriveOdometry(record("diff-drive-odometry", 0.02, inputs, ["/kobuki/wheel_odom"],
                                                 wheelBase=model.wheel_base))
        self.odom_bias = odom_bias
        self.topics: dict[str, tuple[int, float, Any]] = {}
        self.seq = 0
        self.services: dict[str, Service] = {
            "scan": Service(plugin("laser-scan", LaserScanService, fov=self.lidar.fov, rangeMin=self.lidar.range_min,
                                   rangeMax=self.lidar.range_max), {"raw": "hokuyo_raw"}, {"scan": "/scan"}, 0.1),
            "base": Service(
                plugin("base-displacement", BaseDisplacement, speed=speed),
                {"path": "/base/path", "move_goal": "/base/move_goal", "wheel_odom": "/kobuki/wheel_odom"},
                {"odom": "/base/odom", "move_status": "/base/move_status", "wheel_cmd": "/kobuki/cmd_vel"},
                0.05,
            ),
        }
        if nav is not None:
            params = {"environment": environment.name, **model.footprint, **nav}
            navigation = plugin("amcl-navigation", AmclNavigation, environment, **params)
            navigation.setup()
            self.services["nav"] = Service(
                navigation, {"scan": "/scan", "odom": "/base/odom"},
                {"pose": "/nav/pose", "status": "/nav/status", "path": "/base/path"}, 0.8,
            )
        self.estimates: list[tuple[float, float]] = []
        """(time, localization error in metres) at each Navigation frame."""

    @property
    def now(self) -> float:
        return self.world.time

    def publish(self, topic: str, value: Any) -> None:
        """A message on ``topic``, through the codec as over the network."""
        self.seq += 1
        self.topics[topic] = (self.seq, self.now, codec.decode(codec.encode(value)))

    def latest(self, topic: str) -> Any:
        sample = self.topics.get(topic)
        return None if sample is None else sample[2]

    def truth(self) -> tuple[float, float, float]:
        return self.robot.planar_pose()

    def _wheels(self) -> None:
        radius = self.model.wheel_radius
        left = self.robot.joint_state(self.base.left)[1] * radius * (1.0 + self.odom_bias)
        right = self.robot.joint_state(self.base.right)[1] * radius
        (message,) = self.odometer.step_outputs({"measure[0]": left, "measure[1]": right}, 0.02)
        self.publish("/kobuki/wheel_odom", message)
        command = self.topics.get("/kobuki/cmd_vel")
        if command is None or self.now - command[1] > 0.3:
            self.base.drive(0.0, 0.0)
        else:
            self.base.drive(float(command[2]["linear"]), float(command[2]["angular"]))

    def _run(self, name: str, service: Service) -> None:
        samples = {n: self.topics.get(t) for n, t in service.inputs.items()}
        fresh = {n: s[0] for n, s in samples.items() if s is not None}
        if not fresh or fresh == service.taken:
            return
        service.taken = fresh
        values = {n: None if s is None else s[2] for n, s in samples.items()}
        data = next(iter(values.values())) if len(values) == 1 else values
        began = time.process_time()
        result = service.plugin.process(data, Context(service.frames, self.now, name))
        service.cpu.append(time.process_time() - began)
        service.frames += 1
        if len(service.outputs) == 1:
            self.publish(next(iter(service.outputs.values())), result)
        else:
            for key, topic in service.outputs.items():
                if key in result:
                    self.publish(topic, result[key])
        if name == "nav" and "pose" in result:
            pose = result["pose"]["pose"]
            x, y, _ = self.truth()
            self.estimates.append((self.now, math.hypot(pose["x"] - x, pose["y"] - y)))

    def step(self) -> None:
        """One physics step, then whatever is due: wheels and odometry, lidar, services."""
        self.world.step()
        ticks = round(self.now / STEP)
        if ticks % 4 == 0:
            self._wheels()
        if ticks % 20 == 0:
            self.publish("hokuyo_raw", self.shape(self.lidar.scan(), self.now))
        for name, service in self.services.items():
            if self.now + 1e-9 >= service.due:
                service.due += service.period
                self._run(name, service)

    def run(self, until: Callable[[], bool], timeout: float) -> bool:
        """Step until ``until()`` holds (True) or ``timeout`` simulated seconds have passed (False)."""
        end = self.now + timeout
        while self.now < end:
            self.step()
            if until():
                return True
        return False

    def close(self) -> None:
        for service in self.services.values():
            service.plugin.stop()
        self.world.close()
