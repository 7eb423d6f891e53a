"""Texture skins: the learnt prints worn by the textured cylinders and boxes (thesis §6.1.1.1, D116, D145).

pybullet's built-in ``GEOM_CYLINDER`` and ``GEOM_BOX`` get texture coordinates from a planar
projection in metres, so a 7 cm cylinder shows a few magnified texels of its ``<Texture>`` and the
RGB recognition (ORB keypoint matching) never recognises it. A skin is a visual mesh of the same
``<Prism>`` whose texture coordinates put the print upright at its own aspect:

- around a cylinder (``<Circle>`` base) the print repeats ``round(circumference / print width)``
  times, each as high as the cylinder (as a can's label repeats its logo);
- on each side face of a box (``<Rectangle>`` base) the print stands as high as the face at its
  own aspect, cropped to the face's width;
- the caps show the print's centre at the sides' scale.

Orientation (D174): pybullet's texture loader keeps the image's first row at v = 1 (OpenGL's
bottom-up convention), so the print's top is at v = 1 and its left edge at u = 0; u grows left to
right seen from outside (counter-clockwise seen from above, the way the base's corners and the
cylinder's angle run), so every print reads upright and unmirrored.
:class:`~plugins.sim.world.World` gives every textured 2.5D cylinder and box its skin as the body's
own visual shape (its collision shape is unchanged, D145); :func:`dress` adds skins to a world whose
objects do not wear them yet (as separate visual-only bodies).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import pybullet as p

from ckmconf.model import Environment
from ckmconf.model.environment import Circle, Geometry25D, Prism, Rectangle
from plugins.processing.textures import ModelSpec, TextureSpec

from .textures import texture_file, texture_spec


class Dressable(Protocol):
    """What :func:`dress` needs of a world (:class:`plugins.sim.world.World`, which builds skins itself)."""

    client: int
    skins: dict[str, TextureSpec]
    objects: dict[str, int]


SEGMENTS = 48
"""Facets around a cylinder's skin (its radius is at most 0.2 mm short between vertices at 7 cm)."""

OUTSIDE = 0.001
"""How far (m) a separate skin body stands outside its object's own (plain) surface."""

CAP = 0.002
"""Points this close (m) to a skin's top or bottom edge count as on its cap (:func:`texture_point`)."""


@dataclass
class Mesh:
    """A textured triangle mesh as ``createVisualShape(GEOM_MESH, ...)`` takes it."""

    vertices: list[list[float]]
    indices: list[int]
    uvs: list[list[float]]
    normals: list[list[float]]

    def extend(self, other: Mesh) -> None:
        """Append ``other``'s triangles to this mesh."""
        base = len(self.vertices)
        self.vertices += other.vertices
        self.uvs += other.uvs
        self.normals += other.normals
        self.indices += [base + i for i in other.indices]


def _cap(ring: list[tuple[float, float]], z: float, up: bool, scale: tuple[float, float]) -> Mesh:
    """A convex cap at height ``z`` (a fan from its centre), the print's centre at ``scale`` (m per u, v)."""
    su, sv = scale
    points = [(0.0, 0.0), *ring]
    vertices = [[x, y, z] for x, y in points]
    side = 1.0 if up else -1.0  # the bottom cap is seen from below: mirrored in x
    uvs = [[0.5 + side * x / su, 0.5 + y / sv] for x, y in points]
    normals = [[0.0, 0.0, 1.0 if up else -1.0]] * len(points)
    indices: list[int] = []
    for i in range(1, len(ring) + 1):
        j = i % len(ring) + 1
        indices += [0, i, j] if up else [0, j, i]  # counter-clockwise seen from outside
    return Mesh(vertices, indices, uvs, normals)


def tube(radius: float, z0: float, z1: float, repeats: int, segments: int = SEGMENTS) -> Mesh:
    """A closed cylinder's skin: the print ``repeats`` times around (u with the angle, v up), and caps.

    At angle 0 (the object's +x) a copy of the print starts: its left edge, seen from outside."""
    mesh = Mesh([], [], [], [])
    for i in range(segments + 1):
        angle = 2 * math.pi * i / segments
        c, s = math.cos(angle), math.sin(angle)
        for z, v in ((z0, 0.0), (z1, 1.0)):
            mesh.vertices.append([radius * c, radius * s, z])
            mesh.normals.append([c, s, 0.0])
            mesh.uvs.append([repeats * i / segments, v])  # left to right seen from outside, top up
    for i in range(segments):
        a, b, c_, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
        mesh.indices += [a, c_, b, b, c_, d]
    ring = [(radius * math.cos(2 * math.pi * i / segments), radius * math.sin(2 * math.pi * i / segments))
            for i in range(segments)]
    scale = (2 * math.pi * radius / repeats, z1 - z0)
    mesh.extend(_cap(ring, z1, True, scale))
    mesh.extend(_cap(ring, z0, False, scale))
    return mesh


def sides(width: float, depth: float, z0: float, z1: float, aspect: float) -> Mesh:
    """A closed box's skin: each side face with the print upright at its own ``aspect`` (width /
    height), as high as the face and cropped to its width (viewed from outside), and caps."""
    mesh = Mesh([], [], [], [])
    hx, hy = width / 2, depth / 2
    corners = [(hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)]  # counter-clockwise seen from above
    for k in range(4):
        (x0, y0), (x1, y1) = corners[k], corners[(k + 1) % 4]
        length = math.hypot(x1 - x0, y1 - y0)
        normal = [(y1 - y0) / length, -(x1 - x0) / length, 0.0]
        base = len(mesh.vertices)
        share = min(1.0, length / ((z1 - z0) * aspect))  # the print's central share the face shows
        # corners run counter-clockwise seen from above: left to right seen from outside, as on the tube
        for (x, y), u in (((x0, y0), 0.5 - share / 2), ((x1, y1), 0.5 + share / 2)):
            for z, v in ((z0, 0.0), (z1, 1.0)):
                mesh.vertices.append([x, y, z])
                mesh.uvs.append([u, v])
                mesh.normals.append(normal)
        mesh.indices += [base, base + 2, base + 1, base + 1, base + 2, base + 3]
    scale = ((z1 - z0) * aspect, z1 - z0)
    mesh.extend(_cap(corners, z1, True, scale))
    mesh.extend(_cap(corners, z0, False, scale))
    return mesh


def skin_mesh(prism: Prism, spec: TextureSpec, z0: float, z1: float, margin: float = 0.0) -> Mesh | None:
    """The skin of ``prism``'s base (centred on it, yaw excluded) from ``z0`` to ``z1`` wearing
    ``spec``, ``margin`` (m) outside its sides; None for a base neither ``<Circle>`` nor ``<Rectangle>``."""
    base = prism.base
    height = prism.zmax - prism.zmin
    aspect = spec.width / spec.height
    if isinstance(base, Circle):
        return tube(base.radius + margin, z0, z1, repeats(base.radius, height, spec))
    if isinstance(base, Rectangle):
        return sides(base.width + 2 * margin, base.depth + 2 * margin, z0, z1, aspect)
    return None


def repeats(radius: float, height: float, spec: TextureSpec) -> int:
    """How many copies of ``spec``'s print go round a cylinder of ``radius`` and ``height`` (m)."""
    return max(1, round(2 * math.pi * radius / (height * spec.width / spec.height)))


def texture_point(prism: Prism, spec: TextureSpec, point: tuple[float, float, float]) -> tuple[float, float] | None:
    """The texture pixel (x right, y down) the skin of ``prism`` shows at ``point`` of its side.

    ``point`` is in the skin's frame (the body's: centred on the base, z from −height/2 to
    height/2, as :class:`~plugins.sim.world.World` builds it). None on a cap (within ``CAP`` of
    the top or bottom), or for a base neither ``<Circle>`` nor ``<Rectangle>``. The inverse of the
    skin's texture mapping: keypoints learnt from rendered views are placed in the print with it (D175).
    """
    x, y, z = point
    height = prism.zmax - prism.zmin
    up = z / height + 0.5
    if not CAP / height < up < 1.0 - CAP / height:
        return None
    row = (1.0 - up) * spec.height
    base = prism.base
    if isinstance(base, Circle):
        turn = math.atan2(y, x) % (2 * math.pi) / (2 * math.pi)
        return (repeats(base.radius, height, spec) * turn) % 1.0 * spec.width, row
    if isinstance(base, Rectangle):
        hx, hy = base.width / 2, base.depth / 2
        corners = [(hx, -hy), (hx, hy), (-hx, hy), (-hx, -hy)]
        nearest: tuple[float, float] | None = None
        for k in range(4):  # the face whose plane the point is nearest, as sides() builds them
            (x0, y0), (x1, y1) = corners[k], corners[(k + 1) % 4]
            length = math.hypot(x1 - x0, y1 - y0)
            off = abs((x - x0) * (y1 - y0) - (y - y0) * (x1 - x0)) / length
            along = ((x - x0) * (x1 - x0) + (y - y0) * (y1 - y0)) / length**2
            share = min(1.0, length / (height * spec.width / spec.height))
            u = 0.5 - share / 2 + share * min(max(along, 0.0), 1.0)
            if nearest is None or off < nearest[0]:
                nearest = (off, u)
        assert nearest is not None
        return nearest[1] * spec.width, row
    return None


def visual_shape(client: int, mesh: Mesh) -> int:
    """The pybullet visual shape of ``mesh`` in world ``client``."""
    return int(p.createVisualShape(p.GEOM_MESH, vertices=mesh.vertices, indices=mesh.indices, uvs=mesh.uvs,
                                   normals=mesh.normals, physicsClientId=client))


def wear(client: int, body: int, spec: TextureSpec) -> None:
    """Paint ``body``'s base visual with ``spec``'s print (its PNG from the texture cache)."""
    texture = p.loadTexture(str(texture_file(spec)), physicsClientId=client)
    p.changeVisualShape(body, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1], physicsClientId=client)


def dress(world: Dressable, environment: Environment, catalog: ModelSpec | None) -> dict[int, str]:
    """Every textured 2.5D cylinder and box of ``environment`` wearing its print: body ids → object.

    An object ``world`` built with the same print (:attr:`World.skins`) keeps its own body; one
    it did not skin gets a visual-only skin body at its present pose. ValueError names an object
    the world built wearing another print (a world made with another model file)."""
    bodies: dict[int, str] = {}
    cid = world.client
    for obj in environment.objects:
        spec = texture_spec(environment, obj.name, catalog)
        if spec is None or not isinstance(obj.geometry, Geometry25D):
            continue
        worn = world.skins.get(obj.name)
        if worn is not None:
            if worn != spec:
                raise ValueError(f"object {obj.name!r} wears texture {worn.name!r} (seed {worn.seed}), not the "
                                 f"model's {spec.name!r} (seed {spec.seed}): build the World with that catalog")
            bodies[world.objects[obj.name]] = obj.name
            continue
        prism = obj.geometry.prism
        mesh = skin_mesh(prism, spec, prism.zmin, prism.zmax, OUTSIDE)
        if mesh is None:
            continue
        base: Any = prism.base
        yaw = obj.pose.yaw + (base.yaw if isinstance(base, Rectangle) else 0.0)
        c, s = math.cos(obj.pose.yaw), math.sin(obj.pose.yaw)
        at = [obj.pose.x + c * base.x - s * base.y, obj.pose.y + s * base.x + c * base.y, obj.pose.z]
        body = int(p.createMultiBody(0, -1, visual_shape(cid, mesh), at, p.getQuaternionFromEuler([0, 0, yaw]),
                                     physicsClientId=cid))
        wear(cid, body, spec)
        bodies[body] = obj.name
    return bodies
