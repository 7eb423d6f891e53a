"""``plugin.ground-projection``: image detections placed on the map's floor (the ``object-detection``
interface, in the ``map`` frame; D302).

What ROS users do with ``image_geometry``'s ``PinholeCameraModel.projectPixelTo3dRay`` and a tf lookup
(or Duckietown's ``ground_projection`` node), as a Smart Resource service: each detection's image
position — ``x``, ``y`` as shares of the frame's width and height, as ``colour-detection``,
``orb-recognition`` and ``keypoint-matching`` give them — becomes the ray of a pinhole camera, turned
into the map with the camera's mount on the robot and the robot's pose, and cut with the horizontal
plane ``planeHeight`` metres above the floor (0: the floor; a box's height: the top face a downward
camera sees). The result is the detector's objects with ``frame: map``, ``x``, ``y``, ``z`` on the map
and ``observer`` (the pose they were placed with), so every behavior reading a detection
(``search-area``, ``survey-area``, ``spot``) takes them as map positions.

Inputs (a service of two Inputs; ``{input: newest value}``): ``objects``, the detector's result, and
``pose``, the robot's pose on the map — x, y, z (the robot's body frame above the floor, as the flight
interface's ``pose`` gives it) and yaw, or a ``PoseStamped``/``Odometry`` whose quaternion also gives
roll and pitch (then used: a multirotor tilts as it accelerates). A newer pose alone is not a new
frame: a result is projected once, with the newest pose when it arrives.

The camera: ``camera`` names its simulated HWChannel (its ``fov``, ``width`` and ``height``), or
``fov`` gives the horizontal field of view with the frame's aspect from each result's ``width`` and
``height`` (``colour-detection`` writes them) or the Param ``aspect``: square pixels, the principal
point at the frame's centre (an ideal pinhole). Its mount ``mount`` on the robot's body frame (x
ahead, y left, z up): ``"x y z pitch"`` for a downward camera (optical axis along −z, the image's top
towards the front, tilted forward by ``pitch``), or ``"x y z roll pitch yaw"``, the optical frame's
(x right, y down, z along the view) URDF joint origin.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from ckmconf.model import System
from ckmconf.model.resources import Plugin
from plugins.flight.estimate import read_position
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .cameras import Camera
from .channel_camera import camera_channels, channel_camera, channel_problem

Matrix = npt.NDArray[np.float64]


def rotation(roll: float, pitch: float, yaw: float) -> Matrix:
    """Rz(yaw) · Ry(pitch) · Rx(roll), as a URDF ``rpy`` and ROS's fixed-axis convention compose them."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw),
                              math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


DOWNWARD = rotation(math.pi, 0.0, -math.pi / 2)
"""The optical frame of a camera looking straight down, the image's top towards the body's front."""


def mount_of(text: str, owner: str) -> tuple[Matrix, Matrix]:
    """The Param ``mount`` as (position on the body, optical frame's rotation in the body frame)."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) not in (4, 6) or not all(math.isfinite(v) for v in values):
        raise ParamError(f"{owner}: parameter 'mount' = {text!r} is not 'x y z pitch' or 'x y z roll pitch yaw'")
    position = np.array(values[:3])
    if len(values) == 4:
        return position, rotation(0.0, -values[3], 0.0) @ DOWNWARD  # tilted forward by pitch
    return position, rotation(*values[3:])


def _quaternion(q: Mapping[str, Any]) -> Matrix:
    x, y, z, w = (float(q[k]) for k in "xyzw")
    norm = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def body_pose(value: Any, owner: str) -> tuple[Matrix, Matrix, float]:
    """(position, rotation, yaw) of the robot from a pose message: a quaternion gives roll and pitch too,
    a bare ``{x, y, z, yaw}`` (``roll``, ``pitch`` when present) the heading alone."""
    x, y, z, yaw = read_position(value, owner)
    if yaw is None:
        raise ValueError(f"{owner}: input 'pose' gives no heading (yaw or an orientation), got {value!r}"[:300])
    inner: Any = value
    while isinstance(inner, Mapping) and isinstance(inner.get("pose"), Mapping):
        inner = inner["pose"]
    orientation = inner.get("orientation") if isinstance(inner, Mapping) else None
    if isinstance(orientation, Mapping) and all(isinstance(orientation.get(k), int | float) for k in "xyzw"):
        turn = _quaternion(orientation)
    else:
        tilt = [inner.get(k) if isinstance(inner, Mapping) else None for k in ("roll", "pitch")]
        roll, pitch = (float(v) if isinstance(v, int | float) else 0.0 for v in tilt)
        turn = rotation(roll, pitch, yaw)
    return np.array([x, y, z]), turn, yaw


def ground_point(share: tuple[float, float], intrinsics: tuple[float, float, float, float],
                 camera: tuple[Matrix, Matrix], body: tuple[Matrix, Matrix], plane: float) -> Matrix | None:
    """Where the ray through the image point ``share`` (x, y shares of the width and height) meets the
    plane z = ``plane``; None when it does not (pointing level or up, or the camera below the plane).

    ``intrinsics``: (fx, fy, cx, cy) in shares of the frame (fx over the width, fy over the height);
    ``camera``: the mount (position, rotation) on the body; ``body``: its (position, rotation) on the map.
    """
    fx, fy, cx, cy = intrinsics
    ray_optical = np.array([(share[0] - cx) / fx, (share[1] - cy) / fy, 1.0])
    position, turn = body
    origin = position + turn @ camera[0]
    ray = turn @ camera[1] @ ray_optical
    if ray[2] > -1e-9 or origin[2] <= plane:
        return None
    point: Matrix = origin + ray * ((plane - origin[2]) / ray[2])
    return point


def _param(record: Plugin, name: str) -> Any:
    return next((p for p in record.params if p.name == name), None)


class GroundProjection(ProcessingPlugin):
    """``plugin.ground-projection``: image detections and the robot's pose in, the objects on the map out
    (module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "object-detection"  # docs/interfaces.md, in the map frame
    PASSES = "objects"  # the labels of its input's objects (plugins.behaviors.upstream)
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"objects": (
        "objects[].name", "objects[].label", "objects[].frame", "objects[].x", "objects[].y", "objects[].z",
        "objects[].reliability", "objects[].observer", "reliability")}
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("camera", "", "The simulated camera HWChannel whose fov, width and height give the intrinsics "
                        "(or 'fov').", type=str),
        P("fov", None, "The camera's horizontal field of view (without 'camera').", type=float, unit="rad",
          above=0.0, max=3.1),
        P("aspect", None, "The frame's width over its height, for results that do not give their width and "
                          "height (with 'fov').", type=float, above=0.0),
        P("mount", REQUIRED, "The camera on the body frame (x ahead, y left, z up): 'x y z pitch' looking down, "
                             "the image's top to the front, tilted forward by pitch; or the optical frame's "
                             "'x y z roll pitch yaw' (m, rad).", type=str, numbers=(4, 6),
          form="'x y z pitch' or 'x y z roll pitch yaw'"),
        P("planeHeight", 0.0, "Height above the floor of the plane the seen faces lie on (0: the floor).",
          unit="m", min=0.0),
    )

    @classmethod
    def problems(cls, record: Plugin, system: System | None) -> list[tuple[Any, str]]:
        """The camera's field of view must be given, by its channel or as ``fov`` (not both)."""
        camera, fov = _param(record, "camera"), _param(record, "fov")
        if camera is not None and camera.value.strip():
            if fov is not None:
                return [(fov, "give the camera's field of view once: parameter 'camera' or 'fov', not both")]
            if system is None:
                return []
            found = camera_channels(system, camera.value)
            if len(found) != 1:
                return [(camera, f"Param 'camera' = {camera.value!r} names {'no' if not found else len(found)} "
                                 "HWChannel of the system")]
            problem = channel_problem(found[0])
            return [] if problem is None else [(camera, f"Param 'camera': {problem}")]
        if fov is None:
            return [(record, "give the camera's field of view: parameter 'fov' (rad, horizontal) or 'camera' "
                             "naming its HWChannel")]
        return []

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if (problems := self.problems(record, None)):
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.mount = mount_of(self.params["mount"], self.owner)
        self.channel: Camera | None = None
        self._last: Any = None

    def setup(self) -> None:
        """Read the camera channel's intrinsics (when one is named)."""
        if self.params["camera"]:
            self.channel = channel_camera(self.record, self.params["camera"], self.owner)

    def intrinsics(self, result: Mapping[str, Any]) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) in shares of the frame for a detector's ``result``."""
        if self.channel is not None:
            c = self.channel
            return c.fx / c.width, c.fy / c.height, c.cx / c.width, c.cy / c.height
        half = math.tan(self.params["fov"] / 2)
        width, height = result.get("width"), result.get("height")
        if isinstance(width, int | float) and isinstance(height, int | float) and width > 0 and height > 0:
            fx = (width / 2) / half  # pixels; pixel centres at whole coordinates, as a render's
            return fx / width, fx / height, (width - 1) / 2 / width, (height - 1) / 2 / height
        if self.params["aspect"] is None:
            raise ValueError(f"{self.owner}: the detection gives no width and height; give parameter 'aspect'")
        fx_share = 0.5 / half
        return fx_share, fx_share * self.params["aspect"], 0.5, 0.5

    def process(self, data: Any, context: Context) -> dict[str, Any] | None:
        """The newest detection's objects on the map; None until both inputs arrived, or for a pose alone."""
        if not isinstance(data, Mapping) or "objects" not in data or "pose" not in data:
            raise ValueError(f"{self.owner} expects the Inputs 'objects' and 'pose', got "
                             f"{sorted(data) if isinstance(data, Mapping) else type(data).__name__}")
        result, pose = data["objects"], data["pose"]
        if result is None or pose is None or result == self._last:
            return None
        self._last = result
        if not isinstance(result, Mapping) or not isinstance(result.get("objects"), list):
            raise ValueError(f"{self.owner}: input 'objects' is no detection result {{objects: [...]}}")
        position, turn, yaw = body_pose(pose, self.owner)
        intrinsics, plane = self.intrinsics(result), float(self.params["planeHeight"])
        observer = [{"x": float(position[0]), "y": float(position[1]), "yaw": float(yaw)}]
        placed: list[dict[str, Any]] = []
        for item in result["objects"]:
            if not isinstance(item, Mapping) or not all(isinstance(item.get(k), int | float) for k in "xy"):
                continue
            point = ground_point((float(item["x"]), float(item["y"])), intrinsics, self.mount, (position, turn),
                                 plane)
            if point is None:
                continue
            name = str(item.get("name") or item.get("label") or "")
            placed.append({**{k: item[k] for k in ("shape", "texture") if k in item},
                           "name": name, "label": str(item.get("label") or name), "frame": "map",
                           "x": float(point[0]), "y": float(point[1]), "z": float(point[2]),
                           "reliability": float(item.get("reliability") or 0.0), "observer": observer})
        mean = sum(o["reliability"] for o in placed) / len(placed) if placed else 0.0
        return {"objects": placed, "reliability": mean}
