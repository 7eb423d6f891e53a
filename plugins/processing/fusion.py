"""``plugin.feature-fusion``: the GlobalRecog.Fusion service (thesis §6.3, Algorithm 4, Fig. 7.17).

Input: ``{input name: latest result or None}`` of the recognition services feeding the service.
Each input is declared (Param ``inputs``) as ``line`` (2D: ``keypoint-matching``, objects with
normalized image ``x``, ``y``) or ``point`` (3D: ``kdtree-shape-classifier``, objects with ``x y
z`` in metres). A 2D object becomes the projection ray of eq. 6.32–6.34 through its pixel; a 3D
object a point. Both are put in one common frame by the sensor's pose (``sensor_pose``): a
static Param (``poses``), or, for inputs mounted on a robot (``mounts``), the MAP frame: the
robot's pose (the ``pose`` input fed by ``/nav/pose``, or a fixed ``bases`` entry) composed with
the sensor's URDF mount at the head angles of the ``head`` input (``placement.py``, D118).
Noise: a point is isotropic, σ = ``pointSigma`` (3 cm: the depth service reports the visible
surface's centroid, a few cm off the solid's centre); a ray's error is angular, ``lineSigma``
(0.01 rad, ~5 px at VGA), so its lateral σ grows with range.

Feature model θ (eq. 6.35). Services name features differently: the RGB one the object
(``cylinder_red_stripes``), the depth one the shape class (``cylinder``). The catalog (Param
``objects``, and the environment file's Objects, whose semantic ``tag`` is the shape) maps an
object name to its shape and texture; θ is that shape, or the name itself when unmapped. So
C(cylinder) holds every cylinder's line and point, and geometry tells the instances apart.

Matching (Algorithm 4): in reliability order, x₁ seeds an estimate θ̂ (eq. 6.36); every other
observation within Mahalanobis ``dThreshold`` of θ̂ (eq. 6.38) joins, and θ̂ is re-estimated from
all joined (the θ̂' of eq. 6.41); the rest form C(θ') and the loop repeats. A service observes an
instance once, so a second observation from an input already joined goes to C(θ').

Knowledge (eq. 6.39–6.40): each observation's ``object``/``shape``/``texture`` is added unless a
more reliable one already gave it. Reliability (eq. 6.41): each matched xᵢ brings the support
sᵢ = 1/(1 + dᵢ), dᵢ to x₁ when xᵢ's magnitude (2D texture, 3D shape) is already in ψ̂, else to
θ̂'. Added literally (r₁ + Σ sᵢ, reported as ``reinforcement``) it exceeds 1 with any match, so
``reliability`` adds each support as a probabilistic sum, r̂ ← r̂ + sᵢ·(1 − r̂) (docs/decisions.md
D74): a match always raises r̂, r̂ stays a share in [0, 1] and reaches 1 only with a certain first
observation or a match at distance 0. :func:`share_at_bound` tells how many fused values sit at 1.

Max sensors (Table 7.1, ``Max_sensors``): at most ``maxSensors`` observations are fused into one
object, the most reliable first (the order of Algorithm 4); a further observation within
``dThreshold`` is of the same instance, so it is left out rather than starting C(θ'). The service
Parameter ``max_sensors`` sets it at run time (:meth:`FeatureFusion.apply_service_parameters`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ckmconf.model.resources import Plugin
from plugins.environment_file import environment_of
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import ENVIRONMENT_FILE, MAPPING, REQUIRED, Entries, P, Params, Parsed, Ports

from .cameras import Camera, camera_of
from .fusion_model import Observation, fused_object, number, reinforce, share_at_bound
from .geometry import IDENTITY, Geometry, Point, Pose, Ray, distance, estimate
from .placement import BASE, MOUNT, Placement

__all__ = ["FeatureFusion", "Observation", "reinforce", "share_at_bound"]

KINDS = ("line", "point")
KIND = Entries("line|point", choices=KINDS)
"""``inputs``: each input's feature kind (eq. 6.32)."""
POSE = Entries("x y z roll pitch yaw", 6, numbers=True, of="inputs", noun="an input")
"""``poses``: a sensor's optical frame in the common frame (m, rad)."""
DEFAULT_CAMERA = ("fx", "calibrationWidth", "calibrationHeight")
"""The Params the default camera of line inputs needs (``fy cx cy`` default to the ideal pinhole's)."""


@dataclass(frozen=True)
class CameraEntries(Entries):
    """``cameras``: a line input's intrinsics at its calibration size (px); and every line input has a
    camera, its entry or the default one (:data:`DEFAULT_CAMERA`): no lab's camera is a default, and
    the recognition results carry none (normalized ``x y`` and the image's ``width height`` only).

    The check runs where every per-name Param is checked against the others (``strays``), so
    ``verify`` refuses a line input with no camera before anything is built, at the ``cameras``
    Param when it is given, else at the Plugin element.
    """

    def strays(self, param: str, value: Parsed, text: str | None, values: Mapping[str, Any]) -> Iterator[ParamError]:
        yield from super().strays(param, value, text, values)
        inputs = values.get("inputs")
        missing = [name for name in DEFAULT_CAMERA if values.get(name) is None]
        if not isinstance(inputs, Mapping) or not missing:
            return
        needed = " and ".join(", ".join(repr(name) for name in missing).rsplit(", ", 1))
        for name, kind in inputs.items():
            if tuple(kind)[:1] == ("line",) and name not in value:
                yield ParamError(
                    f"line input {name!r} has no intrinsics: give it a {param!r} entry, "
                    f"or parameter{'s' if len(missing) > 1 else ''} {needed} (the line inputs' default camera)"
                )


CAMERA = CameraEntries("fx fy cx cy width height", 6, numbers=True, of="inputs", of_value="line", noun="a line input")
"""``cameras``: a line input's intrinsics at its calibration size (px); every line input needs a camera."""
SIGMA = Entries("σ", numbers=True, above=0.0, of="inputs", noun="an input")
"""``sigmas``: an input's own uncertainty."""
OBJECT = Entries("shape [texture]", 1, 2, need="a shape and maybe a texture")
"""``objects``: a catalog name's shape and, maybe, texture."""
MAGNITUDE = {"line": "texture", "point": "shape"}
"""The magnitude γ each kind of input observes (eq. 6.32): 2D texture patterns, 3D shapes."""
MAX_OBJECTS = 1000
"""Most objects an input may report per result: matching is quadratic, and a recognizer reports a few."""
UNKNOWN = "unknown"
"""The depth classifier's name for a cluster below its threshold: no feature model, not fused."""


class FeatureFusion(ProcessingPlugin):
    """``plugin.feature-fusion``: fused objects of several recognition services (§6.3.4, Algorithm 4).

    Params: ``inputs`` (``"name: line|point; …"``); ``poses`` (``"name: x y z roll pitch yaw; …"``,
    the sensor's optical frame in the common frame; default identity, so the common frame is the
    RGB-D camera's); ``cameras`` (``"name: fx fy cx cy width height; …"`` for line inputs; a line
    input without an entry takes ``fx fy cx cy calibrationWidth calibrationHeight``, of which ``fx``
    and the size must then be given: no camera is a default); ``lineSigma`` (rad) / ``pointSigma`` (m)
    and per-input ``sigmas`` (``"name: σ; …"``); ``dThreshold`` (eq. 6.38); ``minReliability``
    (r_th of eq. 6.31); ``minRange`` (m, nearest feature along a ray); ``objects`` (``"name: shape
    [texture]; …"``) and ``environment`` (an environment XML file, relative to the configuration
    file, read in ``setup()``; ``objects`` entries win); ``maxSensors`` (most observations per fused
    object, Table 7.1; the service Parameter ``max_sensors`` overrides it at run time); ``mounts``,
    ``bases``, ``poseInput``, ``headInput``, ``headJoints`` (the map frame, see ``placement.py``).

    Output (msgpack-able): ``{"objects": [{"name", "shape", "texture", "x", "y", "z", "sigma",
    "origin", "direction", "frame", "reliability", "reinforcement", "sources", "observations"}],
    "reliability"}`` (plus ``"unplaced"``, the observations left out for want of a sensor pose,
    when inputs are mounted; an object seen by a sensor on the moving robot also carries
    ``observer``, a list holding the robot pose ``{"x", "y", "yaw"}`` it was placed with, D172).
    ``frame`` is ``"map"`` with mounted inputs, else ``"sensor"``. A lone 2D observation has no
    position (``x y z sigma`` None) but its ray's ``origin`` and ``direction``; a positioned object
    has ``sigma`` (RMS per axis, m) and no ray. ``reliability`` is the mean fused reliability, 0 with no object.
    """

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})  # one recognition result per input
    PROVIDES = "fusion"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"objects": (
        *(f"objects[].{name}" for name in ("name", "shape", "texture", "x", "y", "z", "sigma", "origin", "direction",
                                           "centre", "frame", "reliability", "reinforcement", "sources",
                                           "observations", "observer")),
        "reliability", "unplaced")}
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("inputs", REQUIRED, "Inputs and their feature kind.", type=str, entries=KIND),
        P("poses", "", "Sensor frames in the common frame (default identity).", entries=POSE),
        P("cameras", "", "Intrinsics of line inputs (one without an entry takes fx fy cx cy).", entries=CAMERA),
        P("fx", None, "Focal length x of line inputs without a 'cameras' entry (then required).", type=float,
          unit="px", above=0.0),
        P("fy", None, "Their focal length y (default: fx).", type=float, unit="px", above=0.0),
        P("cx", None, "Their principal point x (default: (calibrationWidth - 1) / 2).", type=float, unit="px"),
        P("cy", None, "Their principal point y (default: (calibrationHeight - 1) / 2).", type=float, unit="px"),
        P("calibrationWidth", None, "Image width fx, fy, cx, cy are given for (required with fx).", type=int,
          unit="px", above=0),
        P("calibrationHeight", None, "Image height fx, fy, cx, cy are given for (required with fx).", type=int,
          unit="px", above=0),
        P("lineSigma", 0.01, "Angular uncertainty of a line (2D) observation.", unit="rad"),
        P("pointSigma", 0.03, "Positional uncertainty of a point (3D) observation.", unit="m"),
        P("sigmas", "", "Per-input uncertainties (rad for a line, m for a point).", entries=SIGMA),
        P("dThreshold", 3.0, "Association distance threshold of eq. 6.38."),
        P("minReliability", 0.0, "Observations below this reliability (r_th of eq. 6.31) are ignored."),
        P("minRange", 0.3, "Nearest feature along a ray.", unit="m"),
        P("objects", "", "Known objects (win over the environment's).", entries=OBJECT),
        P("environment", "", "Environment XML file, relative to the configuration file, read in setup().",
          file=ENVIRONMENT_FILE),
        P("maxSensors", 8, "Most observations fused into one object (Table 7.1 Max_sensors).", min=1),
        P("mounts", "", "Inputs on a robot (URDF, sensor link): the frame is the map.", entries=MOUNT),
        P("bases", "", "Fixed map poses of mounted inputs' robots (others follow poseInput).", entries=BASE),
        P("poseInput", "pose", "The input carrying the moving robot's PoseEstimate in the map."),
        P("headInput", "head", "The input carrying the head angles {pan, tilt}."),
        P("headJoints", "", "The URDF joints the head input's pan and tilt drive (required when a mount moves "
          "joints)."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p, owner = self.params, self.owner
        for name, value in p.items():
            if isinstance(value, float) and not math.isfinite(value):
                raise ParamError(f"{owner}: parameter {name!r} = {value} is not finite")
        for name in ("lineSigma", "pointSigma", "dThreshold"):
            if not p[name] > 0:
                raise ParamError(f"{owner}: parameter {name!r} = {p[name]} must be greater than 0")
        if not p["minRange"] > 0:
            raise ParamError(f"{owner}: parameter 'minRange' = {p['minRange']} must be greater than 0")
        if not 0 <= p["minReliability"] <= 1:
            raise ParamError(f"{owner}: parameter 'minReliability' = {p['minReliability']} is not in [0, 1]")
        self.max_sensors = self._max_sensors(p["maxSensors"], "parameter 'maxSensors'")
        self.kinds: dict[str, str] = {name: values[0] for name, values in p["inputs"].items()}
        self.cameras: dict[str, Camera] = {}
        if all(p[name] is not None for name in DEFAULT_CAMERA):  # else every line input has its entry
            default = camera_of(p, owner)
            self.cameras = {name: default for name, kind in self.kinds.items() if kind == "line"}
        for name, (fx, fy, cx, cy, width, height) in p["cameras"].items():
            if min(fx, fy, width, height) <= 0 or width != int(width) or height != int(height):
                raise ParamError(f"{owner}: parameter 'cameras' for {name!r} needs fx, fy > 0 and a whole size")
            self.cameras[name] = Camera(fx, fy, cx, cy, int(width), int(height))
        self.sigmas = {name: p[f"{kind}Sigma"] for name, kind in self.kinds.items()}
        self.sigmas |= {name: sigma for name, (sigma,) in p["sigmas"].items()}
        self.poses: dict[str, Pose] = {name: Pose.from_xyzrpy(*values) for name, values in p["poses"].items()}
        """Sensor poses by input (missing: identity); the hook for live poses, see ``sensor_pose``."""
        self.catalog: dict[str, tuple[str, str | None]] = {
            name: (values[0], values[1] if len(values) == 2 else None) for name, values in p["objects"].items()
        }
        base = config_dir(record)
        self.environment = base / p["environment"] if p["environment"] else None
        self._loaded = self.environment is None
        self.placement = Placement(p, self.kinds, base, owner)
        for name in self.placement.mounts:
            if name in self.poses:
                raise ParamError(f"{owner}: input {name!r} has both a static 'poses' entry and a 'mounts' entry")
        self.frame = "map" if self.placement.active else "sensor"
        """The common frame: the map when inputs are mounted on robots, else the sensors' (``poses``)."""
        self.unplaced = 0

    def _max_sensors(self, value: Any, where: str) -> int:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value) or value < 1:
            raise ParamError(f"{self.owner}: {where} = {value!r} must be a whole number of at least 1")
        return int(value)

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``max_sensors`` Parameter (Table 7.1) caps the observations per object.

        Called by the Smart Resource runtime with a service instance's parameters whenever a
        client configures it; the SPT runs the plugin once for every client (§3.2.2), so the
        value last configured holds for all of them. Other names are not this plugin's.
        """
        if "max_sensors" in parameters:
            self.max_sensors = self._max_sensors(parameters["max_sensors"], "service parameter 'max_sensors'")

    def setup(self) -> None:
        """Read the environment's Objects (name → semantic tag as the shape, texture); Params win."""
        if self.environment is None:
            return
        known = {o.name: (o.tag, o.texture) for o in environment_of(self.environment, self.owner).objects}
        self.catalog = known | self.catalog
        self._loaded = True

    def sensor_pose(self, source: str) -> Pose | None:
        """The pose of input ``source``'s sensor in the common frame (f' of eq. 6.34), None while unknown.

        A mounted input's pose is live (the robot's pose estimate and head angles composed with
        its URDF mount, :class:`~plugins.processing.placement.Placement`); another's is the
        static ``poses`` entry (default identity).
        """
        if source in self.placement.mounts:
            return self.placement.sensor_pose(source)
        return self.poses.get(source, IDENTITY)

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The fused objects of the recognition results in ``data`` and their reliability (Algorithm 4).

        Raises:
            RuntimeError: ``setup()`` was not called.
            ValueError: ``data`` is not a mapping of input name to result.
        """
        if not self._loaded:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects a mapping of input name to result, got {type(data).__name__}")
        self.placement.update(data)
        self.unplaced = 0
        observations: dict[str, list[Observation]] = {}
        for source in sorted(data, key=str):
            if source in (self.placement.pose_input, self.placement.head_input):
                continue
            for obs in self._observations(source, data[source]):
                observations.setdefault(obs.model, []).append(obs)
        fused = [obj for model in sorted(observations) for obj in self._fuse(model, observations[model])]
        fused.sort(key=lambda o: (-o["reliability"], o["name"]))
        observer = self.placement.observer
        if observer is not None:  # the robot pose the map positions were placed with (D172)
            for obj in fused:
                if any(s in self.placement.mounts and s not in self.placement.bases for s in obj["sources"]):
                    obj["observer"] = [dict(observer)]
        mean = sum(o["reliability"] for o in fused) / len(fused) if fused else 0.0
        out: dict[str, Any] = {"objects": fused, "reliability": mean}
        if self.placement.active:  # observations left out for want of a sensor pose (a quality measure)
            out["unplaced"] = self.unplaced
        return out

    # ------------------------------------------------------------------ inputs → observations (eq. 6.31–6.34)

    def _observations(self, source: Any, result: Any) -> Iterable[Observation]:
        if result is None:
            return []
        if not isinstance(source, str) or source not in self.kinds:
            raise ValueError(f"{self.owner}: input {source!r} is not declared in parameter 'inputs'")

        def bad(where: str, why: str) -> ValueError:
            return ValueError(f"{self.owner}: input {source!r} {where} {why}")

        if not isinstance(result, Mapping) or not isinstance(result.get("objects"), (list, tuple)):
            raise bad("field 'objects'", "is missing or not a list")
        if len(result["objects"]) > MAX_OBJECTS:
            raise bad("field 'objects'", f"has {len(result['objects'])} objects, more than {MAX_OBJECTS}")
        kind = self.kinds[source]
        camera = self.cameras.get(source)
        size: tuple[float, float] = (camera.width, camera.height) if camera is not None else (1, 1)
        if kind == "line" and ("width" in result or "height" in result):
            size = (
                number(result.get("width"), bad, "field 'width'"),
                number(result.get("height"), bad, "field 'height'"),
            )
            if not all(v >= 1 and v == int(v) for v in size):
                raise bad("fields 'width'/'height'", f"are not a whole image size: {size}")
        pose, sigma, found = self.sensor_pose(source), self.sigmas[source], []
        if pose is None:  # a mounted sensor before its robot's pose (or head state) is known
            self.unplaced += len(result["objects"])
            return []
        for index, item in enumerate(result["objects"]):
            where = f"objects[{index}]"
            if not isinstance(item, Mapping):
                raise bad(where, "is not a mapping")
            name = item.get("name")
            if not isinstance(name, str) or not name:
                raise bad(f"{where} field 'name'", "is not a non-empty string")
            r = number(item.get("reliability"), bad, f"{where} field 'reliability'")
            if not 0 <= r <= 1:
                raise bad(f"{where} field 'reliability'", f"= {r} is not in [0, 1]")
            coords = [number(item.get(axis), bad, f"{where} field {axis!r}") for axis in "xyz"[: 2 + (kind == "point")]]
            if name == UNKNOWN or r < self.params["minReliability"]:
                continue
            if kind == "point":
                geometry: Geometry = Point(pose.point(np.array(coords)), sigma * sigma * np.eye(3))
            else:
                if not all(0 <= v <= 1 for v in coords):
                    raise bad(f"{where} fields 'x'/'y'", f"= {coords} are not normalized image coordinates")
                assert camera is not None
                geometry = self._ray(camera, coords, size, pose, sigma)
            shape, texture = self.catalog.get(name, (None, None))
            knowledge = {"object": name} if kind == "line" else {"shape": name}
            if shape is not None:
                knowledge |= {"object": name, "shape": shape} | ({"texture": texture} if texture else {})
            found.append(Observation(source, index, shape or name, r, geometry, MAGNITUDE[kind], knowledge))
        return found

    def _ray(self, camera: Camera, xy: list[float], size: tuple[float, float], pose: Pose, sigma: float) -> Ray:
        """The projection line of a normalized image point (eq. 6.32–6.34 as a pinhole back-projection).

        The recognizer's ``x = u / columns`` (u in pixels of the image it saw); the intrinsics,
        given at the calibration size, are scaled to that image as the resize plugin samples it,
        so the ray does not depend on the resolution profile.
        """
        cols, rows = int(size[0]), int(size[1])
        fx, fy, cx, cy = camera.intrinsics(rows, cols)
        direction = np.array([(xy[0] * cols - cx) / fx, (xy[1] * rows - cy) / fy, 1.0])
        direction = pose.vector(direction / np.linalg.norm(direction))
        return Ray(pose.translation.copy(), direction, sigma, self.params["minRange"])

    # ------------------------------------------------------------------ Algorithm 4

    def _fuse(self, model: str, collection: list[Observation]) -> list[dict[str, Any]]:
        """The fused objects of C(θ): one per instance, repeating with C(θ') until it is empty."""
        pending = sorted(collection, key=lambda o: (-o.reliability, o.source, o.index))
        fused = []
        while pending:
            first, left = pending[0], []
            members, theta, r_hat = [first], first.geometry, first.reliability
            raw = first.reliability
            knowledge = dict(first.knowledge)
            for obs in pending[1:]:
                d = distance(theta, obs.geometry)  # eq. 6.38
                if any(m.source == obs.source for m in members) or not d < self.params["dThreshold"]:
                    left.append(obs)
                    continue
                if len(members) >= self.max_sensors:  # the same instance, beyond the cap: not fused
                    continue
                if any(m.magnitude == obs.magnitude for m in members):  # eq. 6.41, first case
                    d = distance(first.geometry, obs.geometry)
                support = 1.0 / (1.0 + d)
                raw += support
                r_hat = reinforce(r_hat, support)
                for key, value in obs.knowledge.items():  # eq. 6.40: new magnitudes' knowledge only
                    knowledge.setdefault(key, value)
                members.append(obs)
                theta = estimate([m.geometry for m in members])  # θ̂' (eq. 6.36)
            fused.append(fused_object(model, knowledge, theta, r_hat, raw, members, self.frame))
            pending = left
        return fused
