"""``behavior.pick-object`` and ``behavior.place-object``: general pick and place over the ``arm-motion``
and ``gripper`` interfaces (docs/interfaces.md, docs/manipulation.md), for any arm with a gripper
service of its own.

PICK: open the gripper, move the arm to ``approach``, then to ``grasp``, close the gripper (under
``effort``) until it holds the object, and move to ``lift``. PLACE: move to ``above``, then to
``place`` (reached too when the object set down on its support stops the arm short of it: the goal
asks ``"contact": true``), open the gripper, and move to ``retreat``. Each arm step is a named pose of the arm
service's pose file or a Cartesian target ``"x y z [pitch]"`` (m, rad, the robot's base frame).
Each goal carries a fresh id and only a status of that id ends its step, so a status left over from
an earlier goal (of this behavior or another) never advances one. Progress is the share of steps
done (eq. 5.1's behavior progress); a failure's detail names the step and the service's reason — an
arm target refused as unreachable, a gripper closing on nothing, a stalled jaw (D266). A pick naming
the environment Object it picks (Param ``object``) is refused by ``verify`` when the object is wider
than its gripper's full opening (:mod:`.grip_fit`, D296).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .grip_fit import fit_problems
from .messages import _Goals, _state

ARM_STEP = "A named pose of the arm service, or a target 'x y z [pitch]' (m, rad, base frame)."


@dataclass(frozen=True)
class _Step:
    """One goal of the sequence: to which service (``arm`` or ``gripper``), what, and its label."""

    service: str
    goal: Mapping[str, Any]
    label: str


def arm_step(owner: str, name: str, value: str) -> _Step:
    """The arm goal of Param ``name``: a pose name, or numbers ``x y z [pitch]``.

    Raises:
        ParamError: numbers that are not three or four finite ones.
    """
    words = value.split()
    if len(words) == 1 and not _number(words[0]):
        return _Step("arm", {"group": "arm", "pose": words[0]}, f"{name} ({words[0]})")
    try:
        numbers = [float(w) for w in words]
    except ValueError:
        numbers = []
    if len(numbers) not in (3, 4) or not all(math.isfinite(n) for n in numbers):
        raise ParamError(f"{owner}: parameter {name!r} = {value!r} is neither a pose name nor 'x y z [pitch]'")
    target = dict(zip(("x", "y", "z", "pitch"), numbers, strict=False))
    return _Step("arm", {"group": "arm", "target": target}, f"{name} ({value.strip()})")


def _number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


class _Manipulation(_Goals):
    """A sequence of arm goals and gripper commands, each sent once the previous one ended well."""

    USES = Uses(Use("arm", "arm-motion", "moves the arm to each pose or target"),
                Use("gripper", "gripper", "opens and closes on the object; its status says whether it holds it"))
    PORTS = Ports(outputs={"*": MAPPING})  # arm_goal (ArmGoal), gripper_command (GripperCommand)
    steps: list[_Step]

    def _open(self) -> _Step:
        share = self.params["opening"]
        command = {"action": "open"} if share >= 1.0 else {"action": "position", "position": share}
        return _Step("gripper", command, "open the gripper")

    def start(self) -> None:
        """Configure the services and send the first goal."""
        super().start()
        self.index = 0
        self.goal_id = self._next()

    def _next(self) -> int:
        step = self.steps[self.index]
        return self._send("arm_goal" if step.service == "arm" else "gripper_command", dict(step.goal))

    def step(self) -> BehaviorStatus:
        """Send each goal once the previous one ended as it should; failed, with the reason, if one did not."""
        step = self.steps[self.index]
        status = self.service(step.service).output("status")
        state = _state(status, self.goal_id)
        progress = self.index / len(self.steps)
        if state is None or state == "moving":
            return BehaviorStatus(progress=progress)
        problem = self._problem(step, state, status if isinstance(status, Mapping) else {})
        if problem:
            return BehaviorStatus(progress=progress, failed=True, detail=f"{step.label}: {problem}")
        self.index += 1
        if self.index == len(self.steps):
            return BehaviorStatus(progress=1.0, done=True)
        self.goal_id = self._next()
        return BehaviorStatus(progress=self.index / len(self.steps))

    def _problem(self, step: _Step, state: str, status: Mapping[str, Any]) -> str:
        """Why the ended step ``step`` did not end as it should ("" when it did)."""
        reason = str(status.get("error") or status.get("reason") or "")
        if state == "failed" or state == "stalled":
            return reason or state
        if step.service == "arm":
            return "" if state == "reached" else f"arm state {state!r}"
        if step.goal.get("action") == "close":
            if state != "holding":
                return "the gripper closed on nothing"
            opening = status.get("opening")
            limit = self.params.get("minHold", 0.0)
            if limit > 0 and isinstance(opening, int | float) and opening < limit:
                return f"holds the object at {opening:.2f} of the opening, under {limit:.2f}: closed across its edge"
            return ""
        return "" if state == "reached" else f"gripper state {state!r}"


class PickObject(_Manipulation):
    """``behavior.pick-object``: open, approach, grasp, close until holding, lift (see the module docstring)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("approach", REQUIRED, f"Where the open gripper goes first. {ARM_STEP}", type=str),
        P("grasp", REQUIRED, f"Where the gripper closes on the object. {ARM_STEP}", type=str),
        P("lift", REQUIRED, f"Where the held object is lifted to. {ARM_STEP}", type=str),
        P("effort", 0.0, "The closing command's max_effort (0: the gripper service's own force).", unit="N",
          min=0.0),
        P("opening", 1.0, "How far to open before the approach, as a share of the range (1: fully).",
          above=0.0, max=1.0),
        P("minHold", 0.0, "Least opening (share of the range) an object held must keep (0: any).", min=0.0,
          max=1.0),
        P("object", "", "The environment Object picked (empty: not named): verify checks that it is one of the "
          "map's and fits the full opening of the gripper service's jaw (D296)."),
    )

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """An ``object`` that is no Object of the map, or wider than the gripper's full opening."""
        return fit_problems(record, system)

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        close: dict[str, Any] = {"action": "close"}
        if self.params["effort"] > 0:
            close["max_effort"] = self.params["effort"]
        self.steps = [self._open(), arm_step(self.owner, "approach", self.params["approach"]),
                      arm_step(self.owner, "grasp", self.params["grasp"]),
                      _Step("gripper", close, "close the gripper"),
                      arm_step(self.owner, "lift", self.params["lift"])]


class PlaceObject(_Manipulation):
    """``behavior.place-object``: above, place, open, retreat (see the module docstring); it fails at
    once when the gripper service's ``holding`` measure says it holds nothing (before it is set down)."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("above", REQUIRED, f"Where the held object is brought first. {ARM_STEP}", type=str),
        P("place", REQUIRED, f"Where the object is set down. {ARM_STEP}", type=str),
        P("retreat", REQUIRED, f"Where the open gripper withdraws to. {ARM_STEP}", type=str),
        P("opening", 1.0, "How far to open to let the object go, as a share of the range (1: fully).",
          above=0.0, max=1.0),
    )

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        down = arm_step(self.owner, "place", self.params["place"])
        down = _Step("arm", {**down.goal, "contact": True}, down.label)  # the object may stand before the target
        self.steps = [arm_step(self.owner, "above", self.params["above"]), down, self._open(),
                      arm_step(self.owner, "retreat", self.params["retreat"])]

    def step(self) -> BehaviorStatus:
        """As the sequence, but failed while bringing the object over when the gripper holds nothing."""
        if self.index < 2 and self.service("gripper").measures().get("holding") == 0:
            return BehaviorStatus(progress=0.0, failed=True, detail="the gripper holds nothing to place")
        return super().step()
