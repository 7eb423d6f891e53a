"""``plugin.arm-poses``: the RoboticArm.MoveIt service (thesis Table 7.1, §7.4.2, Fig. 7.20).

The thesis drives the Turtlebot arm through MoveIt! to *predefined positions* in two motion
groups, ``arm`` and ``gripper``. This SPT service plugin plays that role on its two inputs
(``{input name: newest value or None}``; the lab's ``RoboticArm.MoveIt`` service is one):

- ``goal`` (ArmGoal, ``/arm/goal``): ``{"id": int, "group": "arm" | "gripper", "pose": name,
  "speed": optional share in (0, 1]}``, or an arm goal by Cartesian target instead of a pose name,
  ``{"id", "group": "arm", "target": {"x", "y", "z" (m, base frame), "pitch" (rad, optional on an
  arm of two pitch joints, D264)}, "contact": optional, true: reached when stopped by contact, as
  a ``contactPoses`` pose is}`` solved when it comes (IK from the URDF, seeded with the arm's
  present posture); a goal with a new id (or new content) preempts the old;
- ``joint_states`` (JointState, ``/arm/joint_states``): ``{"stamp", "name": [...], "position":
  [...]}``; with no names (as the arm's bus sensor publishes it, D99) the positions are taken in
  the order of the Param ``joints``.

Outputs (only the keys naming a service Output are published):

- ``trajectory`` (JointTrajectory, once per goal, and once more to hold a place ended by contact):
  ``{"joint_names": the group's joints, "points": [{"positions": the measured start,
  "time_from_start": 0}, {"positions": the target, "time_from_start": T}]}`` for the
  joint-trajectory controller; T = max over the joints of
  1.5·|Δq|/(v·speed) — the cubic rest-to-rest profile's peak speed stays within v·speed, v the
  joint's velocity limit (URDF, or Param ``maxVelocity``), speed the service Parameter ``speed``
  (Table 7.1's configuration) or the goal's own;
- ``status`` (ArmStatus, every frame once a goal came): ``{"stamp", "id", "group", "pose",
  "state": "moving" | "reached" | "failed", "active", "error", "holding", "contact", "opening"}``,
  and ``"target"`` for a target goal (pose: the goal's pose name, "" for a target; target: the
  goal's Cartesian target, its pitch None when it gave none; holding: a gripper goal's; contact:
  an arm goal to a ``contactPoses`` pose, or asking for contact, ended by contact; opening: the
  gripper's measured opening as a share of its range, 0 before joint states, None on an arm whose
  gripper is a service of its own, Param ``gripper`` false);
- the measure ``active`` (Table 7.1): 1 while there is no error (no failed goal, joint states
  readable), else 0;
- the measure ``holding`` (the gripper's measure, issue K): 1 from a closing gripper goal that
  stopped on an object until a gripper goal opens or the fingers reach their closed target (the
  object slipped out), else 0 — what a mission checks to know the object is really picked.

Reached: every joint of the group within ``tolerance`` (rad) of its target (the gripper within
``gripperTolerance`` of its range); a gripper *closing* whose fingers have stopped short — an
object between them — for ``settle`` seconds after the planned time is reached too, with
``holding`` true. An arm goal to one of the ``contactPoses`` (the place), or one that asks
``"contact": true``, whose joints have stood still (each within ``stillness``) short of the target
for ``settle`` seconds after the planned time is reached too, with ``contact`` true in its status:
the held object stands on the table and holds the arm back (a carried object hangs lower after a
grasp that tilted it, D251); a last trajectory then holds the arm where it stopped, so that it
stops pressing the object and the fingers open.
Failed: an unknown pose, a pose or target the IK left out of reach or out of the joint limits (a
pose solved once, at set-up, a target when it comes, in a private pybullet client:
:mod:`.kinematics`), a pitch the arm cannot set there, or not reached ``timeout`` seconds after the
planned time; ``error`` says which. Time is the frame's stamp (``Context.stamp``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .joint_states import joint_values
from .kinematics import MODELS, ArmModel, ArmTarget, PoseFile, Solution, read_poses, target_of, target_text

CUBIC_PEAK = 1.5
"""Peak over mean speed of the controller's cubic rest-to-rest segment (plugins/controllers/trajectory.py)."""
MIN_DURATION = 0.1
"""Shortest planned motion (s): a goal already met still gets a well-formed trajectory."""


class MotionGoal:
    """An arm-motion goal being executed: what it asked, its target and its timing (also plugin.joint-poses')."""

    def __init__(self, message: Mapping[str, Any], group: str, pose: str, speed: float) -> None:
        self.id = message.get("id")
        self.group, self.pose, self.speed = group, pose, speed
        self.target_asked: dict[str, float | None] | None = None  # a Cartesian target, as the goal gave it
        self.point: ArmTarget | None = None  # that target, parsed
        self.state = "moving"
        self.error = ""
        self.holding = False
        self.contact = False
        self.stops_on_contact = False  # a contactPoses pose, or a goal asking "contact": true
        self.indices: list[int] = []
        self.target: list[float] = []
        self.started: float | None = None  # planned once joint states are known
        self.duration = 0.0


class ArmPoses(ProcessingPlugin):
    """Goals by predefined pose name to joint trajectories, and their status (see the module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})  # ArmGoal + JointState in; trajectory, status out
    PROVIDES = "arm-motion"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", REQUIRED, "Robot URDF: a model name of plugins/sim/models, or a path relative to the "
          "configuration file.", type=str),
        P("poses", REQUIRED, "Pose file (the named poses' targets, docs/manipulation.md), relative to the "
          "configuration file.", type=str),
        P("joints", REQUIRED, "The pan joint and the two or three pitch joints, in chain order, then the "
          "gripper joint when 'gripper' is true (also the order of a JointState without names).", type=str),
        P("gripper", True, "Whether the last of 'joints' is a gripper moved by 'gripper' goals (false: the "
          "arm alone; its gripper, if any, is a gripper service of its own)."),
        P("maxVelocity", "", "Velocity limit per joint, one value or one per joint (empty: the URDF's).",
          unit="rad/s"),
        P("pitchTolerance", 0.1, "On an arm of two pitch joints, the largest difference between a target's "
          "pitch and the pitch the arm has at its point (see the module docstring).", unit="rad", above=0.0),
        P("speed", 0.5, "Velocity scaling until the service Parameter 'speed' sets it.", above=0.0, max=1.0),
        P("tolerance", 0.02, "Largest arm joint error at which a pose counts as reached.", unit="rad", above=0.0),
        P("gripperTolerance", 0.05, "Largest gripper error, as a share of its range.", above=0.0, max=1.0),
        P("settle", 0.5, "How long closing fingers must stand still on an object to count as holding it.",
          unit="s", above=0.0),
        P("contactPoses", "", "Arm poses (space-separated) reached when the arm stops short of them on "
          "contact for 'settle' s: setting the held object down."),
        P("stillness", 0.005, "Largest joint motion over 'settle' s of an arm standing still on contact.",
          unit="rad", above=0.0),
        P("timeout", 5.0, "Time allowed after the planned duration before a goal fails.", unit="s", above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        v = self.params
        self.joints: list[str] = v["joints"].split()
        self.has_gripper: bool = v["gripper"]
        self.arm_count = len(self.joints) - self.has_gripper
        if self.arm_count not in (3, 4) or len(set(self.joints)) != len(self.joints):
            gripper = " and the gripper joint" if self.has_gripper else ""
            raise ParamError(f"{self.owner}: parameter 'joints' must name 3 or 4 arm joints{gripper}, "
                             f"each once, got {v['joints']!r}")
        base = config_dir(record)
        model = str(v["model"])
        self.model_path = base / model if Path(model).suffix else MODELS / f"{model}.urdf"
        self.poses_path = base / v["poses"]
        velocity = v["maxVelocity"].split()
        try:
            self.max_velocity = [float(x) for x in velocity]
        except ValueError:
            raise ParamError(f"{self.owner}: parameter 'maxVelocity' = {v['maxVelocity']!r} is not numbers") from None
        count = len(self.joints)
        positive = all(x > 0 and math.isfinite(x) for x in self.max_velocity)
        if len(self.max_velocity) not in (0, 1, count) or not positive:
            raise ParamError(f"{self.owner}: parameter 'maxVelocity' needs one or {count} positive numbers")
        self.speed: float = v["speed"]
        self.contact_poses = frozenset(str(v["contactPoses"]).split())
        self.model: ArmModel | None = None
        self.file: PoseFile | None = None
        self.solutions: dict[str, Solution] = {}
        self.velocity: list[float] = []
        self.goal: MotionGoal | None = None
        self._message: Any = None
        self._history: deque[tuple[float, tuple[float, ...]]] = deque()  # the goal's joints over 'settle' s
        self._posture: list[float] | None = None  # the arm joints' last measured positions (the IK's seed)
        self.held: float | None = None  # the closing target of the gripper goal now holding an object

    # ------------------------------------------------------------------ set-up

    def setup(self) -> None:
        """Read the pose file, load the URDF privately and solve every arm pose (Fig. 7.20)."""
        try:
            self.file = read_poses(self.poses_path)
        except OSError as exc:
            raise OSError(exc.errno, f"{self.owner}: cannot read pose file {self.poses_path}: {exc.strerror}") from exc
        except ValueError as exc:
            raise ValueError(f"{self.owner}: bad pose file: {exc}") from None
        if not self.model_path.is_file():
            raise FileNotFoundError(f"{self.owner}: robot model {self.model_path} does not exist")
        try:
            gripper = self.joints[-1] if self.has_gripper else None
            self.model = ArmModel(self.model_path, self.joints[: self.arm_count], gripper, self.file.tool)
        except ValueError as exc:
            raise ValueError(f"{self.owner}: {exc}") from None
        given = self.max_velocity * len(self.joints) if len(self.max_velocity) == 1 else self.max_velocity
        self.velocity = [min(u, g) for u, g in zip(self.model.velocity, given, strict=True)] if given else list(
            self.model.velocity)
        self.solutions = {name: self.model.solve(target) for name, target in self.file.arm.items()}

    def stop(self) -> None:
        """Close the private arm model."""
        if self.model is not None:
            self.model.close()
            self.model = None

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``speed`` Parameter (Table 7.1): the velocity scaling of later goals."""
        if "speed" in parameters:
            self.speed = self._speed(parameters["speed"], "service parameter 'speed'")

    def _speed(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < value <= 1.0:
            raise ValueError(f"{self.owner}: {where} = {value!r} must be a number in (0, 1]")
        return float(value)

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The trajectory of a new goal, the arm's status and its ``active`` measure (Table 7.1).

        Raises:
            RuntimeError: ``setup()`` was not called.
            ValueError: ``data`` is not a mapping of the inputs.
        """
        if self.model is None or self.file is None:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'goal': …, 'joint_states': …}}, got {type(data).__name__}")
        now = context.stamp
        result: dict[str, Any] = {}
        try:
            positions = self._positions(data.get("joint_states"))
            reading = ""
        except ValueError as exc:
            positions, reading = None, str(exc)
        message = data.get("goal")
        if message is not None and message != self._message:
            self._message = message
            self.goal = self._accept(message)
            self._history.clear()
        goal = self.goal
        if goal is not None and goal.state == "moving" and positions is not None:
            if goal.started is None:
                result["trajectory"] = self._plan(goal, positions, now)
            self._judge(goal, positions, now)
            if goal.contact:  # stop pressing the object onto the table: the fingers must open freely
                result["trajectory"] = self._stay(goal, positions)
        grip = self.arm_count  # the gripper joint's index, when there is one
        if positions is not None and self.has_gripper:
            self._hold(goal, positions[grip])
        active = not reading and (goal is None or goal.state != "failed")
        result["active"] = 1 if active else 0
        result["holding"] = 0 if self.held is None else 1
        if goal is not None:
            error = goal.error or reading
            opening = None if not self.has_gripper else 0.0 if positions is None else self._opening(positions[grip])
            status = {"stamp": now, "id": goal.id, "group": goal.group, "pose": goal.pose, "state": goal.state,
                      "active": active, "error": error,
                      "holding": goal.holding,  # never true for an arm goal
                      "contact": goal.contact,  # never true for a gripper goal
                      "opening": opening}
            if goal.target_asked is not None:  # (a pose goal's status keeps the fields it always had)
                status["target"] = goal.target_asked
            result["status"] = status
        return result

    def _opening(self, position: float) -> float:
        """The gripper joint's ``position`` as a share of its range (the pose file's gripper scale)."""
        assert self.model is not None
        low, high = self.model.lower[-1], self.model.upper[-1]
        return round((position - low) / (high - low), 4)

    def _positions(self, state: Any) -> list[float] | None:
        """The joint positions (Param ``joints`` order) of a JointState, None before the first."""
        values = joint_values(state, self.joints, self.owner)
        if values is not None:
            self._posture = values[: self.arm_count]
        return values

    def _accept(self, message: Any) -> MotionGoal:
        """A new goal, already failed if it cannot be executed (the reason in its ``error``)."""
        assert self.file is not None
        if not isinstance(message, Mapping):
            goal = MotionGoal({}, "", "", self.speed)
            return self._fail(goal, f"goal is {type(message).__name__}, not an ArmGoal mapping")
        group, pose = message.get("group"), message.get("pose")
        goal = MotionGoal(message, str(group or ""), str(pose or ""), self.speed)
        if isinstance(goal.id, bool) or not isinstance(goal.id, int):
            return self._fail(goal, f"goal id {goal.id!r} is not an integer")
        if group not in ("arm", "gripper"):
            return self._fail(goal, f"goal {goal.id}: group {group!r} is not 'arm' or 'gripper'")
        if group == "gripper" and not self.has_gripper:
            return self._fail(goal, f"goal {goal.id}: this arm moves no gripper (its gripper is a service of "
                                    "its own)")
        target = message.get("target")
        known = self.file.arm if group == "arm" else self.file.gripper
        if target is not None:
            if group != "arm" or pose:
                return self._fail(goal, f"goal {goal.id}: a target is an arm goal's, instead of a pose")
            parsed = target_of(target)
            if isinstance(parsed, str):
                return self._fail(goal, f"goal {goal.id}: {parsed}")
            goal.point = parsed
            goal.target_asked = {"x": parsed.x, "y": parsed.y, "z": parsed.z, "pitch": parsed.pitch}
        elif pose not in known:
            return self._fail(goal, f"goal {goal.id}: unknown {group} pose {pose!r} (defined: {', '.join(known)})")
        goal.stops_on_contact = group == "arm" and (pose in self.contact_poses or message.get("contact") is True)
        speed = message.get("speed")
        if speed:
            try:
                goal.speed = self._speed(speed, f"goal {goal.id} speed")
            except ValueError as exc:
                return self._fail(goal, str(exc))
        assert self.model is not None
        if group == "arm" and goal.point is not None and goal.target_asked is not None:
            solution = self.model.solve(goal.point, self._posture,
                                        pitch_tolerance=self.params["pitchTolerance"])
            if solution.error:
                return self._fail(goal, f"goal {goal.id}: target {target_text(goal.target_asked)} cannot be reached: "
                                        f"{solution.error}")
            goal.indices, goal.target = list(range(self.arm_count)), list(solution.joints)
        elif group == "arm":
            solution = self.solutions[goal.pose]
            if solution.error:
                return self._fail(goal, f"goal {goal.id}: arm pose {goal.pose!r} cannot be reached: {solution.error}")
            goal.indices, goal.target = list(range(self.arm_count)), list(solution.joints)
        else:
            goal.indices, goal.target = [self.arm_count], [self.model.gripper_position(self.file.gripper[goal.pose])]
        return goal

    def _fail(self, goal: MotionGoal, error: str) -> MotionGoal:
        goal.state, goal.error = "failed", error
        return goal

    def _plan(self, goal: MotionGoal, positions: Sequence[float], now: float) -> dict[str, Any]:
        """The goal's JointTrajectory from the measured ``positions``, timed at the goal's speed."""
        start = [positions[i] for i in goal.indices]
        duration = max(CUBIC_PEAK * abs(t - s) / (self.velocity[i] * goal.speed)
                       for i, s, t in zip(goal.indices, start, goal.target, strict=True))
        goal.started, goal.duration = now, max(MIN_DURATION, duration)
        return self._trajectory(goal, start, goal.target, goal.duration)

    def _trajectory(
        self, goal: MotionGoal, start: list[float], end: Sequence[float], duration: float
    ) -> dict[str, Any]:
        """A JointTrajectory of the goal's joints from ``start`` to ``end`` in ``duration`` s."""
        return {
            "joint_names": [self.joints[i] for i in goal.indices],
            "points": [{"positions": start, "time_from_start": 0.0},
                       {"positions": list(end), "time_from_start": duration}],
        }

    def _stay(self, goal: MotionGoal, positions: Sequence[float]) -> dict[str, Any]:
        """A JointTrajectory holding the goal's joints where they stand (the controller's target
        becomes the measured position: the arm no longer pushes on what stopped it)."""
        here = [positions[i] for i in goal.indices]
        return self._trajectory(goal, here, here, MIN_DURATION)

    def _judge(self, goal: MotionGoal, positions: Sequence[float], now: float) -> None:
        """Reached, still moving, or failed by timeout (see the module docstring)."""
        assert self.model is not None and goal.started is not None
        errors = [abs(positions[i] - t) for i, t in zip(goal.indices, goal.target, strict=True)]
        if goal.group == "arm":
            if max(errors) <= self.params["tolerance"]:
                goal.state = "reached"
                return
            if goal.stops_on_contact and self._still(goal, positions, now, self.params["stillness"]):
                goal.state, goal.contact = "reached", True
                return
        else:
            span = self.model.upper[-1] - self.model.lower[-1]
            if errors[0] <= self.params["gripperTolerance"] * span:
                goal.state = "reached"
                return
            if self._holding(goal, positions, now, span):
                goal.state, goal.holding = "reached", True
                return
        if now - goal.started > goal.duration + self.params["timeout"]:
            worst = max(range(len(errors)), key=errors.__getitem__)
            what = f"pose {goal.pose!r}" if goal.target_asked is None else f"target {target_text(goal.target_asked)}"
            self._fail(goal, f"goal {goal.id}: {goal.group} {what} not reached in "
                             f"{goal.duration + self.params['timeout']:.1f} s ({self.joints[goal.indices[worst]]} "
                             f"still {errors[worst]:.3f} from its target)")

    def _hold(self, goal: MotionGoal | None, position: float) -> None:
        """Keep the ``holding`` measure: set when a closing gripper goal stops on an object, cleared
        when a gripper goal opens, or when the fingers reach their closed target (the object slipped out)."""
        assert self.model is not None
        if goal is not None and goal.group == "gripper":
            if goal.holding:
                self.held = goal.target[0]
            elif goal.state != "failed" and (self.held is None or goal.target[0] > self.held):
                self.held = None  # an opening goal lets the object go (or nothing was held)
        if self.held is not None:
            span = self.model.upper[-1] - self.model.lower[-1]
            if abs(position - self.held) <= self.params["gripperTolerance"] * span:
                self.held = None

    def _holding(self, goal: MotionGoal, positions: Sequence[float], now: float, span: float) -> bool:
        """Whether closing fingers have stood still short of their target for ``settle`` s (an object)."""
        closing = goal.target[0] < positions[self.arm_count]
        return self._still(goal, positions, now, 0.01 * span) and closing

    def _still(self, goal: MotionGoal, positions: Sequence[float], now: float, bound: float) -> bool:
        """Whether the goal's joints have each moved less than ``bound`` over the last ``settle`` s,
        after its planned time."""
        assert goal.started is not None
        self._history.append((now, tuple(positions[i] for i in goal.indices)))
        settle = self.params["settle"]
        while len(self._history) > 1 and self._history[1][0] <= now - settle:
            self._history.popleft()  # keep one sample at or before the window's start
        if now - goal.started < goal.duration or now - self._history[0][0] < settle:
            return False
        return all(max(values) - min(values) < bound for values in zip(*(q for _, q in self._history), strict=True))
