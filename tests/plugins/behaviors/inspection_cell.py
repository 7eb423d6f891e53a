"""The inspection station and its parcel (issue N, D296), as the behaviors' closed-loop tests use
them: the station arm's arm-motion and gripper services in a :class:`ManipulatorLoop`, its wrist roll
driven by a ``controller.joint-trajectory`` of its own (the arm-motion chain leaves the roll out), and a
parcel whose two end faces are painted so that a camera tells them apart."""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np
import pybullet as p

from ckmconf.model import Param
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.missions import BehaviorOutput, Uses
from plugins.behaviors.pick_place import PickObject, PlaceObject
from plugins.sim.robots import Robot
from plugins.sim.world import World
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.resources.api import Bounds
from tests.conftest import CONFIGS
from tests.plugins.manipulation.arm_loop import to_world
from tests.plugins.manipulation.manipulator_loop import (
    CONTROL_STEPS,
    ManipulatorLoop,
    Model,
    _controller,
    arm_service,
    gripper_service,
)
from tests.plugins.sim.conftest import ROOM

INSPECTION = Model(
    "inspection_arm",
    ("turret_joint", "shoulder_joint", "elbow_joint", "wrist_pitch_joint"),
    "left_finger_joint",
    "right_finger_joint",
    "palm_link",
    str(CONFIGS / "examples" / "models" / "inspection_arm_poses.yml"),
    0.0,
)
"""hold_force 0: the grasp's own, the fingers' friction grip (D296)."""
RED, BLUE = (0.9, 0.1, 0.1, 1.0), (0.1, 0.2, 0.9, 1.0)
"""The parcel's +x and -x end faces (in its own frame)."""


class InspectionLoop(ManipulatorLoop):
    """The ManipulatorLoop with the wrist roll under a joint-trajectory controller of its own."""

    def __init__(self, world: World, robot: Robot) -> None:
        arm, gripper = arm_service(INSPECTION), gripper_service(INSPECTION)
        arm.setup()
        gripper.setup()
        super().__init__(world, robot, INSPECTION, arm, gripper)
        self.roll = robot.joint("wrist_roll_joint")
        self.roll_control = _controller(("wrist_roll_joint",), "1.0")
        self.roll_trajectory: dict[str, object] | None = None

    def turn(self, angle: float, seconds: float = 4.0) -> None:
        """Turn the wrist to ``angle`` (rad) in ``seconds``, then let it settle for 1 s."""
        here = self.robot.joint_state(self.roll)[0]
        self.roll_trajectory = {
            "joint_names": ["wrist_roll_joint"],
            "points": [
                {"positions": [here], "time_from_start": 0.0},
                {"positions": [angle], "time_from_start": seconds},
            ],
        }
        self.run(seconds + 1.0)

    def control(self) -> None:
        super().control()
        dt = CONTROL_STEPS * self.world.time_step
        [command] = self.roll_control.step_outputs(
            {"setpoint": self.roll_trajectory, "measure": [self.robot.joint_state(self.roll)[0]]}, dt
        )
        self.robot.command(self.roll, "position", float(command))


def station(pose: tuple[float, float, float] = (2.0, 2.0, 0.0)) -> Iterator[InspectionLoop]:
    """The inspection station at ``pose`` in the room, closed afterwards."""
    world = World(ROOM, seed=5)
    robot = Robot(world, INSPECTION.name, world.load_robot(INSPECTION.name, INSPECTION.name, pose))
    world.step(24)
    loop = InspectionLoop(world, robot)
    try:
        yield loop
    finally:
        loop.arm.stop()
        world.close()


def table(loop: ManipulatorLoop, centre: tuple[float, float, float], half: tuple[float, float, float]) -> int:
    """A static box (a work table) at a base-frame ``centre``, square to the robot."""
    cid = loop.world.client
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=list(half), physicsClientId=cid)
    return int(
        p.createMultiBody(
            0.0, shape, -1, to_world(loop.robot, centre), loop.robot.link_pose(-1)[1], physicsClientId=cid
        )
    )


def parcel(
    loop: ManipulatorLoop, centre: tuple[float, float, float], half: float, mass: float, yaw: float = 0.0
) -> int:
    """A cube parcel of side ``2 half`` at a base-frame ``centre``, turned ``yaw`` from the robot's
    heading: grey, its +x end face red and its -x end face blue (thin visual plates, no collision)."""
    cid = loop.world.client
    box = p.createCollisionShape(p.GEOM_BOX, halfExtents=[half] * 3, physicsClientId=cid)
    grey = p.createVisualShape(p.GEOM_BOX, halfExtents=[half] * 3, rgbaColor=[0.6, 0.6, 0.55, 1.0], physicsClientId=cid)
    plate = [
        p.createVisualShape(
            p.GEOM_BOX, halfExtents=[0.002, half * 0.9, half * 0.9], rgbaColor=list(c), physicsClientId=cid
        )
        for c in (RED, BLUE)
    ]
    base_yaw = p.getEulerFromQuaternion(loop.robot.link_pose(-1)[1])[2]
    body = int(
        p.createMultiBody(
            mass,
            box,
            grey,
            to_world(loop.robot, centre),
            p.getQuaternionFromEuler([0.0, 0.0, base_yaw + yaw]),
            linkMasses=[0.001, 0.001],
            linkCollisionShapeIndices=[-1, -1],
            linkVisualShapeIndices=plate,
            linkPositions=[[half + 0.002, 0, 0], [-half - 0.002, 0, 0]],
            linkOrientations=[[0, 0, 0, 1]] * 2,
            linkInertialFramePositions=[[0, 0, 0]] * 2,
            linkInertialFrameOrientations=[[0, 0, 0, 1]] * 2,
            linkParentIndices=[0, 0],
            linkJointTypes=[p.JOINT_FIXED] * 2,
            linkJointAxis=[[0, 0, 1]] * 2,
            physicsClientId=cid,
        )
    )
    p.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=cid)
    return body


def in_base(loop: ManipulatorLoop, body: int) -> tuple[float, float, float]:
    """A body's position in the robot's base frame (the world's own pose)."""
    base, orientation = loop.robot.link_pose(-1)
    rotation = np.array(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
    where = p.getBasePositionAndOrientation(body, physicsClientId=loop.world.client)[0]
    x, y, z = rotation.T @ (np.asarray(where) - np.asarray(base))
    return float(x), float(y), float(z)


class LoopService:
    """A service handle on one of a ManipulatorLoop's services (``arm_result`` or ``gripper_result``)."""

    def __init__(self, loop: ManipulatorLoop, result: str) -> None:
        self.ref, self.loop, self.result = result, loop, result

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        return None

    def output(self, name: str) -> Any:
        return getattr(self.loop, self.result).get(name)

    def measures(self) -> dict[str, float]:
        return {k: float(v) for k, v in getattr(self.loop, self.result).items() if isinstance(v, int | float)}

    def samples(self, measure: str) -> list[float]:
        return [self.measures().get(measure, 0.0)]

    def running(self) -> bool:
        return True


KINDS: dict[str, type[Behavior]] = {"pick-object": PickObject, "place-object": PlaceObject}


def run_behavior(loop: ManipulatorLoop, kind: str, params: Mapping[str, str], limit: float = 40.0) -> BehaviorStatus:
    """``kind`` (pick-object or place-object) on the loop's services, stepped every 0.05 s of simulated
    time until it ends (bounded by ``limit`` simulated seconds)."""

    def publish(name: str, value: Any) -> None:
        if name == "arm_goal":
            loop.arm_goal = value
        else:
            loop.command = value

    record = BehaviorRecord(
        name=kind.split("-")[0].upper(),
        kind=kind,
        timeout=60.0,
        params=tuple(Param(name=k, value=v) for k, v in params.items()),
        uses=(Uses(service="Arm.Motion", as_="arm"), Uses(service="Arm.Gripper", as_="gripper")),
        outputs=(
            BehaviorOutput(name="arm_goal", topic="/arm/goal"),
            BehaviorOutput(name="gripper_command", topic="/gripper/command"),
        ),
    )
    services = {"arm": LoopService(loop, "arm_result"), "gripper": LoopService(loop, "gripper_result")}
    context = BehaviorContext(
        services=services,
        inputs={},
        now=lambda: loop.world.time,
        outputs={n: functools.partial(publish, n) for n in ("arm_goal", "gripper_command")},
    )
    made = KINDS[kind](record, context)
    made.start()
    start = loop.world.time
    while loop.world.time - start < limit:
        loop.run(0.05)
        status = made.step()
        if status.done or status.failed:
            return status
    raise AssertionError(f"{kind} did not end in {limit} s")
