"""The behaviors of the two-robot use case (Tables 7.5 and 7.7), written against services.

None of them knows a robot: they configure Smart Resource services (their ``<Uses>``), read the
services' outputs, and publish goals on their ``<Output>`` topics. The messages they exchange,
and the frames of the object positions (D125), are described in :mod:`plugins.behaviors.messages`.
A goal is matched to its status by ``id`` (fresh per behavior run), so a status left over from an
earlier state never ends this one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

# re-exported (``as``): docking and recovery import these from here
from .messages import _share_done as _share_done
from .messages import _state as _state
from .messages import find_target as find_target
from .messages import in_robot_frame as in_robot_frame
from .messages import object_position as object_position
from .messages import observer_pose as observer_pose
from .messages import robot_pose as robot_pose

_TARGET = (
    P("target", "", "Shape (or name) of the object looked for."),
    P("targetTexture", "", "Texture of the object looked for."),
)

_ids = itertools.count(1)


class Init(Behavior):
    """INIT: records what the mission is after (target, home); no service."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(*_TARGET, P("home", "", "Name of the home area."))

    def step(self) -> BehaviorStatus:
        """Done at once (INIT only records the mission's target and home, Table 7.5)."""
        return BehaviorStatus(progress=1.0, done=True, detail=f"target {self.params['target']}")


class End(Behavior):
    """END: closes the execution; its services were released by the previous states."""

    def step(self) -> BehaviorStatus:
        """Done at once: the previous states released their services."""
        return BehaviorStatus(progress=1.0, done=True)


class SetNavGoal(Behavior):
    """NAV, NAV_HOME, NAV_COOP: sets AMCL's goal and waits until a path to it is established.

    With an input (NAV_COOP's ``spotted`` signal) the goal is the object's position there, moved
    ``approachDistance`` towards the robot and facing the object (a ``map`` position needs the
    ``nav`` service's pose estimate); the behavior waits for it (untraceable), logs it, and
    also writes it on a ``goal`` output when it has one. Without a ``nav`` service it is done once
    the goal is set (the goal is handed over on its output only).
    """

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("approachDistance", 0.0, "Stop this far short of a position received on the input.", unit="m"),
        P("approachHeading", None, "Reach a received position along this map heading (the free side of the "
          "table it stands on); unset: straight from the robot.", type=float, unit="rad"),
    )
    PORTS = Ports(inputs={"*": MAPPING})

    def start(self) -> None:
        """Take the configured goal; with an input (NAV_COOP) the goal comes later, from the signal."""
        super().start()
        self.goal: str | None = None
        if not self.record.inputs:
            uses = next((u for u in self.record.uses if u.alias == "nav"), None)
            self.goal = next((c.value for c in uses.configure if c.parameter == "goal"), None) if uses else None

    def _goal_from_input(self) -> str | None:
        spotted = self.read(self.record.inputs[0].name)
        value = spotted.get("position", spotted) if isinstance(spotted, Mapping) else None
        if not isinstance(value, Mapping) or not all(isinstance(value.get(k), int | float) for k in ("x", "y")):
            return None
        x, y = float(value["x"]), float(value["y"])
        ox, oy = 0.0, 0.0  # the robot, in the frame of the position
        if value.get("frame") == "map":
            pose = robot_pose(self.service("nav").output("pose")) if "nav" in self.context.services else None
            if pose is None:
                return None
            ox, oy = pose[0], pose[1]
        heading = self.params["approachHeading"]
        if heading is not None:  # along the table's free side: a diagonal way in meets its legs (D204)
            back = self.params["approachDistance"]
            return f"{x - back * math.cos(heading):.3f} {y - back * math.sin(heading):.3f} {heading:.3f}"
        dx, dy = x - ox, y - oy
        distance = math.hypot(dx, dy)
        keep = max(0.0, distance - self.params["approachDistance"]) / distance if distance > 0 else 0.0
        return f"{ox + dx * keep:.3f} {oy + dy * keep:.3f} {math.atan2(dy, dx):.3f}"

    def step(self) -> BehaviorStatus:
        """Done once Navigation echoes this goal and is planning or driving to it; failed if it failed."""
        if self.goal is None and self.record.inputs:
            self.goal = self._goal_from_input()
            if self.goal is None:
                return BehaviorStatus(progress=0.0, detail="waiting for the goal")
            self.context.log("goal set", goal=self.goal, source=self.record.inputs[0].name)
            if "nav" in self.context.services:
                self.service("nav").configure({"goal": self.goal}, ())
            if "goal" in self.context.outputs:
                self.write("goal", self.goal)
        if "nav" not in self.context.services:  # no navigation service: the goal is handed over on its output
            return BehaviorStatus(progress=1.0, done=self.goal is not None)
        status = self.service("nav").output("status")
        state = _state(status) if isinstance(status, Mapping) and status.get("goal") == self.goal else None
        if state in ("active", "arrived"):
            return BehaviorStatus(progress=1.0, done=True)
        if state == "failed":
            return BehaviorStatus(progress=0.5, failed=True, detail="no path to the goal")
        return BehaviorStatus(progress=0.5)


class WaitGoal(Behavior):
    """WAIT: drives along AMCL's path; progress is the share of the path covered."""

    def step(self) -> BehaviorStatus:
        """Done when Navigation reports the goal reached (its progress is the share of the path done)."""
        status = self.service("nav").output("status")
        state = _state(status)
        if state == "arrived":
            return BehaviorStatus(progress=1.0, done=True)
        if state == "failed":
            return BehaviorStatus(progress=_share_done(status), failed=True, detail="navigation failed")
        return BehaviorStatus(progress=_share_done(status))


class SpotObjects(Behavior):
    """SPOT, SPOT_COOP: waits until the fused recognition holds the target (untraceable), then
    writes its position (an ``ObjectPosition``) on the ``target`` output."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        *_TARGET, P("minSources", 1, "Fewest recognition sources that must have seen the object.")
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    def step(self) -> BehaviorStatus:
        """Done when the fused recognition holds the target; its position is then written on ``target``."""
        result = self.read("objects") if "objects" in self.context.inputs else self.service("fusion").output("objects")
        p = self.params
        found = find_target(result, p["target"], p["targetTexture"], p["minSources"])
        if found is None:
            return BehaviorStatus(progress=0.0)
        self.write("target", object_position(found, self.context.now()))  # an ObjectPosition (topic or signal)
        return BehaviorStatus(progress=1.0, done=True, detail=f"{found.get('name')} at {found.get('reliability')}")


class _Goals(Behavior):
    """Sends goals and follows their statuses by id."""

    def _send(self, output: str, goal: dict[str, Any]) -> int:
        goal_id = next(_ids)
        self.write(output, {"id": goal_id, **goal})
        return goal_id


class Approach(_Goals):
    """APPR: the arm to ``armPose``, then the base to ``standoff`` metres from the target (a ``map``
    target is placed relative to the robot with the pose it was placed with, its ``observer``, or
    else the ``pose`` input); the base waits for the arm, so the arm never rises through the
    table's edge.

    A drive longer than ``reaimAbove`` (one from where BACK left the robot after a missed grasp)
    stops ``reaim`` metres short, stands ``settle`` seconds and takes the last leg from a fresh
    sighting of the target on the ``objects`` input (the fused recognition), placed with its own
    observer pose: the heading the wheel odometry lost on the long drive (D207) is measured again
    where the arm still lets the camera see the object. No fresh sighting within ``reaimWait``
    seconds: the last leg goes straight on, as one move would have. A target without a ``label``
    or no sighting of it on ``objects`` when the drive starts: one move, as before."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("standoff", 0.2, "Distance kept from the target.", unit="m"),
        P("armPose", "pre_grasp", "Predefined arm pose reached on the way."),
        P("reaim", 0.0, "Stop this far short of the standoff to look again (0: never).", unit="m", min=0.0),
        P("reaimAbove", 0.0, "Only on drives longer than this.", unit="m", min=0.0),
        P("settle", 2.5, "Standing still this long before a sighting counts (camera, recognition, fusion).",
          unit="s", min=0.0),
        P("reaimWait", 5.0, "Longest wait for a fresh sighting after settling.", unit="s", min=0.0),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    def start(self) -> None:
        """Send the arm goal; the base goal follows once the arm has reached it."""
        super().start()
        self.phase = "arm"  # arm → drive (one move, or the short one) → look → last (the last leg)
        self.move_id: int | None = None
        self.legs: list[float] = []  # the drive's lengths: one move, or the short move and the last leg
        self.label = ""
        self.stopped = 0.0  # when the short move ended
        self.settled: Any = None  # the fused message when the settling ended: a sighting must be newer
        self.arm_id = self._send("arm_goal", {"group": "arm", "pose": self.params["armPose"]})

    def _relative(self, target: Any) -> tuple[float, float] | None:
        """The target in the robot frame: with the pose it was placed with, else the ``pose`` input."""
        # The pose the fusion placed the target with, when it says: the robot has stood still
        # since, and the estimate's bias cancels (D172). Else the latest estimate.
        pose = observer_pose(target)
        if pose is None and "pose" in self.context.inputs:
            pose = robot_pose(self.read("pose"))
        return in_robot_frame(target, pose)

    def _sighting(self) -> Mapping[str, Any] | None:
        """The most reliable positioned sighting of the target on the ``objects`` input, None if none."""
        result = self.read("objects") if self.label and "objects" in self.context.inputs else None
        if not isinstance(result, Mapping) or not isinstance(result.get("objects"), list):
            return None
        placed = [o for o in result["objects"] if isinstance(o, Mapping) and isinstance(o.get("x"), int | float)
                  and isinstance(o.get("y"), int | float)]  # fmt: skip
        return find_target({"objects": placed}, self.label, "")

    def _move(self, relative: tuple[float, float], keep_off: float) -> float:
        """Send the drive to ``keep_off`` metres from the target at ``relative``, facing it; its length."""
        x, y = relative
        distance = math.hypot(x, y)
        keep = max(0.0, distance - keep_off) / distance if distance > 0 else 0.0
        self.move_id = self._send("move", {"frame": "robot", "x": x * keep, "y": y * keep, "yaw": math.atan2(y, x)})
        return distance * keep

    def _first_move(self) -> BehaviorStatus | None:
        """Send the first move (status while it cannot be sent): to the standoff, or short of it to look again."""
        target = self.read("target")
        if not isinstance(target, Mapping) or not isinstance(target.get("x"), int | float):
            return BehaviorStatus(progress=0.0, detail="no target")
        relative = self._relative(target)
        if relative is None:
            return BehaviorStatus(progress=0.0, detail="waiting for the pose estimate")
        p = self.params
        self.label = str(target.get("label") or "")
        drive = math.hypot(*relative) - p["standoff"]
        if p["reaim"] > 0 and drive > max(p["reaimAbove"], p["reaim"]) and self._sighting() is not None:
            self.legs = [self._move(relative, p["standoff"] + p["reaim"]), p["reaim"]]
        else:
            self.legs = [self._move(relative, p["standoff"])]
        self.phase = "drive"
        return None

    def _fresh(self) -> tuple[float, float] | None:
        """The target relative to the robot as a sighting made since the robot settled sees it, else None."""
        objects = self.read("objects")
        if self.settled is None:
            self.settled = objects if objects is not None else {}
        sighting = self._sighting() if objects != self.settled else None  # a new fusion result
        observer = None if sighting is None else observer_pose(sighting)
        pose = robot_pose(self.read("pose")) if "pose" in self.context.inputs else None
        if observer is None or pose is None:
            return None
        # placed with the pose where the robot stands (not one from before the stop)
        if math.dist(observer[:2], pose[:2]) > 0.05 or abs(math.remainder(observer[2] - pose[2], math.tau)) > 0.05:
            return None
        assert sighting is not None
        return self._relative(sighting)

    def _look(self) -> bool:
        """Standing short of the standoff: send the last leg once a fresh sighting or the wait's end allows."""
        waited, p = self.context.now() - self.stopped, self.params
        if waited < p["settle"]:
            return False
        relative = self._fresh()
        if relative is not None:
            self.legs[1] = self._move(relative, p["standoff"])
            self.context.log("re-aimed", x=round(relative[0], 4), y=round(relative[1], 4))
            return True
        if waited >= p["settle"] + p["reaimWait"]:  # the move short faced the target: straight on
            self.legs[1] = self._move((self.legs[1] + p["standoff"], 0.0), p["standoff"])
            self.context.log("no fresh sighting: straight on", distance=round(self.legs[1], 4))
            return True
        return False

    def step(self) -> BehaviorStatus:
        """Raise the arm, then drive to ``standoff`` from the target; done when both are reached."""
        arm_state = _state(self.service("arm").output("status"), self.arm_id)
        if self.phase == "arm":
            if arm_state != "reached":  # the arm up first: it must not sweep the table
                if arm_state == "failed":
                    return BehaviorStatus(progress=0.0, failed=True, detail="the arm did not reach its pose")
                return BehaviorStatus(progress=0.0, detail="raising the arm")
            if (waiting := self._first_move()) is not None:
                return waiting
        move = self.service("base").output("move_status")
        move_state = _state(move, self.move_id)
        if self.phase == "drive" and move_state == "done" and len(self.legs) == 2:
            self.phase, self.stopped = "look", self.context.now()
        if self.phase == "look":
            if not self._look():
                return BehaviorStatus(progress=self._progress(arm_state, 1.0), detail="looking again")
            self.phase, move_state = "last", None
        share = _share_done(move) if move_state else 0.0
        if "failed" in (move_state, arm_state):
            return BehaviorStatus(progress=self._progress(arm_state, share), failed=True)
        done = move_state == "done" and arm_state == "reached" and (self.phase == "last" or len(self.legs) == 1)
        return BehaviorStatus(progress=1.0 if done else self._progress(arm_state, share), done=done)

    def _progress(self, arm_state: str | None, share: float) -> float:
        """0.2 for the arm, 0.8 for the share of the whole drive done (``share`` of the current move)."""
        total = sum(self.legs)
        before = self.legs[0] if self.phase == "last" else 0.0
        current = self.legs[-1] if self.phase == "last" else self.legs[0] if self.legs else 0.0
        driven = (before + share * current) / total if total > 0 else share
        return 0.8 * driven + 0.2 * (arm_state == "reached")


class ArmSequence(_Goals):
    """PICK, PLACE: the ``sequence`` of ``group:pose`` goals, each after the previous is reached."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("sequence", REQUIRED, "Space-separated goals 'arm:POSE' or 'gripper:POSE', reached in order.", type=str)
    )
    PORTS = Ports(outputs={"*": MAPPING})

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        self.steps = []
        for item in str(self.params["sequence"]).split():
            group, _, pose = item.partition(":")
            if group not in ("arm", "gripper") or not pose:
                raise ParamError(f"{self.owner}: sequence step {item!r} is not arm:POSE or gripper:POSE")
            self.steps.append({"group": group, "pose": pose})
        if not self.steps:
            raise ParamError(f"{self.owner}: parameter 'sequence' is empty")

    def start(self) -> None:
        """Send the sequence's first goal."""
        super().start()
        self.index = 0
        self.goal_id = self._send("arm_goal", self.steps[0])

    def step(self) -> BehaviorStatus:
        """Send each goal of the sequence once the previous one is reached; failed if one fails."""
        state = _state(self.service("arm").output("status"), self.goal_id)
        if state == "failed":
            return BehaviorStatus(progress=self.index / len(self.steps), failed=True)
        if state == "reached":
            self.index += 1
            if self.index == len(self.steps):
                return BehaviorStatus(progress=1.0, done=True)
            self.goal_id = self._send("arm_goal", self.steps[self.index])
        return BehaviorStatus(progress=self.index / len(self.steps))


class BackOff(_Goals):
    """BACK: moves ``distance`` metres backwards."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(P("distance", 0.3, "How far to move backwards.", unit="m"))
    PORTS = Ports(outputs={"*": MAPPING})

    def start(self) -> None:
        """Send the backwards move."""
        super().start()
        self.move_id = self._send("move", {"frame": "robot", "x": -abs(self.params["distance"]), "y": 0.0, "yaw": 0.0})

    def step(self) -> BehaviorStatus:
        """Done when the Displacement service reports the move done."""
        status = self.service("base").output("move_status")
        state = _state(status, self.move_id)
        return BehaviorStatus(progress=1.0 if state == "done" else _share_done(status) if state else 0.0,
                              done=state == "done", failed=state == "failed")  # fmt: skip


class TrackObject(Behavior):
    """OBJ_TRACK: waits until the pan-tilt recognition sees the target and the head follows it."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(*_TARGET)

    def step(self) -> BehaviorStatus:
        """Done once the pan-tilt recognition sees the target and the head is following it."""
        found = find_target(
            self.service("recog").output("objects"), self.params["target"], self.params["targetTexture"]
        )
        moving = self.service("track").measures().get("moving")
        if found is not None and moving:
            return BehaviorStatus(progress=1.0, done=True)
        return BehaviorStatus(progress=0.5 if found is not None else 0.0)


class FixObject(Behavior):
    """OBJ_FIX: holds the camera on the target until the recognition has been reliable for
    ``holdTime`` seconds, then writes the target's position (an ``ObjectPosition``) on its
    outputs: the payload of the plan signal (``<Output signal=…>``) or a topic. With a ``track``
    service the position is the tracked target it places on the map; else the recognition's."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("holdTime", 2.0, "How long the recognition must stay reliable.", unit="s"),
        *_TARGET,
        P("minReliability", 0.7, "Reliability the recognition must keep."),
    )
    PORTS = Ports(outputs={"*": MAPPING})

    def start(self) -> None:
        """Forget the previous holding time."""
        super().start()
        self.since: float | None = None

    def step(self) -> BehaviorStatus:
        """Done once the recognition kept ``minReliability`` for ``holdTime`` s; the position goes on the outputs."""
        p = self.params
        found = find_target(self.service("recog").output("objects"), p["target"], p["targetTexture"])
        now = self.context.now()
        if found is None or float(found.get("reliability", 0.0)) < p["minReliability"]:
            self.since = None
            return BehaviorStatus(progress=0.0)
        self.since = now if self.since is None else self.since
        held = now - self.since
        if held >= p["holdTime"]:
            position = object_position(found, now)
            if "track" in self.context.services:
                target = self.service("track").output("target")
                if not isinstance(target, Mapping) or target.get("frame") != "map":
                    return BehaviorStatus(progress=0.99, detail="waiting for the tracked target's map position")
                position = object_position({**target, "name": target.get("label", found.get("name"))}, now)
            for port in self.record.outputs:
                self.write(port.name, position)
            return BehaviorStatus(progress=1.0, done=True)
        return BehaviorStatus(progress=held / p["holdTime"])
