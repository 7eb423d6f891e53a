"""The devices behind ``hardware.sim`` channels (thesis §3.1.5.1 HWChannel, issue J), one code path for
both places a channel can be served from (decision D100):

- in-process: the channel's own :class:`SimWorld` (one per plant scope, D88);
- in the world server (:mod:`plugins.sim.server`): one :class:`SimWorld` for every process of a run.

A :class:`Spec` is what a device needs of its HWChannel record (kind, direction, size, max and the
read Params, paths resolved), JSON-able so a client can send it to the server. A
:class:`ChannelDevice` reads or writes one device; the caller holds the world's lock and has synced
it (``sim.sync()``) first. Large reads (lidar ranges, images) come back as numpy arrays: the backend
flattens them into the channel's flat array (:func:`to_value`), after the server has shipped them whole.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import pybullet as p

from ckmconf.model import Environment
from plugins.hardware.simulation import Clock, SimulationHook
from plugins.processing.textures import read_model

from .device_table import find, unserved
from .flight import Airframe, Multirotor
from .grasp import ChannelGrasp
from .robots import Robot
from .sensors import Bumper, Camera, Frame, GroundSensor, Imu, Lidar
from .world import World

Sample = float | tuple[float, ...] | np.ndarray
"""What a device read gives: a number, a tuple (joints, IMU) or an array (lidar, images)."""
KINDS = ("analog", "digital", "pwm", "counter", "bus", "stream")


@dataclass(frozen=True)
class Spec:
    """What a device needs of its HWChannel: the record's kind, direction, size and max, and its
    Params as ``hardware.sim`` read them (``model`` resolved to an absolute path)."""

    name: str
    kind: str
    direction: str
    size: int
    max: float | None
    values: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The spec as plain data (what a client sends the world server)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Any) -> Spec:
        """A spec from a client's request; ValueError naming what is wrong."""
        if not isinstance(data, dict):
            raise ValueError("the channel spec is not an object")
        name = data.get("name")
        if not isinstance(name, str) or not name:
            raise ValueError("the channel spec has no 'name'")
        kind, direction, size, top = data.get("kind"), data.get("direction"), data.get("size"), data.get("max")
        values = data.get("values")
        if kind not in KINDS or direction not in ("in", "out"):
            raise ValueError(f"sim channel {name!r}: kind {kind!r} / direction {direction!r} are not a HWChannel's")
        if not isinstance(size, int) or size < 1 or not (top is None or isinstance(top, int | float)):
            raise ValueError(f"sim channel {name!r}: size {size!r} / max {top!r} are not a HWChannel's")
        if not isinstance(values, dict) or not isinstance(values.get("body"), str) or not values["body"]:
            raise ValueError(f"sim channel {name!r}: the spec's values name no 'body'")
        return cls(name, kind, direction, size, None if top is None else float(top), values)


class SimWorld(SimulationHook):
    """The pybullet world shared by sim channels (of a scope in-process, of a run in the server),
    built from the ``<Environment>`` of ``source`` (a configuration file)."""

    def __init__(self, clock: Clock, environment: Environment | None, seed: int, textures: str, source: str) -> None:
        super().__init__(clock)
        self.source = source
        self.world = World(environment, seed=seed, catalog=read_model(textures) if textures else None)
        self.environment = environment
        self.robots: dict[str, Robot] = {}
        self.flyers: dict[str, Multirotor] = {}
        """Each multirotor robot's rotors and flight controller, by robot name (one per robot: a second
        channel of the same airframe flies the same one, D293)."""
        self.origin = 0.0
        self._frames: dict[tuple[int, int, float, int, int], tuple[int, Frame]] = {}

    def frame(self, camera: Camera, width: int, height: int) -> Frame:
        """A render of ``camera`` at this world step: the RGB and the depth channels of one camera
        (same viewpoint, field of view and size) read at the same step share one render (D89, D240)."""
        key = (camera.robot.body, camera.view, camera.fov, width, height)
        cached = self._frames.get(key)
        if cached is not None and cached[0] == self.world.steps:
            return cached[1]
        frame = camera.render(width, height)
        self._frames[key] = (self.world.steps, frame)
        return frame

    def kept_frame(self, key: tuple[int, int, float, int, int]) -> Frame | None:
        """The frame of ``key`` rendered at this world step, if one was (None otherwise)."""
        cached = self._frames.get(key)
        return cached[1] if cached is not None and cached[0] == self.world.steps else None

    def keep_frame(self, key: tuple[int, int, float, int, int], step: int, frame: Frame) -> None:
        """Remember a frame rendered elsewhere (the server's render worker) for ``step`` (not over a newer one)."""
        kept = self._frames.get(key)
        if kept is None or kept[0] <= step:
            self._frames[key] = (step, frame)

    def robot(self, name: str, model: str, pose: str) -> Robot:
        """The robot ``name``, loaded on first use (at ``pose`` "x y yaw", else beside the map's centre)."""
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
        """Start the world's clock at ``now`` (the scope's time)."""
        self.origin = now

    def advance(self, start: float, end: float) -> None:
        """Step the physics from ``start`` to ``end`` (simulated seconds)."""
        self.world.run_until(end - self.origin)

    def __del__(self) -> None:
        self.world.close()


class ChannelDevice:
    """One channel's device in ``sim``: a row of :data:`plugins.sim.device_table.DEVICES` (what each
    kind × direction × device reads or writes); a combination no row names is refused."""

    def __init__(self, sim: SimWorld, spec: Spec) -> None:
        self.sim, self.spec = sim, spec
        v = spec.values
        self.robot = sim.robot(v["body"], v.get("model", ""), v.get("pose", ""))
        self.device: Any = self._make()
        self._rng = np.random.default_rng(v.get("seed", 0))
        self.grasp: ChannelGrasp | None = None
        if v.get("grasp"):  # a gripper channel: its fingers hold what they close on (D187)
            self.grasp = ChannelGrasp(self.robot, v["joint"], v["mirror"], v["grasp"], v["holdForce"])
        if spec.direction == "out" and isinstance(v.get("initial"), int | float):
            self.place(float(v["initial"]))

    def place(self, raw: float) -> None:
        """Stand the channel's joint(s) at ``raw`` at once and hold them there (a servo's power-on
        position): no physics in between, so the robot starts in that posture."""
        v = self.spec.values
        angle = (raw - v["offset"]) * v["scale"]
        for joint in self.device:
            p.resetJointState(self.robot.body, joint, angle, physicsClientId=self.sim.world.client)
            self.robot.command(joint, "position", angle)

    def _make(self) -> Any:
        v, sensor, robot = self.spec.values, self.spec.values.get("sensor", ""), self.robot
        chosen = sensor or v.get("joint") or v.get("joints") or v.get("actuator")
        if chosen and find(self.spec.kind, self.spec.direction, v) is None:
            raise ValueError(f"sim channel {self.spec.name!r}: {unserved(self.spec.kind, self.spec.direction, v)}")
        if sensor in ("lidar", "rgb", "depth") and v.get("fov") is None:  # the backend refuses it first (D284)
            raise ValueError(f"sim channel {self.spec.name!r}: a {sensor} channel needs its field of view, Param 'fov'")
        if sensor == "lidar":
            if self.spec.max is None:
                raise ValueError(f"sim channel {self.spec.name!r}: a lidar needs its range (the HWChannel's max)")
            return Lidar(
                robot,
                v["link"],
                beams=self.spec.size,
                fov=v["fov"],
                range_min=v["rangeMin"],
                range_max=self.spec.max,
                noise=v["noise"],
                seed=v["seed"],
            )
        if sensor in ("rgb", "depth"):
            return Camera(robot, v["link"], fov=v["fov"])
        if sensor == "imu":
            return Imu(robot, v["link"], noise=v["noise"], seed=v["seed"])
        if sensor == "contact":
            return Bumper(robot, v["link"], self.sim.world.floor, arc=v["arc"])
        if sensor in ("altimeter", "pose"):
            return robot.link(v["link"])
        if sensor in ("flow", "position", "compass"):
            return GroundSensor(robot, v["link"], noise=v["noise"], seed=v["seed"])
        if v.get("actuator") == "multirotor":
            return self._flyer()
        if v.get("joints"):
            return [robot.joint(name) for name in v["joints"].split()]
        if not v.get("joint"):
            raise ValueError(f"sim channel {self.spec.name!r}: no 'sensor' nor 'joint'/'joints' chooses the device")
        return [robot.joint(v["joint"])] + ([robot.joint(v["mirror"])] if v.get("mirror") else [])

    def _flyer(self) -> Multirotor:
        """The robot's multirotor: the one already flying it if it has the same airframe, else a new one."""
        owner = f"sim channel {self.spec.name!r}"
        frame = Airframe.from_values(self.spec.values, owner)
        flying = self.sim.flyers.get(self.robot.name)
        if flying is None:
            flying = self.sim.flyers[self.robot.name] = Multirotor(self.robot, frame, owner)
        elif flying.frame != frame:  # one robot, one set of rotors: its axis channels say the same
            raise ValueError(f"{owner}: robot {self.robot.name!r} is flown by {flying.owner} with another "
                             f"airframe ({flying.frame}); give every channel of it the same rotor Params")
        return flying

    def _joint_value(self, joint: int) -> float:
        v = self.spec.values
        position, velocity, effort = self.robot.joint_state(joint)
        if self.spec.kind == "counter":
            return float(velocity * v["ticksPerRev"] / (2 * math.pi))
        value = {"position": position, "velocity": velocity, "effort": effort}[v["mode"]]
        return float(value / v["scale"] + v["offset"])

    def _noisy(self, value: float) -> float:
        noise = self.spec.values["noise"]
        return float(value + self._rng.normal(0.0, noise)) if noise > 0.0 else float(value)

    def read(self) -> Sample:
        """The device's value now (the world's lock held, the world synced)."""
        v, sensor = self.spec.values, self.spec.values.get("sensor", "")
        if self.spec.direction == "out":
            raise ValueError(f"sim channel {self.spec.name!r} is an output: it reads back what was written")
        if sensor == "lidar":
            return self.device.scan()  # type: ignore[no-any-return]
        if sensor in ("rgb", "depth"):
            return self.from_frame(self.sim.frame(self.device, v["width"], v["height"]))
        if sensor == "imu":
            return self.device.read()  # type: ignore[no-any-return]
        if sensor == "contact":
            return 1.0 if self.device.pressed() else 0.0
        if sensor == "altimeter":
            return self._noisy(self.robot.link_pose(self.device)[0][2])
        if sensor == "pose":  # ground truth: never noisy
            return self.robot.planar_pose(self.device)
        if sensor in ("flow", "position", "compass"):
            return getattr(self.device, sensor)()  # type: ignore[no-any-return]
        if v.get("joints"):
            return tuple(self._noisy(self._joint_value(j)) for j in self.device)
        return self._noisy(self._joint_value(self.device[0]))

    @property
    def camera(self) -> tuple[int, int, float, int, int] | None:
        """The render this camera channel reads (the key of :meth:`SimWorld.frame`); None if no camera."""
        if self.spec.values.get("sensor") not in ("rgb", "depth"):
            return None
        v = self.spec.values
        return (self.device.robot.body, self.device.view, self.device.fov, v["width"], v["height"])

    def from_frame(self, frame: Frame) -> np.ndarray:
        """A camera channel's read of ``frame``: its colour, or its depth in mm."""
        return frame.rgb if self.spec.values.get("sensor") == "rgb" else np.round(frame.depth * 1000.0)

    def write(self, raw: float | Sequence[float]) -> None:
        """Drive the joint(s) to ``raw``, or fly a multirotor's set-point (the world's lock held, the
        world synced); ValueError naming the channel for a value its device refuses."""
        v = self.spec.values
        if self.spec.direction != "out":
            raise ValueError(f"sim channel {self.spec.name!r} is an input channel")
        if isinstance(self.device, Multirotor):
            owner = f"sim channel {self.spec.name!r}"
            if v.get("axis") and isinstance(raw, int | float):  # one value of the set-point (an Actuator's)
                self.device.command_axis(v["axis"], float(raw), owner)
            else:
                self.device.command([raw] if isinstance(raw, int | float) else list(raw), owner)
            return
        if not isinstance(raw, int | float):
            raise ValueError(f"sim channel {self.spec.name!r} takes one value, got {len(raw)}")
        for joint in self.device:
            if self.spec.kind == "pwm":
                velocity = v["mode"] == "velocity"
                target = raw * (v["maxVelocity"] if velocity else self.robot.max_effort(joint))
                self.robot.command(joint, "velocity" if velocity else "effort", target)
            else:
                self.robot.command(joint, v["mode"], (raw - v["offset"]) * v["scale"])
        if self.grasp is not None:
            self.grasp.command((raw - v["offset"]) * v["scale"])


def to_value(sample: Sample) -> float | tuple[float, ...] | np.ndarray:
    """A device read as the channel's value: arrays flattened row-major, kept arrays (D243)."""
    if isinstance(sample, np.ndarray):
        return sample.ravel()
    return sample
