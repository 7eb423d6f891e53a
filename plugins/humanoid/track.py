"""``plugin.pan-tilt-track``: the PanTiltCamera.Track service (thesis Table 7.2, §7.3.2, Table 7.7 OBJ_TRACK).

Inputs (``{input name: newest value or None}``; the lab's ``PanTiltCamera.Track`` service is one):

- ``objects``: the PanTiltCamera.Recog result, ``{"objects": [{"name", "x", "y", "reliability",
  …}], "width", "height"}``, ``x``/``y`` the object's centre in the image as shares (0..1) of its
  width and height (``plugin.keypoint-matching``);
- ``head_state`` (PanTilt ``{"pan", "tilt"}``, from Nao.NaoQi).

Tracking is image-based (D90): the target's angular offset from the optical axis, from its image
position through the pinhole model (horizontal field of view ``fov``), moves the head by a share
``gain`` of it, at most ``speed``·Δt per frame (Δt: the time since the previous frame, the
service Parameter ``speed`` of Table 7.2 in rad/s), within the Nao's joint limits. A result
already acted on (the stream hands the newest one again when only the head state is new) does not
move the head twice: the same goal, track and target are published again. The target is the most reliable
object matching the Parameters ``target`` (its name or shape contains it) and ``targetTexture``;
any object when both are empty.

Outputs: ``head_goal`` (PanTilt, head angles for the ``pan-tilt-position`` controller, while a
target is in view), ``track`` (TrackState ``{"stamp", "label", "moving", "in_view", "error",
"head", "target"}``: ``error`` the target's angular offset, rad), ``target`` (ObjectPosition in
the MAP frame) and the measure ``moving`` (Table 7.2): 1 while the head follows a target in view
(and for ``hold`` seconds after it was last seen: one missed recognition does not end it).

Map position (D114): the camera's pose for the head angles comes from the Nao's URDF (private
pybullet client, :class:`.head.HeadModel`) placed at the Nao's map pose (Param ``pose``); the
target's viewing ray is intersected with the horizontal plane at the height of the object's
centre — from the environment model's Object of that name (Param ``environment``), the
``heights`` Param, or ``planeHeight``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ckmconf.model.environment import Geometry2D, Geometry3D
from ckmconf.model.resources import Plugin
from plugins.environment_file import environment_of
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, REQUIRED, Entries, P, Params, Ports, fixed_numbers

from .head import HeadModel, map_frame, on_plane

MODELS = Path(__file__).resolve().parents[1] / "sim" / "models"


class PanTiltTrack(ProcessingPlugin):
    """Head goals that keep the recognised target centred, and its map position (see the module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})  # Recog result + PanTilt in; goals, state out
    PROVIDES = "pan-tilt-tracking"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", REQUIRED, "Robot URDF: a model name of plugins/sim/models, or a path relative to the "
          "configuration file.", type=str),
        P("panJoint", REQUIRED, "The pan joint of the model.", type=str),
        P("tiltJoint", REQUIRED, "The tilt joint of the model.", type=str),
        P("camera", REQUIRED, "The camera's optical frame link (z forward, x right, y down).", type=str),
        P("pose", "0 0 0", "The robot's pose in the map: 'x y yaw'.", unit="m m rad", numbers=(3,), form="'x y yaw'"),
        P("baseHeight", 0.0, "Height of the robot's base frame above the map floor.", unit="m"),
        P("fov", REQUIRED, "Horizontal field of view of the camera.", unit="rad", type=float, above=0.0,
          below=math.pi),
        P("imageWidth", 640, "Image width, for results that do not give theirs.", unit="px", min=1),
        P("imageHeight", 480, "Image height, for results that do not give theirs.", unit="px", min=1),
        P("panMin", None, "Lowest pan goal (default: the pan joint's lower limit in the URDF).", unit="rad",
          type=float),
        P("panMax", None, "Highest pan goal (default: the URDF's upper limit).", unit="rad", type=float),
        P("tiltMin", None, "Lowest tilt goal (default: the tilt joint's lower limit in the URDF).", unit="rad",
          type=float),
        P("tiltMax", None, "Highest tilt goal (default: the URDF's upper limit).", unit="rad", type=float),
        P("speed", 0.5, "Top head speed until the service Parameter 'speed' sets it.", unit="rad/s", above=0.0),
        P("gain", 0.6, "Share of the target's offset corrected per frame (D90).", above=0.0, max=1.0),
        P("tolerance", 0.02, "Offset under which the target counts as centred (D90).", unit="rad", above=0.0),
        P("period", 0.5, "Frame period assumed for the first frame (the service rate, Table 7.8).", unit="s",
          above=0.0),
        P("hold", 1.0, "How long the head keeps following (moving = 1) after the target was last seen.",
          unit="s", min=0.0),
        P("target", "", "Name or shape of the object to track (empty: the most reliable)."),
        P("targetTexture", "", "Texture of the object to track."),
        P("minReliability", 0.0, "Objects less reliable than this are ignored.", min=0.0, max=1.0),
        P("environment", "", "Environment XML file (relative to the configuration file) giving the objects' heights.",
          file=ENVIRONMENT_FILE),
        P("heights", "", "Object centre heights (win over the environment's).", unit="m",
          entries=Entries("z", numbers=True)),
        P("planeHeight", 0.0, "Height of the plane met by the ray of an object of unknown height.", unit="m"),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        v, owner = self.params, self.owner
        self.pose = fixed_numbers(v["pose"], 3, "pose", owner)
        self.given = ((v["panMin"], v["panMax"]), (v["tiltMin"], v["tiltMax"]))
        self.limits = self._limits(((-math.inf, math.inf), (-math.inf, math.inf)))  # the URDF's fill in at setup
        self.heights: dict[str, float] = {name: z for name, (z,) in v["heights"].items()}
        base = config_dir(record)
        model = str(v["model"])
        self.model_path = base / model if Path(model).suffix else MODELS / f"{model}.urdf"
        self.environment = base / v["environment"] if v["environment"] else None
        self.speed: float = v["speed"]
        self.target: str = v["target"]
        self.texture: str = v["targetTexture"]
        self.head: HeadModel | None = None
        self._acted: Any = None
        self._goal: dict[str, float] | None = None
        self._seen: float | None = None  # when the target was last in view
        self._last: float | None = None
        self._track: dict[str, Any] = {"label": "", "moving": False, "in_view": False, "error": None, "target": None}

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        """Load the head's URDF privately and read the objects' heights from the environment model."""
        if not self.model_path.is_file():
            raise FileNotFoundError(f"{self.owner}: robot model {self.model_path} does not exist")
        if self.environment is not None:
            environment = environment_of(self.environment, self.owner)
            known = {}
            for obj in environment.objects:
                geometry = obj.geometry
                if isinstance(geometry, Geometry2D):  # as tall as the simulated world stands it (a marking: 0)
                    low, high = 0.0, geometry.solid_height
                else:
                    prisms = geometry.prisms if isinstance(geometry, Geometry3D) else (geometry.prism,)
                    low, high = min(q.zmin for q in prisms), max(q.zmax for q in prisms)
                known[obj.name] = obj.pose.z + (low + high) / 2
            self.heights = known | self.heights
        try:
            self.head = HeadModel(self.model_path, self.params["panJoint"], self.params["tiltJoint"],
                                  self.params["camera"])
        except ValueError as exc:
            raise ValueError(f"{self.owner}: {exc}") from None
        urdf = tuple(limit or (-math.pi, math.pi) for limit in self.head.limits)
        self.limits = self._limits((urdf[0], urdf[1]))

    def _limits(self, urdf: tuple[tuple[float, float], tuple[float, float]]) -> tuple[tuple[float, float], ...]:
        """The pan and tilt goal limits: the Params given, else the URDF joints' ``urdf``."""
        limits = []
        for axis, (low, high), (low_urdf, high_urdf) in zip(("pan", "tilt"), self.given, urdf, strict=True):
            low, high = low_urdf if low is None else low, high_urdf if high is None else high
            if not low < high:
                raise ParamError(f"{self.owner}: the {axis} limits must be ordered: '{axis}Min' = {low:g} is not "
                                 f"less than '{axis}Max' = {high:g}")
            limits.append((low, high))
        return tuple(limits)

    def stop(self) -> None:
        """Close the private head model."""
        if self.head is not None:
            self.head.close()
            self.head = None

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """Table 7.2's ``speed`` (rad/s), and the ``target``/``targetTexture`` a behavior asks for."""
        if "speed" in parameters:
            speed = parameters["speed"]
            if isinstance(speed, bool) or not isinstance(speed, int | float) or not 0.0 < speed < math.inf:
                raise ValueError(f"{self.owner}: service parameter 'speed' = {speed!r} must be a positive number")
            self.speed = float(speed)
        for name in ("target", "targetTexture"):
            if name in parameters and not isinstance(parameters[name], str):
                raise ValueError(f"{self.owner}: service parameter {name!r} = {parameters[name]!r} is not a string")
        self.target = parameters.get("target", self.target)
        self.texture = parameters.get("targetTexture", self.texture)

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """Head goal, track state, target's map position and ``moving`` measure (Table 7.2, OBJ_TRACK).

        Raises:
            RuntimeError: ``setup()`` was not called.
            ValueError: ``data`` is not a mapping of the inputs.
        """
        if self.head is None:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'objects': …, 'head_state': …}}, got {type(data).__name__}")
        now = context.stamp
        dt = self.params["period"] if self._last is None else min(max(now - self._last, 0.0), 4 * self.params["period"])
        self._last = now
        head = self._head(data.get("head_state"))
        result: dict[str, Any] = {}
        recognised = data.get("objects")
        if head is not None and recognised is not None:
            fresh = recognised != self._acted  # a result already acted on must not move the head twice
            self._acted = recognised
            found = self.choose(recognised)
            if found is None:  # a missed frame or two do not end the following (Param 'hold')
                following = self._seen is not None and now - self._seen <= self.params["hold"]
                self._track = {"label": self._track["label"] if following else "", "moving": following,
                               "in_view": False, "error": None, "target": None}
            else:
                self._seen = now
                result.update(self._follow(found, recognised, head, dt, now, fresh))
        moving = bool(self._track["moving"])
        result["track"] = {"stamp": now, **self._track,
                           "head": None if head is None else {"pan": head[0], "tilt": head[1]}}
        result["moving"] = 1 if moving else 0
        return result

    def _head(self, state: Any) -> tuple[float, float] | None:
        if state is None:
            return None
        if not isinstance(state, Mapping):
            raise ValueError(f"{self.owner}: head_state is {type(state).__name__}, not a PanTilt")
        values = []
        for key in ("pan", "tilt"):
            value = state.get(key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{self.owner}: head_state {key!r} = {value!r} is not a finite angle")
            values.append(float(value))
        return values[0], values[1]

    def choose(self, recognised: Any) -> dict[str, Any] | None:
        """The most reliable object of a Recog result matching ``target`` / ``targetTexture``."""
        if not isinstance(recognised, Mapping) or not isinstance(recognised.get("objects"), list):
            raise ValueError(f"{self.owner}: objects is not a recognition result (no 'objects' list)")
        best: dict[str, Any] | None = None
        for item in recognised["objects"]:
            if not isinstance(item, Mapping):
                continue
            x, y, reliability = item.get("x"), item.get("y"), item.get("reliability", 0.0)
            if not all(isinstance(v, int | float) and math.isfinite(v) for v in (x, y, reliability)):
                continue
            name = str(item.get("name", ""))
            if self.target and self.target not in name and self.target not in str(item.get("shape", "")):
                continue
            if self.texture and self.texture not in f"{name} {item.get('texture', '')}":
                continue
            if reliability < self.params["minReliability"]:
                continue
            if best is None or reliability > best["reliability"]:
                best = {**item, "name": name, "reliability": float(reliability)}
        return best

    def _offsets(self, found: Mapping[str, Any], recognised: Mapping[str, Any]) -> tuple[float, float]:
        """The tangents of the target's offset from the optical axis (right, down)."""
        width, height = recognised.get("width"), recognised.get("height")
        if not (isinstance(width, int | float) and isinstance(height, int | float) and width > 0 and height > 0):
            width, height = self.params["imageWidth"], self.params["imageHeight"]
        half = math.tan(self.params["fov"] / 2)
        return (float(found["x"]) - 0.5) * 2 * half, (float(found["y"]) - 0.5) * 2 * half * height / width

    def _follow(self, found: Mapping[str, Any], recognised: Mapping[str, Any], head: tuple[float, float],
                dt: float, now: float, fresh: bool) -> dict[str, Any]:
        right, down = self._offsets(found, recognised)
        offset = (math.atan(right), math.atan(down))
        error = math.hypot(*offset)
        goal = list(head)
        if error > self.params["tolerance"]:
            step = self.speed * dt
            moves = (-self.params["gain"] * offset[0], self.params["gain"] * offset[1])  # pan left +, tilt down +
            goal = [min(max(h + max(-step, min(step, m)), low), high)
                    for h, m, (low, high) in zip(head, moves, self.limits, strict=True)]
        target = self._locate(found, right, down, head, now)
        self._track = {"label": found["name"], "moving": True, "in_view": True, "error": error, "target": target}
        if fresh or self._goal is None:
            self._goal = {"pan": goal[0], "tilt": goal[1]}
        out: dict[str, Any] = {"head_goal": dict(self._goal)}  # a repeated result: the same goal again
        if target is not None:
            out["target"] = target
        return out

    def _locate(self, found: Mapping[str, Any], right: float, down: float, head: tuple[float, float],
                now: float) -> dict[str, Any] | None:
        """The target's ObjectPosition on the map (None when its ray does not meet its plane)."""
        assert self.head is not None
        origin, rotation = self.head.camera_pose(*head)
        x, y, yaw = self.pose
        z = self.params["baseHeight"]
        start = map_frame(x, y, yaw, z, origin)
        c, s = math.cos(yaw), math.sin(yaw)
        direction = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ rotation @ np.array([right, down, 1.0])
        height = self.heights.get(found["name"], self.params["planeHeight"])
        point = on_plane(start, direction, height)
        if point is None:
            return None
        return {"stamp": now, "label": found["name"], "frame": "map", "x": float(point[0]), "y": float(point[1]),
                "z": float(point[2]), "reliability": found["reliability"]}
