"""The pybullet world of the simulated laboratory, built from an ``<Environment>`` (thesis §6.1, §7.1).

- DIRECT mode only (headless; TinyRenderer is the only renderer), and every call passes the
  world's ``physicsClientId`` so one process can hold several worlds (tests, one per scope).
- A fixed time step (default 1/240 s) and ``deterministicOverlappingPairs``: the same seed and
  the same commands give the same sensor data.
- Map bounds → floor and four walls; ``<AvoidedArea>`` → obstacles its ``height`` tall (the map's
  when absent); ``<Object>`` prisms → static bodies, except objects whose semantic tag affords
  ``pick``, which are dynamic (they can be grasped and carried); a 2D-only object stands its
  ``<Geometry2D height>`` tall (``FOOTPRINT_HEIGHT`` of ``ckmconf.model.environment``, 0.75 m, when
  absent), and at ``height="0"`` is a marking: a visual-only slab ``MARKING_THICKNESS`` thick that
  the cameras see and nothing hits (D294).
- A textured 2.5D cylinder or box wears a texture skin (:mod:`plugins.sim.skins`, D145) as its
  visual shape: its print upright at its own aspect, which the RGB recognition knows; its collision
  shape is the plain prism's.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pybullet as p

from ckmconf.model import Environment
from ckmconf.model.environment import (
    Circle,
    EnvObject,
    Geometry2D,
    Geometry3D,
    Geometry25D,
    Polygon,
    Prism,
    Rectangle,
)
from plugins.processing.textures import ModelSpec, TextureSpec, rgb

from .skins import skin_mesh, visual_shape
from .textures import texture_file, texture_spec

MODELS = Path(__file__).with_name("models")
"""The robot models (URDF) shipped with the package."""
MARKING_THICKNESS = 0.004
"""Thickness (m) of a marking's slab (``<Geometry2D height="0">``): above the floor, so a camera sees its top."""
DENSITY = 300.0
"""Density (kg/m³) of the movable objects: a 12 cm cylinder of radius 3.5 cm weighs 0.14 kg."""
WALL = 0.1
"""Wall thickness (m), outside the map bounds."""


def _rgba(color: str) -> list[float]:
    r, g, b = rgb(color)
    return [r / 255, g / 255, b / 255, 1.0]


@dataclass
class Shape:
    """One prism as pybullet shape arguments (position relative to the object's pose)."""

    kind: int
    kwargs: dict[str, Any]
    offset: tuple[float, float, float]
    yaw: float
    volume: float


def prism_shape(prism: Prism) -> Shape:
    """The pybullet shape of one ``<Prism>`` (its 2D base extruded from zmin to zmax)."""
    height = prism.zmax - prism.zmin
    zc = (prism.zmin + prism.zmax) / 2
    base = prism.base
    if isinstance(base, Circle):
        volume = math.pi * base.radius**2 * height
        return Shape(p.GEOM_CYLINDER, {"radius": base.radius, "height": height}, (base.x, base.y, zc), 0.0, volume)
    if isinstance(base, Rectangle):
        half = [base.width / 2, base.depth / 2, height / 2]
        volume = base.width * base.depth * height
        return Shape(p.GEOM_BOX, {"halfExtents": half}, (base.x, base.y, zc), base.yaw, volume)
    assert isinstance(base, Polygon)
    points = [(v.x, v.y) for v in base.vertices]
    return _polygon_shape(points, prism.zmin, prism.zmax)


def _polygon_shape(points: Sequence[tuple[float, float]], zmin: float, zmax: float) -> Shape:
    """A convex mesh of a polygon extruded (pybullet takes the convex hull of the vertices)."""
    cx = sum(x for x, _ in points) / len(points)
    cy = sum(y for _, y in points) / len(points)
    zc = (zmin + zmax) / 2
    h = (zmax - zmin) / 2
    vertices = [[x - cx, y - cy, z] for z in (-h, h) for x, y in points]
    ring = zip(points, [*points[1:], points[0]], strict=True)
    area = 0.5 * abs(sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in ring))
    return Shape(p.GEOM_MESH, {"vertices": vertices}, (cx, cy, zc), 0.0, area * 2 * h)


def _prisms(obj: EnvObject) -> list[Prism]:
    """The object's prisms as the world builds them: a 2D footprint extruded to its height (a marking: a slab)."""
    geometry = obj.geometry
    if isinstance(geometry, Geometry3D):
        return list(geometry.prisms)
    if isinstance(geometry, Geometry2D):
        top = MARKING_THICKNESS if geometry.marking else geometry.solid_height
        return [Prism(zmin=0.0, zmax=top, base=atom) for atom in geometry.atoms]
    return [geometry.prism]


def _is_marking(obj: EnvObject) -> bool:
    return isinstance(obj.geometry, Geometry2D) and obj.geometry.marking


class World:
    """A headless pybullet world; ``environment`` (optional) is built into it.

    Args:
        environment: the ``<Environment>`` record to build (None: an empty floor).
        seed: seeds every random draw of the world and of the devices made from it.
        time_step: the fixed physics step, seconds.
        catalog: the RGB recognition's model file, whose textures paint the objects it names.
    """

    def __init__(
        self,
        environment: Environment | None = None,
        *,
        seed: int = 0,
        time_step: float = 1.0 / 240.0,
        catalog: ModelSpec | None = None,
    ) -> None:
        self.client = p.connect(p.DIRECT)
        self.seed = seed
        self.rng = random.Random(seed)
        self.time_step = time_step
        self.time = 0.0
        self.steps = 0
        self.objects: dict[str, int] = {}
        """Body ids of the environment objects by name (a multi-prism static object: its first prism)."""
        self.robots: dict[str, int] = {}
        self.skins: dict[str, TextureSpec] = {}
        """The print each object wearing a texture skin wears, by object name (D145)."""
        self.torques: dict[tuple[int, int], float] = {}
        """Joint torques held across steps (effort-mode joints), by (body, joint)."""
        self.hooks: list[Callable[[World], None]] = []
        """Called after each advance (:meth:`step`): a scenario's disturbances (D178) fire there."""
        self.before_step: list[Callable[[], None]] = []
        """Called before every physics step: an external force lasts one step only (a multirotor's
        thrust, :mod:`plugins.sim.flight`, D293), so whatever pushes a body pushes it again there."""
        cid = self.client
        p.resetSimulation(physicsClientId=cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=time_step, deterministicOverlappingPairs=1, numSolverIterations=50, physicsClientId=cid
        )
        p.setGravity(0, 0, -9.81, physicsClientId=cid)
        self.floor = self._static_box([0, 0, -0.05], [50, 50, 0.05], [0.85, 0.85, 0.8, 1.0])
        if environment is not None:
            self.build(environment, catalog)

    # ------------------------------------------------------------------ construction

    def _static_box(
        self, centre: Sequence[float], half: Sequence[float], rgba: Sequence[float], yaw: float = 0.0
    ) -> int:
        cid = self.client
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=cid)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=list(half), rgbaColor=list(rgba), physicsClientId=cid)
        orn = p.getQuaternionFromEuler([0, 0, yaw])
        return int(p.createMultiBody(0, col, vis, list(centre), orn, physicsClientId=cid))

    def _body(
        self,
        shape: Shape,
        pose: tuple[float, float, float, float],
        mass: float,
        rgba: list[float],
        visual: int = -1,
        collides: bool = True,
    ) -> int:
        """A body of ``shape`` at the object ``pose``; ``visual`` (a visual shape id) replaces its plain look.

        ``collides=False``: a visual-only body (a marking) that rays, robots and objects pass through.
        """
        cid = self.client
        x, y, z, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        ox, oy, oz = shape.offset
        position = [x + c * ox - s * oy, y + s * ox + c * oy, z + oz]
        orn = p.getQuaternionFromEuler([0, 0, yaw + shape.yaw])
        args = dict(shape.kwargs)
        col = p.createCollisionShape(shape.kind, physicsClientId=cid, **args) if collides else -1
        if shape.kind == p.GEOM_CYLINDER:
            args["length"] = args.pop("height")
        if shape.kind == p.GEOM_MESH:  # a visual mesh needs triangles: fan the two caps and the sides
            args["indices"] = _prism_indices(len(args["vertices"]) // 2)
        vis = visual if visual >= 0 else p.createVisualShape(shape.kind, rgbaColor=rgba, physicsClientId=cid, **args)
        return int(p.createMultiBody(mass, col, vis, position, orn, physicsClientId=cid))

    def build(self, environment: Environment, catalog: ModelSpec | None = None) -> None:
        """Add the map's walls, the avoided areas and the objects of ``environment``."""
        bounds = environment.map
        height = bounds.height
        grey = [0.75, 0.75, 0.72, 1.0]
        cx, cy = (bounds.xmin + bounds.xmax) / 2, (bounds.ymin + bounds.ymax) / 2
        hx, hy = (bounds.xmax - bounds.xmin) / 2 + WALL, (bounds.ymax - bounds.ymin) / 2 + WALL
        for centre, half in (
            ([cx, bounds.ymin - WALL / 2, height / 2], [hx, WALL / 2, height / 2]),
            ([cx, bounds.ymax + WALL / 2, height / 2], [hx, WALL / 2, height / 2]),
            ([bounds.xmin - WALL / 2, cy, height / 2], [WALL / 2, hy, height / 2]),
            ([bounds.xmax + WALL / 2, cy, height / 2], [WALL / 2, hy, height / 2]),
        ):
            self._static_box(centre, half, grey)
        for area in environment.avoided:
            shape = _polygon_shape(area.points(), 0.0, area.top(height))
            self.objects[area.name] = self._body(shape, (0.0, 0.0, 0.0, 0.0), 0.0, grey)
        movable = {s.tag for s in environment.semantics if any(a.action == "pick" for a in s.affordances)}
        colours = {t.name: _rgba(t.color) for t in environment.textures}
        for obj in environment.objects:
            self._add_object(environment, obj, obj.tag in movable, colours, catalog)

    def _add_object(
        self, environment: Environment, obj: EnvObject, movable: bool, colours: dict[str, list[float]],
        catalog: ModelSpec | None,
    ) -> None:
        cid = self.client
        rgba = colours.get(obj.texture or "", [0.5, 0.5, 0.5, 1.0])
        spec = texture_spec(environment, obj.name, catalog)
        texture = -1
        if spec is not None:
            texture = p.loadTexture(str(texture_file(spec)), physicsClientId=cid)
            rgba = [1.0, 1.0, 1.0, 1.0]
        pose = (obj.pose.x, obj.pose.y, obj.pose.z, obj.pose.yaw)
        solid = not _is_marking(obj)
        movable = movable and solid  # a marking is never carried (ckm-validate refuses a pickable one)
        first = -1
        for prism in _prisms(obj):
            shape = prism_shape(prism)
            half = (prism.zmax - prism.zmin) / 2  # the body's origin is the prism's centre
            skin = None
            if spec is not None and isinstance(obj.geometry, Geometry25D):
                skin = skin_mesh(prism, spec, -half, half)
            visual = visual_shape(cid, skin) if skin is not None else -1
            body = self._body(shape, pose, DENSITY * shape.volume if movable else 0.0, rgba, visual, solid)
            if texture >= 0:
                p.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=rgba, physicsClientId=cid)
            if skin is not None and spec is not None:
                self.skins[obj.name] = spec
            if movable:
                p.changeDynamics(body, -1, lateralFriction=1.0, spinningFriction=0.001, physicsClientId=cid)
            first = body if first < 0 else first
        self.objects[obj.name] = first

    def load_robot(self, name: str, model: str | Path, pose: Sequence[float] = (0.0, 0.0, 0.0)) -> int:
        """Load a robot URDF at ``pose`` (x, y, yaw); a bare model name is looked up in :data:`MODELS`."""
        path = Path(model)
        if not path.suffix:
            path = MODELS / f"{model}.urdf"
        if not path.is_file():
            raise FileNotFoundError(f"robot model {str(path)!r} (robot {name!r}) does not exist")
        x, y, yaw = ([*list(pose), 0.0, 0.0, 0.0])[:3]
        body = int(p.loadURDF(str(path), [x, y, 0.0], p.getQuaternionFromEuler([0, 0, yaw]),
                              flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=self.client))
        for link in range(-1, p.getNumJoints(body, physicsClientId=self.client)):
            name_of = p.getJointInfo(body, link, physicsClientId=self.client)[12].decode() if link >= 0 else ""
            if "caster" in name_of:  # casters slide: the wheels alone carry the traction
                p.changeDynamics(body, link, lateralFriction=0.0, rollingFriction=0.0, physicsClientId=self.client)
        self.robots[name] = body
        return body

    # ------------------------------------------------------------------ time

    def step(self, count: int = 1) -> None:
        """Advance the physics by ``count`` fixed steps, then call the :attr:`hooks`."""
        for _ in range(count):
            # pybullet applies a torque-control command for one step only: re-apply the held ones
            for (body, joint), torque in self.torques.items():
                p.setJointMotorControl2(body, joint, p.TORQUE_CONTROL, force=torque, physicsClientId=self.client)
            for push in self.before_step:
                push()
            p.stepSimulation(physicsClientId=self.client)
        self.steps += count
        self.time = self.steps * self.time_step
        if count > 0:
            for hook in self.hooks:
                hook(self)

    def run_until(self, time: float) -> int:
        """Step while a whole step fits before ``time`` (simulated seconds); returns the steps taken."""
        count = max(0, math.floor((time - self.time) / self.time_step + 1e-9))
        self.step(count)
        return count

    def pose(self, body: int) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """Position and orientation quaternion of a body's base."""
        position, orientation = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        return tuple(position), tuple(orientation)

    def movable_positions(self) -> dict[str, list[float]]:
        """Where every body that can move stands now (objects with mass, robots' bases): name → x, y, z."""
        bodies = {**{n: b for n, b in self.objects.items()
                     if p.getDynamicsInfo(b, -1, physicsClientId=self.client)[0] > 0.0}, **self.robots}  # fmt: skip
        return {name: [round(v, 4) for v in self.pose(body)[0]] for name, body in bodies.items()}

    def object_poses(self) -> dict[str, list[float]]:
        """Every object with mass: name → x, y, z and its tilt (rad between its up axis and the vertical)."""
        poses = {}
        for name, body in self.objects.items():
            if p.getDynamicsInfo(body, -1, physicsClientId=self.client)[0] <= 0.0:
                continue
            position, orientation = self.pose(body)
            up = p.getMatrixFromQuaternion(orientation)[8]  # the body's z axis, its vertical component
            poses[name] = [round(v, 4) for v in (*position, math.acos(max(-1.0, min(1.0, up))))]
        return poses

    def close(self) -> None:
        """Disconnect from the physics server (idempotent)."""
        if self.client >= 0:
            p.disconnect(physicsClientId=self.client)
            self.client = -1

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _prism_indices(n: int) -> list[int]:
    """Triangles of a convex prism whose 2n vertices are the bottom ring then the top ring."""
    indices: list[int] = []
    for i in range(1, n - 1):
        indices += [0, i + 1, i, n, n + i, n + i + 1]
    for i in range(n):
        j = (i + 1) % n
        indices += [i, j, n + j, i, n + j, n + i]
    return indices
