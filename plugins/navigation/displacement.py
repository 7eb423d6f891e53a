"""``plugin.base-displacement``: the Mobile Base's Displacement service (thesis §7.1, Table 7.1).

Inputs (a mapping, the service's ``<Input>`` names): ``path`` (Path2D from Navigation.AMCL, in the
odom frame, re-anchored every 0.8 s), ``move_goal`` (Move2D, a relative move of APPR or BACK, in the
robot frame, with an optional ``yaw_tolerance`` of its own for the final heading, 0 or none for the
service's own, as a ``ckm_interfaces/msg/MoveGoal`` carries it when not given) and
``wheel_odom`` (the Odometry of the kobuki's diff-drive-odometry controller).

Outputs: ``odom`` (Odometry: the wheel odometry's pose and twist with this service's dispersion),
``move_status`` (MoveStatus of the current or last relative move, by id: moving / done / failed
with ``remaining`` and ``total`` metres), ``wheel_cmd`` (Twist for /kobuki/cmd_vel). Top-level
``dispersion`` is the Table 7.1 "Odometry Dispersion" measure.

Behaviour, at the service rate (0.05 s): a path is followed by pure pursuit, a relative move by
rotate / drive / rotate (plugins/navigation/control.py), both on the wheel odometry, at most at
the ``speed`` Parameter (Table 7.1 "Speed"), acceleration-limited. A new move goal (new id) or a
new path (new id) preempts what runs: a preempted move ends ``failed``, and a preempted path's
id is ignored from then on (Navigation's re-anchored copies of it do not resume it); a path with
the same id replaces the points of the one followed (the re-anchoring). A path with no points
stops path following. No new ``wheel_odom`` for ``staleAfter`` seconds: the command is zero and
the acceleration limiter restarts from rest (the base's own ramp-stop has decelerated it).

Odometry dispersion (decision D105): the error model of the localization's odometry (AMCL's
alpha1..alpha4, plugins/localization/odometry.py, ``odometryNoise``) applied to the distance D and
the rotation Θ travelled since the last reset, as one move: σ_t² = α3·D² + α4·Θ² along the way,
σ_r² = α1·Θ² + α2·D² in heading, whose lateral effect integrates to D²·σ_r²/3; dispersion =
√(σ_t² + D²·σ_r²/3). It resets when a new path message (Navigation has just corrected the
odometry by localization) or a new move goal arrives: it is the uncertainty of the odometry as
the reference of the displacement under way.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, ClassVar

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .control import STOP, Command, Gains, Limiter, PathFollower, RelativeMove
from .frames import Point, Pose, compose, mapping, number, pose_message, pose_of, wrap

INPUTS = ("path", "move_goal", "wheel_odom")
MAX_POINTS = 10_000


def _alphas(text: str, owner: str) -> tuple[float, float, float, float]:
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) and v >= 0 for v in values):
        raise ParamError(f"{owner}: parameter 'odometryNoise' = {text!r} is not four non-negative numbers")
    return values[0], values[1], values[2], values[3]


def _goal_id(message: Mapping[str, Any], owner: str, where: str) -> int:
    value = message.get("id")
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{owner}: {where} field 'id' must be an integer, got {value!r}")
    return value


class BaseDisplacement(ProcessingPlugin):
    """``plugin.base-displacement``: path following, relative moves and odometry of the Kobuki base."""

    PORTS = Ports(inputs={"path": MAPPING, "move_goal": MAPPING, "wheel_odom": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "base-drive"  # docs/interfaces.md
    WRITES: ClassVar[Mapping[str, tuple[str, ...]]] = {"wheel_cmd": ("linear", "angular")}  # beyond its ports
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("speed", 0.3, "Top linear speed (Table 7.1 Speed); the service Parameter 'speed' overrides it.",
          unit="m/s", above=0.0, max=0.7),
        P("maxAngular", 1.5, "Top angular speed.", unit="rad/s", above=0.0),
        P("accel", 0.5, "Linear acceleration limit.", unit="m/s^2", above=0.0),
        P("angularAccel", 2.5, "Angular acceleration limit.", unit="rad/s^2", above=0.0),
        P("lookahead", 0.35, "Pure pursuit look-ahead distance.", unit="m", above=0.0),
        P("tolerance", 0.03, "A path end or a move goal within this distance is reached.", unit="m", above=0.0),
        P("yawTolerance", 0.03, "Final heading tolerance.", unit="rad", above=0.0),
        P("staleAfter", 0.3, "No new wheel odometry for this long: zero command.", unit="s", above=0.0),
        P("odometryNoise", "0.02 0.02 0.02 0.02", "alpha1..alpha4 of the odometry error model (dispersion)."),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        self.alphas = _alphas(p["odometryNoise"], self.owner)
        self.gains = Gains(max_angular=p["maxAngular"], accel=p["accel"], angular_accel=p["angularAccel"],
                           lookahead=p["lookahead"], tolerance=p["tolerance"], yaw_tolerance=p["yawTolerance"])
        self.speed: float = p["speed"]
        self.limiter = Limiter(self.gains)
        self.pose: Pose | None = None
        self.odom: Mapping[str, Any] | None = None
        self.fresh_at: float | None = None
        self.last_frame: float | None = None
        self.distance = self.rotation = 0.0
        self.follower: PathFollower | None = None
        self.path_id: int | None = None
        self.dropped: set[int] = set()
        self.move: RelativeMove | None = None
        self.move_id: int | None = None
        self.move_state = "done"
        self.move_reason = ""  # why the move failed (MoveStatus reason)
        self.move_deadline = 0.0
        self.ended: dict[str, Any] | None = None
        self._seen: dict[str, Any] = {}

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``speed`` Parameter (Table 7.1) caps the linear speed."""
        if "speed" in parameters:
            value = parameters["speed"]
            if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value <= 0.7:
                raise ValueError(f"{self.owner}: service parameter 'speed' = {value!r} must be in (0, 0.7] m/s")
            self.speed = float(value)

    @property
    def dispersion(self) -> float:
        """√(σ_t² + D²·σ_r²/3) for the distance and rotation travelled since the last reset (D105)."""
        a1, a2, a3, a4 = self.alphas
        d, r = self.distance, self.rotation
        trans = a3 * d * d + a4 * r * r
        rot = a1 * r * r + a2 * d * d
        return math.sqrt(trans + d * d * rot / 3.0)

    def _new(self, name: str, value: Any) -> bool:
        """Whether input ``name`` holds a message not handled yet (the stream hands the newest of each)."""
        if value is None or self._seen.get(name) == value:
            return False
        self._seen[name] = value
        return True

    # ------------------------------------------------------------------ delegation

    def state(self) -> dict[str, Any]:
        """Everything a copy on another node needs to go on (§3.1.2.5–6 delegation), msgpack-able."""
        return {
            "kind": "base-displacement", "speed": self.speed, "pose": None if self.pose is None else list(self.pose),
            "odom": None if self.odom is None else dict(self.odom), "fresh_at": self.fresh_at,
            "last_frame": self.last_frame, "distance": self.distance, "rotation": self.rotation,
            "follower": None if self.follower is None else self.follower.state(), "path_id": self.path_id,
            "dropped": sorted(self.dropped), "move": None if self.move is None else self.move.state(),
            "move_id": self.move_id, "move_state": self.move_state, "move_reason": self.move_reason,
            "move_deadline": self.move_deadline,
            "ended": self.ended, "command": list(self.limiter.last), "seen": dict(self._seen),
        }

    def restore(self, state: Mapping[str, Any]) -> None:
        """Go on from :meth:`state` of another copy; ValueError naming what is wrong."""
        try:
            if state.get("kind") != "base-displacement":
                raise ValueError(f"kind is {state.get('kind')!r}")
            pose = state["pose"]
            self.speed = float(state["speed"])
            self.pose = None if pose is None else (float(pose[0]), float(pose[1]), float(pose[2]))
            self.odom, self.fresh_at, self.last_frame = state["odom"], state["fresh_at"], state["last_frame"]
            self.distance, self.rotation = float(state["distance"]), float(state["rotation"])
            follower, move = state["follower"], state["move"]
            self.follower = None if follower is None else PathFollower.from_state(follower, self.gains)
            self.move = None if move is None else RelativeMove.from_state(move, self.gains)
            self.path_id, self.dropped = state["path_id"], {int(i) for i in state["dropped"]}
            self.move_id, self.move_state = state["move_id"], str(state["move_state"])
            self.move_reason = str(state.get("move_reason", ""))
            self.move_deadline, self.ended = float(state["move_deadline"]), state["ended"]
            self.limiter.last = (float(state["command"][0]), float(state["command"][1]))
            self._seen = dict(state["seen"])
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise ValueError(f"{self.owner}: not a base-displacement state ({exc})") from None

    # ------------------------------------------------------------------ inputs

    def _odometry(self, message: Any, now: float) -> None:
        odom = mapping(message, self.owner, "input 'wheel_odom'")
        pose = pose_of(odom, self.owner, "input 'wheel_odom'")
        if self.pose is not None:
            self.distance += math.dist(pose[:2], self.pose[:2])
            self.rotation += abs(wrap(pose[2] - self.pose[2]))
        self.pose, self.odom, self.fresh_at = pose, odom, now

    def _path(self, message: Any) -> None:
        path = mapping(message, self.owner, "input 'path'")
        path_id = _goal_id(path, self.owner, "input 'path'")
        if path.get("frame", "odom") != "odom":
            raise ValueError(f"{self.owner}: input 'path' must be in the odom frame, got {path.get('frame')!r}")
        raw = path.get("points")
        if not isinstance(raw, list | tuple) or len(raw) > MAX_POINTS:
            raise ValueError(
                f"{self.owner}: input 'path' field 'points' must be a list of [x, y] (at most {MAX_POINTS})"
            )
        points: list[Point] = []
        for i, item in enumerate(raw):
            pair = list(item) if isinstance(item, list | tuple) else []
            if len(pair) != 2 or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                                         for v in pair):
                raise ValueError(f"{self.owner}: input 'path' point {i} = {item!r} is not [x, y]")
            points.append((float(pair[0]), float(pair[1])))
        yaw = None if path.get("yaw") is None else wrap(number(path, "yaw", self.owner, "input 'path'"))
        speed = self.speed
        if path.get("speed") is not None:
            speed = min(speed, max(0.0, number(path, "speed", self.owner, "input 'path'"))) or self.speed
        self.distance = self.rotation = 0.0  # re-anchored by localization: the odometry error counts from here
        if not points:
            self.follower = None
            return
        if path_id in self.dropped:
            return
        if self.follower is not None and path_id == self.path_id:
            self.follower.update(points, yaw, speed)
            return
        self._end_move("failed", f"preempted by path {path_id}")  # a new path preempts a relative move
        self.follower, self.path_id = PathFollower(points, yaw, speed, self.gains), path_id

    def _move_goal(self, message: Any, now: float) -> None:
        goal = mapping(message, self.owner, "input 'move_goal'")
        goal_id = _goal_id(goal, self.owner, "input 'move_goal'")
        if goal.get("frame", "robot") != "robot":
            raise ValueError(f"{self.owner}: input 'move_goal' must be in the robot frame, got {goal.get('frame')!r}")
        where = "input 'move_goal'"
        local = (number(goal, "x", self.owner, where), number(goal, "y", self.owner, where),
                 wrap(number(goal, "yaw", self.owner, where)))
        gains = self.gains
        # a move that must end aimed finer (APPR_FLOOR, D252); 0 is ckm_interfaces/msg/MoveGoal's "not given"
        if goal.get("yaw_tolerance") not in (None, 0, 0.0):
            tolerance = number(goal, "yaw_tolerance", self.owner, where)
            if not 0.005 <= tolerance <= 0.5:
                raise ValueError(f"{self.owner}: {where} field 'yaw_tolerance' = {tolerance!r} must be in "
                                 "[0.005, 0.5] rad")
            gains = replace(gains, yaw_tolerance=tolerance)
        if goal_id == self.move_id:
            return
        self._end_move("failed", f"preempted by move {goal_id}")
        if self.follower is not None and self.path_id is not None:
            self.dropped.add(self.path_id)  # the move preempts the path, for good
            self.follower = None
        self.move_id, self.move_state, self.move_reason = goal_id, "moving", ""
        self.distance = self.rotation = 0.0
        if self.pose is None:
            self.move, self.move_state = None, "failed"
            self.move_reason = "no odometry received yet: no pose to move from"
            return
        self.move = RelativeMove(self.pose, compose(self.pose, local), self.speed, gains)
        turning = 2 * math.pi / self.gains.max_angular
        self.move_deadline = now + self.move.total / (0.5 * self.speed) + turning + 5.0

    def _end_move(self, state: str, reason: str = "") -> None:
        if self.move_state == "moving":
            self.move_state, self.move_reason = state, reason  # the move is kept for its remaining/total
            if self.move_id is not None:
                self.ended = self._status()  # a preempted move's end is published before the new one's

    def _status(self) -> dict[str, Any]:
        move = self.move
        return {
            "id": self.move_id,
            "state": self.move_state,
            "remaining": 0.0 if self.move_state == "done" or move is None else float(move.remaining),
            "total": 0.0 if move is None else float(move.total),
            "reason": self.move_reason,
        }

    # ------------------------------------------------------------------ frame

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """One control period: read the fresh inputs, step the running law, publish (module docstring)."""
        inputs = mapping(data, self.owner, "the input")
        unknown = sorted(set(map(str, inputs)) - set(INPUTS))
        if unknown:
            raise ValueError(f"{self.owner}: unknown inputs {unknown}; the service's Inputs must be named "
                             f"{', '.join(INPUTS)}")
        now = context.stamp
        dt = 0.05 if self.last_frame is None else min(max(now - self.last_frame, 0.0), 0.2)
        self.last_frame = now
        if self._new("wheel_odom", inputs.get("wheel_odom")):
            self._odometry(inputs["wheel_odom"], now)
        if self._new("move_goal", inputs.get("move_goal")):
            self._move_goal(inputs["move_goal"], now)
        if self._new("path", inputs.get("path")):
            self._path(inputs["path"])
        command = self._command(now, dt)
        result: dict[str, Any] = {"wheel_cmd": {"linear": command[0], "angular": command[1]},
                                  "dispersion": self.dispersion}
        if self.odom is not None and self.pose is not None:
            twist = self.odom.get("twist")
            result["odom"] = {
                "stamp": float(self.odom.get("stamp") or now),
                "pose": pose_message(self.pose),
                "twist": dict(twist) if isinstance(twist, Mapping) else {"linear": 0.0, "angular": 0.0},
                "dispersion": self.dispersion,
            }
        if self.ended is not None and self.ended["id"] != self.move_id:
            result["move_status"], self.ended = self.ended, None
        elif self.move_id is not None:
            result["move_status"], self.ended = self._status(), None
        return result

    def _command(self, now: float, dt: float) -> Command:
        stale = self.fresh_at is None or now - self.fresh_at > self.params["staleAfter"]
        if self.move is not None and self.move_state == "moving" and now > self.move_deadline:
            self._end_move("failed", f"not done by its deadline ({self.move.total:.2f} m at half speed, "
                                     "a full turn and 5 s)")
        if stale or self.pose is None:
            self.limiter.reset()
            return STOP
        wanted = STOP
        if self.move is not None and self.move_state == "moving":
            wanted = self.move.command(self.pose)
            if self.move.done:
                self.move_state = "done"
        elif self.follower is not None:
            wanted = self.follower.command(self.pose)
        return self.limiter(wanted, dt)
