"""``plugin.parallel-gripper``: a parallel-jaw gripper as a goal service, the ``gripper`` interface
(docs/interfaces.md; control_msgs/GripperCommand as an action).

Configured only by its Params — the robot's URDF (``model``), the finger joint(s) (``joints``: the
first is measured and gives the range, lower limit closed, upper open; every one is commanded to the
same position, for a controller that drives each finger, or one joint whose channel mirrors the
other), the speed and force — and its two inputs (``{input name: newest value or None}``):

- ``command`` (GripperCommand): ``{"id": int, "action": "open" | "close" | "position", "position":
  the opening for ``position`` (a share 0..1 of the range, or the joint's unit — m on prismatic
  fingers — with Param ``positionUnit`` = joint), "max_effort": optional force limit (N, > 0)}``;
  every new command (new id or content) preempts the one before;
- ``joint_states`` (JointState): the fingers' positions (and efforts, when it carries them); with
  no names, in the order of ``joints``.

Outputs (only the keys naming a service Output are published):

- ``trajectory`` (JointTrajectory, once per command): ``{"joint_names": joints, "points": [the
  measured start at 0, the target at T]}``, T = 1.5·|Δ|/speed (the cubic rest-to-rest profile's
  peak speed stays within ``speed``); each point's ``effort`` is the force limit, min(``force``,
  the command's ``max_effort``), for an actuator that takes one (the simulated channels drive at the
  URDF's effort limit);
- ``status`` (GripperStatus, every frame once a command came): ``{"stamp", "id", "action",
  "state": "moving" | "reached" | "holding" | "stalled" | "failed", "position" (the first finger's
  joint position), "opening" (its share of the range), "holding" (bool), "effort" (measured, None
  when the joint states carry none), "max_effort", "reason"}`` of the newest command;
- the measures ``holding`` (1 while the newest command holds an object, else 0) and ``active`` (0
  after a failed command or unreadable joint states).

Reached: the finger within ``tolerance`` (share of the range) of the target. Holding: a closing
command whose finger has stood still (within ``stillness`` of the range over ``settle`` s, after
the planned time) short of its target: an object is between the fingers (D265); if it slips out,
the fingers go on to their target and the command is ``reached``, no longer holding. Stalled: an
opening command stopped short the same way (the jaws blocked; ``reason`` says where). Failed: a bad
command (its ``reason``), or not reached ``timeout`` s after the planned time. Time is the frame's
stamp (``Context.stamp``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import pybullet as p

from ckmconf.model.resources import Plugin
from plugins.urdf_model import load_urdf
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin, config_dir
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .joint_states import joint_values
from .kinematics import MODELS

CUBIC_PEAK = 1.5
"""Peak over mean speed of the controller's cubic rest-to-rest segment (plugins/controllers/trajectory.py)."""
MIN_DURATION = 0.1
"""Shortest planned motion (s)."""
ACTIONS = ("open", "close", "position")


class _Command:
    """The command being executed: what it asked, its target and how it ended."""

    def __init__(self, message: Mapping[str, Any], limit: float) -> None:
        self.id = message.get("id")
        self.action = str(message.get("action") or "")
        self.max_effort = limit
        self.state = "moving"
        self.reason = ""
        self.target = 0.0
        self.closing = False
        self.started: float | None = None
        self.duration = 0.0


class ParallelGripper(ProcessingPlugin):
    """GripperCommand goals to finger trajectories, and their status (see the module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})  # GripperCommand + JointState in
    PROVIDES = "gripper"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("model", REQUIRED, "Robot URDF: a model name of plugins/sim/models, or a path relative to the "
          "configuration file.", type=str),
        P("joints", REQUIRED, "The finger joint(s), space-separated: the first is measured and gives the range "
          "(lower limit closed, upper open); each is commanded to the same position.", type=str),
        P("positionUnit", "share", "What a 'position' command's position is: a share of the range, or the "
          "joint's own unit (m on prismatic fingers, rad on a revolute jaw).", choices=("share", "joint")),
        P("speed", 0.0, "Finger speed, joint units per second (0: the URDF's velocity limit).", min=0.0),
        P("force", 0.0, "Force limit of every command, N (0: the URDF's effort limit); a command's max_effort "
          "lowers it.", unit="N", min=0.0),
        P("tolerance", 0.03, "Largest finger error, as a share of the range, at which a command is reached.",
          above=0.0, max=1.0),
        P("settle", 0.3, "How long the fingers must stand still short of the target to be holding or stalled.",
          unit="s", above=0.0),
        P("stillness", 0.01, "Largest finger motion over 'settle' s, as a share of the range, of fingers "
          "standing still.", above=0.0, max=1.0),
        P("timeout", 3.0, "Time allowed after the planned duration before a command fails.", unit="s", above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        v = self.params
        self.joints: list[str] = str(v["joints"]).split()
        if not self.joints or len(set(self.joints)) != len(self.joints):
            raise ParamError(f"{self.owner}: parameter 'joints' must name each finger joint once, got {v['joints']!r}")
        model = str(v["model"])
        self.model_path = config_dir(record) / model if Path(model).suffix else MODELS / f"{model}.urdf"
        self.lower = self.upper = 0.0
        self.speed = self.force = 0.0
        self.command: _Command | None = None
        self._message: Any = None
        self._history: deque[tuple[float, float]] = deque()  # the finger over 'settle' s
        self._ready = False

    def setup(self) -> None:
        """The range, speed and force of the first finger joint from the URDF (loaded privately, then closed)."""
        if not self.model_path.is_file():
            raise FileNotFoundError(f"{self.owner}: robot model {self.model_path} does not exist")
        try:
            model = load_urdf(self.model_path)
        except ValueError as exc:
            raise ValueError(f"{self.owner}: {exc}") from None
        try:
            missing = [j for j in self.joints if j not in model.joints]
            if missing:
                raise ValueError(f"{self.owner}: the robot model {self.model_path} has no joint {', '.join(missing)}")
            info = p.getJointInfo(model.body, model.joints[self.joints[0]], physicsClientId=model.client)
        finally:
            p.disconnect(physicsClientId=model.client)
        self.lower, self.upper = float(info[8]), float(info[9])
        if not self.lower < self.upper:
            raise ValueError(f"{self.owner}: finger joint {self.joints[0]!r} has no range in {self.model_path} "
                             f"(limits {self.lower} to {self.upper})")
        self.speed = self.params["speed"] or float(info[11]) or 1.0
        self.force = self.params["force"] or float(info[10]) or 10.0
        self._ready = True

    @property
    def span(self) -> float:
        """The fingers' range (joint units)."""
        return self.upper - self.lower

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The trajectory of a new command, the gripper's status and its measures.

        Raises:
            RuntimeError: ``setup()`` was not called.
            ValueError: ``data`` is not a mapping of the inputs.
        """
        if not self._ready:
            raise RuntimeError(f"{self.owner} is not set up")
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'command': …, 'joint_states': …}}, got {type(data).__name__}")
        now = context.stamp
        result: dict[str, Any] = {}
        state = data.get("joint_states")
        try:
            positions = joint_values(state, self.joints, self.owner)
            efforts = joint_values(state, self.joints, self.owner, "effort")
            reading = ""
        except ValueError as exc:
            positions, efforts, reading = None, None, str(exc)
        message = data.get("command")
        if message is not None and message != self._message:
            self._message = message
            self.command = self._accept(message)
            self._history.clear()
        command = self.command
        if command is not None and command.state in ("moving", "holding") and positions is not None:
            if command.started is None:
                result["trajectory"] = self._plan(command, positions[0], now)
            self._judge(command, positions[0], now)
        active = not reading and (command is None or command.state != "failed")
        holding = command is not None and command.state == "holding"
        result["active"] = 1 if active else 0
        result["holding"] = 1 if holding else 0
        if command is not None:
            position = None if positions is None else round(positions[0], 5)
            opening = None if positions is None else round((positions[0] - self.lower) / self.span, 4)
            result["status"] = {"stamp": now, "id": command.id, "action": command.action, "state": command.state,
                                "position": position, "opening": opening, "holding": holding,
                                "effort": None if efforts is None else efforts[0],
                                "max_effort": command.max_effort, "reason": command.reason or reading}
        return result

    def _accept(self, message: Any) -> _Command:
        """A new command, already failed if it cannot be executed (the reason in its ``reason``)."""
        if not isinstance(message, Mapping):
            return self._fail(_Command({}, self.force), f"command is {type(message).__name__}, not a GripperCommand")
        command = _Command(message, self.force)
        if isinstance(command.id, bool) or not isinstance(command.id, int):
            return self._fail(command, f"command id {command.id!r} is not an integer")
        if command.action not in ACTIONS:
            return self._fail(command, f"command {command.id}: action {command.action!r} is not one of "
                                       f"{', '.join(ACTIONS)}")
        effort = message.get("max_effort")
        if effort not in (None, 0, 0.0):
            if isinstance(effort, bool) or not isinstance(effort, int | float) or not effort > 0:
                return self._fail(command, f"command {command.id}: max_effort {effort!r} is not a positive number")
            command.max_effort = min(self.force, float(effort))
        if command.action == "open":
            command.target = self.upper
        elif command.action == "close":
            command.target = self.lower
        else:
            wanted = message.get("position")
            if isinstance(wanted, bool) or not isinstance(wanted, int | float):
                return self._fail(command, f"command {command.id}: position {wanted!r} is not a number")
            share = self.params["positionUnit"] == "share"
            low, high = (0.0, 1.0) if share else (self.lower, self.upper)
            if not low <= wanted <= high:
                unit = "share of the range" if share else "joint position"
                return self._fail(command, f"command {command.id}: position {wanted} is outside the "
                                           f"{unit} [{low:g}, {high:g}]")
            command.target = self.lower + wanted * self.span if share else float(wanted)
        return command

    def _fail(self, command: _Command, reason: str) -> _Command:
        command.state, command.reason = "failed", reason
        return command

    def _plan(self, command: _Command, start: float, now: float) -> dict[str, Any]:
        """The command's JointTrajectory from the measured ``start``, at ``speed``."""
        command.closing = command.target < start
        command.started = now
        command.duration = max(MIN_DURATION, CUBIC_PEAK * abs(command.target - start) / self.speed)
        effort = [command.max_effort] * len(self.joints)
        return {"joint_names": list(self.joints),
                "points": [{"positions": [start] * len(self.joints), "effort": effort, "time_from_start": 0.0},
                           {"positions": [command.target] * len(self.joints), "effort": effort,
                            "time_from_start": command.duration}]}

    def _judge(self, command: _Command, position: float, now: float) -> None:
        """Reached, holding, stalled, still moving, or failed by timeout (see the module docstring)."""
        assert command.started is not None
        error = abs(position - command.target)
        if error <= self.params["tolerance"] * self.span:
            command.state, command.reason = "reached", ""  # (an object held slipped out: closed on nothing)
            return
        if command.state == "holding":
            return
        if self._still(command, position, now):
            if command.closing:
                command.state = "holding"
            else:
                command.state = "stalled"
                command.reason = (f"command {command.id}: the fingers stopped at {position:.4f}, "
                                  f"{error:.4f} short of {command.target:.4f}")
            return
        if now - command.started > command.duration + self.params["timeout"]:
            self._fail(command, f"command {command.id}: {command.action} not reached in "
                                f"{command.duration + self.params['timeout']:.1f} s (the fingers still "
                                f"{error:.4f} from {command.target:.4f})")

    def _still(self, command: _Command, position: float, now: float) -> bool:
        """Whether the finger has moved less than ``stillness`` over the last ``settle`` s, after the plan."""
        assert command.started is not None
        self._history.append((now, position))
        settle = self.params["settle"]
        while len(self._history) > 1 and self._history[1][0] <= now - settle:
            self._history.popleft()  # keep one sample at or before the window's start
        if now - command.started < command.duration or now - self._history[0][0] < settle:
            return False
        values = [q for _, q in self._history]
        return bool(max(values) - min(values) < self.params["stillness"] * self.span)
