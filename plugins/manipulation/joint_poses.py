"""``plugin.joint-poses``: the ``arm-motion`` interface for joints that need no inverse kinematics — a
lift, a linear axis, a wrist roll, a turntable — moved to named poses given as joint values.

``plugin.arm-poses`` solves Cartesian poses on a pan joint and two or three pitch joints (D264); a
carrier's lift (one prismatic joint) or a station's wrist roll (one revolute joint on the tool axis)
has no such chain, yet ``pick-object``, ``place-object`` and ``pick`` drive them through the same
interface. Configured by its Params — the URDF (``model``: each joint's limits and velocity), the
joints (``joints``, any number, any of revolute or prismatic) and the poses (``poses``: ``"down: 0.0;
carry: 0.25"``, one value per joint, in the joint's unit: rad or m) — and its two inputs:

- ``goal`` (ArmGoal): ``{"id": int, "group": "arm", "pose": name, "speed": optional share in (0, 1],
  "contact": optional, true: reached when stopped short of the pose by contact}``; a Cartesian
  ``target`` is refused (this service has no kinematic chain); a new goal preempts the old;
- ``joint_states`` (JointState): the joints' positions; with no names, in the order of ``joints``.

Outputs: ``trajectory`` (JointTrajectory, once per goal and once more to hold a place ended by
contact: the measured start at 0, the pose at T = max over the joints of 1.5·|Δq|/(v·speed), v the
URDF's velocity limit) and ``status`` (ArmStatus: ``{stamp, id, group, pose, state: moving | reached
| failed, active, error, holding: false, contact, opening: None}``), the measures ``active`` and
``holding`` (always 0: the gripper is a service of its own). Reached: every joint within
``tolerance`` of the pose; with ``contact`` (or a pose of ``contactPoses``), also when the joints have
stood still (each within ``stillness``) short of it for ``settle`` s after the planned time — a
carried object set down on its support. Failed: an unknown pose or group, a target, or not reached
``timeout`` s after the planned time. A pose without one value per joint, or outside its joint's URDF
limits, and a joint the URDF lacks or that is fixed are refused by ``verify`` at the Param. Time is the
frame's stamp.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import pybullet as p

from ckmconf.model import System
from ckmconf.model.resources import Plugin
from plugins.urdf_model import load_urdf
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.entries import Entries
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .arm_poses import MotionGoal
from .joint_states import joint_values
from .kinematics import MODELS

POSES = Entries("value…", count=1, most=32, numbers=True)
"""The ``poses`` Param's syntax: each pose one number per joint (the count is checked against ``joints``)."""

CUBIC_PEAK = 1.5
"""Peak over mean speed of the controller's cubic rest-to-rest segment (plugins/controllers/trajectory.py)."""
MIN_DURATION = 0.1
"""Shortest planned motion (s)."""


class JointPoses(ProcessingPlugin):
    """Named joint poses to joint trajectories, and their status (see the module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})  # ArmGoal + JointState in; trajectory, status out
    PROVIDES = "arm-motion"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", REQUIRED, "Robot URDF: a model name of plugins/sim/models, or a path relative to the "
          "configuration file.", type=str),
        P("joints", REQUIRED, "The joints moved, space-separated (any number, revolute or prismatic; also the "
          "order of a JointState without names).", type=str),
        P("poses", REQUIRED, "The named poses, 'name: one value per joint; …' (rad or m, within the URDF's "
          "limits).", type=str, entries=POSES),
        P("speed", 0.5, "Velocity scaling until the service Parameter 'speed' sets it.", above=0.0, max=1.0),
        P("tolerance", 0.01, "Largest joint error at which a pose counts as reached (rad or m).", above=0.0),
        P("settle", 0.5, "How long joints stopped short by contact must stand still to count as reached.",
          unit="s", above=0.0),
        P("stillness", 0.003, "Largest joint motion over 'settle' s of joints standing still on contact (rad or "
          "m).", above=0.0),
        P("contactPoses", "", "Poses (space-separated) reached when the joints stop short of them on contact."),
        P("timeout", 5.0, "Time allowed after the planned duration before a goal fails.", unit="s", above=0.0),
    )

    @classmethod
    def problems(cls, record: Plugin, system: System | None) -> list[tuple[Any, str]]:
        """What ``verify`` (and the build) refuses across the Params, at the Param: joints named twice, a
        pose without one value per joint, a contact pose that is no pose, and against the URDF a joint
        it lacks, a joint neither revolute nor prismatic, a pose value outside its joint's limits."""
        given = {p.name: p for p in record.params}
        joints_param, poses_param = given.get("joints"), given.get("poses")
        if joints_param is None or poses_param is None:
            return []  # the manifest check reports a missing Param
        joints = joints_param.value.split()
        if not joints or len(set(joints)) != len(joints):
            return [(joints_param, f"parameter 'joints' must name each joint once, got {joints_param.value!r}")]
        try:
            poses = POSES.parse(poses_param.value, "poses")
        except ParamError:
            return []  # the manifest check reports the syntax at its entry
        found: list[tuple[Any, str]] = []
        for name, values in poses.items():
            if len(values) != len(joints):
                found.append((poses_param, f"parameter 'poses': pose {name!r} needs one value per joint "
                                           f"({len(joints)}: {' '.join(joints)}), got {len(values)}"))
        contact = given.get("contactPoses")
        for name in (contact.value.split() if contact is not None else []):
            if name not in poses:
                found.append((contact, f"parameter 'contactPoses' names pose {name!r}, which is not one of "
                                       f"'poses' ({', '.join(poses)})"))
        model = given.get("model")
        if found or model is None:
            return found
        path = _model_path(record, model.value)
        if not path.is_file():
            return [(model, f"robot model {path} does not exist")]
        try:
            limits = _joint_limits(path, joints)
        except ValueError as exc:
            return [(joints_param, str(exc))]
        for name, values in poses.items():
            for joint, q in zip(joints, values, strict=True):
                lower, upper, _ = limits[joint]
                if lower < upper and not lower - 1e-9 <= q <= upper + 1e-9:
                    found.append((poses_param, f"parameter 'poses': pose {name!r} puts joint {joint!r} at {q}, "
                                               f"outside its limits {lower} to {upper} in {path.name}"))
        return found

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        if (problems := self.problems(record, None)):
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        v = self.params
        self.joints: list[str] = str(v["joints"]).split()
        self.poses: dict[str, list[float]] = {name: [float(q) for q in values] for name, values in v["poses"].items()}
        self.model_path = _model_path(record, str(v["model"]))
        self.speed: float = v["speed"]
        self.contact_poses = frozenset(str(v["contactPoses"]).split())
        self.velocity: list[float] = []
        self.goal: MotionGoal | None = None
        self._message: Any = None
        self._history: deque[tuple[float, tuple[float, ...]]] = deque()

    def setup(self) -> None:
        """Each joint's velocity limit from the URDF (loaded privately, then closed); the Params re-checked."""
        if not self.model_path.is_file():
            raise FileNotFoundError(f"{self.owner}: robot model {self.model_path} does not exist")
        try:
            limits = _joint_limits(self.model_path, self.joints)
        except ValueError as exc:
            raise ValueError(f"{self.owner}: {exc}") from None
        self.velocity = [limits[j][2] or 1.0 for j in self.joints]

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``speed`` Parameter: the velocity scaling of later goals."""
        if "speed" in parameters:
            self.speed = _speed(parameters["speed"], f"{self.owner}: service parameter 'speed'")

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The trajectory of a new goal, its status and the ``active`` measure.

        Raises:
            RuntimeError: ``setup()`` was not called.
            ValueError: ``data`` is not a mapping of the inputs.
        """
        if not self.velocity:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'goal': …, 'joint_states': …}}, got {type(data).__name__}")
        now = context.stamp
        result: dict[str, Any] = {}
        try:
            positions, reading = joint_values(data.get("joint_states"), self.joints, self.owner), ""
        except ValueError as exc:
            positions, reading = None, str(exc)
        message = data.get("goal")
        if message is not None and message != self._message:
            self._message, self.goal = message, self._accept(message)
            self._history.clear()
        goal = self.goal
        if goal is not None and goal.state == "moving" and positions is not None:
            if goal.started is None:
                result["trajectory"] = self._plan(goal, positions, now)
            self._judge(goal, positions, now)
            if goal.contact:  # hold where it stopped: no more pressing on what stopped it
                result["trajectory"] = _trajectory(self.joints, list(positions), list(positions), MIN_DURATION)
        active = not reading and (goal is None or goal.state != "failed")
        result["active"], result["holding"] = (1 if active else 0), 0
        if goal is not None:
            result["status"] = {"stamp": now, "id": goal.id, "group": goal.group, "pose": goal.pose,
                                 "state": goal.state, "active": active, "error": goal.error or reading,
                                 "holding": False, "contact": goal.contact, "opening": None}
        return result

    def _accept(self, message: Any) -> MotionGoal:
        """A new goal, already failed if it cannot be executed (the reason in its ``error``)."""
        if not isinstance(message, Mapping):
            nothing = MotionGoal({}, "", "", self.speed)
            return _failed(nothing, f"goal is {type(message).__name__}, not an ArmGoal mapping")
        goal = MotionGoal(message, str(message.get("group") or ""), str(message.get("pose") or ""), self.speed)
        if isinstance(goal.id, bool) or not isinstance(goal.id, int):
            return _failed(goal, f"goal id {goal.id!r} is not an integer")
        if goal.group != "arm":
            return _failed(goal, f"goal {goal.id}: group {goal.group!r} is not 'arm' (a gripper is a service of its "
                                 "own)")
        if message.get("target") is not None:
            return _failed(goal, f"goal {goal.id}: this service moves its joints to named poses only, not to "
                                 "Cartesian targets")
        if goal.pose not in self.poses:
            return _failed(goal, f"goal {goal.id}: unknown pose {goal.pose!r} (defined: {', '.join(self.poses)})")
        if message.get("speed"):
            try:
                goal.speed = _speed(message["speed"], f"goal {goal.id} speed")
            except ValueError as exc:
                return _failed(goal, str(exc))
        goal.stops_on_contact = goal.pose in self.contact_poses or message.get("contact") is True
        goal.target = list(self.poses[goal.pose])
        return goal

    def _plan(self, goal: MotionGoal, positions: Sequence[float], now: float) -> dict[str, Any]:
        duration = max(CUBIC_PEAK * abs(t - s) / (v * goal.speed)
                       for s, t, v in zip(positions, goal.target, self.velocity, strict=True))
        goal.started, goal.duration = now, max(MIN_DURATION, duration)
        return _trajectory(self.joints, list(positions), goal.target, goal.duration)

    def _judge(self, goal: MotionGoal, positions: Sequence[float], now: float) -> None:
        """Reached, still moving, or failed by timeout (see the module docstring)."""
        assert goal.started is not None
        errors = [abs(q - t) for q, t in zip(positions, goal.target, strict=True)]
        if max(errors) <= self.params["tolerance"]:
            goal.state = "reached"
            return
        if goal.stops_on_contact and self._still(goal, positions, now):
            goal.state, goal.contact = "reached", True
            return
        if now - goal.started > goal.duration + self.params["timeout"]:
            worst = max(range(len(errors)), key=errors.__getitem__)
            _failed(goal, f"goal {goal.id}: pose {goal.pose!r} not reached in "
                          f"{goal.duration + self.params['timeout']:.1f} s ({self.joints[worst]} still "
                          f"{errors[worst]:.3f} from its target)")

    def _still(self, goal: MotionGoal, positions: Sequence[float], now: float) -> bool:
        """Whether the joints have each moved less than ``stillness`` over the last ``settle`` s, after the
        planned time."""
        assert goal.started is not None
        self._history.append((now, tuple(positions)))
        settle = self.params["settle"]
        while len(self._history) > 1 and self._history[1][0] <= now - settle:
            self._history.popleft()  # keep one sample at or before the window's start
        if now - goal.started < goal.duration or now - self._history[0][0] < settle:
            return False
        bound = self.params["stillness"]
        return all(max(q) - min(q) < bound for q in zip(*(s for _, s in self._history), strict=True))


def _model_path(record: Plugin, model: str) -> Path:
    """A model name of plugins/sim/models, or a path relative to the configuration file."""
    return config_dir(record) / model if Path(model).suffix else MODELS / f"{model}.urdf"


def _joint_limits(path: Path, joints: Sequence[str]) -> dict[str, tuple[float, float, float]]:
    """Each joint's (lower, upper, velocity) limits in the URDF at ``path``.

    Raises:
        ValueError: the model cannot be loaded, lacks a joint, or a joint is not revolute or prismatic.
    """
    model = load_urdf(path)
    try:
        missing = [j for j in joints if j not in model.joints]
        if missing:
            raise ValueError(f"the robot model {path} has no joint {', '.join(missing)}")
        infos = {j: p.getJointInfo(model.body, model.joints[j], physicsClientId=model.client) for j in joints}
    finally:
        p.disconnect(physicsClientId=model.client)
    for joint, info in infos.items():
        if info[2] not in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC):
            raise ValueError(f"joint {joint!r} of {path} is not revolute or prismatic")
    return {j: (float(info[8]), float(info[9]), float(info[11])) for j, info in infos.items()}


def _speed(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0.0 < value <= 1.0:
        raise ValueError(f"{where} = {value!r} must be a number in (0, 1]")
    return float(value)


def _failed(goal: MotionGoal, error: str) -> MotionGoal:
    goal.state, goal.error = "failed", error
    return goal


def _trajectory(joints: Sequence[str], start: list[float], end: Sequence[float], duration: float) -> dict[str, Any]:
    """A JointTrajectory of ``joints`` from ``start`` to ``end`` in ``duration`` s."""
    if not math.isfinite(duration):
        duration = MIN_DURATION
    return {"joint_names": list(joints),
            "points": [{"positions": start, "time_from_start": 0.0},
                       {"positions": list(end), "time_from_start": duration}]}
