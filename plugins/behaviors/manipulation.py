"""Manipulation behaviors over the ``arm-motion`` and ``base-drive`` interfaces (docs/interfaces.md).

``pick`` / ``place`` send a sequence of named arm and gripper poses, each after the previous one is
reached; ``back-off`` moves the base backwards. Goals carry a fresh ``id`` and are followed by it, so a
status of an earlier goal never ends one of these.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .messages import _failed, _Goals, _share_done, _state


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
                              done=state == "done", failed=state == "failed",
                              detail=_failed("the backwards move failed", status) if state == "failed" else "")
