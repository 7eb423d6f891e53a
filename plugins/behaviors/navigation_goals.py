"""Navigation behaviors over the ``navigation`` interface (docs/interfaces.md): set a goal, wait for it.

``set-nav-goal`` gives the navigation service its goal (from the ``<Configure>``, or a position
received on an input, short of it and facing it) and is done once the service plans or drives to it;
``wait-goal`` is done when the goal is reached. Both read only the status of their own goal (its echo
in ``goal``), so a status left over from an earlier goal never ends them, and a failure's detail
carries the navigation's reason into the mission log.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.missions.behaviors import Behavior, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .messages import _failed, _share_done, _state, robot_pose


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
        if state in ("failed", "cancelled"):
            return BehaviorStatus(progress=0.5, failed=True, detail=_failed("no path to the goal", status))
        return BehaviorStatus(progress=0.5)


def _goal_configured(record: BehaviorRecord, alias: str) -> str | None:
    """The ``goal`` a behavior's ``<Uses as=alias>`` configures (None: it configures none)."""
    uses = next((u for u in record.uses if u.alias == alias), None)
    return next((c.value for c in uses.configure if c.parameter == "goal"), None) if uses else None


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
        if state in ("failed", "cancelled"):
            return BehaviorStatus(progress=_share_done(status), failed=True,
                                  detail=_failed("navigation failed", status))
        return BehaviorStatus(progress=_share_done(status))
