"""Odometry drifts as configured; a grasped object stays in the gripper while the base drives 2 m;
the pan-tilt head centres a moving object; the same seed gives the same sensor data."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pybullet as p
import pytest
from ckm_lab.arm import POSES, Arm
from ckm_lab.devices import HOKUYO, KOBUKI, NAO_HEAD, XTION_FOV

from plugins.sim.grasp import Gripper
from plugins.sim.head import PanTiltHead
from plugins.sim.robots import DiffDriveBase, OdometryNoise
from plugins.sim.sensors import Camera, Lidar
from plugins.sim.world import World

from .conftest import ROOM, add_box, robot

STEPS_PER_UPDATE = 5  # odometry at 48 Hz with the 240 Hz physics


def _drive(world: World, odometers: list[DiffDriveBase], seconds: float) -> None:
    for _ in range(int(seconds * 240 / STEPS_PER_UPDATE)):
        world.step(STEPS_PER_UPDATE)
        for odometer in odometers:
            odometer.update()


def test_odometry_without_slip_follows_the_truth_and_slip_makes_it_drift_as_configured(world: World) -> None:
    tb = robot(world, "turtlebot", (1.0, 2.0, 0.0))
    slip = 0.2
    exact = DiffDriveBase(tb, **KOBUKI)
    noisy = [DiffDriveBase(tb, **KOBUKI, noise=OdometryNoise(slip=slip, seed=seed)) for seed in range(12)]
    exact.drive(0.3, 0.0)
    _drive(world, [exact, *noisy], 5.0)
    truth = tb.planar_pose()
    assert truth[0] - 1.0 > 1.3  # it drove
    # without slip noise only the contact model's own slip remains: under 2.5 % of the distance
    assert math.dist(exact.pose[:2], truth[:2]) < 0.025 * (truth[0] - 1.0)
    # Each update scales each wheel's travel by 1 + N(0, slip): the distance's spread is
    # slip · d · sqrt(n / 2) for n updates of travel d each.
    travelled = [math.hypot(o.pose[0] - 1.0, o.pose[1] - 2.0) for o in noisy]
    n = int(5.0 * 240 / STEPS_PER_UPDATE)
    expected = slip * (exact.pose[0] - 1.0) / n * math.sqrt(n / 2)
    assert expected / 3 < statistics.stdev(travelled) < expected * 3
    assert max(abs(o.pose[2] - truth[2]) for o in noisy) > 10 * abs(exact.pose[2] - truth[2]) or slip == 0


def test_a_grasped_object_stays_in_the_gripper_while_the_base_drives_2_m(world: World) -> None:
    tb = robot(world, "turtlebot", (3.5, 2.0, 0.0))
    add_box(world, (3.88, 2.0, 0.075), 0.075, [0.3, 0.3, 0.3, 1.0])  # a pedestal under the part
    part = add_box(world, (3.83, 2.0, 0.19), 0.02, [0.0, 0.6, 0.0, 1.0], mass=0.1)
    arm = Arm(tb)
    gripper = Gripper(tb, left="gripper_joint", right="gripper_right_joint", wrist="arm_wrist_flex_link")
    gripper.open()
    for pose in ("pre-grasp", "grasp"):
        arm.go(pose)
        world.step(480)
    gripper.close()
    for _ in range(240):
        world.step()
        gripper.update()
    assert gripper.held == part
    arm.go("lift")
    world.step(480)
    base = DiffDriveBase(tb, **KOBUKI)
    base.drive(-0.25, 0.0)
    start = tb.planar_pose()
    offsets = []
    while math.dist(tb.planar_pose()[:2], start[:2]) < 2.0:
        world.step(24)
        position = np.asarray(p.getBasePositionAndOrientation(part, physicsClientId=world.client)[0])
        offsets.append(float(np.linalg.norm(position - np.asarray(arm.tool_position()))))
        assert world.time < 30.0, "the base did not drive 2 m"
    assert gripper.held == part
    assert max(offsets) - min(offsets) < 0.005  # it kept the place where the fingers took it
    assert max(offsets) < 0.06  # which is within the fingers' reach of the tool point
    assert p.getBasePositionAndOrientation(part, physicsClientId=world.client)[0][2] > 0.2  # still lifted
    gripper.open()
    world.step(240)
    assert gripper.held is None


@pytest.mark.parametrize("name", sorted(POSES))
def test_each_predefined_pose_is_reached(world: World, name: str) -> None:
    tb = robot(world, "turtlebot", (3.0, 2.0, 0.7))
    arm = Arm(tb)
    arm.go(name)
    world.step(480)
    assert arm.error() < 0.01
    pose = POSES[name]
    if pose.position is not None:  # the tool point where Fig. 7.20's pose puts it, in the base frame
        base, orientation = tb.link_pose(-1)
        rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
        expected = np.asarray(base) + rotation @ np.asarray(pose.position)
        assert float(np.linalg.norm(np.asarray(arm.tool_position()) - expected)) < 0.005


def test_the_pan_tilt_head_centres_a_moving_object(world: World) -> None:
    nao = robot(world, "nao", (1.0, 2.0, 0.0))
    camera = Camera(nao, "CameraTop_optical_frame", fov=0.8331)
    head = PanTiltHead(nao, camera, **NAO_HEAD)
    target = add_box(world, (2.5, 1.4, 0.3), 0.05, [0.0, 0.0, 1.0, 1.0])
    fixed_at: list[float] = []
    for k in range(150):  # 5 s; the tracker at 30 Hz; the object slides along y at 0.2 m/s
        position = (2.5, 1.4 + 0.2 * k / 30, 0.3)
        p.resetBasePositionAndOrientation(target, position, (0, 0, 0, 1), physicsClientId=world.client)
        if head.track(position):
            fixed_at.append(world.time)
        world.step(8)
    assert fixed_at and fixed_at[-1] > 4.0  # it stays fixed on the moving object
    frame = camera.render(160, 120)
    centre = frame.rgb[55:65, 75:85].reshape(-1, 3).mean(axis=0)
    assert centre[2] > 150 and centre[0] < 60  # the blue object fills the image centre
    yaw = nao.joint_state(head.yaw)[0]
    assert yaw == pytest.approx(math.atan2(1.4 + 0.2 * 149 / 30 - 2.0, 1.5), abs=0.1)


def _record(seed: int) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float]]:
    with World(ROOM, seed=seed) as world:
        tb = robot(world, "turtlebot", (2.0, 2.0, 0.3))
        add_box(world, (3.5, 2.5, 0.2), 0.1, [1.0, 0.5, 0.0, 1.0], mass=0.5)
        base = DiffDriveBase(tb, **KOBUKI, noise=OdometryNoise(slip=0.05, seed=seed))
        base.drive(0.3, 0.4)
        _drive(world, [base], 2.0)
        lidar = Lidar(tb, "hokuyo_link", **HOKUYO, noise=0.01, seed=seed)
        frame = Camera(tb, "camera_rgb_optical_frame", fov=XTION_FOV).render(80, 60)
        return lidar.scan(), frame.rgb, base.pose


def test_the_same_seed_gives_the_same_sensor_data() -> None:
    first, again, other = _record(7), _record(7), _record(8)
    assert np.array_equal(first[0], again[0])
    assert np.array_equal(first[1], again[1])
    assert first[2] == again[2]
    assert not np.array_equal(first[0], other[0])
