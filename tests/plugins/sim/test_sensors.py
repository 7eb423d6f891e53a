"""The lidar measures known wall distances; the camera sees an object where the geometry says."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from ckm_lab.arm import Arm
from ckm_lab.devices import HOKUYO, XTION_FOV

from plugins.sim.devices import SimWorld
from plugins.sim.sensors import Camera, Lidar
from plugins.sim.world import World

from .conftest import add_box, robot


def test_lidar_measures_the_walls(world: World) -> None:
    tb = robot(world, "turtlebot", (3.0, 2.0, 0.0))
    lidar = Lidar(tb, "hokuyo_link", **HOKUYO)
    ranges = lidar.scan()
    assert ranges.shape == (683,)
    step = lidar.fov / 682
    ahead = ranges[341]  # beam at 0 rad: the wall at x = 6, the scanner at x = 3.10
    left = ranges[round((math.pi / 2 + lidar.fov / 2) / step)]  # the wall at y = 4
    assert ahead == pytest.approx(6.0 - 3.10, abs=0.01)
    assert left == pytest.approx(2.0, abs=0.01)
    assert lidar.angles[0] == pytest.approx(-lidar.fov / 2)


def test_lidar_range_is_capped(world: World) -> None:
    tb = robot(world, "turtlebot", (3.0, 2.0, 0.0))
    ranges = Lidar(tb, "hokuyo_link", **{**HOKUYO, "range_max": 1.0}).scan()
    assert float(ranges.max()) == pytest.approx(1.0)


def test_camera_sees_the_object_where_the_geometry_says(world: World) -> None:
    tb = robot(world, "turtlebot", (2.0, 2.0, 0.0))
    Arm(tb).go("rest")
    world.step(240)
    face = (2.8, 2.3, 0.1)  # centre of the red cube's face towards the robot
    add_box(world, (2.85, 2.3, 0.1), 0.05, [1.0, 0.0, 0.0, 1.0])
    camera = Camera(tb, "camera_rgb_optical_frame", fov=XTION_FOV)
    frame = camera.render(320, 240)
    assert frame.rgb.shape == (240, 320, 3) and frame.depth.shape == (240, 320)
    u, v, z = camera.project(face)
    col, row = round(frame.fx * u + frame.cx), round(frame.fy * v + frame.cy)
    assert 0 <= col < 320 and 0 <= row < 240
    assert frame.depth[row, col] == pytest.approx(z, abs=0.02)
    red, green, blue = (int(c) for c in frame.rgb[row, col])
    assert red > 100 and green < 60 and blue < 60
    # y = 2.3 is to the robot's left (+y): the object shows left of the image centre
    assert col < 160
    assert camera.renders == 1


def test_one_render_gives_colour_and_depth_at_the_asked_resolution(world: World) -> None:
    tb = robot(world, "turtlebot", (2.0, 2.0, 0.0))
    camera = Camera(tb, "camera_depth_optical_frame", fov=XTION_FOV)
    for width, height in ((160, 120), (320, 240)):
        frame = camera.render(width, height)
        assert frame.rgb.shape == (height, width, 3)
        assert np.all(frame.depth > 0.0) and np.all(frame.depth <= camera.far + 1e-6)
    assert camera.renders == 2


def test_the_xtions_rgb_and_depth_frames_coincide_and_share_one_render() -> None:
    """D240: the model's RGB and depth optical frames are at one pose on one rigid body, so the two
    channels' reads at a step are one render; a camera on the moving arm has its own viewpoint."""
    sim = SimWorld(time.monotonic, None, 3, "", "")
    try:
        tb = sim.robot("turtlebot", "", "2 2 0.7")  # turned: float32 quaternions, no exact 1
        rgb = Camera(tb, "camera_rgb_optical_frame", fov=XTION_FOV)
        depth = Camera(tb, "camera_depth_optical_frame", fov=XTION_FOV)
        assert rgb.view == depth.view == rgb.link != depth.link
        assert Camera(tb, "gripper_tool_link", fov=XTION_FOV).view == tb.link("gripper_tool_link")
        assert Camera(tb, "camera_link", fov=XTION_FOV).view == tb.link("camera_link")  # rigid with them, but elsewhere
        colour = sim.frame(rgb, 80, 60)
        assert sim.frame(depth, 80, 60) is colour and rgb.renders + depth.renders == 1
        sim.world.step(1)
        assert sim.frame(depth, 80, 60) is not colour and depth.renders == 1
    finally:
        sim.world.close()
