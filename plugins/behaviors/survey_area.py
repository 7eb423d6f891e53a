"""``behavior.survey-area``: an aerial robot sweeps a named Area at an altitude until it finds the wanted
object, confirms it, hovers and reports its map position (issue N point 3a; D302).

The sibling of ``search-area`` (D269) for the ``flight`` interface (docs/interfaces.md): the coverage
waypoints of the ``<Area name=area>`` (:func:`~plugins.behaviors.coverage.lawnmower`, lanes ``spacing``
apart — at most the camera's footprint across at ``altitude`` — inside the Area shrunk by ``margin``)
are each a ``goto`` goal at ``altitude`` above the floor, written on the ``flight_goal`` Output with a
fresh id; only the status of that id counts, so an earlier goal's ``arrived`` never moves the sweep on.
A waypoint the flight service fails ("the leg meets 'rack'") or does not reach in ``waypointTimeout``
is skipped, its reason in the mission log and in the failure's detail.

All along it watches the perception it uses (``detection``: a ``ground-projection`` service placing
a camera's detections on the map, or any detector in the map or robot frame; or ``fusion``). A new
result holding an object answering to ``label`` with at least ``minReliability`` is a *candidate*: the
robot holds (a ``hold`` goal: it hovers where it is) and counts the new results that place the object
again within ``confirmDistance`` of the candidates' mean; at ``confirmFrames`` of them the object is
found — one noisy frame, or an object of another colour, never ends the survey. A candidate not
confirmed within ``confirmTime`` is dropped and the sweep flies on to the waypoint it was heading for.
Found, the robot keeps hovering and the mean of the confirming positions, an ``ObjectPosition`` ``{stamp,
label, frame: map, x, y, z, reliability, observer}``, is written on every Output but ``flight_goal`` (a
topic, or a plan signal's payload: a ground robot's ``navigate-to`` or a ``fly-to`` goes to it). It
fails when every waypoint was visited or skipped without the object; leaving the state mid-sweep holds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .coverage import area_problems, sweep_waypoints
from .messages import _failed, _Goals, _state, robot_pose
from .sightings import SIGHTING_USES, labels, map_sighting, mount_of, on_map, perception, sighting_problems
from .upstream import perception_reports

GOAL = "flight_goal"


def _param(record: BehaviorRecord, name: str) -> Any:
    return next((p for p in record.params if p.name == name), None)


def _perception_problems(record: BehaviorRecord, system: System) -> list[tuple[Any, str]]:
    """The watched detector must give positions (not image shares) and be able to report ``label``."""
    use = next((u for u in record.uses if u.alias in ("detection", "fusion")), None)
    reports = perception_reports(system, use.service) if use is not None else None
    if use is None or reports is None:
        return []
    if reports.image:
        return [(use, f"{use.service!r} ({reports.kind}) gives its objects' x, y as shares of the image, not "
                      "positions: watch a ground-projection service placing them on the map (docs/flight.md)")]
    label = _param(record, "label")
    if label is not None and reports.labels is not None and label.value not in reports.labels:
        return [(label, f"parameter 'label' = {label.value!r} is no label {use.service!r} can report (its "
                        f"{reports.kind}: {', '.join(sorted(reports.labels))})")]
    return []


class SurveyArea(_Goals):
    """``behavior.survey-area``: the Area's coverage flight, confirming the object before it reports it
    (module docstring)."""

    USES = Uses(Use("flight", "flight", "flies each waypoint and the hover; its pose places a sighting"),
                *SIGHTING_USES)
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("area", REQUIRED, "The <Area> of the system's <Environment> to sweep.", type=str),
        P("altitude", REQUIRED, "Height above the floor the sweep is flown at.", type=float, unit="m", above=0.0),
        P("spacing", REQUIRED, "Distance between two lanes, and between two waypoints of a lane: at most the "
                               "camera's footprint across at 'altitude'.", type=float, unit="m", above=0.0),
        P("label", REQUIRED, "The object looked for: its label, name, shape or texture as the detector reports it "
                             "(a colour-detection's colour name).", type=str),
        P("minReliability", 0.5, "Least reliability a sighting must have.", min=0.0, max=1.0),
        P("sensorPose", "0 0 0", "Where the detector's sensor sits on the robot, 'x y yaw' (m, m, rad): places a "
                                 "sighting given relative to the robot (one in the map frame needs none).",
          numbers=(3,), form="'x y yaw'"),
        P("margin", -1.0, "How far inside the Area's outline the outer lanes run (negative: half the spacing).",
          unit="m"),
        P("along", "long", "The lanes' direction: the Area's longer side, or the map's x or y axis.",
          choices=("long", "x", "y")),
        P("confirmFrames", 3, "New detection results that must place a candidate again before it is taken.",
          min=1),
        P("confirmDistance", 0.3, "How close to the candidates' mean each confirming position must be.",
          unit="m", above=0.0),
        P("confirmTime", 5.0, "How long the robot hovers to confirm a candidate before it sweeps on.", unit="s",
          above=0.0),
        P("waypointTimeout", 0.0, "A waypoint not reached in this time is skipped (0: the flight service's "
                                  "deadline decides).", unit="s", min=0.0),
    )
    PORTS = Ports(outputs={"*": MAPPING})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """The Area is one of the map's; one perception is watched; the goal and a report have outputs."""
        found = sighting_problems(record, system)
        names = [o.name for o in record.outputs]
        if GOAL not in names:
            found.append((record, f"it flies through its <Output name=\"{GOAL}\"> (the flight service's goal "
                                  "topic), and has none"))
        if not [n for n in names if n != GOAL]:
            found.append((record, "give an <Output> (a topic or a plan signal) for the object's map position"))
        if system is not None:
            found.extend(_perception_problems(record, system))
        area = _param(record, "area")
        if area is not None:
            found.extend(area_problems(area, system))
        return found

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        if (problems := self.problems(record, None)):
            raise ParamError(f"{self.owner}: {problems[0][1]}")
        self.waypoints = sweep_waypoints(context.environment, self.params, self.owner)
        self.mount = mount_of(self.params["sensorPose"], self.owner)
        self.reports = [o.name for o in record.outputs if o.name != GOAL]

    def start(self) -> None:
        """Configure the services and fly to the first waypoint; results from before now never count."""
        super().start()
        self.next, self.visited = 0, 0
        self.skipped: list[dict[str, Any]] = []
        self.goal_id: int | None = None
        self.found: dict[str, Any] | None = None
        self.candidates: list[tuple[float, float, float, float]] = []  # x, y, z, reliability
        self.confirm_since: float | None = None
        self.seen = perception(self)
        self._fly()

    # ------------------------------------------------------------------ goals

    def _fly(self) -> None:
        """Send the next waypoint as a goto (none when the sweep is over)."""
        self.goal_id = None
        if self.next < len(self.waypoints):
            x, y, _ = self.waypoints[self.next]
            self.goal_id = self._send(GOAL, {"action": "goto", "frame": "map", "x": x, "y": y,
                                             "z": float(self.params["altitude"]), "yaw": math.nan})
            self.sent_at = self.context.now()

    def _hold(self) -> None:
        """Hover where the robot is (a fresh ``hold`` goal preempts the waypoint)."""
        self.goal_id = None
        self._send(GOAL, {"action": "hold", "frame": "robot", "x": 0.0, "y": 0.0, "z": 0.0, "yaw": math.nan})

    def _skip(self, reason: str) -> None:
        waypoint = self.waypoints[self.next]
        self.skipped.append({"waypoint": f"{waypoint[0]:.2f} {waypoint[1]:.2f}", "reason": reason})
        self.context.log("waypoint skipped", waypoint=self.skipped[-1]["waypoint"], reason=reason)
        self.next += 1
        self._fly()

    # ------------------------------------------------------------------ sightings

    def _sighting(self, result: Any) -> tuple[dict[str, Any], tuple[float, float, float]] | None:
        """The wanted object of ``result`` on the map: while confirming the one nearest the candidates,
        else the most reliable; None when none is placed."""
        objects = result.get("objects") if isinstance(result, Mapping) else None
        robot = robot_pose(self.service("flight").output("pose"))
        mean = self._mean() if self.candidates else None
        best: tuple[float, dict[str, Any], tuple[float, float, float]] | None = None
        for item in objects if isinstance(objects, list) else []:
            if not isinstance(item, Mapping) or self.params["label"] not in labels(item):
                continue
            reliability = item.get("reliability")
            if not isinstance(reliability, int | float) or reliability < self.params["minReliability"]:
                continue
            where = on_map(item, robot, self.mount)
            if where is None:
                continue
            rank = math.hypot(where[0] - mean[0], where[1] - mean[1]) if mean else -float(reliability)
            if best is None or rank < best[0]:
                best = (rank, dict(item), where)
        return None if best is None else (best[1], best[2])

    def _mean(self) -> tuple[float, float, float, float]:
        count = len(self.candidates)
        return tuple(sum(c[k] for c in self.candidates) / count for k in range(4))  # type: ignore[return-value]

    def _look(self, now: float) -> BehaviorStatus | None:
        """Follow a new perception result: start, grow or end a confirmation; the found status, else None."""
        result = perception(self)
        if result is self.seen or result is None:
            return None
        self.seen = result
        sighting = self._sighting(result)
        if sighting is None:
            return None
        item, where = sighting
        reliability = float(item.get("reliability") or 0.0)
        if not self.candidates:
            self.candidates, self.confirm_since = [(*where, reliability)], now
            self._hold()
            self.context.log("candidate seen, hovering to confirm", label=self.params["label"], x=where[0],
                             y=where[1], reliability=reliability)
        else:
            mean = self._mean()
            if math.hypot(where[0] - mean[0], where[1] - mean[1]) > self.params["confirmDistance"]:
                return None
            self.candidates.append((*where, reliability))
        if len(self.candidates) <= self.params["confirmFrames"]:
            return None
        x, y, z, reliability = self._mean()
        robot = robot_pose(self.service("flight").output("pose"))
        self.found = map_sighting({**item, "reliability": reliability}, (x, y, z), robot, now)
        observer = item.get("observer")  # the pose a map-frame detector placed it with
        if isinstance(observer, list) and len(observer) == 1 and isinstance(observer[0], Mapping):
            self.found["observer"] = [dict(observer[0])]
        for name in self.reports:
            self.write(name, self.found)
        self.context.log("object found", label=self.found["label"], x=x, y=y, reliability=reliability,
                         confirmations=len(self.candidates) - 1, skipped=len(self.skipped))
        return BehaviorStatus(progress=1.0, done=True, detail=f"{self.found['label']} at ({x:.2f}, {y:.2f})")

    # ------------------------------------------------------------------ the sweep

    def step(self) -> BehaviorStatus:
        """Watch for the object; confirm a candidate while hovering; else follow the waypoint's status."""
        if self.found is not None:
            return BehaviorStatus(progress=1.0, done=True)
        now = self.context.now()
        seen = self._look(now)
        if seen is not None:
            return seen
        if self.candidates:
            assert self.confirm_since is not None
            if now - self.confirm_since <= self.params["confirmTime"]:
                return BehaviorStatus(progress=self._progress(),
                                      detail=f"confirming {self.params['label']} ({len(self.candidates) - 1} of "
                                             f"{self.params['confirmFrames']})")
            self.context.log("candidate not confirmed", label=self.params["label"],
                             confirmations=len(self.candidates) - 1)
            self.candidates, self.confirm_since = [], None
            self._fly()  # on to the waypoint it was heading for
        if self.goal_id is None:
            return self._covered()
        status = self.service("flight").output("status")
        state = _state(status, self.goal_id)
        if state == "failed":
            self._skip(_failed("the flight failed", status))
        elif state == "arrived":
            self.visited += 1
            self.next += 1
            self._fly()
        elif self.params["waypointTimeout"] > 0 and now - self.sent_at > self.params["waypointTimeout"]:
            self._skip(f"not reached in {self.params['waypointTimeout']:g} s")
        if self.goal_id is None:
            return self._covered()
        return BehaviorStatus(progress=self._progress(), detail=f"waypoint {self.next + 1} of {len(self.waypoints)}")

    def _progress(self) -> float:
        return (self.visited + len(self.skipped)) / len(self.waypoints)

    def _covered(self) -> BehaviorStatus:
        """Failed: every waypoint visited or skipped (the reasons in the detail), the object not found."""
        reasons = "; ".join(f"{s['waypoint']}: {s['reason']}" for s in self.skipped)
        return BehaviorStatus(progress=1.0, failed=True,
                              detail=f"area {self.params['area']} covered ({len(self.waypoints)} waypoints, "
                                     f"{len(self.skipped)} skipped) without finding {self.params['label']}"
                                     + (f"; skipped {reasons}" if reasons else ""))

    def stop(self) -> None:
        """Left mid-sweep (timeout, preemption): hover, so the robot does not fly on to the waypoint."""
        if getattr(self, "goal_id", None) is not None and self.found is None:
            self._hold()
