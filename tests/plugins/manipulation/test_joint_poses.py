"""``plugin.joint-poses`` (D303): named joint poses over the ``arm-motion`` interface, on two robot models in
the pybullet closed loop — the carrier's lift (one prismatic joint) and the inspection arm's wrist roll
(one revolute joint) — each played by a ``controller.joint-trajectory``; bad goals and Params are refused
with their reason. The evidence is the world's joint positions."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest

from ckmconf.errors import Loc
from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.controllers.trajectory import JointTrajectory
from plugins.manipulation.joint_poses import JointPoses
from plugins.manipulation.joint_states import joint_values
from plugins.sim.robots import Robot
from plugins.sim.world import World
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context
from tests.conftest import REPO
from tests.plugins.controllers.vector_records import record
from tests.plugins.sim.conftest import ROOM

CONTROL_STEPS, SERVICE_STEPS = 4, 12  # the controller at 60 Hz, the service at 20 Hz, on the 240 Hz physics
MODELS = {
    "carrier": ("lift_joint", "down: 0.0; carry: 0.25", "carry", 0.25, 0.15),
    "inspection_arm": ("wrist_roll_joint", "front: 0.0; back: 3.1416", "back", 3.1416, 2.0),
}
"""model → (joint, poses, the pose driven to, its value, the joint's velocity limit in the controller)."""


def service(model: str, joint: str, poses: str, **extra: str) -> JointPoses:
    loc = Loc(str(REPO / "configs" / "warehouse" / "carrier.xml"), 1, 1, "/Plugin")
    params = {"model": model, "joints": joint, "poses": poses, **extra}
    return JointPoses(Plugin(name="joints", kind="joint-poses", loc=loc,
                             params=tuple(Param(name=k, value=v) for k, v in params.items())))


class Loop:
    """The service → its joint-trajectory controller → the joint, stepped as a node runs them."""

    def __init__(self, world: World, robot: Robot, joint: str, poses: str, velocity: float, **extra: str) -> None:
        self.world, self.robot = world, robot
        self.joint = robot.joint(joint)
        self.service = service(robot.name, joint, poses, **extra)
        self.service.setup()
        self.control = JointTrajectory(record("joint-trajectory", 0.02, [("/setpoint", "setpoint"),
                                                                         ("/measure", "measure")],
                                              ["j0"], 50, joints=joint, maxVelocity=velocity))
        self.goal: dict[str, Any] | None = None
        self.trajectory: Any = None
        self.status: dict[str, Any] = {}
        self.frames = 0

    def state(self) -> dict[str, Any]:
        return {"stamp": self.world.time, "name": [], "position": [self.robot.joint_state(self.joint)[0], 0.0]}

    def move(self, goal: dict[str, Any], limit: float = 20.0) -> dict[str, Any]:
        """Send ``goal``; its status once it ended (bounded by ``limit`` simulated seconds)."""
        self.goal = goal
        start = self.world.time
        while self.world.time - start < limit:
            for _ in range(SERVICE_STEPS // CONTROL_STEPS):
                [command] = self.control.step_outputs({"setpoint": self.trajectory, "measure": self.state()},
                                                      CONTROL_STEPS * self.world.time_step)
                self.robot.command(self.joint, "position", float(command))
                self.world.step(CONTROL_STEPS)
            result = self.service.process({"goal": self.goal, "joint_states": self.state()},
                                          Context(self.frames, self.world.time, "joints"))
            self.frames += 1
            self.trajectory = result.get("trajectory", self.trajectory)
            self.status = result.get("status", {})
            if self.status.get("id") == goal["id"] and self.status.get("state") != "moving":
                return dict(self.status)
        raise AssertionError(f"goal {goal} did not end in {limit} s: {self.status}")


@pytest.fixture(params=sorted(MODELS))
def loop(request: pytest.FixtureRequest) -> Iterator[Loop]:
    model = request.param
    joint, poses, _, _, velocity = MODELS[model]
    world = World(ROOM, seed=11)
    robot = Robot(world, model, world.load_robot(model, model, (2.0, 2.0, 0.0)))
    world.step(24)
    try:
        yield Loop(world, robot, joint, poses, velocity)
    finally:
        world.close()


def test_each_model_s_joint_reaches_its_named_poses_in_the_world(loop: Loop) -> None:
    _, _, pose, value, _ = MODELS[loop.robot.name]
    reached = loop.move({"id": 1, "group": "arm", "pose": pose})
    assert reached["state"] == "reached" and reached["contact"] is False, reached
    assert loop.robot.joint_state(loop.joint)[0] == pytest.approx(value, abs=0.02)  # the world's joint
    first = next(iter(loop.service.poses))
    back = loop.move({"id": 2, "group": "arm", "pose": first})
    assert back["state"] == "reached" and back["pose"] == first
    assert loop.robot.joint_state(loop.joint)[0] == pytest.approx(0.0, abs=0.02)


def test_goals_the_service_cannot_execute_fail_with_their_reason() -> None:
    made = service("carrier", "lift_joint", "down: 0.0; carry: 0.25")
    made.setup()
    state = {"stamp": 0.0, "name": ["lift_joint"], "position": [0.0]}
    cases = [({"id": 1, "group": "arm", "pose": "up"}, "unknown pose 'up' (defined: down, carry)"),
             ({"id": 2, "group": "gripper", "pose": "down"}, "is not 'arm'"),
             ({"id": 3, "group": "arm", "target": {"x": 0.5, "y": 0.0, "z": 0.3}}, "not to Cartesian targets"),
             ({"id": "4", "group": "arm", "pose": "down"}, "is not an integer")]
    for frame, (goal, reason) in enumerate(cases):
        status = made.process({"goal": goal, "joint_states": state}, Context(frame, float(frame), "lift"))["status"]
        assert status["state"] == "failed" and reason in status["error"], status
        assert status["holding"] is False and status["opening"] is None


@pytest.mark.parametrize(
    ("params", "message"),
    [({"poses": "down: 0.0 0.1"}, "needs one value per joint (1: lift_joint)"),
     ({"contactPoses": "floor"}, "names pose 'floor'"),
     ({"joints": "lift_joint lift_joint"}, "each joint once")],
)
def test_params_that_cannot_work_are_refused_when_built(params: dict[str, str], message: str) -> None:
    values = {"joints": "lift_joint", "poses": "down: 0.0", **params}
    with pytest.raises(ParamError, match=message.replace("(", r"\(").replace(")", r"\)")):
        service("carrier", values.pop("joints"), values.pop("poses"), **values)


def test_a_pose_beyond_the_urdf_s_limits_or_an_unknown_joint_is_refused_when_built() -> None:
    with pytest.raises(ValueError, match=r"pose 'high' puts joint 'lift_joint' at 0.5, outside its limits 0.0 to 0.3"):
        service("carrier", "lift_joint", "down: 0.0; high: 0.5")
    with pytest.raises(ValueError, match="has no joint mast_joint_x"):
        service("carrier", "mast_joint_x", "down: 0.0")
    with pytest.raises(ValueError, match="is not revolute or prismatic"):
        service("carrier", "laser_joint", "down: 0.0")


def test_an_unnamed_joint_state_gives_its_leading_positions_and_too_few_are_refused() -> None:
    state = {"stamp": 0.0, "name": [], "position": [0.12, 0.19]}  # a bus of the lift, then the clamp's pad
    assert joint_values(state, ["lift_joint"], "lift") == [0.12]
    with pytest.raises(ValueError, match="2 unnamed positions, expected 3"):
        joint_values(state, ["a", "b", "c"], "arm")
    assert math.isclose(joint_values(state, ["a", "b"], "arm")[1], 0.19)  # type: ignore[index]


def test_a_pose_stopped_short_ends_reached_on_contact_only_when_the_goal_asks_for_it() -> None:
    """Joint states stuck short of the pose (what a place meets when the object stands on its table):
    a contact goal is reached once they stood still ``settle`` s after the planned time, and the last
    trajectory holds them there; a plain goal waits, then fails at its timeout."""
    made = service("carrier", "lift_joint", "down: 0.0; carry: 0.28", settle="0.5", timeout="2.0")
    made.setup()

    def run(goal: dict[str, Any], seconds: float) -> tuple[dict[str, Any], dict[str, Any]]:
        result: dict[str, Any] = {}
        trajectory: dict[str, Any] = {}
        for frame in range(round(seconds / 0.05)):
            stamp = goal["id"] * 100.0 + frame * 0.05
            here = 0.28 - min(0.18, frame * 0.05 * 0.15)  # lowering at 0.15 m/s, stopped at 0.10 m
            result = made.process({"goal": goal, "joint_states": {"stamp": stamp, "name": [], "position": [here]}},
                                  Context(frame, stamp, "lift"))
            trajectory = result.get("trajectory", trajectory)
            if result["status"]["state"] != "moving":
                break
        return result["status"], trajectory

    stopped, held = run({"id": 1, "group": "arm", "pose": "down", "contact": True}, 6.0)
    assert stopped["state"] == "reached" and stopped["contact"] is True, stopped
    assert held["points"][-1]["positions"] == [pytest.approx(0.10)]  # no more pressing on it
    plain, _ = run({"id": 2, "group": "arm", "pose": "down"}, 8.0)
    assert plain["state"] == "failed" and "not reached" in plain["error"] and "lift_joint still 0.100" in plain["error"]
