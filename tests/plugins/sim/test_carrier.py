"""The warehouse carrier (plugins/sim/models/carrier.urdf, issue N point 2, D296): its clamp, driven
by the real parallel-gripper service through a controller.joint-trajectory as a node runs them,
closes on a 0.3 m parcel standing on the floor (the Turtlebot's jaw opens 0.09 m), its lift raises it,
and it stays in the clamp while the base drives 2 m; its lidar sees over what it carries. A parcel
heavier than the clamp's friction grip slips out as the lift rises. The evidence is the world's poses."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pybullet as p
import pytest

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.controllers.trajectory import JointTrajectory
from plugins.hardware.simulation import ManualClock, PlantScope
from plugins.manipulation.gripper import ParallelGripper
from plugins.sim.grasp import ChannelGrasp
from plugins.sim.robots import DiffDriveBase, Robot
from plugins.sim.sensors import Lidar
from plugins.sim.world import World
from runtime.resources.spt import Context
from tests.conftest import REPO
from tests.plugins.controllers.vector_records import record

from .conftest import ROOM
from .test_backend import channel, open_all

CONTROL_STEPS, SERVICE_STEPS = 4, 12  # controllers at 60 Hz, the service at 20 Hz, on the 240 Hz physics
PARCEL = 0.15  # half side (m): a 0.3 m cube
AHEAD = 0.53  # its centre ahead of the base: between the open pads (0.38 to 0.68 m)


class Clamp:
    """The carrier's gripper service → its jaw controller → both pads and the channel's grasp; the
    lift held at a height as an analog sim channel in position mode holds it (the URDF's effort)."""

    def __init__(self, world: World, robot: Robot) -> None:
        self.world, self.robot = world, robot
        loc = Loc(str(REPO / "configs" / "examples" / "sim_station.xml"), 1, 1, "/Plugin")
        params = {"model": "carrier", "joints": "left_jaw_joint"}
        self.service = ParallelGripper(
            Plugin(
                name="clamp",
                kind="parallel-gripper",
                loc=loc,
                params=tuple(Param(name=k, value=v) for k, v in params.items()),
            )
        )
        self.service.setup()
        self.control = JointTrajectory(
            record(
                "joint-trajectory",
                0.02,
                [("/setpoint", "setpoint"), ("/measure", "measure")],
                ["j0"],
                50,
                joints="left_jaw_joint",
                interpolation="cubic",
            )
        )
        self.pads = (robot.joint("left_jaw_joint"), robot.joint("right_jaw_joint"))
        self.lift = robot.joint("lift_joint")
        self.grasp = ChannelGrasp(robot, "left_jaw_joint", "right_jaw_joint", "lift_link", 0.0)
        self.command: dict[str, Any] | None = None
        self.result: dict[str, Any] = {}
        self.trajectory: Any = None
        self.frames = 0
        self.height = 0.0
        self.base: DiffDriveBase | None = None

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds * 240 / SERVICE_STEPS)):
            for _ in range(SERVICE_STEPS // CONTROL_STEPS):
                measure = [self.robot.joint_state(self.pads[0])[0]]
                [pad] = self.control.step_outputs(
                    {"setpoint": self.trajectory, "measure": measure}, CONTROL_STEPS * self.world.time_step
                )
                for joint in self.pads:  # the channel's joint and its mirror, at the URDF's effort
                    self.robot.command(joint, "position", float(pad))
                self.grasp.command(float(pad))
                self.robot.command(self.lift, "position", self.height)
                self.world.step(CONTROL_STEPS)
                if self.base is not None:
                    self.base.update()
            state = {"stamp": self.world.time, "name": [], "position": [self.robot.joint_state(self.pads[0])[0]]}
            self.result = self.service.process(
                {"command": self.command, "joint_states": state}, Context(self.frames, self.world.time, "carrier")
            )
            self.frames += 1
            if "trajectory" in self.result:
                self.trajectory = self.result["trajectory"]

    def grip(self, command: dict[str, Any], limit: float = 8.0) -> dict[str, Any]:
        """Send a gripper command; its status once it ended (bounded by ``limit`` simulated seconds)."""
        self.command = command
        start = self.world.time
        while self.world.time - start < limit:
            self.run(0.05)
            status = self.result.get("status", {})
            if status.get("id") == command["id"] and status.get("state") != "moving":
                return dict(status)
        raise AssertionError(f"command {command} did not end in {limit} s: {self.result}")


@pytest.fixture
def carrier() -> Iterator[Clamp]:
    world = World(ROOM, seed=7)
    robot = Robot(world, "carrier", world.load_robot("carrier", "carrier", (1.0, 2.0, 0.0)))
    world.step(24)
    try:
        yield Clamp(world, robot)
    finally:
        world.close()


def _parcel(clamp: Clamp, mass: float) -> int:
    cid = clamp.world.client
    x, y, _ = clamp.robot.planar_pose()
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[PARCEL] * 3, physicsClientId=cid)
    body = int(p.createMultiBody(mass, shape, -1, [x + AHEAD, y, PARCEL + 0.001], physicsClientId=cid))
    p.changeDynamics(body, -1, lateralFriction=0.8, physicsClientId=cid)
    clamp.world.step(60)
    return body


def _where(clamp: Clamp, body: int) -> np.ndarray:
    return np.asarray(p.getBasePositionAndOrientation(body, physicsClientId=clamp.world.client)[0])


def test_the_clamp_opens_wide_enough_for_a_0_3_m_parcel_from_its_joint_limits(carrier: Clamp) -> None:
    assert carrier.service.upper == pytest.approx(0.19) and carrier.service.force == pytest.approx(150.0)
    assert carrier.grasp.gripper.hold_force == pytest.approx(2 * 0.75 * 150.0)  # the pads' friction grip
    opened = carrier.grip({"id": 1, "action": "open"})
    assert opened["state"] == "reached"
    cid = carrier.world.client
    gap = p.getClosestPoints(
        carrier.robot.body, carrier.robot.body, 1.0, carrier.pads[0], carrier.pads[1], physicsClientId=cid
    )
    assert min(c[8] for c in gap) == pytest.approx(0.42, abs=0.01)  # inner faces 0.42 m apart


def test_the_carrier_lifts_a_0_3_m_parcel_and_carries_it_while_driving(carrier: Clamp) -> None:
    clamp = carrier
    assert clamp.grip({"id": 1, "action": "open"})["state"] == "reached"
    parcel = _parcel(clamp, 3.0)
    resting = _where(clamp, parcel)
    closed = clamp.grip({"id": 2, "action": "close"})
    assert closed["state"] == "holding", closed
    assert closed["position"] == pytest.approx(PARCEL - 0.02, abs=0.005)  # each pad on a side
    assert clamp.grasp.held == parcel
    clamp.height = 0.15
    clamp.run(2.0)
    assert _where(clamp, parcel)[2] - resting[2] == pytest.approx(0.15, abs=0.01)  # lifted with the clamp
    lidar = Lidar(clamp.robot, "laser_link", beams=181, fov=math.pi, range_max=8.0)
    assert lidar.scan()[90] > 4.0  # straight ahead it sees the far wall, over the lifted parcel
    offset = _where(clamp, parcel) - np.asarray(clamp.robot.link_pose(-1)[0])
    clamp.base = DiffDriveBase(
        clamp.robot, left="left_wheel_joint", right="right_wheel_joint", wheel_radius=0.08, wheel_base=0.50
    )
    clamp.base.drive(0.5, 0.0, force=15.0)
    start = clamp.robot.planar_pose()
    while math.dist(clamp.robot.planar_pose()[:2], start[:2]) < 2.0:
        clamp.run(0.1)
        assert clamp.world.time < 30.0, "the carrier did not drive 2 m"
        moved = _where(clamp, parcel) - np.asarray(clamp.robot.link_pose(-1)[0])
        assert float(np.linalg.norm(moved - offset)) < 0.02  # kept in the clamp
    clamp.base.drive(0.0, 0.0, force=15.0)
    clamp.run(1.0)
    assert clamp.grasp.held == parcel
    clamp.height = 0.0
    clamp.run(2.5)
    assert clamp.grip({"id": 3, "action": "open"})["state"] == "reached"
    assert clamp.grasp.held is None
    down = _where(clamp, parcel)
    assert down[2] == pytest.approx(PARCEL, abs=0.01) and down[0] - resting[0] > 1.9  # set down 2 m on


def test_a_parcel_heavier_than_the_clamp_s_grip_slips_out_as_the_lift_rises(carrier: Clamp) -> None:
    clamp = carrier
    assert clamp.grip({"id": 1, "action": "open"})["state"] == "reached"
    parcel = _parcel(clamp, 60.0)  # 588 N: more than the pads' 225 N grip and their friction together
    resting = _where(clamp, parcel)
    assert clamp.grip({"id": 2, "action": "close"})["state"] == "holding"
    assert clamp.grasp.held == parcel  # caught as the pads closed on it
    clamp.height = 0.15
    clamp.run(2.5)
    assert clamp.robot.joint_state(clamp.lift)[0] > 0.1  # the lift rose
    assert clamp.grasp.held is None  # the parcel slipped out
    assert _where(clamp, parcel)[2] - resting[2] < 0.02  # and stayed on the floor


def test_the_clamp_as_configured_holds_by_the_models_own_grip() -> None:
    """The same clamp through ``hardware.sim`` channels (D296): ``joint``, ``mirror`` and ``grasp``
    name the carrier's pads and carriage, no ``holdForce`` is given — the grip is the model's — and
    the lift is an analog channel in position mode. Closed on the parcel and lifted, it holds it."""
    clock = ManualClock()
    clamp, lift = open_all(
        PlantScope(clock, name="carrier-clamp"),
        channel("clamp", "out", "analog", 1, body="carrier", pose="3.0 1.0 0", joint="left_jaw_joint",
                mirror="right_jaw_joint", grasp="lift_link"),
        channel("lift", "out", "analog", 1, body="carrier", joint="lift_joint"),
    )  # fmt: skip
    clamp.write(0.19)  # the pads' travel from closed, m: fully open
    lift.write(0.0)
    clock.advance(2.0)
    clamp.write(0.19)
    sim, device = clamp._require()  # type: ignore[attr-defined]
    world, robot = sim.world, device.robot
    assert device.grasp.gripper.hold_force == pytest.approx(225.0)
    x, y, _ = robot.planar_pose()
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[PARCEL] * 3, physicsClientId=world.client)
    parcel = int(p.createMultiBody(3.0, shape, -1, [x + AHEAD, y, PARCEL + 0.001], physicsClientId=world.client))
    clock.advance(0.5)
    clamp.write(0.19)
    for _ in range(8):  # the actuator repeats its command
        clamp.write(0.0)
        clock.advance(0.5)
    assert device.grasp.held == parcel
    for _ in range(6):
        lift.write(0.15)
        clamp.write(0.0)
        clock.advance(0.5)
    assert _where_in(world.client, parcel)[2] == pytest.approx(PARCEL + 0.15, abs=0.01)
    assert device.grasp.held == parcel


def _where_in(client: int, body: int) -> tuple[float, ...]:
    return tuple(p.getBasePositionAndOrientation(body, physicsClientId=client)[0])


def test_a_parcel_as_wide_as_the_open_clamp_is_let_go_when_it_opens_to_its_stop(carrier: Clamp) -> None:
    """Caught less than the grasp's release gap short of the open stop (a 0.415 m box: the pads stand
    0.187 m open on it, 3 mm from their 0.19 m limit), the box is let go once the pads reach the stop;
    before, the release waited for an opening beyond the limit and the carrier drove off with it."""
    clamp = carrier
    assert clamp.grip({"id": 1, "action": "open"})["state"] == "reached"
    cid = clamp.world.client
    x, y, _ = clamp.robot.planar_pose()
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.1, 0.2075, 0.1], physicsClientId=cid)
    wide = int(p.createMultiBody(2.0, shape, -1, [x + AHEAD, y, 0.101], physicsClientId=cid))
    clamp.world.step(60)
    closed = clamp.grip({"id": 2, "action": "close"})
    assert closed["state"] == "holding" and clamp.grasp.held == wide, closed
    assert clamp.grasp.opening_held > clamp.grasp.gripper.open_limit - clamp.grasp.RELEASE_GAP
    assert clamp.grip({"id": 3, "action": "open"})["state"] == "reached"
    clamp.run(0.5)
    assert clamp.grasp.held is None
