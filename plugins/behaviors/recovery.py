"""Behaviors of the dropped-object recovery (issue K point 3d; ours: the thesis draws only the
success path of Fig. 7.12, §5.2 leaves failure handling to the mission designer).

When the gripper's holding measure (RoboticArm.MoveIt, D169) drops while the Turtlebot drives
home, the lab's ObjectPlace mission runs its ObjectRecovery sub-mission:

- ``stop-nav`` (HALT): cancels the Navigation goal (the ``nav`` service's ``goal`` Parameter set
  empty by its ``<Configure>``) and sends the base a move of zero length, which preempts the path
  being followed for good (plugins/navigation/displacement.py); done when the base reports it done.
- ``search-object`` (LOOK): looks for the target with the fused recognition, standing still at
  each view — the fusion places what it sees with the robot's pose (D172), so a sighting made
  while turning would be misplaced — and turning ``turn`` radians between views. It first backs
  ``back`` metres along the way the robot just drove (free; the robot stopped past where the object
  fell, and an object nearer than about 0.45 m is under the camera's view, D225); after a full
  round of ``views`` it backs ``shift`` metres and looks round again, up to ``rounds`` rounds. A
  texture print is recognisable from some sides only: a candidate of the target's shape that the
  depth recognition alone saw (no texture) within ``probeRange`` is looked at again from ``probe``
  radians round it (the robot moves round it, facing it, to either side of where the first probe
  started in turn: +probe, −probe, +probe…), at ``probeDistance`` metres from it (0: the distance it
  was seen at), ``probes`` times at most (D254). A move the base could not finish (blocked by a table) does not end the
  search: the robot looks from where it stopped, unless ``blockedMoves`` moves failed in a row.
  Writes the target's position (an ``ObjectPosition``) like SPOT, so APPR can approach it.

Messages are those of :mod:`plugins.behaviors.messages` (``/base/move_goal``, ``/base/move_status``,
the fused recognition's objects).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .messages import (
    TARGET_PARAMS,
    _failed,
    _Goals,
    _share_done,
    _state,
    find_target,
    in_robot_frame,
    object_position,
    observer_pose,
)


class StopNavigation(_Goals):
    """HALT: the Navigation goal cancelled (its ``<Configure>``) and the base stopped by a zero move."""

    USES = Uses(Use("base", "base-drive", "takes the zero move that stops the base"))

    PORTS = Ports(outputs={"*": MAPPING})

    def start(self) -> None:
        """Configure the services (the empty goal cancels the navigation), then send the zero move."""
        super().start()
        self.move_id = self._send("move", {"frame": "robot", "x": 0.0, "y": 0.0, "yaw": 0.0})

    def step(self) -> BehaviorStatus:
        """Done once the base has carried out the zero move (it no longer follows the path)."""
        status = self.service("base").output("move_status")
        state = _state(status, self.move_id)
        if state == "failed":
            return BehaviorStatus(progress=0.0, failed=True, detail=_failed("the base did not stop", status))
        return BehaviorStatus(progress=1.0 if state == "done" else 0.0, done=state == "done")


class SearchObject(_Goals):
    """LOOK: views round the robot until the fused recognition holds the target (module docstring)."""

    USES = Uses(Use("base", "base-drive", "turns and moves the robot to look"),
                Use("fusion", "fusion", "the recognition looked in, unless an input named objects gives it",
                    optional=True))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        *TARGET_PARAMS,
        P("minSources", 1, "Fewest recognition sources that must have seen the object."),
        P("minReliability", 0.0, "Least fused reliability a sighting must have.", min=0.0, max=1.0),
        P("turn", 0.6, "Turn between two views (positive: to the left).", unit="rad"),
        P("views", 11, "Views in one round (with the first, views × turn should cover a full turn).", min=1),
        P("settle", 2.5, "Wait at a view before a sighting counts: the camera, recognition and fusion "
          "latencies after the robot stopped.", unit="s", min=0.0),
        P("dwell", 2.0, "How long a view is watched after it settled.", unit="s", min=0.0),
        P("back", 0.0, "Backward move before the first view: back along the way just driven (free), towards "
          "where the object fell.", unit="m", min=0.0),
        P("shift", 0.4, "Backward move between two rounds.", unit="m", min=0.0),
        P("rounds", 2, "Rounds of views at most.", min=1),
        P("probe", 0.0, "A candidate of the target's shape that no recogniser told the texture of (a print is "
          "recognisable from some sides only) is looked at again from this far round it (0: never).", unit="rad"),
        P("probes", 3, "Such second looks at most, in the whole search.", min=0),
        P("probeRange", 1.2, "Farthest candidate looked at again.", unit="m", min=0.0),
        P("probeDistance", 0.0, "Distance from the candidate the second looks are taken at (0: the distance it "
          "was seen at).", unit="m", min=0.0),
        P("blockedMoves", 2, "Failed moves in a row (the base blocked by furniture) that end the search; "
          "after fewer, it looks from where the robot stopped.", min=1),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        if self.params["turn"] == 0.0 and self.params["views"] > 1:
            raise ParamError(f"{self.owner}: parameter 'turn' must not be 0 (the views would all be the same)")

    def start(self) -> None:
        """Look from where the robot stands first."""
        super().start()
        self.view, self.round, self.probed, self.blocked = 0, 0, 0, 0
        self.orbit = 0.0  # how far round the first probed candidate the probes have taken the robot (rad)
        self.candidate: tuple[float, float] | None = None
        self.looking_since: float | None = self.context.now()
        self.move_id: int | None = None
        if self.params["back"] > 0.0:
            back = -float(self.params["back"])
            self.move_id = self._send("move", {"frame": "robot", "x": back, "y": 0.0, "yaw": 0.0})
            self.looking_since = None

    def _total(self) -> int:
        return int(self.params["views"]) * int(self.params["rounds"])

    def step(self) -> BehaviorStatus:
        """Watch the view once settled; turn (or back off, after a round) when it shows nothing."""
        p = self.params
        now = self.context.now()
        done_views = self.round * int(p["views"]) + self.view
        if self.looking_since is None:  # moving to the next view
            move = self.service("base").output("move_status")
            state = _state(move, self.move_id)
            if state == "failed":
                self.blocked += 1
                if self.blocked >= p["blockedMoves"]:
                    return BehaviorStatus(progress=done_views / self._total(), failed=True,
                                          detail=_failed(f"the base could not move to the next view "
                                                         f"({self.blocked} moves failed in a row)", move))
                self.context.log("the base could not move there; looking from where it stopped", view=done_views)
            elif state != "done":
                return BehaviorStatus(progress=(done_views + 0.5 * _share_done(move)) / self._total())
            else:
                self.blocked = 0
            self.looking_since = now
        watched = now - self.looking_since
        if watched >= p["settle"]:
            result = self.read("objects") if "objects" in self.context.inputs else self.service("fusion").output(
                "objects")
            found = find_target(result, p["target"], p["targetTexture"], p["minSources"])
            if found is not None and float(found.get("reliability", 0.0)) >= p["minReliability"]:
                self.write("target", object_position(found, now))
                self.context.log("target found", view=done_views, name=found.get("name"),
                                 reliability=found.get("reliability"))
                return BehaviorStatus(progress=1.0, done=True, detail=f"{found.get('name')} at view {done_views}")
            self.candidate = self._candidate(result) or self.candidate
        if watched < p["settle"] + p["dwell"]:
            return BehaviorStatus(progress=done_views / self._total(), detail=f"view {done_views}")
        if self.candidate is not None and p["probe"] != 0.0 and self.probed < p["probes"]:
            self.probed += 1
            self.context.log("looking again round a candidate", at=list(self.candidate), probe=self.probed)
            # either side of where the probes started, in turn (one may be blocked); a blocked move
            # is taken as done: the next probe then goes a little further than asked
            side = 1.0 if self.probed % 2 else -1.0
            angle, self.orbit = side * float(p["probe"]) - self.orbit, side * float(p["probe"])
            self.move_id = self._send("move", self._round(self.candidate, angle, float(p["probeDistance"])))
            self.candidate, self.looking_since = None, None
            return BehaviorStatus(progress=done_views / self._total(), detail="looking at a candidate again")
        self.candidate = None
        self.view += 1
        if self.view < int(p["views"]):
            goal = {"frame": "robot", "x": 0.0, "y": 0.0, "yaw": math.remainder(float(p["turn"]), 2 * math.pi)}
        else:
            self.view, self.round = 0, self.round + 1
            if self.round >= int(p["rounds"]):
                return BehaviorStatus(progress=1.0, failed=True, detail=f"not found in {self._total()} views")
            goal = {"frame": "robot", "x": -abs(float(p["shift"])), "y": 0.0, "yaw": 0.0}
        self.move_id = self._send("move", goal)
        self.looking_since = None
        return BehaviorStatus(progress=(done_views + 1) / self._total(), detail="moving to the next view")

    def _candidate(self, result: Any) -> tuple[float, float] | None:
        """The nearest object of the target's shape within ``probeRange`` whose texture no recogniser
        gave (seen by its shape alone), in the robot frame; None if there is none."""
        objects = result.get("objects") if isinstance(result, Mapping) else None
        best: tuple[float, float] | None = None
        for item in objects if isinstance(objects, list) else []:
            if not isinstance(item, Mapping) or item.get("texture") or item.get("name") != self.params["target"]:
                continue
            relative = in_robot_frame(item, observer_pose(item))
            if relative is not None and math.hypot(*relative) <= self.params["probeRange"] and (
                    best is None or math.hypot(*relative) < math.hypot(*best)):
                best = relative
        return best

    @staticmethod
    def _round(candidate: tuple[float, float], angle: float, distance: float = 0.0) -> dict[str, Any]:
        """The move (robot frame) to the point ``angle`` rad round ``candidate`` at ``distance`` from it
        (0: the same distance), facing it. At the same distance the straight way there keeps at least
        cos(angle / 2) of it from the candidate."""
        cx, cy = candidate
        seen = math.hypot(cx, cy)
        scale = distance / seen if distance > 0.0 and seen > 0.0 else 1.0
        # the candidate seen from the new point: the current view turned by `angle` about it, scaled
        vx = scale * (cx * math.cos(angle) - cy * math.sin(angle))
        vy = scale * (cx * math.sin(angle) + cy * math.cos(angle))
        return {"frame": "robot", "x": cx - vx, "y": cy - vy, "yaw": math.atan2(vy, vx)}
