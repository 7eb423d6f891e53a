"""``behavior.navigate-to``: one state that gives the navigation its goal and ends when it is reached.

Over the ``navigation`` interface (docs/interfaces.md), as Nav2's NavigateToPose is one action. The goal
comes from the Param ``goal`` (``"x y yaw"``, an Area's name, or an Object's name: the navigation then
goes up to it and faces it, D260), or from the input the Param ``input`` names when it has a value (a
plan signal's payload or a topic): a goal string, or a position ``{x, y[, yaw]}`` (or ``{"position":
{…}}``) in the map frame, reached ``standoff`` metres short of it and facing it, from where the robot
is (the service's ``pose``). The behavior reads only its own goal's status heard after it set the goal
(an earlier goal's, even the same goal's, never ends it), its progress is the share of the path
covered, and a failure's detail is the navigation's reason (it reaches the mission log).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import ANY, P, Params, Ports

from .messages import _failed, _share_done, _state, robot_pose


def _position(value: Any) -> tuple[float, float, float | None] | None:
    """(x, y, yaw or None) of a map position (bare or under ``position``), None when ``value`` is none."""
    found = value.get("position", value) if isinstance(value, Mapping) else None
    if not isinstance(found, Mapping) or found.get("frame", "map") != "map":
        return None
    x, y, yaw = (_finite(found.get(key)) for key in ("x", "y", "yaw"))
    return None if x is None or y is None else (x, y, yaw)


def _finite(value: Any) -> float | None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    return float(value) if ok else None


class NavigateTo(Behavior):
    """``behavior.navigate-to``: the navigation to a goal, in one state (see the module docstring)."""

    USES = Uses(Use("nav", "navigation", "given the goal; its status ends the state, its pose places a "
                                         "received position"))
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("goal", "", "The goal: 'x y yaw' on the map, an Area's name or an Object's name (empty: from 'input').",
          place=True),
        P("input", "", "Take the goal from this <Input> when it has a value (a goal string or a map position)."),
        P("standoff", 0.0, "Stop this far short of a position received on the input, facing it.", unit="m",
          min=0.0),
    )
    PORTS = Ports(inputs={"*": ANY})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """One goal source: the ``goal`` Param or an ``input`` that names one of its <Input>s (D307)."""
        params = {p.name: p for p in record.params}
        goal, source = params.get("goal"), params.get("input")
        has_goal, has_source = bool(goal and goal.value.strip()), bool(source and source.value.strip())
        if has_goal == has_source:
            return [(source if has_goal else record, "give the goal either as parameter 'goal' or through "
                                                     "parameter 'input', one of the two")]
        names = [p.name for p in record.inputs]
        if source is not None and has_source and source.value.strip() not in names:
            return [(source, f"parameter 'input' = {source.value.strip()!r} is not one of its inputs ({names})")]
        return []

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")

    def start(self) -> None:
        """Configure the services; with a goal Param, send it at once."""
        self.before: Any = self.service("nav").output("status")  # an earlier goal's, as the state is entered
        super().start()
        self.goal: str | None = None
        if self.params["goal"].strip():
            self._send(self.params["goal"].strip())

    def _send(self, goal: str) -> None:
        self.goal = goal
        self.service("nav").configure({"goal": goal}, ())
        self.context.log("goal set", goal=goal)

    def _from_input(self) -> str | None:
        value = self.read(self.params["input"])
        if isinstance(value, str):
            return value.strip() or None
        position = _position(value)
        if position is None:
            return None
        x, y, yaw = position
        standoff = self.params["standoff"]
        if standoff <= 0:
            return f"{x:.3f} {y:.3f} {0.0 if yaw is None else yaw:.3f}"
        here = robot_pose(self.service("nav").output("pose"))
        if here is None:
            return None  # the robot's pose first: the way in is from where it stands
        dx, dy = x - here[0], y - here[1]
        distance = math.hypot(dx, dy)
        heading = math.atan2(dy, dx) if distance > 1e-9 else here[2]
        keep = max(0.0, distance - standoff)
        return f"{here[0] + keep * math.cos(heading):.3f} {here[1] + keep * math.sin(heading):.3f} {heading:.3f}"

    def step(self) -> BehaviorStatus:
        """Done when the navigation reports this goal reached; failed with its reason if it failed."""
        if self.goal is None:
            goal = self._from_input()
            if goal is None:
                return BehaviorStatus(progress=0.0, detail="waiting for the goal")
            self._send(goal)
        status = self.service("nav").output("status")
        if status is self.before or not isinstance(status, Mapping) or status.get("goal") != self.goal:
            return BehaviorStatus(progress=0.0, detail="waiting for the navigation to take the goal")
        state = _state(status)
        if state == "arrived":
            return BehaviorStatus(progress=1.0, done=True)
        if state in ("failed", "cancelled"):
            return BehaviorStatus(progress=_share_done(status), failed=True,
                                  detail=_failed(f"navigation to {self.goal} failed", status))
        return BehaviorStatus(progress=_share_done(status))
