"""APPR (Table 7.7): the approach to the spotted object, with its re-aim after a long drive (D207).

Over ``base-drive`` and, optionally, ``arm-motion``: a robot without an arm (or one that need not raise
it) drives to the standoff alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.missions.behaviors import BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, P, Params, Ports

from .messages import _failed, _Goals, _share_done, _state, find_target, in_robot_frame, observer_pose, robot_pose


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
    or no sighting of it on ``objects`` when the drive starts: one move, as before.

    ``faceFirst`` turns the robot on the spot to face the target before any drive and looks again
    the same way, so the turn's odometry error is measured away and the drive goes straight
    (APPR_FLOOR, D253). ``aimAtCentre`` takes a fresh sighting's ``centre`` (its 3D source's point,
    the solid's centre) rather than the fused estimate, which a print seen aside pulls off the axis.

    ``yawTolerance`` > 0 asks the base to end each move within that heading of facing the target
    (Move2D ``yaw_tolerance``): the floor grasp's fingers clear the object by 1 cm a side (D252)."""

    USES = Uses(Use("base", "base-drive", "drives the moves towards the target"),
                Use("arm", "arm-motion", "raises the arm to armPose before the drive (none: the base alone)",
                    optional=True))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("standoff", 0.2, "Distance kept from the target.", unit="m"),
        P("armPose", "", "Named arm pose reached before the drive (required with an arm service)."),
        P("reaim", 0.0, "Stop this far short of the standoff to look again (0: never).", unit="m", min=0.0),
        P("reaimAbove", 0.0, "Only on drives longer than this.", unit="m", min=0.0),
        P("settle", 2.5, "Standing still this long before a sighting counts (camera, recognition, fusion).",
          unit="s", min=0.0),
        P("reaimWait", 5.0, "Longest wait for a fresh sighting after settling.", unit="s", min=0.0),
        P("yawTolerance", 0.0, "Final heading tolerance asked of the base (0: the Displacement's own).",
          unit="rad", min=0.0, max=0.5),
        P("faceFirst", False, "Turn on the spot to face the target and look again before driving."),
        P("aimAtCentre", False, "Aim a fresh sighting at its 3D source's point, not the fused estimate."),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """An arm service without the pose to raise it to."""
        arm = next((u for u in record.uses if u.alias == "arm"), None)
        pose = next((p for p in record.params if p.name == "armPose"), None)
        if arm is not None and (pose is None or not pose.value.strip()):
            return [(arm, "an approach with an arm needs the pose to raise it to: <Param name=\"armPose\" "
                          "value=\"…\"/> (a named pose of its arm-motion service)")]
        return []

    FACED = 0.01
    """rad: a target this near straight ahead needs no turn first."""

    def start(self) -> None:
        """Send the arm goal; the base goal follows once the arm has reached it."""
        super().start()
        self.phase = "arm"  # arm → drive (a move) → look (standing, after a move that is not the last) → drive…
        self.move_id: int | None = None
        self.legs: list[float] = []  # the lengths of the moves sent
        self.planned = 0.0  # the whole drive as planned at the start
        self.final = False  # the move sent is the last leg
        self.ahead = 0.0  # where the target should stand straight ahead after the move sent (m)
        self.reaimed = False
        self.label = ""
        self.stopped = 0.0  # when the last move that is not the last leg ended
        self.settled: Any = None  # the fused message when the settling ended: a sighting must be newer
        with_arm = "arm" in self.context.services
        self.arm_id = self._send("arm_goal", {"group": "arm", "pose": self.params["armPose"]}) if with_arm else None

    def _relative(self, target: Any) -> tuple[float, float] | None:
        """The target in the robot frame: with the pose it was placed with, else the ``pose`` input."""
        # The pose the fusion placed the target with, when it says: the robot has stood still
        # since, and the estimate's bias cancels (D172). Else the latest estimate.
        pose = observer_pose(target)
        if pose is None and "pose" in self.context.inputs:
            pose = robot_pose(self.read("pose"))
        return in_robot_frame(target, pose)

    def _sighting(self) -> Mapping[str, Any] | None:
        """The most reliable positioned sighting of the target on the ``objects`` input, None if none
        (at its ``centre`` with ``aimAtCentre``, when it has one)."""
        result = self.read("objects") if self.label and "objects" in self.context.inputs else None
        if not isinstance(result, Mapping) or not isinstance(result.get("objects"), list):
            return None
        placed = [o for o in result["objects"] if isinstance(o, Mapping) and isinstance(o.get("x"), int | float)
                  and isinstance(o.get("y"), int | float)]  # fmt: skip
        found = find_target({"objects": placed}, self.label, "")
        if found is None or not self.params["aimAtCentre"]:
            return found
        centre = found.get("centre")
        if isinstance(centre, list | tuple) and len(centre) == 3 and all(isinstance(v, int | float) for v in centre):
            return {**found, "x": centre[0], "y": centre[1], "z": centre[2]}
        return found

    def _send_move(self, x: float, y: float, yaw: float) -> None:
        goal = {"frame": "robot", "x": x, "y": y, "yaw": yaw}
        if self.params["yawTolerance"] > 0:  # aimed finer than the base's default (D252)
            goal["yaw_tolerance"] = self.params["yawTolerance"]
        self.move_id = self._send("move", goal)

    def _next_move(self, relative: tuple[float, float]) -> None:
        """Send the next move towards the target at ``relative``: a turn to face it (``faceFirst``), a
        long drive's move short of it (``reaim``), or the last leg to the standoff."""
        x, y = relative
        p, distance, bearing = self.params, math.hypot(x, y), math.atan2(y, x)
        drive = distance - p["standoff"]
        can_look = self.label and self._sighting() is not None  # the fusion holds the target now
        if p["faceFirst"] and not self.legs and can_look and abs(bearing) > self.FACED:
            keep_off, self.final = distance, False  # the first move: a turn on the spot
        elif p["reaim"] > 0 and not self.reaimed and can_look and drive > max(p["reaimAbove"], p["reaim"]):
            self.reaimed, keep_off, self.final = True, p["standoff"] + p["reaim"], False
        else:
            keep_off, self.final = p["standoff"], True
        keep = max(0.0, distance - keep_off) / distance if distance > 0 else 0.0
        self._send_move(x * keep, y * keep, bearing)
        self.legs.append(distance * keep)
        self.ahead = min(distance, keep_off)
        self.phase = "drive"

    def _first_move(self) -> BehaviorStatus | None:
        """Send the first move (status while it cannot be sent)."""
        target = self.read("target")
        if not isinstance(target, Mapping) or not isinstance(target.get("x"), int | float):
            return BehaviorStatus(progress=0.0, detail="no target")
        relative = self._relative(target)
        if relative is None:
            return BehaviorStatus(progress=0.0, detail="waiting for the pose estimate")
        self.label = str(target.get("label") or "")
        self.planned = max(0.0, math.hypot(*relative) - self.params["standoff"])
        self._next_move(relative)
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
        """Standing after a move that is not the last: send the next once a fresh sighting or the wait's end allows."""
        waited, p = self.context.now() - self.stopped, self.params
        if waited < p["settle"]:
            return False
        relative = self._fresh()
        if relative is not None:
            self.context.log("re-aimed", x=round(relative[0], 4), y=round(relative[1], 4))
        elif waited >= p["settle"] + p["reaimWait"]:  # the move faced the target: straight on
            relative = (self.ahead, 0.0)
            self.context.log("no fresh sighting: straight on", distance=round(self.ahead - p["standoff"], 4))
        else:
            return False
        self.settled = None
        self._next_move(relative)
        return True

    def step(self) -> BehaviorStatus:
        """Raise the arm, then drive to ``standoff`` from the target; done when both are reached."""
        arm_state = "reached" if self.arm_id is None else _state(self.service("arm").output("status"), self.arm_id)
        if self.phase == "arm":
            if arm_state != "reached":  # the arm up first: it must not sweep the table
                if arm_state == "failed":
                    return BehaviorStatus(progress=0.0, failed=True, detail="the arm did not reach its pose")
                return BehaviorStatus(progress=0.0, detail="raising the arm")
            if (waiting := self._first_move()) is not None:
                return waiting
        move = self.service("base").output("move_status")
        move_state = _state(move, self.move_id)
        if self.phase == "drive" and move_state == "done" and not self.final:
            self.phase, self.stopped = "look", self.context.now()
        if self.phase == "look":
            if not self._look():
                return BehaviorStatus(progress=self._progress(arm_state, 1.0), detail="looking again")
            move_state = None
        share = _share_done(move) if move_state else 0.0
        if "failed" in (move_state, arm_state):
            what = _failed("the move failed", move) if move_state == "failed" else "the arm failed"
            return BehaviorStatus(progress=self._progress(arm_state, share), failed=True, detail=what)
        done = move_state == "done" and arm_state == "reached" and self.final
        return BehaviorStatus(progress=1.0 if done else self._progress(arm_state, share), done=done)

    def _progress(self, arm_state: str | None, share: float) -> float:
        """0.2 for the arm, 0.8 for the share of the planned drive done (``share`` of the current move)."""
        driven = sum(self.legs[:-1]) + share * (self.legs[-1] if self.legs else 0.0)
        part = min(1.0, driven / self.planned) if self.planned > 0 else share
        return 0.8 * part + 0.2 * (arm_state == "reached")
