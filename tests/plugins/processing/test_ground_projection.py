"""``plugin.ground-projection`` (D302): a downward camera's detections placed on the map's floor.

Exact geometry first (a known pose, height and image point give one map point, by hand), then the real
camera: the quadrotor's and the hexarotor's downward ``camera_link`` rendered by pybullet above a red
parcel among green and blue distractors, ``colour-detection`` on the render, and the projection of each
blob landing on its box's top within a few centimetres.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest

import ckmconf
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.colour import ColourDetection
from plugins.processing.ground_projection import GroundProjection, ground_point, mount_of, rotation
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context


def projector(**params: object) -> GroundProjection:
    given = {"fov": "1.2", "mount": "0 0 0 0", **params}
    made = GroundProjection(Plugin(name="ground", kind="ground-projection",
                                   params=tuple(Param(name=k, value=str(v)) for k, v in given.items())))
    made.setup()
    return made


def pose(x: float, y: float, z: float, yaw: float) -> dict[str, Any]:
    return {"stamp": 0.0, "frame": "map", "pose": {"x": x, "y": y, "z": z, "yaw": yaw}}


def detection(*objects: tuple[str, float, float], width: int = 160, height: int = 120) -> dict[str, Any]:
    return {"objects": [{"name": n, "label": n, "x": x, "y": y, "reliability": 0.9} for n, x, y in objects],
            "reliability": 0.9, "width": width, "height": height}


def test_a_downward_mount_is_the_urdf_optical_frame_looking_down_with_the_image_top_ahead() -> None:
    position, turn = mount_of("0.05 0 0.09 0", "t")
    urdf = mount_of("0.05 0 0.09 3.14159265 0 -1.57079633", "t")[1]  # quadrotor.urdf's camera_joint
    assert np.allclose(turn, urdf, atol=1e-7) and np.allclose(position, (0.05, 0, 0.09))
    assert np.allclose(turn @ (0, 0, 1), (0, 0, -1))  # looks down
    assert np.allclose(turn @ (0, -1, 0), (1, 0, 0))  # the image's up is the body's front
    assert np.allclose(turn @ (1, 0, 0), (0, -1, 0))  # the image's right is the body's right
    tilted = mount_of("0 0 0 0.3", "t")[1]
    assert np.allclose(tilted @ (0, 0, 1), (math.sin(0.3), 0, -math.cos(0.3)))  # pitched forward
    with pytest.raises(ParamError, match="is not 'x y z pitch' or 'x y z roll pitch yaw'"):
        mount_of("0 0 0", "t")


def test_exact_geometry_by_hand() -> None:
    # fov 90 degrees: tan(fov/2) = 1; an aspect 4:3 frame given as shares (no pixel size): fy = fx * 4/3
    fx = 0.5
    intrinsics = (fx, fx * 4 / 3, 0.5, 0.5)
    camera = mount_of("0.1 0 -0.05 0", "t")
    body = (np.array([2.0, 3.0, 3.05]), rotation(0.0, 0.0, math.pi / 2))  # facing +y, the camera 3 m up
    centre = ground_point((0.5, 0.5), intrinsics, camera, body, 0.0)
    assert centre is not None and np.allclose(centre, (2.0, 3.1, 0.0))  # under the lens, 0.1 m ahead
    top = ground_point((0.5, 0.0), intrinsics, camera, body, 0.0)  # the image's top edge: 3 x 0.75 ahead
    assert top is not None and np.allclose(top, (2.0, 3.1 + 2.25, 0.0))
    right = ground_point((1.0, 0.5), intrinsics, camera, body, 0.0)  # its right edge: 3 m to the right (+x)
    assert right is not None and np.allclose(right, (5.0, 3.1, 0.0))
    box_top = ground_point((1.0, 0.5), intrinsics, camera, body, 0.3)  # a 0.3 m box's top: 2.7 m below
    assert box_top is not None and np.allclose(box_top, (4.7, 3.1, 0.3))
    rolled = (body[0], rotation(0.1, 0.0, 0.0))  # rolled right by 0.1 rad: the centre ray meets the floor left
    point = ground_point((0.5, 0.5), intrinsics, camera, rolled, 0.0)
    lens_y, lens_z = 3.0 + 0.05 * math.sin(0.1), 3.05 - 0.05 * math.cos(0.1)  # the mount turned with the body
    assert point is not None and np.allclose(point, (2.1, lens_y + lens_z * math.tan(0.1), 0.0))
    assert ground_point((0.5, 0.5), intrinsics, mount_of("0 0 0 1.6", "t"), body, 0.0) is None  # above level


def test_the_plugin_places_each_object_and_projects_a_frame_once() -> None:
    ground = projector(fov=2 * math.atan(1.0), planeHeight=0.3)  # 90 degrees
    frame = detection(("red", 159 / 160, 59.5 / 120), ("blue", 79.5 / 160, 59.5 / 120))
    result = ground.process({"objects": frame, "pose": pose(1.0, 1.0, 2.3, 0.0)}, Context(0, 0.0, "r"))
    assert result is not None
    red, blue = result["objects"]
    assert (red["frame"], red["name"], red["label"]) == ("map", "red", "red") and red["reliability"] == 0.9
    # pixel column 159 of 160 is 79.5 px right of the centre; fx = 80 px: 2 m below, 1.9875 m right (-y)
    assert (red["x"], red["y"], red["z"]) == pytest.approx((1.0, 1.0 - 2.0 * 79.5 / 80, 0.3))
    assert (blue["x"], blue["y"]) == pytest.approx((1.0, 1.0))
    assert red["observer"] == [{"x": 1.0, "y": 1.0, "yaw": 0.0}]
    assert ground.process({"objects": frame, "pose": pose(2.0, 1.0, 2.3, 0.0)}, Context(1, 0.1, "r")) is None
    assert ground.process({"objects": None, "pose": pose(2.0, 1.0, 2.3, 0.0)}, Context(2, 0.1, "r")) is None
    tilted = {"header": {}, "pose": {"position": {"x": 1.0, "y": 1.0, "z": 2.3},  # a PoseStamped, pitched 0.1
                                     "orientation": {"x": 0.0, "y": math.sin(0.05), "z": 0.0, "w": math.cos(0.05)}}}
    again = ground.process({"objects": detection(("blue", 79.5 / 160, 59.5 / 120)), "pose": tilted},
                           Context(3, 0.2, "r"))
    assert again is not None and again["objects"][0]["x"] == pytest.approx(1.0 - 2.0 * math.tan(0.1))  # nose down


def test_shares_without_a_frame_size_need_the_aspect() -> None:
    bare = {"objects": [{"name": "red", "x": 0.5, "y": 0.0, "reliability": 1.0}], "reliability": 1.0}
    with pytest.raises(ValueError, match="give parameter 'aspect'"):
        projector().process({"objects": bare, "pose": pose(0, 0, 2, 0)}, Context(0, 0.0, "r"))
    result = projector(fov=2 * math.atan(1.0), aspect=2.0).process({"objects": bare, "pose": pose(0, 0, 2, 0)},
                                                                   Context(0, 0.0, "r"))
    assert result is not None and result["objects"][0]["x"] == pytest.approx(1.0)  # 2 m x 0.5 / 1.0 ahead


@pytest.mark.parametrize(("params", "message"), [
    ({"fov": None}, "give the camera's field of view: parameter 'fov'"),
    ({"camera": "cam"}, "parameter 'camera' or 'fov', not both"),
    ({"mount": "0 0 1"}, "'mount'"),
])
def test_a_camera_without_its_field_of_view_or_mount_is_refused(params: dict[str, Any], message: str) -> None:
    given = {"fov": "1.2", "mount": "0 0 0 0", **params}
    with pytest.raises(ParamError, match=message):
        GroundProjection(Plugin(name="g", kind="ground-projection",
                                params=tuple(Param(name=k, value=str(v)) for k, v in given.items() if v is not None)))


# ---------------------------------------------------------------------- the real cameras

BOXES = {"parcel": (3.0, 2.0, "red"), "crate": (2.2, 1.4, "green"), "tote": (3.7, 2.7, "blue"),
         "bin": (2.3, 2.8, "green")}
COLOURS = "red: 345-15 0.5 0.3; green: 100-150 0.4 0.3; blue: 200-250 0.4 0.3"
UAVS = {  # model: (base_link's inertial origin height, camera_joint origin, a pose over the boxes: x y z yaw)
    "quadrotor": (0.13, (0.05, 0.0, 0.09), (2.7, 2.2, 3.0, 0.4)),
    "hexarotor": (0.20, (0.06, 0.0, 0.145), (3.2, 1.8, 2.6, -2.5)),
}
SCENE = """<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0" description="boxes on the floor">
  <Environment name="floor" frame="map">
    <Map xmin="0" ymin="0" xmax="6" ymax="5" height="5"/>
    <Texture name="red" pattern="plain" color="#C0392B"/>
    <Texture name="green" pattern="plain" color="#27AE60"/>
    <Texture name="blue" pattern="plain" color="#2E6FD8"/>
    <Semantic tag="box" landmark="free" dynamic="static"/>
    {objects}
  </Environment>
</Part>"""


def side_shift(offset: float, height: float, size: float = 0.3, tall: float = 0.3) -> float:
    """How far a box's blob centroid, projected on its top, moves towards the camera along one axis: a box
    ``offset`` m off the camera's axis also shows its near side, a strip ``near · tall / height`` wide."""
    strip = max(0.0, abs(offset) - size / 2) * tall / height
    return size * strip * (size / 2 + strip / 2) / (size * size + size * strip)


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    objects = "".join(f'<Object name="{n}" tag="box" texture="{t}"><Pose x="{x}" y="{y}"/><Geometry25D>'
                      '<Prism zmax="0.3"><Rectangle width="0.3" depth="0.3"/></Prism></Geometry25D></Object>'
                      for n, (x, y, t) in BOXES.items())
    path: Path = tmp_path_factory.mktemp("ground") / "scene.xml"
    path.write_text(SCENE.replace("{objects}", objects))
    environment = ckmconf.load(path).environment
    assert environment is not None
    made = World(environment, seed=3)
    yield made
    made.close()


@pytest.mark.parametrize("model", sorted(UAVS))
def test_the_uavs_real_camera_renders_place_every_box_on_its_top(world: World, model: str) -> None:
    com, (cx, cy, cz), (x, y, z, yaw) = UAVS[model]
    body = Robot(world, model, world.load_robot(model, model, (x, y, yaw)))
    p.resetBasePositionAndOrientation(body.body, (x, y, z), p.getQuaternionFromEuler((0, 0, yaw)),
                                      physicsClientId=world.client)
    fov, width, height = 1.2, 160, 120
    image = Camera(body, "camera_link", fov=fov).render(width, height).rgb
    colours = ColourDetection(Plugin(name="c", kind="colour-detection", params=(Param(name="colours", value=COLOURS),)))
    seen = colours.process(image, Context(0, 0.0, model))
    # the pose a position fix gives: the base's centre of mass, base_link's inertial origin above its frame
    ground = projector(fov=fov, mount=f"{cx} {cy} {cz - com} 0", planeHeight=0.3)
    placed = ground.process({"objects": seen, "pose": pose(x, y, z, yaw)}, Context(0, 0.0, model))
    assert placed is not None
    found = {o["name"]: o for o in placed["objects"]}
    assert {"red", "green", "blue"} <= set(found), seen
    (lx, ly, lz), _ = body.link_pose(body.link("camera_link"))
    for name, (bx, by, colour) in BOXES.items():
        error = min(math.dist((o["x"], o["y"]), (bx, by)) for o in placed["objects"] if o["name"] == colour)
        assert error < 0.015 + math.hypot(side_shift(bx - lx, lz), side_shift(by - ly, lz)), (model, name, error)
    p.removeBody(body.body, physicsClientId=world.client)
