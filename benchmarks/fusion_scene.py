"""The simulated laboratory seen by the Turtlebot's Xtion, run through the use case's real recognition.

Used by ``ckm-bench fusion`` (Fig. 7.18, 7.19) and the fusion tests. One :class:`Lab` holds:

- the pybullet :class:`~plugins.sim.world.World` of ``configs/usecase`` (environment.xml: the
  workbench and its objects, wearing the textures the RGB model learnt) and the Turtlebot,
  placed kinematically (no physics: a pose is set, one frame is rendered) with its arm at rest;
- the RGB and depth pipelines of ``RGBDCamera`` built from resources.xml's own plugin records
  (``camera-acquisition → image-resize → orb-keypoints → keypoint-matching`` and
  ``depth-acquisition → image-resize → euclidean-clustering → kdtree-shape-classifier``), the
  clustering's intrinsics set to the simulated camera's and its kind ``tabletop-clustering``
  (the same Params, more support planes removed: the objects stand on the workbench, D117);
- the GlobalRecog ``feature-fusion`` plugin with the two inputs mounted on the Turtlebot's URDF,
  fed the robot's pose as ``/nav/pose`` would (here its true pose: this measures recognition,
  not localization).

:meth:`Lab.observe` renders ONE frame (colour and depth of the same render), runs both real
pipelines on it and fuses their two results: nothing is made from the ground truth, which only
serves to score the results (which object is where, and whether it is in view).

Texture skins. pybullet's built-in cylinder and box give texture coordinates that show a few
magnified texels of the image (a planar projection in metres), so the learnt print would never
appear. The :class:`~plugins.sim.world.World` built with the model file dresses each textured
cylinder and box in a skin wearing the learnt print upright at its own aspect
(:mod:`plugins.sim.skins`, D116, D145); :func:`dress` (from there) lists those bodies.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from ckm_lab.arm import ARM_JOINTS, POSES
from ckm_lab.devices import XTION_FOV

import ckmconf
from ckmconf.model import Param
from ckmconf.model.environment import Circle, Geometry25D, Rectangle
from ckmconf.model.resources import Plugin
from plugins.processing.depth import DepthAcquisition, EuclideanClustering, KdTreeShapeClassifier
from plugins.processing.fusion import FeatureFusion
from plugins.processing.image import Resize
from plugins.processing.recognition import CameraAcquisition, KeypointMatching, OrbKeypoints
from plugins.processing.tabletop import TabletopClustering
from plugins.processing.textures import read_model
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.skins import dress
from plugins.sim.world import World
from runtime.resources.spt import Context, ProcessingPlugin

USECASE = Path(__file__).resolve().parent.parent / "configs" / "usecase"
LINK = "camera_rgb_optical_frame"
NAO_LINK = "CameraTop_optical_frame"
NAO_FOV = 0.8331
"""The Nao's top camera's horizontal field of view (rad), as ``benchmarks/sim.py`` mounts it."""
SIZES = {"VGA": (640, 480), "QVGA": (320, 240), "QQVGA": (160, 120)}
TABLETOP = "tabletop-clustering"
XTION_RANGE = (0.4, 6.0)
"""Depth the Xtion returns (m); outside it a pixel reads 0, as in ``shapes.render_depth_scene``."""
KINDS: dict[str, type[ProcessingPlugin]] = {
    "camera-acquisition": CameraAcquisition,
    "image-resize": Resize,
    "orb-keypoints": OrbKeypoints,
    "keypoint-matching": KeypointMatching,
    "depth-acquisition": DepthAcquisition,
    "euclidean-clustering": EuclideanClustering,
    "tabletop-clustering": TabletopClustering,
    "kdtree-shape-classifier": KdTreeShapeClassifier,
}


@dataclass(frozen=True)
class Target:
    """An object of the workbench: its map centre (m), shape (semantic tag), size and texture."""

    name: str
    shape: str
    centre: tuple[float, float, float]
    radius: float
    """Half its footprint's diagonal (m): how far its surface reaches from the centre line."""
    textured: bool


@dataclass
class View:
    """One observation: the robot's pose, each object's pixels in view, the three results."""

    pose: tuple[float, float, float]
    pixels: dict[str, int]
    """Pixels of each workbench object in the render (its body and skin, by segmentation)."""
    rgb: dict[str, Any]
    depth: dict[str, Any]
    fused: dict[str, Any]
    camera: tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]
    """The camera's map rotation and position (to score image-frame results)."""


def _record(plugins: dict[str, Plugin], name: str, **override: Any) -> Plugin:
    record = plugins[name]
    if not override:
        return record
    kept = tuple(q for q in record.params if q.name not in override)
    return dataclasses.replace(record, params=kept + tuple(Param(name=k, value=str(v)) for k, v in override.items()))


class Lab:
    """The use case's lab, the Turtlebot and its recognition and fusion services (see the module doc)."""

    def __init__(
        self,
        rgb_profile: str = "VGA",
        depth_profile: str = "QVGA",
        *,
        noise: bool = True,
        seed: int = 0,
        nao: tuple[float, float, float] | None = None,
        nao_profile: str = "VGA",
    ) -> None:
        system = ckmconf.load(USECASE / "lab.xml", strict=False).system
        assert system is not None and system.environment is not None
        self.environment = system.environment
        catalog = read_model(USECASE / "models" / "lab_objects_orb.yml")
        self.world = World(self.environment, catalog=catalog, seed=seed)
        self.skins = dress(self.world, self.environment, catalog)
        self.robot = Robot(self.world, "turtlebot", self.world.load_robot("turtlebot", "turtlebot", (0.0, 0.0, 0.0)))
        for joint, angle in zip(ARM_JOINTS, POSES["rest"].joints or (), strict=True):
            p.resetJointState(self.robot.body, self.robot.joint(joint), angle, physicsClientId=self.world.client)
        self.camera = Camera(self.robot, LINK, fov=XTION_FOV)
        self.size = SIZES[rgb_profile]
        self.rng = np.random.default_rng(seed)
        self.noise = noise
        resource = next(r for r in system.resources if r.name == "RGBDCamera")
        plugins = {plugin.name: plugin for plugin in resource.plugins}
        suffix = {"VGA": "vga", "QVGA": "qvga", "QQVGA": "qqvga"}
        rgb_names = [
            "rgb_acquire",
            f"rgb_resize_{suffix[rgb_profile]}",
            f"orb_{suffix[rgb_profile]}",
            f"match_{suffix[rgb_profile]}",
        ]
        focal = (self.size[0] / 2) / math.tan(self.camera.fov / 2)  # Camera.matrices' focal length
        cx, cy = (self.size[0] - 1) / 2, (self.size[1] - 1) / 2
        intrinsics = {
            "fx": focal,
            "fy": focal,
            "cx": cx,
            "cy": cy,
            "calibrationWidth": self.size[0],
            "calibrationHeight": self.size[1],
        }
        d = suffix[depth_profile]
        depth_records = [
            _record(plugins, "depth_acquire"),
            _record(plugins, f"depth_resize_{d}"),
            dataclasses.replace(_record(plugins, f"cluster_{d}", **intrinsics), kind=TABLETOP),
            _record(plugins, f"shape_{d}"),
        ]
        self.rgb = [KINDS[r.kind](r) for r in (_record(plugins, n) for n in rgb_names)]
        self.depth = [KINDS[r.kind](r) for r in depth_records]
        for plugin in (*self.rgb, *self.depth):
            plugin.setup()
        loc = resource.plugins[0].loc
        given = {
            "inputs": "rgb: line; depth: point",
            "environment": "environment.xml",
            "dThreshold": 3.0,
            "cameras": f"rgb: {focal} {focal} {cx} {cy} {self.size[0]} {self.size[1]}",
            "mounts": f"rgb: turtlebot {LINK}; depth: turtlebot camera_depth_optical_frame",
        }
        self._set_fusion(given, loc)
        self.nao: Robot | None = None
        self.nao_pipeline: list[ProcessingPlugin] = []
        if nao is not None:
            self._add_nao(system, nao, nao_profile, given, loc)
        self.targets = {t.name: t for t in self._targets()}
        self.frames = 0

    def _set_fusion(self, given: dict[str, Any], loc: Any) -> None:
        """The FeatureFusion plugin named ``fusion``, its Params ``given``, set up."""
        record = Plugin(
            name="fusion",
            kind="feature-fusion",
            loc=loc,
            params=tuple(Param(name=k, value=str(v)) for k, v in given.items()),
        )
        self.fusion = FeatureFusion(record)
        self.fusion.setup()

    def _add_nao(
        self, system: Any, pose: tuple[float, float, float], profile: str, given: dict[str, Any], loc: Any
    ) -> None:
        """The Nao at ``pose`` with its top camera, PanTiltCamera's RGB pipeline, and the fusion's
        ``pantilt`` line input mounted on its head (map pose Param ``bases``, angles from ``head``)."""
        self.nao = Robot(self.world, "nao", self.world.load_robot("nao", "nao", pose))
        self.nao_camera = Camera(self.nao, NAO_LINK, fov=NAO_FOV)
        self.nao_size = SIZES[profile]
        resource = next(r for r in system.resources if r.name == "PanTiltCamera")
        plugins = {plugin.name: plugin for plugin in resource.plugins}
        low = profile.lower()
        self.nao_pipeline = [
            KINDS[r.kind](r)
            for r in (plugins[n] for n in ("nao_acquire", f"resize_{low}", f"orb_{low}", f"match_{low}"))
        ]
        for plugin in self.nao_pipeline:
            plugin.setup()
        width, height = self.nao_size
        focal = (width / 2) / math.tan(NAO_FOV / 2)
        given = given | {
            "inputs": "rgb: line; depth: point; pantilt: line",
            "cameras": f"{given['cameras']}; pantilt: {focal} {focal} {(width - 1) / 2} {(height - 1) / 2} "
            f"{width} {height}",
            "mounts": f"{given['mounts']}; pantilt: nao {NAO_LINK}",
            "bases": f"pantilt: {pose[0]} {pose[1]} {pose[2]}",
            "headJoints": "HeadYaw HeadPitch",
        }
        self._set_fusion(given, loc)

    def look(self, pan: float, tilt: float) -> dict[str, Any]:
        """Turn the Nao's head to (pan, tilt) rad, render its top camera once, run PanTiltCamera's pipeline."""
        assert self.nao is not None, "the Lab was made without a Nao"
        cid = self.world.client
        p.resetJointState(self.nao.body, self.nao.joint("HeadYaw"), pan, physicsClientId=cid)
        p.resetJointState(self.nao.body, self.nao.joint("HeadPitch"), tilt, physicsClientId=cid)
        frame = self.nao_camera.render(*self.nao_size)
        context = Context(frame=self.frames, stamp=float(self.frames), resource="PanTiltCamera")
        value: Any = frame.rgb
        for plugin in self.nao_pipeline:
            value = plugin.process(value, context)
        result: dict[str, Any] = value
        return result

    def _targets(self) -> list[Target]:
        textured = set(self.skins.values())
        found = []
        for obj in self.environment.objects:
            if not isinstance(obj.geometry, Geometry25D):
                continue
            prism, base = obj.geometry.prism, obj.geometry.prism.base
            if isinstance(base, Circle):
                reach = base.radius
            elif isinstance(base, Rectangle):
                reach = math.hypot(base.width, base.depth) / 2
            else:
                continue
            centre = (obj.pose.x + base.x, obj.pose.y + base.y, obj.pose.z + (prism.zmin + prism.zmax) / 2)
            found.append(Target(obj.name, obj.tag, centre, reach, obj.name in textured))
        return found

    def close(self) -> None:
        """Close the pybullet world."""
        self.world.close()

    def place(self, x: float, y: float, yaw: float) -> None:
        """Put the robot at (x, y, yaw) in the map (kinematically: no physics step)."""
        orientation = p.getQuaternionFromEuler([0, 0, yaw])
        p.resetBasePositionAndOrientation(self.robot.body, [x, y, 0.0], orientation, physicsClientId=self.world.client)

    def camera_pose(self) -> tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]:
        """The Xtion's optical frame in the map: its rotation matrix (3×3) and position (m)."""
        position, orientation = self.robot.link_pose(self.robot.link(LINK))
        return np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3), np.asarray(position)

    def render(self) -> tuple[np.ndarray[Any, Any], np.ndarray[Any, Any], np.ndarray[Any, Any]]:
        """One render: RGB, depth in mm (uint16, the Xtion's noise and range), segmentation (body ids)."""
        width, height = self.size
        view, projection, _ = self.camera.matrices(width, height)
        _, _, pixels, zbuffer, mask = p.getCameraImage(
            width, height, view, projection, renderer=p.ER_TINY_RENDERER, physicsClientId=self.world.client
        )
        self.camera.renders += 1
        self.frames += 1
        rgb = np.ascontiguousarray(np.asarray(pixels, np.uint8).reshape(height, width, 4)[:, :, :3])
        z = np.asarray(zbuffer, float).reshape(height, width)
        far, near = self.camera.far, self.camera.near
        depth = far * near / (far - (far - near) * z)
        if self.noise:  # the Xtion's axial noise (Nguyen, Izadi and Lovell 2012), as shapes.render_depth_scene
            depth = depth + (0.0012 + 0.0019 * (depth - 0.4) ** 2) * self.rng.standard_normal(depth.shape)
        depth[(depth < XTION_RANGE[0]) | (depth > XTION_RANGE[1])] = 0.0
        return rgb, np.rint(depth * 1000.0).astype(np.uint16), np.asarray(mask).reshape(height, width)

    def visible(self, mask: np.ndarray[Any, Any], name: str) -> int:
        """Pixels of object ``name`` (its body or its skin) in a segmentation mask."""
        ids = [self.world.objects[name], *(b for b, n in self.skins.items() if n == name)]
        return int(np.isin(mask, ids).sum())

    def observe(self, pose: tuple[float, float, float]) -> View:
        """Place the robot, render once, run the RGB and depth pipelines and fuse their two results."""
        self.place(*pose)
        rgb_image, depth_image, mask = self.render()
        context = Context(frame=self.frames, stamp=float(self.frames), resource="RGBDCamera")
        value: Any = rgb_image
        for plugin in self.rgb:
            value = plugin.process(value, context)
        rgb = value
        value = depth_image
        for plugin in self.depth:
            value = plugin.process(value, context)
        depth = value
        estimate = {"stamp": float(self.frames), "pose": {"x": pose[0], "y": pose[1], "yaw": pose[2]}}
        fused = self.fusion.process({"rgb": rgb, "depth": depth, "pose": estimate}, context)
        pixels = {name: self.visible(mask, name) for name in self.targets}
        return View(pose, pixels, rgb, depth, fused, self.camera_pose())
