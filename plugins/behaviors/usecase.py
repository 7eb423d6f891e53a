"""The behaviors of the two-robot use case (Tables 7.5 and 7.7), written against services.

None of them knows a robot: they configure Smart Resource services (their ``<Uses>``), read the
services' outputs, and publish goals on their ``<Output>`` topics. The messages they exchange,
and the frames of the object positions (D125), are described in :mod:`plugins.behaviors.messages`.
A goal is matched to its status by ``id`` (fresh per behavior run), so a status left over from an
earlier state never ends this one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

# re-exported (``as``): docking and recovery import these from here; Approach moved to .approach
from .approach import Approach as Approach
from .messages import _Goals as _Goals
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

    USES = Uses(Use("nav", "navigation", "given the goal; without it the goal only goes on the output", optional=True))

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
            self.goal = _goal_configured(self.record, "nav")

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
            return BehaviorStatus(progress=0.5, failed=True, detail=_failure(status, "no path to the goal"))
        return BehaviorStatus(progress=0.5)


def _goal_configured(record: BehaviorRecord, alias: str) -> str | None:
    """The ``goal`` a behavior's ``<Uses as=alias>`` configures (None: it configures none)."""
    uses = next((u for u in record.uses if u.alias == alias), None)
    return next((c.value for c in uses.configure if c.parameter == "goal"), None) if uses else None


def _failure(status: Any, what: str) -> str:
    """``what`` failed, with the reason the status gives (navigation's ``reason``)."""
    reason = status.get("reason") if isinstance(status, Mapping) else None
    return f"{what}: {reason}" if isinstance(reason, str) and reason else what


class WaitGoal(Behavior):
    """WAIT: drives along AMCL's path; progress is the share of the path covered.

    With its own ``<Configure parameter="goal">`` only a status of that goal heard after the state was
    entered counts: the status of the goal before it (failed, or arrived elsewhere, even at the same
    goal) is not this one's. Without, the status of whatever goal the previous state set. A failure's
    detail carries the navigation's reason."""

    USES = Uses(Use("nav", "navigation", "the goal driven to and its status"))

    def start(self) -> None:
        """Configure the navigation (its own goal, if any) and remember which goal this is."""
        self.before = self.service("nav").output("status")  # the last goal's, as the state is entered
        super().start()
        self.goal = _goal_configured(self.record, "nav")

    def step(self) -> BehaviorStatus:
        """Done when Navigation reports the goal reached (its progress is the share of the path done)."""
        status = self.service("nav").output("status")
        if self.goal is not None and (status is self.before or not isinstance(status, Mapping)
                                      or status.get("goal") != self.goal):
            return BehaviorStatus(progress=0.0, detail="waiting for the navigation to take the goal")
        state = _state(status)
        if state == "arrived":
            return BehaviorStatus(progress=1.0, done=True)
        if state == "failed":
            return BehaviorStatus(progress=_share_done(status), failed=True,
                                  detail=_failure(status, "navigation failed"))
        return BehaviorStatus(progress=_share_done(status))


class SpotObjects(Behavior):
    """SPOT, SPOT_COOP: waits until the fused recognition holds the target (untraceable), then
    writes its position (an ``ObjectPosition``) on the ``target`` output."""

    USES = Uses(Use("fusion", "fusion", "the recognition looked in, unless an input named objects gives it",
                    optional=True))

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


class ArmSequence(_Goals):
    """PICK, PLACE: the ``sequence`` of ``group:pose`` goals, each after the previous is reached.

    With ``minHold`` > 0, a gripper goal that stops on an object with the fingers nearer than that
    share of their range has closed across the object's edge, not round its middle (an aim off by
    more than the fingers' clearance, D251): the behavior fails there, before lifting it."""

    USES = Uses(Use("arm", "arm-motion", "reaches each pose of the sequence"))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("sequence", REQUIRED, "Space-separated goals 'arm:POSE' or 'gripper:POSE', reached in order.", type=str),
        P("minHold", 0.0, "Least gripper opening (share of its range) an object held must keep (0: any).",
          min=0.0, max=1.0),
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
        status = self.service("arm").output("status")
        state = _state(status, self.goal_id)
        if state == "failed":
            error = status.get("error") if isinstance(status, Mapping) else None
            step = self.steps[self.index]
            return BehaviorStatus(progress=self.index / len(self.steps), failed=True,
                                  detail=f"{step['group']}:{step['pose']}: {error or 'failed'}")
        if state == "reached":
            if (narrow := self._narrow_hold(status)) is not None:
                return BehaviorStatus(progress=self.index / len(self.steps), failed=True, detail=narrow)
            self.index += 1
            if self.index == len(self.steps):
                return BehaviorStatus(progress=1.0, done=True)
            self.goal_id = self._send("arm_goal", self.steps[self.index])
        return BehaviorStatus(progress=self.index / len(self.steps))


    def _narrow_hold(self, status: Any) -> str | None:
        """Why a reached gripper goal holds the object by its edge (``minHold``), None if it does not."""
        limit, step = self.params["minHold"], self.steps[self.index]
        if limit <= 0 or step["group"] != "gripper" or not isinstance(status, Mapping) or not status.get("holding"):
            return None
        opening = status.get("opening")
        if not isinstance(opening, int | float) or opening >= limit:
            return None
        return (f"gripper:{step['pose']}: holds the object at {opening:.2f} of the opening, under {limit:.2f}: "
                "closed across its edge")


class BackOff(_Goals):
    """BACK: moves ``distance`` metres backwards."""

    USES = Uses(Use("base", "base-drive", "drives the backwards move"))

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

    USES = Uses(Use("recog", "object-detection", "sees the target"),
                Use("track", "pan-tilt-tracking", "keeps the head on it (measure moving)"))

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

    USES = Uses(Use("recog", "object-detection", "sees the target and rates it"),
                Use("track", "pan-tilt-tracking", "places the target on the map", optional=True))

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
