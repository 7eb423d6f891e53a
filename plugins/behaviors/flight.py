"""Flight behaviors over the ``flight`` interface (docs/interfaces.md): take off, fly to, land.

Each sends one goal on its ``flight_goal`` Output (the flight service's ``goal`` Input) and follows
the status of that goal's id on the service it uses as ``flight``, so a status of an earlier goal
never ends it; a failure's detail carries the service's reason into the mission log.

- ``take-off``: climbs ``altitude`` metres; done when the service reports it ``arrived``.
- ``fly-to``: flies to ``goal`` (``"x y z"`` or ``"x y z yaw"`` on the map), or — with an input —
  to ``altitude`` above the position it receives (an ``ObjectPosition`` on the map, a signal's
  ``position``); done on ``arrived``.
- ``land``: descends where it is; done when the service reports it ``landed``.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .messages import _failed, _Goals, _state

FLIGHT = Uses(Use("flight", "flight", "flies the goal and reports its status"))


class _FlightGoal(_Goals):
    """Sends one flight goal and ends with its status: done on ``until``, failed on ``failed``."""

    USES = FLIGHT
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})
    until = "arrived"
    what = "the flight"

    def start(self) -> None:
        """Forget the last goal; the next is sent at the first step that has one."""
        super().start()
        self.goal_id: int | None = None

    @abc.abstractmethod
    def goal(self) -> dict[str, Any] | None:
        """The goal to send (None: not known yet)."""

    def step(self) -> BehaviorStatus:
        """Send the goal once, then follow its status by id."""
        if self.goal_id is None:
            goal = self.goal()
            if goal is None:
                return BehaviorStatus(progress=0.0, detail="waiting for the goal")
            self.context.log("flight goal", **{k: v for k, v in goal.items() if isinstance(v, str | float | int)})
            self.goal_id = self._send("flight_goal", goal)
        status = self.service("flight").output("status")
        state = _state(status, self.goal_id)
        remaining = status.get("remaining") if isinstance(status, Mapping) and state else None
        progress = 1.0 if state == self.until else 0.5 if isinstance(remaining, int | float) else 0.0
        return BehaviorStatus(progress=progress, done=state == self.until, failed=state == "failed",
                              detail=_failed(f"{self.what} failed", status) if state == "failed" else "")


class TakeOff(_FlightGoal):
    """Climbs ``altitude`` metres above where the robot stands."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("altitude", REQUIRED, "Height to climb.", type=float, unit="m", above=0.0),
    )
    what = "the take-off"

    def goal(self) -> dict[str, Any] | None:
        """A takeoff of ``altitude``."""
        return {"action": "takeoff", "frame": "robot", "x": 0.0, "y": 0.0, "z": float(self.params["altitude"]),
                "yaw": math.nan}


class Land(_FlightGoal):
    """Descends where the robot is until it rests."""

    until = "landed"
    what = "the landing"

    def goal(self) -> dict[str, Any] | None:
        """A land goal."""
        return {"action": "land", "frame": "robot", "x": 0.0, "y": 0.0, "z": 0.0, "yaw": math.nan}


def _map_goal(text: str, owner: str) -> tuple[float, float, float, float]:
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) not in (3, 4) or not all(math.isfinite(v) for v in values):
        raise ParamError(f"{owner}: parameter 'goal' = {text!r} is not 'x y z' or 'x y z yaw' (m, m, m, rad)")
    return values[0], values[1], values[2], values[3] if len(values) == 4 else math.nan


class FlyTo(_FlightGoal):
    """Flies to the map point ``goal``, or ``altitude`` above the position received on its input."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("goal", "", "Map point to fly to: 'x y z' or 'x y z yaw' (m, m, m, rad); not with an input.", type=str,
          numbers=(3, 4), form="'x y z' or 'x y z yaw'"),
        P("altitude", None, "With an input: the height above the floor to fly at over the received position.",
          type=float, unit="m", above=0.0),
    )
    what = "the flight"

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """A goal Param, or an input to fly over with an ``altitude``: not both, not neither (D307)."""
        params = {p.name: p for p in record.params}
        goal, altitude = params.get("goal"), params.get("altitude")
        if record.inputs:
            if goal is not None and goal.value.strip():
                return [(goal, "give parameter 'goal' or an input to fly over, not both")]
            if altitude is None:
                return [(record, "flying over a received position needs parameter 'altitude'")]
        elif goal is None or not goal.value.strip():
            return [(record, "parameter 'goal' is required (or an input to fly over)")]
        return []

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.point: tuple[float, float, float, float] | None = None
        if not record.inputs:
            self.point = _map_goal(str(self.params["goal"]), self.owner)

    def goal(self) -> dict[str, Any] | None:
        """The configured point, or ``altitude`` over the newest received map position."""
        point = self.point
        if point is None:
            received = self.read(self.record.inputs[0].name)
            value = received.get("position", received) if isinstance(received, Mapping) else None
            if not isinstance(value, Mapping) or value.get("frame", "map") != "map":
                return None
            if not all(isinstance(value.get(k), int | float) for k in ("x", "y")):
                return None
            point = float(value["x"]), float(value["y"]), float(self.params["altitude"]), math.nan
        x, y, z, yaw = point
        return {"action": "goto", "frame": "map", "x": x, "y": y, "z": z, "yaw": yaw}
