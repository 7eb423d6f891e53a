"""Texture skins read upright and unmirrored (plugins/sim/skins.py, D174): a skinned box face and a
skinned cylinder rendered face-on by pybullet's TinyRenderer show their print as the texture image
is drawn (top up, left on the left), and the cylinder shows the copy's column its angle predicts."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pybullet as p
import pytest
from ckm_lab.scenes import USECASE_MODEL

from ckmconf.loader import load
from ckmconf.model import Environment
from ckmconf.model.environment import Circle, Geometry25D, Rectangle
from plugins.processing.textures import read_model, render_texture
from plugins.sim.skins import skin_mesh, texture_point
from plugins.sim.world import World
from tests.conftest import CONFIGS

SIZE = 480
FOV = 20.0
VARIANTS = {"upright": lambda t: t, "upside down": np.flipud, "mirrored": np.fliplr, "turned": lambda t: t[::-1, ::-1]}


def _environment() -> Environment:
    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    assert environment is not None
    return environment


ENVIRONMENT = _environment()


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    made = World(ENVIRONMENT, seed=1, catalog=read_model(USECASE_MODEL))
    yield made
    made.close()


def _look(world: World, target: tuple[float, float, float], azimuth: float, distance: float) -> tuple[Any, Any]:
    """A render (grey image, segmentation) from ``distance`` m at ``azimuth`` (map rad) level with ``target``."""
    x, y, z = target
    eye = [x + distance * math.cos(azimuth), y + distance * math.sin(azimuth), z]
    view = p.computeViewMatrix(eye, list(target), [0, 0, 1])
    projection = p.computeProjectionMatrixFOV(FOV, 1.0, 0.05, 5.0)
    _, _, rgb, _, mask = p.getCameraImage(SIZE, SIZE, view, projection, renderer=p.ER_TINY_RENDERER,
                                          physicsClientId=world.client)
    image = np.asarray(rgb, np.uint8).reshape(SIZE, SIZE, 4)[:, :, :3]
    return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY), np.asarray(mask).reshape(SIZE, SIZE)


def _crop(grey: Any, mask: Any, body: int, margin: float) -> Any:
    """The object's pixels, its bounding box shrunk by ``margin`` (a share) on every side."""
    rows, cols = np.nonzero(mask == body)
    top, bottom, left, right = rows.min(), rows.max(), cols.min(), cols.max()
    dy, dx = int((bottom - top) * margin), int((right - left) * margin)
    return grey[top + dy : bottom - dy, left + dx : right - dx]


def _scores(patch: Any, texture: Any) -> dict[str, tuple[float, int]]:
    """Best normalised correlation of ``patch`` in each variant of ``texture`` and its column."""
    found = {}
    for name, turn in VARIANTS.items():
        image = np.ascontiguousarray(turn(texture))
        score = cv2.matchTemplate(image, patch, cv2.TM_CCOEFF_NORMED)
        _, best, _, at = cv2.minMaxLoc(score)
        found[name] = (float(best), int(at[0]))
    return found


def _grey(name: str) -> Any:
    spec = next(o for o in read_model(USECASE_MODEL).objects if o.name == name)
    return cv2.cvtColor(np.ascontiguousarray(render_texture(spec)), cv2.COLOR_RGB2GRAY)


def test_a_box_face_shows_its_print_upright_and_unmirrored(world: World) -> None:
    """box_cereal's +x face (turned by the box's yaw) seen face-on: the central share of the print."""
    obj = next(o for o in ENVIRONMENT.objects if o.name == "box_cereal")
    assert isinstance(obj.geometry, Geometry25D) and isinstance(obj.geometry.prism.base, Rectangle)
    prism, base = obj.geometry.prism, obj.geometry.prism.base
    centre = (obj.pose.x, obj.pose.y, obj.pose.z + (prism.zmin + prism.zmax) / 2)
    grey, mask = _look(world, centre, obj.pose.yaw + base.yaw, 0.5)
    texture = _grey("box_cereal")
    h, w = texture.shape
    height = prism.zmax - prism.zmin
    shown = w * base.depth / (height * w / h)  # the face's width in texture pixels (the print as high as the face)
    patch = _crop(grey, mask, world.objects["box_cereal"], 0.12)
    patch = cv2.resize(patch, (round(shown * 0.76), round(h * 0.76)), interpolation=cv2.INTER_AREA)
    scores = _scores(patch, texture)
    upright = scores["upright"][0]
    assert upright > 0.9, scores
    assert all(upright > score + 0.15 for name, (score, _) in scores.items() if name != "upright"), scores
    assert abs(scores["upright"][1] + patch.shape[1] / 2 - w / 2) < 0.05 * w  # the print's centre faces out


@pytest.mark.parametrize("azimuth", [-math.pi / 2, math.pi / 2, 0.4])
def test_a_cylinder_shows_its_print_upright_unmirrored_at_the_column_its_angle_predicts(
    world: World, azimuth: float
) -> None:
    """The strip of cylinder_red_stripes facing the camera is the print's column ``repeats · angle / 2π``."""
    obj = next(o for o in ENVIRONMENT.objects if o.name == "cylinder_red_stripes")
    assert isinstance(obj.geometry, Geometry25D) and isinstance(obj.geometry.prism.base, Circle)
    prism, radius = obj.geometry.prism, obj.geometry.prism.base.radius
    centre = (obj.pose.x, obj.pose.y, obj.pose.z + (prism.zmin + prism.zmax) / 2)
    grey, mask = _look(world, centre, azimuth, 0.45)
    texture = _grey("cylinder_red_stripes")
    h, w = texture.shape
    height = prism.zmax - prism.zmin
    repeats = max(1, round(2 * math.pi * radius / (height * w / h)))
    strip = _crop(grey, mask, world.objects["cylinder_red_stripes"], 0.0)
    rows, cols = strip.shape
    middle = strip[int(rows * 0.1) : int(rows * 0.9), int(cols * 0.3) : int(cols * 0.7)]
    per_metre = repeats * w / (2 * math.pi * radius)  # texture columns per metre of arc
    width = round(2 * math.asin(0.4) * radius * per_metre)  # the arc behind the middle two fifths
    patch = cv2.resize(middle, (width, round(0.8 * h)), interpolation=cv2.INTER_AREA)
    tiled = np.hstack([texture, texture])  # the strip may straddle the end of one copy and the next
    scores = _scores(patch, tiled)
    upright, column = scores["upright"]
    assert upright > 0.75, scores
    assert all(upright > score + 0.15 for name, (score, _) in scores.items() if name != "upright"), scores
    expected = (repeats * (azimuth - obj.pose.yaw) / (2 * math.pi)) % 1.0 * w
    offset = (column + width / 2 - expected + w / 2) % w - w / 2
    assert abs(offset) < 0.06 * w, (column, expected)


@pytest.mark.parametrize("name", ["cylinder_red_stripes", "box_cereal"])
def test_texture_point_inverts_the_skin_mapping(name: str) -> None:
    """Every side vertex of a skin maps back to the print pixel its texture coordinates show: the map
    the keypoints learnt from rendered views are placed in the print with (D175)."""
    obj = next(o for o in ENVIRONMENT.objects if o.name == name)
    assert isinstance(obj.geometry, Geometry25D)
    prism = obj.geometry.prism
    spec = next(o for o in read_model(USECASE_MODEL).objects if o.name == name)
    half = (prism.zmax - prism.zmin) / 2
    mesh = skin_mesh(prism, spec, -half, half)
    assert mesh is not None
    checked = 0
    for k in range(0, len(mesh.indices), 3):
        corners = mesh.indices[k : k + 3]
        if any(mesh.normals[i][2] != 0.0 for i in corners):
            continue  # a cap
        # the triangle's centroid, which its corners' texture coordinates interpolate
        centre = np.mean([mesh.vertices[i] for i in corners], axis=0)
        u, v = np.mean([mesh.uvs[i] for i in corners], axis=0)
        at = texture_point(prism, spec, (float(centre[0]), float(centre[1]), float(centre[2])))
        assert at is not None
        expected = (u % 1.0 if spec.wrap else u) * spec.width, (1.0 - v) * spec.height
        gap = abs(at[0] - expected[0])
        assert min(gap, spec.width - gap) < 0.5 and abs(at[1] - expected[1]) < 0.5, (centre, (u, v), at)
        checked += 1
    assert checked >= 8  # a box: 4 faces of 2 triangles; a cylinder: 2 per facet
    assert texture_point(prism, spec, (0.0, 0.0, half)) is None  # the top cap
