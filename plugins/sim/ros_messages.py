"""The simulation's sensors as ROS 2 messages: SPT plugins of a Smart Resource (issue L point 1, §4.4.1).

A ``hardware.sim`` channel's sensor publishes its read whole, shaped for its topic (a raw message
of a MessageType with a ``stamp`` and a vector field, runtime/kernel/vectors.py, D99). These plugins
make of that raw message the ROS 2 message a Gazebo sensor plugin or a ROS driver would publish, as
a Smart Resource service (the thesis' Laser Sensor ``Scan`` service is one: urg_node's place):

- ``ros-laser-scan``: a lidar channel's ranges → ``sensor_msgs/msg/LaserScan``;
- ``ros-camera``: an ``rgb`` (rgb8) or ``depth`` (mm: 16UC1) channel's frame → output ``image``
  (``sensor_msgs/msg/Image``) and output ``info`` (``sensor_msgs/msg/CameraInfo``);
- ``ros-joint-state``: a ``joints`` bus channel's positions (raw units) → ``sensor_msgs/msg/JointState``;
- ``ros-odometry``: an ``Odometry`` of ``diff-drive-odometry`` (stamp, pose, twist, dispersion) →
  ``nav_msgs/msg/Odometry``;
- ``ros-tf``: the ``joints`` (JointState) and/or ``odom`` (Odometry) above → ``tf2_msgs/msg/TFMessage``.

Everything but the data comes from where the simulation takes it, so it cannot disagree with it:
Param ``channel`` names the ``hardware.sim`` HWChannel (looked up in the plugin's configuration
file), whose ``link`` is the ``header.frame_id`` and must be a link of the robot's URDF (its
``body`` or ``model``), whose ``fov``/``size``/``rangeMin``/``max`` give the scan's geometry,
``fov``/``width``/``height`` the camera's intrinsics (:func:`plugins.sim.sensors.pinhole`, the
projection the render uses), ``joints``/``scale``/``offset`` the joint names and radians. The values
are read through ``hardware.sim``'s own Param table and checks (:class:`plugins.hardware.sim.SimBackend`,
D284): its defaults are the only ones, and a camera or lidar without its ``fov`` (a lidar without
its ``max``) is refused as the backend refuses it, never given the lab's sensor's. ``ros-tf``
is ``robot_state_publisher`` on the URDF of Param ``body`` plus the ``odom`` → root link transform.
``header.stamp`` is the raw message's ``stamp``: the sensor's read, on the run's clock (simulated
time under ``--time-scale``). Results are dicts of the ROS fields (Time as float seconds), which the
recorder and the rmw_zenoh bridge encode as CDR (runtime.ros.convert).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ckmconf.loader import load
from ckmconf.model import HWChannel, System
from ckmconf.model.resources import Plugin
from plugins.hardware.sim import SimBackend
from runtime.kernel.interfaces import ParamError, read_params
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .sensors import pinhole
from .urdf import MOVING, Kinematics, quaternion_from_rpy

LASER_SCAN, IMAGE, CAMERA_INFO = "sensor_msgs/msg/LaserScan", "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo"
JOINT_STATE, ODOMETRY, TF = "sensor_msgs/msg/JointState", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"
_CHANNEL = P("channel", REQUIRED, "The hardware.sim HWChannel whose reads this plugin receives.", type=str)


@lru_cache(maxsize=8)
def _system(path: str, mtime: float) -> System:
    return load(path)


def sim_channel(record: Plugin, name: str, owner: str, param: str = "channel") -> HWChannel:
    """The ``hardware.sim`` HWChannel ``name`` (the value of the plugin's Param ``param``) of the
    configuration file ``record`` was read from."""
    file = record.loc.file if record.loc is not None else ""
    if not file or not Path(file).is_file():
        raise ParamError(f"{owner}: Param {param!r} needs the plugin's configuration file, and it has none")
    system = _system(str(Path(file).resolve()), Path(file).stat().st_mtime)
    found = [c for n in system.nodes for c in n.channels if c.name == name]
    if len(found) != 1:
        what = "no" if not found else f"{len(found)}"
        raise ParamError(f"{owner}: Param {param!r} = {name!r}: {what} HWChannel of that name in {file}")
    if found[0].backend != "sim":
        raise ParamError(f"{owner}: HWChannel {name!r} has backend {found[0].backend!r}, not 'sim'")
    return found[0]


def raw_read(data: Any, context: Context, owner: str) -> tuple[float, np.ndarray]:
    """(stamp, values) of a raw sensor message: its ``stamp`` field (else the frame's) and its vector
    field (the first array, list or bytes field), or a bare array with the frame's stamp."""
    if isinstance(data, Mapping):
        stamp = data.get("stamp")
        stamp = float(stamp) if isinstance(stamp, int | float) and not isinstance(stamp, bool) else context.stamp
        for value in data.values():
            if isinstance(value, bytes | bytearray):
                return stamp, np.frombuffer(bytes(value), dtype=np.uint8)
            if isinstance(value, np.ndarray | list | tuple):
                return stamp, np.asarray(value)
        raise ValueError(f"{owner}: the raw message has no vector field (fields: {', '.join(map(str, data))})")
    if isinstance(data, np.ndarray | list | tuple):
        return context.stamp, np.asarray(data)
    raise ValueError(f"{owner}: expected a raw sensor message (a dict with a vector field), got {type(data).__name__}")


def header(stamp: float, frame: str) -> dict[str, Any]:
    """A ``std_msgs/msg/Header``: the stamp in seconds, the frame id."""
    return {"stamp": stamp, "frame_id": frame}


class _SimPlugin(ProcessingPlugin):
    """A plugin reading one ``hardware.sim`` channel's raw messages (Param ``channel``)."""

    SENSORS: ClassVar[tuple[str, ...]] = ()

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.channel = sim_channel(record, self.params["channel"], self.owner)
        # The channel's values as hardware.sim reads them, defaults and checks included: the backend's
        # Param table is the one place they live (D284), so a message cannot disagree with the device.
        owner = f"{self.owner}: HWChannel {self.channel.name!r}"
        self.values = read_params(self.channel.params, SimBackend.PARAMS, owner=owner)
        problems = SimBackend.problems(self.channel)
        if problems:
            raise ParamError(f"{owner}: {problems[0][1]}")
        sensor = self.values["sensor"]
        if self.SENSORS and sensor not in self.SENSORS:
            raise ParamError(
                f"{self.owner}: HWChannel {self.channel.name!r} is a {sensor or 'joint'} channel, "
                f"not {' or '.join(self.SENSORS)}"
            )
        try:
            self.model = Kinematics.of_body(self.values["body"], self._model_path())
            self.frame = self.model.link(self.values["link"], self.owner)
        except ValueError as error:
            raise ParamError(str(error)) from None

    def _model_path(self) -> str:
        model: str = self.values["model"]
        if not model or self.channel.loc is None:
            return model
        return str((Path(self.channel.loc.file).parent / model).resolve())


class RosLaserScan(_SimPlugin):
    """``plugin.ros-laser-scan``: a simulated lidar's sweep as a ``sensor_msgs/msg/LaserScan``."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        _CHANNEL, P("scanTime", 0.1, "Time between two sweeps (the sensor's period).", unit="s", above=0.0)
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": LASER_SCAN})
    SENSORS = ("lidar",)

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        fov, beams = float(self.values["fov"]), self.channel.size  # required of a lidar (SimBackend.problems)
        self.geometry = {
            "angle_min": -fov / 2,
            "angle_max": fov / 2,
            "angle_increment": fov / (beams - 1) if beams > 1 else 0.0,  # beams span -fov/2..fov/2 (Lidar)
            "time_increment": 0.0,  # a simulated sweep is taken at one instant
            "scan_time": self.params["scanTime"],
            "range_min": float(self.values["rangeMin"]),
            "range_max": float(self.channel.max or 0.0),  # required of a lidar (SimBackend.problems)
        }

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The LaserScan of one raw sweep."""
        stamp, ranges = raw_read(data, context, self.owner)
        if ranges.size != self.channel.size:
            raise ValueError(f"{self.owner}: {ranges.size} ranges, the channel reads {self.channel.size}")
        return {"header": header(stamp, self.frame), **self.geometry, "ranges": ranges.astype(np.float32)}


class RosCamera(_SimPlugin):
    """``plugin.ros-camera``: a simulated camera's frame as ``sensor_msgs/msg/Image`` and its
    ``sensor_msgs/msg/CameraInfo`` (outputs ``image`` and ``info``)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(_CHANNEL)
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING, "image": IMAGE, "info": CAMERA_INFO})
    SENSORS = ("rgb", "depth")

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.width, self.height = int(self.values["width"]), int(self.values["height"])
        self.depth = self.values["sensor"] == "depth"
        fx, fy, cx, cy = pinhole(self.width, self.height, float(self.values["fov"]))  # required of a camera
        self.info = {
            "height": self.height,
            "width": self.width,
            "distortion_model": "plumb_bob",
            "d": np.zeros(5),  # a simulated pinhole has no distortion
            "k": np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
            "r": np.eye(3).ravel(),
            "p": np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
        }

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The Image (rgb8, or 16UC1 depth in mm as REP 118 allows) and CameraInfo of one frame."""
        stamp, values = raw_read(data, context, self.owner)
        channels = 1 if self.depth else 3
        if values.size != self.width * self.height * channels:
            raise ValueError(f"{self.owner}: {values.size} values are not a {self.width}×{self.height} frame")
        dtype = np.uint16 if self.depth else np.uint8
        shape = (self.height, self.width) if self.depth else (self.height, self.width, 3)
        pixels = np.clip(values, 0, np.iinfo(dtype).max).astype(dtype).reshape(shape)
        head = header(stamp, self.frame)
        encoding = "16UC1" if self.depth else "rgb8"
        return {"image": {"header": head, "encoding": encoding, "data": pixels}, "info": {"header": head, **self.info}}


class RosJointState(_SimPlugin):
    """``plugin.ros-joint-state``: a simulated ``joints`` bus channel as a ``sensor_msgs/msg/JointState``
    (raw values back to rad or m: (raw − offset) × scale, the inverse of ``hardware.sim``'s read)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(_CHANNEL)
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": JOINT_STATE})

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.names = str(self.values["joints"]).split()
        if not self.names:
            raise ParamError(f"{self.owner}: HWChannel {self.channel.name!r} reads no 'joints'")
        unknown = [n for n in self.names if n not in self.model.joints]
        if unknown:
            raise ParamError(f"{self.owner}: the model {self.model.path.name} has no joint {', '.join(unknown)}")
        self.scale, self.offset = float(self.values["scale"]), float(self.values["offset"])
        self.mode: str = self.values["mode"]

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The JointState of one raw read; the channel's ``mode`` says which field it fills."""
        stamp, raw = raw_read(data, context, self.owner)
        if raw.size != len(self.names):
            raise ValueError(f"{self.owner}: {raw.size} values for {len(self.names)} joints")
        values = (raw.astype(np.float64) - self.offset) * self.scale
        return {"header": header(stamp, ""), "name": list(self.names), self.mode: values}


class RosOdometry(ProcessingPlugin):
    """``plugin.ros-odometry``: a ``diff-drive-odometry`` estimate as a ``nav_msgs/msg/Odometry`` from
    ``frame`` (``odom``) to the root link of the URDF of ``body``; the position's variance on x and
    y is half the dispersion's square (dispersion = √(σx² + σy²), D92)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("body", REQUIRED, "The robot (its model plugins/sim/models/<body>.urdf).", type=str),
        P("frame", "odom", "The odometry frame (header.frame_id)."),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": ODOMETRY})

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        try:
            self.child = Kinematics.of_body(self.params["body"]).root
        except ValueError as error:
            raise ParamError(f"{self.owner}: {error}") from None

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The Odometry of one estimate (``stamp``, ``pose`` {x, y, yaw}, ``twist`` {linear, angular})."""
        if not isinstance(data, Mapping) or not isinstance(data.get("pose"), Mapping):
            raise ValueError(f"{self.owner}: expected an Odometry message with a 'pose', got {type(data).__name__}")
        pose, twist = data["pose"], data.get("twist") or {}
        stamp = data.get("stamp")
        variance = float(data.get("dispersion") or 0.0) ** 2 / 2
        x, y, z, w = quaternion_from_rpy(0.0, 0.0, float(pose.get("yaw", 0.0)))
        covariance = np.zeros(36)
        covariance[0] = covariance[7] = variance
        return {
            "header": header(float(stamp) if isinstance(stamp, int | float) else context.stamp, self.params["frame"]),
            "child_frame_id": self.child,
            "pose": {
                "pose": {
                    "position": {"x": float(pose["x"]), "y": float(pose["y"])},
                    "orientation": {"x": x, "y": y, "z": z, "w": w},
                },
                "covariance": covariance,
            },
            "twist": {
                "twist": {
                    "linear": {"x": float(twist.get("linear", 0.0))},
                    "angular": {"z": float(twist.get("angular", 0.0))},
                }
            },
        }


class RosTf(ProcessingPlugin):
    """``plugin.ros-tf``: ``tf2_msgs/msg/TFMessage`` of the robot ``body``: every joint's parent → child
    transform at its position in the ``joints`` input (fixed joints always; a moving joint once
    measured), as ``robot_state_publisher`` gives, and the ``odom`` input's frame → root link."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("body", REQUIRED, "The robot (its model plugins/sim/models/<body>.urdf).", type=str),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": TF})

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        try:
            self.model = Kinematics.of_body(self.params["body"])
        except ValueError as error:
            raise ParamError(f"{self.owner}: {error}") from None
        self.positions: dict[str, float] = {}

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The transforms now known, stamped with the newest input's stamp."""
        if isinstance(data, Mapping) and ("joints" in data or "odom" in data):
            inputs: Mapping[str, Any] = data  # several Inputs: by name
        else:  # one Input: a JointState has names, an Odometry a pose
            inputs = {"odom" if isinstance(data, Mapping) and "pose" in data else "joints": data}
        stamps = [context.stamp]
        transforms: list[dict[str, Any]] = []
        joints = inputs.get("joints")
        if isinstance(joints, Mapping) and "name" in joints:
            stamps.append(_stamp(joints, context.stamp))
            for name, value in zip(joints["name"], np.asarray(joints.get("position", [])).ravel(), strict=False):
                if math.isfinite(float(value)):
                    self.positions[str(name)] = float(value)
        odom = inputs.get("odom")
        if isinstance(odom, Mapping) and "pose" in odom:
            stamps.append(_stamp(odom, context.stamp))
            pose = odom["pose"]["pose"]
            transforms.append(
                _transform(
                    odom["header"]["frame_id"],
                    odom.get("child_frame_id") or self.model.root,
                    (pose["position"].get("x", 0.0), pose["position"].get("y", 0.0), pose["position"].get("z", 0.0)),
                    tuple(pose["orientation"].get(k, 0.0) for k in "xyzw"),
                )
            )
        stamp = max(stamps[1:], default=stamps[0])
        for joint in self.model.joints.values():
            if joint.type in MOVING and joint.name not in self.positions:
                continue  # not measured: robot_state_publisher leaves it out too
            xyz, rotation = self.model.transform(joint, self.positions.get(joint.name, 0.0))
            transforms.append(_transform(joint.parent, joint.child, xyz, rotation))
        for transform in transforms:
            transform["header"]["stamp"] = stamp
        return {"transforms": transforms}


def _stamp(message: Mapping[str, Any], default: float) -> float:
    stamp = (message.get("header") or {}).get("stamp")
    return float(stamp) if isinstance(stamp, int | float) else default


def _transform(parent: str, child: str, xyz: Any, rotation: Any) -> dict[str, Any]:
    return {
        "header": {"stamp": 0.0, "frame_id": parent},
        "child_frame_id": child,
        "transform": {
            "translation": dict(zip("xyz", (float(v) for v in xyz), strict=True)),
            "rotation": dict(zip("xyzw", (float(v) for v in rotation), strict=True)),
        },
    }
