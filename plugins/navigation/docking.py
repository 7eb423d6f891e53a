"""``plugin.docking``: a base docked at (and undocked from) a known dock, the ``docking`` interface
(docs/interfaces.md; Nav2's docking server and its DockRobot / UndockRobot actions as a goal service).

Configured by its Params — the docks (``docks``: each one's docked pose on the map, where the base's
centre ends, facing the dock), the staging distance, tolerances and retries — and its inputs
(``{input name: newest value or None}``):

- ``goal`` (DockGoal): ``{id, action: dock | undock, dock: a name of ``docks`` (or empty, with the
  docked pose in ``x``, ``y``, ``yaw``)}``; every new goal preempts the one before;
- ``pose``: the base's pose estimate on the map (a navigation or localization service's ``pose``);
- ``move_status``: the base-drive service's MoveStatus, for the moves this service sends;
- optional ``dock_pose``: the dock seen by a sensor, as the docked pose relative to the base
  (``{x, y, yaw}``, robot frame) — when fresh, the final approach uses it instead of the map;
- optional ``contact``: 1 (or true) while the base touches the dock's contacts (a charger's
  current, a bumper); when the service has this input, docked needs it.

Outputs: ``move_goal`` (MoveGoal, relative moves for the base-drive service: its ``move_goal``
Input) and ``status`` (DockStatus ``{stamp, id, action, state: staging | docking | docked |
undocking | undocked | failed, attempt, reason}`` of the newest goal).

Docking: a move to the staging pose (``staging`` m short of the docked pose along its heading), then,
from a pose estimate taken after that move, a straight final move onto the docked pose; docked when
that move is done and, with ``contact``, contact is made within ``contactTimeout`` s. A failed move, a
pose estimate more than ``tolerance`` m off the docked pose (the first estimate after the final
move's end, when the service has no ``contact`` input), or no contact, retries from staging,
``retries`` times, then fails with the reason. Undocking: a straight move ``staging`` m back. A goal
with no pose estimate yet waits for one.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from ckmconf.model.resources import Plugin
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.ros.interface_types import yaw_of
from runtime.verification.entries import Entries
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .frames import Pose, compose, inverse, wrap

ACTIONS = ("dock", "undock")
_move_ids = itertools.count(1 << 40)  # far above the behaviors' goal ids, which share the base's topic


def planar_pose(value: Any) -> Pose | None:
    """(x, y, yaw) of a pose message in CKM's form or a ROS 2 one (PoseWithCovarianceStamped, PoseStamped)."""
    pose = value.get("pose", value) if isinstance(value, Mapping) else None
    if isinstance(pose, Mapping) and isinstance(pose.get("pose"), Mapping):
        pose = pose["pose"]
    if isinstance(pose, Mapping) and isinstance(pose.get("position"), Mapping):
        position, orientation = pose["position"], pose.get("orientation")
        if isinstance(orientation, Mapping) and all(isinstance(position.get(k), int | float) for k in "xy"):
            try:
                return float(position["x"]), float(position["y"]), yaw_of(orientation)
            except (KeyError, TypeError, ValueError):
                return None
        return None
    if isinstance(pose, Mapping) and all(isinstance(pose.get(k), int | float) for k in ("x", "y", "yaw")):
        return float(pose["x"]), float(pose["y"]), float(pose["yaw"])
    return None


@dataclass
class _Goal:
    id: Any
    action: str
    docked: Pose | None = None
    state: str = "staging"
    attempt: int = 1
    reason: str = ""
    move_id: int | None = None
    estimate_after: Any = None  # the pose message the final move must not be planned from
    moved_at: float = 0.0


class Docking(ProcessingPlugin):
    """Dock and undock goals to base moves, and their status (see the module docstring)."""

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "docking"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("docks", "", "Each dock's docked pose on the map, where the base's centre ends facing the dock: "
          "'name: x y yaw; …' (m, m, rad).", entries=Entries("x y yaw", count=3, numbers=True)),
        P("staging", 0.6, "Distance short of the docked pose, along its heading, where the final approach "
          "starts (and an undocking ends).", unit="m", above=0.0),
        P("tolerance", 0.1, "Largest distance between the pose estimate and the docked pose after the final "
          "move (without a contact input).", unit="m", above=0.0),
        P("retries", 2, "Approaches tried again from staging after a failed one.", min=0),
        P("contactTimeout", 1.0, "Time after the final move within which contact must be made.", unit="s",
          above=0.0),
        P("detectionAge", 0.5, "Oldest dock detection the final approach uses (older: the map).", unit="s",
          above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        self.docks: dict[str, tuple[float, ...]] = dict(self.params["docks"] or {})
        self.goal: _Goal | None = None
        self._message: Any = None
        self._seen_dock: tuple[Any, float] = (None, -math.inf)  # the newest detection and when it changed

    # ------------------------------------------------------------------ frames

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The move to send (when one is due) and the newest goal's status."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects {{'goal': …, 'pose': …, 'move_status': …}}, "
                             f"got {type(data).__name__}")
        now = context.stamp
        message = data.get("goal")
        if message is not None and message != self._message:
            self._message = message
            self.goal = self._accept(message)
        detection = data.get("dock_pose")
        if detection is not None and detection != self._seen_dock[0]:
            self._seen_dock = (detection, now)
        result: dict[str, Any] = {}
        goal = self.goal
        if goal is None:
            return result
        if goal.state not in ("docked", "undocked", "failed"):
            move = self._advance(goal, data, now)
            if move is not None:
                goal.move_id = next(_move_ids)
                goal.moved_at = now
                result["move_goal"] = {"id": goal.move_id, "frame": "robot", "x": move[0], "y": move[1],
                                       "yaw": move[2], "yaw_tolerance": 0.0}
        result["status"] = {"stamp": now, "id": goal.id, "action": goal.action, "state": goal.state,
                            "attempt": goal.attempt, "reason": goal.reason}
        return result

    def _accept(self, message: Any) -> _Goal:
        if not isinstance(message, Mapping):
            return self._fail(_Goal(None, ""), f"the goal is {type(message).__name__}, not a DockGoal")
        goal = _Goal(message.get("id"), str(message.get("action") or ""))
        if isinstance(goal.id, bool) or not isinstance(goal.id, int):
            return self._fail(goal, f"goal id {goal.id!r} is not an integer")
        if goal.action not in ACTIONS:
            return self._fail(goal, f"goal {goal.id}: action {goal.action!r} is not one of {', '.join(ACTIONS)}")
        if goal.action == "undock":
            goal.state = "undocking"
            return goal
        name = str(message.get("dock") or "")
        if name:
            if name not in self.docks:
                known = ", ".join(sorted(self.docks)) or "none configured"
                return self._fail(goal, f"goal {goal.id}: no dock {name!r} (docks: {known})")
            x, y, yaw = self.docks[name]
            goal.docked = (x, y, yaw)
        else:
            values = [message.get(k) for k in ("x", "y", "yaw")]
            if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in values):
                return self._fail(goal, f"goal {goal.id}: name a dock, or give its docked pose x, y, yaw")
            goal.docked = (float(values[0]), float(values[1]), float(values[2]))  # type: ignore[arg-type]
        return goal

    @staticmethod
    def _fail(goal: _Goal, reason: str) -> _Goal:
        goal.state, goal.reason = "failed", reason
        return goal

    def _move_state(self, goal: _Goal, status: Any) -> tuple[str | None, str]:
        if goal.move_id is None or not isinstance(status, Mapping) or status.get("id") != goal.move_id:
            return None, ""
        reason = status.get("reason")
        return str(status.get("state") or ""), reason if isinstance(reason, str) else ""

    def _advance(self, goal: _Goal, data: Mapping[str, Any], now: float) -> Pose | None:
        """The next move of ``goal`` (None: none due now), after following the last one."""
        pose = planar_pose(data.get("pose"))
        state, why = self._move_state(goal, data.get("move_status"))
        if goal.action == "undock":
            if goal.move_id is None:
                return (-self.params["staging"], 0.0, 0.0)
            if state == "done":
                goal.state = "undocked"
            elif state == "failed":
                self._fail(goal, f"the undocking move failed: {why}" if why else "the undocking move failed")
            return None
        assert goal.docked is not None
        staging = compose(goal.docked, (-self.params["staging"], 0.0, 0.0))
        if goal.move_id is None:  # a new approach: to staging
            if pose is None:
                return None
            return compose(inverse(pose), staging)
        if state == "failed":
            return self._retry(goal, f"the {goal.state} move failed" + (f": {why}" if why else ""), pose, staging)
        if state != "done":
            return None
        if goal.state == "staging":
            if goal.estimate_after is None:
                goal.estimate_after = data.get("pose")  # the final move is planned from a newer estimate
            final = self._final_move(goal, data, now)
            if final is not None:
                goal.state, goal.estimate_after = "docking", None
            return final
        return self._judge(goal, data, pose, now, staging)

    def _final_move(self, goal: _Goal, data: Mapping[str, Any], now: float) -> Pose | None:
        assert goal.docked is not None
        seen, at = self._seen_dock
        detected = planar_pose(seen)
        if detected is not None and now - at <= self.params["detectionAge"] and at > goal.moved_at:
            return detected
        current = data.get("pose")
        pose = planar_pose(current)
        if pose is None or current == goal.estimate_after:
            return None
        return compose(inverse(pose), goal.docked)

    def _judge(self, goal: _Goal, data: Mapping[str, Any], pose: Pose | None, now: float, staging: Pose) -> Pose | None:
        """After the final move: docked, or a retry."""
        assert goal.docked is not None
        if "contact" in data:
            contact = data.get("contact")
            touching = contact.get("data") if isinstance(contact, Mapping) else contact
            if touching is True or (isinstance(touching, int | float) and touching > 0.5):
                goal.state = "docked"
            elif now - goal.moved_at > self.params["contactTimeout"] + 2.0:  # the move's own time included
                return self._retry(goal, "no contact with the dock after the final approach", pose, staging)
            return None
        if goal.estimate_after is None:  # judged on an estimate newer than the move's end, not its echo
            goal.estimate_after = data.get("pose")
            return None
        if pose is None or data.get("pose") == goal.estimate_after:
            return None
        error = math.dist(pose[:2], goal.docked[:2])
        if error <= self.params["tolerance"]:
            goal.state = "docked"
            return None
        return self._retry(goal, f"ended {error:.2f} m from the docked pose (tolerance "
                                 f"{self.params['tolerance']:g} m)", pose, staging)

    def _retry(self, goal: _Goal, reason: str, pose: Pose | None, staging: Pose) -> Pose | None:
        if goal.attempt > self.params["retries"]:
            self._fail(goal, f"{reason} (attempt {goal.attempt} of {self.params['retries'] + 1})")
            return None
        goal.attempt += 1
        goal.state, goal.reason, goal.estimate_after = "staging", reason, None
        if pose is None:
            goal.move_id = None  # the next frame with an estimate starts again
            return None
        return compose(inverse(pose), staging)

    def state(self) -> dict[str, Any]:
        """Nothing survives a delegation: the behavior sends its goal again."""
        return {"kind": "docking"}

    def restore(self, state: Mapping[str, Any]) -> None:
        """Continue from a ``state()`` of a docking plugin (a fresh start)."""
        if state.get("kind") != "docking":
            raise ValueError(f"{self.owner}: not a docking state: {state!r}"[:200])


__all__ = ["Docking", "planar_pose", "wrap"]
