"""``plugin.undistort`` and ``plugin.grayscale`` on frames of two robots' cameras (issue M, point 6).

The station of configs/examples/sim_station.xml (its table and part) rendered from the station arm's
wrist camera and from a Turtlebot's Xtion standing before the table, each at its own resolution and
field of view. A known Brown–Conrady distortion is put on each frame with OpenCV (the lens a real
camera has); ``undistort``, given that camera's intrinsics and coefficients as Params, must bring the
frame back; ``grayscale`` must give OpenCV's luma of it.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pybullet as p
import pytest
from ckm_lab.arm import ARM_JOINTS, POSES

import ckmconf
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.processing.image import Grayscale, Undistort
from plugins.sim.robots import Robot
from plugins.sim.sensors import Camera
from plugins.sim.world import World
from runtime.resources.spt import Context
from tests.conftest import CONFIGS

COEFFICIENTS = {"k1": -0.28, "k2": 0.09, "p1": 0.001, "p2": -0.0015, "k3": 0.0}
"""A wide-angle lens's barrel distortion (of the order of a webcam's calibration)."""

CAMERAS = {  # robot: (URDF, link, pose, fov, width, height)
    "station_arm": ("station_arm", "wrist_camera_optical_frame", (1.0, 1.0, 0.0), 1.0, 320, 240),
    "turtlebot": ("turtlebot", "camera_rgb_optical_frame", (2.5, 1.0, math.pi), 1.0123, 640, 480),
}


@pytest.fixture(scope="module")
def world() -> Iterator[World]:
    environment = ckmconf.load(CONFIGS / "examples" / "sim_station.xml").environment
    assert environment is not None
    made = World(environment, seed=1)
    yield made
    made.close()


def frame(world: World, robot: str) -> tuple[np.ndarray[Any, Any], np.ndarray[Any, Any]]:
    """The robot's camera frame (RGB) and its pinhole camera matrix at the frame's resolution."""
    urdf, link, pose, fov, width, height = CAMERAS[robot]
    body = Robot(world, robot, world.load_robot(robot, urdf, pose))
    if robot == "station_arm":  # the elbow bent forward: the wrist camera looks down at the table
        p.resetJointState(body.body, body.joint("elbow_joint"), 1.9, physicsClientId=world.client)
    else:  # the arm folded at rest, out of the Xtion's view
        for joint, angle in zip(ARM_JOINTS, POSES["rest"].joints or (), strict=True):
            p.resetJointState(body.body, body.joint(joint), angle, physicsClientId=world.client)
    image = Camera(body, link, fov=fov).render(width, height).rgb
    focal = (width / 2) / math.tan(fov / 2)
    matrix = np.array([[focal, 0.0, (width - 1) / 2], [0.0, focal, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return np.ascontiguousarray(image), matrix


def distorted(image: np.ndarray[Any, Any], matrix: np.ndarray[Any, Any]) -> np.ndarray[Any, Any]:
    """``image`` as the lens of COEFFICIENTS would have shown it: each distorted pixel takes the ideal
    pixel its ray comes from."""
    rows, cols = image.shape[:2]
    grid = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 1, 2).astype(np.float64)
    coefficients = np.array([COEFFICIENTS[k] for k in ("k1", "k2", "p1", "p2", "k3")])
    ideal = cv2.undistortPoints(grid, matrix, coefficients, P=matrix).reshape(rows, cols, 2).astype(np.float32)
    return cv2.remap(image, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def plugin(cls: type[Any], **params: object) -> Any:
    return cls(
        Plugin(
            name=cls.__name__.lower(),
            kind=cls.__name__.lower(),
            params=tuple(Param(name=k, value=str(v)) for k, v in params.items()),
        )
    )


@pytest.mark.parametrize("robot", sorted(CAMERAS))
def test_undistort_brings_a_distorted_frame_back_with_the_camera_s_own_intrinsics(world: World, robot: str) -> None:
    image, matrix = frame(world, robot)
    assert image.std() > 10, "the camera sees nothing: the test would prove nothing"
    lens = distorted(image, matrix)
    intrinsics = {"fx": matrix[0, 0], "fy": matrix[1, 1], "cx": matrix[0, 2], "cy": matrix[1, 2]}
    undistort = plugin(Undistort, **intrinsics, **COEFFICIENTS)
    restored = undistort.process(lens, Context(0, 0.0, robot))
    assert restored.shape == image.shape and restored.dtype == image.dtype
    rows, cols = image.shape[:2]
    inner = (slice(rows // 6, rows - rows // 6), slice(cols // 6, cols - cols // 6))  # what the lens kept

    def error(one: np.ndarray[Any, Any]) -> float:
        return float(np.abs(one[inner].astype(float) - image[inner].astype(float)).mean())

    assert error(restored) < 0.35 * error(lens), (error(restored), error(lens))
    assert error(restored) < 6.0, error(restored)  # two resamplings blur the edges a little
    wrong = plugin(Undistort, **intrinsics, **{k: -v for k, v in COEFFICIENTS.items()})
    assert error(wrong.process(lens, Context(1, 0.0, robot))) > 2 * error(restored)  # the Params matter


@pytest.mark.parametrize("robot", sorted(CAMERAS))
def test_grayscale_is_opencv_s_luma_of_the_frame_in_either_channel_order(world: World, robot: str) -> None:
    image, _ = frame(world, robot)
    expected = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(int)
    grey = plugin(Grayscale).process(image, Context(0, 0.0, robot))
    assert grey.shape == image.shape[:2] and grey.dtype == np.uint8
    assert np.abs(grey.astype(int) - expected).max() <= 1
    from_bgr = plugin(Grayscale, order="bgr").process(np.ascontiguousarray(image[..., ::-1]), Context(1, 0.0, robot))
    assert np.array_equal(from_bgr, grey)
