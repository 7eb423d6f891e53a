"""``behavior.search-area``: sweep a named Area of the map until the wanted object is seen (D269).

The robot drives through the coverage waypoints of the ``<Area name=area>`` of the system's
``<Environment>`` (:func:`~plugins.behaviors.coverage.lawnmower`: lanes ``spacing`` apart inside the
Area shrunk by ``margin``), each one a goal of the ``navigation`` service (its status echoes the goal
it reports: only this waypoint's status, heard after it was set, counts — docs/interfaces.md). A
waypoint the navigation refuses or fails, or does not reach within ``waypointTimeout``, is skipped,
its reason kept in the mission log. All along, the behavior watches an ``object-detection`` service
(``<Uses as="detection">``) or a ``fusion`` service (``as="fusion"``) for an object answering to
``label`` with a reliability of at least ``minReliability``; once seen, the navigation goal is
cancelled and the object's map pose (an ``ObjectPosition``, frame ``map``) is written on every
``<Output>``. It fails when every waypoint was visited or skipped without the object.

Progress is the share of waypoints visited or skipped; the performance (eq. 5.1) is that of the
navigation and perception services it uses.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import Behavior, BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .coverage import area_problems, sweep_waypoints
from .messages import _state, robot_pose
from .sightings import (
    SIGHTING_PARAMS,
    SIGHTING_USES,
    best_sighting,
    map_sighting,
    mount_of,
    on_map,
    perception,
    sighting_problems,
)


def _value(record: BehaviorRecord, name: str) -> Any:
    return next((p for p in record.params if p.name == name), None)


class SearchArea(Behavior):
    """``behavior.search-area``: the Area's coverage sweep, watching for the object (module docstring)."""

    USES = Uses(Use("nav", "navigation", "given each waypoint as its goal; its pose places a sighting"),
                *SIGHTING_USES)
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("area", "", "The <Area> of the system's <Environment> to sweep (required)."),
        *SIGHTING_PARAMS,
        P("spacing", 1.0, "Distance between two lanes, and between two waypoints of a lane: at most the "
                          "detector's useful range across.", unit="m", above=0.0),
        P("margin", -1.0, "How far inside the Area's outline the outer lanes run (negative: half the spacing).",
          unit="m"),
        P("along", "long", "The lanes' direction: the Area's longer side, or the map's x or y axis.",
          choices=("long", "x", "y")),
        P("dwell", 0.0, "How long the robot watches at each waypoint it reached.", unit="s", min=0.0),
        P("confirm", 0.3, "A sighting placed with the robot's pose (not on the map already) counts once a "
                          "newer pose estimate places it again within this distance: one placed with a pose "
                          "the robot has turned away from since is not taken (0: at once).", unit="m", min=0.0),
        P("waypointTimeout", 0.0, "A waypoint not reached in this time is skipped (0: the navigation decides).",
          unit="s", min=0.0),
    )
    PORTS = Ports(outputs={"*": MAPPING})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """The Area must be one of the map's, and one perception service watched."""
        found = sighting_problems(record, system)
        area = _value(record, "area")
        if area is None or not area.value.strip():
            found.append((record, "give the Area to sweep: <Param name=\"area\" value=\"…\"/>"))
        else:
            found.extend(area_problems(area, system))
        return found

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.waypoints = sweep_waypoints(context.environment, self.params, self.owner)
        self.mount = mount_of(self.params["sensorPose"], self.owner)

    def start(self) -> None:
        """Configure the services and send the first waypoint."""
        super().start()
        self.next, self.visited = 0, 0
        self.skipped: list[dict[str, str | None]] = []
        self.goal: str | None = None
        self.reached_at: float | None = None
        self.found: dict[str, Any] | None = None
        self.candidate: tuple[Any, tuple[float, float, float]] | None = None  # (pose message, map place)
        self._advance()

    def _advance(self) -> None:
        """Set the next waypoint as the navigation's goal (or none when the sweep is over)."""
        self.goal, self.reached_at = None, None
        if self.next < len(self.waypoints):
            x, y, yaw = self.waypoints[self.next]
            self.goal = f"{x:.3f} {y:.3f} {yaw:.3f}"
            self.before = self.service("nav").output("status")  # an earlier goal's, as this one is set
            self.sent_at = self.context.now()
            self.service("nav").configure({"goal": self.goal}, ())
            self.next += 1

    def _progress(self) -> float:
        return (self.visited + len(self.skipped)) / len(self.waypoints)

    def _skip(self, reason: str) -> None:
        self.skipped.append({"waypoint": self.goal, "reason": reason})
        self.context.log("waypoint skipped", waypoint=self.goal, reason=reason)
        self._advance()

    def _look(self) -> BehaviorStatus | None:
        """Done when the perception shows the object (written on the outputs), else None."""
        item = best_sighting(perception(self), self.params["label"], self.params["minReliability"])
        if item is None:
            return None
        estimate = self.service("nav").output("pose")
        robot = robot_pose(estimate)
        where = on_map(item, robot, self.mount)
        if where is None:
            return None  # relative to the robot, whose pose is not known yet
        if item.get("frame") != "map" and self.params["confirm"] > 0 and not self._confirmed(estimate, where):
            return None
        self.found = map_sighting(item, where, robot, self.context.now())
        if self.goal is not None:
            self.service("nav").configure({"goal": ""}, ())  # the empty goal cancels the sweep's
            self.goal = None
        for port in self.record.outputs:
            self.write(port.name, self.found)
        self.context.log("object found", label=self.found["label"], x=where[0], y=where[1],
                         reliability=self.found["reliability"], skipped=len(self.skipped))
        return BehaviorStatus(progress=1.0, done=True,
                              detail=f"{self.found['label']} at ({where[0]:.2f}, {where[1]:.2f})")

    def _confirmed(self, estimate: Any, where: tuple[float, float, float]) -> bool:
        """Whether a newer pose estimate than the candidate's places the sighting within ``confirm`` of it."""
        if self.candidate is not None and self.candidate[0] is not estimate:
            gap = ((where[0] - self.candidate[1][0]) ** 2 + (where[1] - self.candidate[1][1]) ** 2) ** 0.5
            if gap <= self.params["confirm"]:
                return True
        if self.candidate is None or self.candidate[0] is not estimate:
            self.candidate = (estimate, where)
        return False

    def step(self) -> BehaviorStatus:
        """Watch for the object; follow the current waypoint's status; move on when it is reached or skipped."""
        if self.found is not None:
            return BehaviorStatus(progress=1.0, done=True)
        seen = self._look()
        if seen is not None:
            return seen
        if self.goal is None:
            return self._covered()
        now = self.context.now()
        status = self.service("nav").output("status")
        ours = status is not self.before and isinstance(status, Mapping) and status.get("goal") == self.goal
        state = _state(status) if ours else None
        if state in ("failed", "cancelled"):
            self._skip(str(status.get("reason") or "the navigation failed"))
        elif state == "arrived":
            self.reached_at = now if self.reached_at is None else self.reached_at
            if now - self.reached_at >= self.params["dwell"]:
                self.visited += 1
                self._advance()
        elif self.params["waypointTimeout"] > 0 and now - self.sent_at > self.params["waypointTimeout"]:
            self._skip(f"not reached in {self.params['waypointTimeout']:g} s")
        if self.goal is None:
            return self._covered()
        return BehaviorStatus(progress=self._progress(),
                              detail=f"waypoint {self.next} of {len(self.waypoints)}")

    def _covered(self) -> BehaviorStatus:
        """Failed: every waypoint visited or skipped (the reasons in the detail), the object not seen."""
        reasons = "; ".join(f"{s['waypoint']}: {s['reason']}" for s in self.skipped)
        wanted = self.params["label"] or "an object"
        return BehaviorStatus(progress=1.0, failed=True,
                              detail=f"area {self.params['area']} covered ({len(self.waypoints)} waypoints, "
                                     f"{len(self.skipped)} skipped) without seeing {wanted}"
                                     + (f"; skipped {reasons}" if reasons else ""))

    def stop(self) -> None:
        """Left mid-sweep (timeout, preemption): cancel the waypoint, so the robot does not drive on."""
        if getattr(self, "goal", None) is not None:
            self.service("nav").configure({"goal": ""}, ())
            self.goal = None
