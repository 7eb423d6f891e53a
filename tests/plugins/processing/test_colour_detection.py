"""``plugin.colour-detection`` (issue M, point 2: detection by colour) on renders of two robots' cameras.

A red parcel and a green crate on a work table, seen from the station arm's wrist camera (320 × 240,
87°), and a red parcel and a green crate on the floor, seen from a Turtlebot's Xtion (640 × 480, 58°):
each colour's blob must be named after its colour where the object truly projects, the other colour
never taken for it; bad ``colours`` Params are refused naming the entry.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
import pytest
from ckm_lab.arm import ARM_JOINTS, POSES
from ckm_lab.devices import XTION_FOV

import ckmconf
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.colour import ColourDetection
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.registry import Registry
from runtime.resources.spt import Context, Topology
from runtime.verification.verify import verify
from tests.conftest import REPO as ROOT

COLOURS = "parcel: 350-15 0.5 0.3; crate: 100-150 0.4 0.3"
"""Red (through 0°) and green, as a user would write them for these two objects."""

OBJECTS = {  # name: (x, y, z of the base, height, texture)
    "table_parcel": (1.5, 0.92, 0.72, 0.08, "red"), "table_crate": (1.62, 1.12, 0.72, 0.10, "green"),
    "floor_parcel": (4.2, 2.3, 0.0, 0.12, "red"), "floor_crate": (4.3, 2.85, 0.0, 0.12, "green"),
}


def _object(name: str) -> str:
    x, y, z, height, texture = OBJECTS[name]
    return (f'<Object name="{name}" tag="box" texture="{texture}"><Pose x="{x}" y="{y}" z="{z}"/>'
            f'<Geometry25D><Prism zmax="{height}"><Rectangle width="0.08" depth="0.08"/></Prism></Geometry25D>'
            "</Object>")


SCENE = f"""<?xml version="1.0" encoding="UTF-8"?>
<Part xmlns="urn:ckm:1" version="1.0" description="coloured boxes on a table and on the floor">
  <Environment name="colours" frame="map">
    <Map xmin="0" ymin="0" xmax="5.5" ymax="4" height="2"/>
    <Texture name="red" pattern="plain" color="#C0392B"/>
    <Texture name="green" pattern="plain" color="#27AE60"/>
    <Texture name="wood" pattern="plain" color="#D2B48C"/>
    <Semantic tag="table" landmark="landmark" dynamic="static"/>
    <Semantic tag="box" landmark="free" dynamic="static"/>
    <Object name="table" tag="table" texture="wood"><Pose x="1.6" y="1.0"/>
      <Geometry3D><Prism zmin="0.68" zmax="0.72"><Rectangle width="0.8" depth="0.6"/></Prism>
        <Prism zmin="0" zmax="0.68"><Rectangle width="0.1" depth="0.1"/></Prism></Geometry3D></Object>
    {"".join(_object(n) for n in OBJECTS)}
  </Environment>
</Part>"""

CAMERAS = {  # robot: (URDF, camera link, pose, fov, width, height, the objects in its view)
    "station_arm": ("station_arm", "wrist_camera_optical_frame", (1.0, 1.0, 0.0), 1.5184, 320, 240, "table"),
    "turtlebot": ("turtlebot", "camera_rgb_optical_frame", (3.4, 2.55, 0.0), XTION_FOV, 640, 480, "floor"),
}


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Iterator[World]:
    path: Path = tmp_path_factory.mktemp("colours") / "scene.xml"
    path.write_text(SCENE)
    environment = ckmconf.load(path).environment
    assert environment is not None
    made = World(environment, seed=2)
    yield made
    made.close()


def detector(**params: object) -> ColourDetection:
    given = {"colours": COLOURS, **params}
    return ColourDetection(Plugin(name="colour", kind="colour-detection",
                                  params=tuple(Param(name=k, value=str(v)) for k, v in given.items())))


def view(world: World, robot: str) -> tuple[np.ndarray[Any, Any], Camera]:
    urdf, link, pose, fov, width, height, _ = CAMERAS[robot]
    body = Robot(world, robot, world.load_robot(robot, urdf, pose))
    if robot == "station_arm":  # leaning over the table, the wrist camera looking down at it
        for joint, angle in (("shoulder_joint", 0.3), ("elbow_joint", 1.9)):
            p.resetJointState(body.body, body.joint(joint), angle, physicsClientId=world.client)
    else:  # the arm folded at rest, out of the Xtion's view
        for joint, angle in zip(ARM_JOINTS, POSES["rest"].joints or (), strict=True):
            p.resetJointState(body.body, body.joint(joint), angle, physicsClientId=world.client)
    camera = Camera(body, link, fov=fov)
    return camera.render(width, height).rgb, camera


@pytest.mark.parametrize("robot", sorted(CAMERAS))
def test_each_colour_is_found_where_its_object_projects_on_two_robots_cameras(world: World, robot: str) -> None:
    image, camera = view(world, robot)
    width, height, place = CAMERAS[robot][4], CAMERAS[robot][5], CAMERAS[robot][6]
    result = detector().process(image, Context(0, 0.0, robot))
    assert (result["width"], result["height"]) == (width, height)
    for colour in ("parcel", "crate"):
        x, y, z, tall, _ = OBJECTS[f"{place}_{colour}"]
        u, v, _ = camera.project((x, y, z + tall / 2))
        focal = (width / 2) / math.tan(camera.fov / 2)
        column, row = (focal * u + (width - 1) / 2) / width, (focal * v + (height - 1) / 2) / height
        named = [o for o in result["objects"] if o["name"] == colour]
        assert named, (colour, result)
        best = named[0]
        assert math.dist((best["x"], best["y"]), (column, row)) < 0.05, (colour, best, (column, row))
        assert best["reliability"] > 0.6 and best["points"] > 50, best
    assert 0.6 < result["reliability"] <= 1.0


def test_bgr_frames_and_a_colour_nobody_shows(world: World) -> None:
    image, _ = view(world, "station_arm")
    rgb = detector().process(image, Context(0, 0.0, "s"))
    bgr = detector(encoding="bgr8").process(np.ascontiguousarray(image[..., ::-1]), Context(1, 0.0, "s"))
    assert bgr == rgb
    nobody = detector(colours="violet: 270-300 0.5 0.3").process(image, Context(2, 0.0, "s"))
    assert nobody["objects"] == [] and nobody["reliability"] == 0.0


def test_a_synthetic_blob_s_centroid_and_reliability() -> None:
    image = np.zeros((100, 200, 3), np.uint8)
    image[20:40, 50:90] = (200, 30, 30)  # a red 40 × 20 rectangle: solid
    result = detector(minArea=0.001).process(image, Context(0, 0.0, "x"))
    (parcel,) = result["objects"]
    assert parcel["points"] == 800 and (parcel["x"], parcel["y"]) == pytest.approx((69.5 / 200, 29.5 / 100))
    assert parcel["reliability"] == pytest.approx(1.0 - math.exp(-800 / 80), abs=0.02)


@pytest.mark.parametrize("colours", ["parcel 350-15 0.5 0.3", "parcel: 350 0.5 0.3", "parcel: 10-20 2 0.3",
                                     "parcel: a-b 0.5 0.3", "parcel: 0-10 0.5 0.3; parcel: 20-30 0.5 0.3", " ; "])
def test_bad_colours_are_refused_naming_the_entry(colours: str) -> None:
    with pytest.raises(ParamError, match=r"plugin 'colour' \(colour-detection\): parameter 'colours'"):
        detector(colours=colours)


def test_a_frame_that_is_not_a_colour_image_is_refused() -> None:
    with pytest.raises(ValueError, match=r"expects an H x W x 3 uint8 colour image"):
        detector().process(np.zeros((10, 10), np.uint8), Context(0, 0.0, "x"))


def test_the_guide_s_colour_station_validates_and_detects_through_its_smart_resource(world: World,
                                                                                       tmp_path: Path) -> None:
    """docs/recognition.md's example: `ckm-validate`'s checks find nothing, and its Smart Resource's
    profile (camera-acquisition → colour-detection) finds both objects in the station camera's frame."""
    guide = (ROOT / "docs" / "recognition.md").read_text(encoding="utf-8")
    [example] = [b for b in re.findall(r"```xml\n(.*?)```", guide, re.S) if 'name="colour-station"' in b]
    (tmp_path / "system.xml").write_text(example)
    system = ckmconf.load(tmp_path / "system.xml")
    assert [e.message for e in verify(system, Registry(packages=("ckm",)))] == []
    [resource] = system.resources
    topology = Topology(resource)
    topology.setup()
    topology.select("Detect", "detect")
    image, _ = view(world, "station_arm")
    found = topology.run(image, stamp=0.0).outputs["Detect"]
    topology.stop()
    assert {o["name"] for o in found["objects"]} == {"parcel", "crate"} and found["reliability"] > 0.6
