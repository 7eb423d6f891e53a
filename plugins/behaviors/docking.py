"""Docking behaviors. ``dock-robot`` and ``undock-robot`` send one goal to a ``docking`` service
(docs/interfaces.md) and follow its id, as Nav2's DockRobot and UndockRobot nodes do; ``dock`` below
is the lab's simpler DOCK, a single base-drive move.

DOCK (ours, docs/decisions.md D196): the base to a known map pose.

ObjectPlace (Fig. 7.12) puts the object down on the drop table; the navigation arrives within its
tolerance (0.15 m) of a goal kept clear of the table's planning margin, so the arm's place pose
would reach the table's edge or miss it. DOCK turns the map pose ``pose`` into a relative move with
the latest pose estimate (its ``pose`` input, ``/nav/pose``: a few centimetres off) and sends it to
MobileBase.Displacement, which drives it on odometry — as APPR does with the camera's measurement.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
from runtime.verification.entries import Entries
from runtime.verification.interfaces import Use, Uses
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

from .messages import _failed, _Goals, _share_done, _state, robot_pose


def _map_pose(text: str, owner: str) -> tuple[float, float, float]:
    try:
        x, y, yaw = (float(v) for v in text.split())
    except ValueError:
        raise ParamError(f"{owner}: parameter 'pose' = {text!r} is not 'x y yaw' (m, m, rad)") from None
    return x, y, yaw


class Dock(_Goals):
    """DOCK: the base to the map pose ``pose``, placed relative to the robot by its pose estimate."""

    USES = Uses(Use("base", "base-drive", "drives to the docking pose"))

    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("pose", REQUIRED, "Map pose to end at: 'x y yaw' (m, m, rad).", type=str, numbers=(3,), form="'x y yaw'"),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        self.goal = _map_pose(str(self.params["pose"]), self.owner)  # a bad pose is refused when built

    def start(self) -> None:
        """Forget the last move; the next is sent once a pose estimate is read."""
        super().start()
        self.move_id: int | None = None

    def step(self) -> BehaviorStatus:
        """Send the move from the latest estimate, then follow it; done when the base reports it done."""
        if self.move_id is None:
            pose = robot_pose(self.read("pose")) if "pose" in self.context.inputs else None
            if pose is None:
                return BehaviorStatus(progress=0.0, detail="waiting for the pose estimate")
            px, py, pyaw = pose
            dx, dy = self.goal[0] - px, self.goal[1] - py
            c, s = math.cos(pyaw), math.sin(pyaw)
            turn = math.atan2(math.sin(self.goal[2] - pyaw), math.cos(self.goal[2] - pyaw))
            move = {"frame": "robot", "x": c * dx + s * dy, "y": -s * dx + c * dy, "yaw": turn}
            self.context.log("dock", goal=" ".join(f"{v:.3f}" for v in self.goal), move=move)
            self.move_id = self._send("move", move)
        status = self.service("base").output("move_status")
        state = _state(status, self.move_id)
        return BehaviorStatus(progress=1.0 if state == "done" else _share_done(status) if state else 0.0,
                              done=state == "done", failed=state == "failed",
                              detail=_failed("the docking move failed", status) if state == "failed" else "")


DOCKING = Uses(Use("dock", "docking", "docks the base and reports the goal's status"))
DOCKING_KIND = "docking"
_DOCKS = Entries("x y yaw", count=3, numbers=True)


def _docking_plugin(record: BehaviorRecord, system: System) -> tuple[str, Plugin] | None:
    """The service the behavior uses as ``dock`` and its docking plugin, when it has exactly one."""
    use = next((u for u in record.uses if u.alias == "dock"), None)
    if use is None or "." not in use.service:
        return None
    resource_name, service_name = use.service.split(".", 1)
    resource = system.resource(resource_name)
    service = next((s for s in resource.services if s.name == service_name), None) if resource else None
    if resource is None or service is None:
        return None
    profiles = {scenario.profile for scenario in service.scenarios}
    outputs = {profile.output_plugin() for profile in resource.profiles if profile.name in profiles}
    found = [plugin for plugin in resource.plugins if plugin.name in outputs and plugin.kind == DOCKING_KIND]
    return (use.service, found[0]) if len(found) == 1 else None


def dock_problems(record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
    """``dock`` or ``pose``, one of them; a ``dock`` the docking service it uses does not know (D307)."""
    params = {p.name: p for p in record.params}
    dock, pose = params.get("dock"), params.get("pose")
    name = dock.value.strip() if dock is not None else ""
    if bool(name) == bool(pose is not None and pose.value.strip()):
        return [(dock or pose or record, "give the dock's name ('dock') or its docked pose ('pose'), one of them")]
    used = _docking_plugin(record, system) if name and system is not None else None
    if used is None:
        return []
    service, plugin = used
    text = next((p.value for p in plugin.params if p.name == "docks"), "")
    try:
        docks = list(_DOCKS.parse(text, "docks")) if text.strip() else []
    except ParamError:
        return []  # the docking plugin's own Param check reports its docks
    if name in docks:
        return []
    close = difflib.get_close_matches(name, docks, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return [(dock, f"parameter 'dock' = {name!r} is no dock of the docking service {service} "
                   f"(its docks: {', '.join(docks) or 'none'}){hint}")]


class DockRobot(_Goals):
    """Docks at the dock named ``dock`` (one the docking service knows) or at the map pose ``pose``."""

    USES = DOCKING
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("dock", "", "The dock's name among the docking service's docks (or give 'pose').", type=str),
        P("pose", "", "The docked pose on the map, 'x y yaw' (m, m, rad), for a dock the service does not name.",
          type=str, numbers=(3,), form="'x y yaw'"),
    )
    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})
    action, until = "dock", "docked"

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """A dock by name or by pose, and a name the docking service knows."""
        return dock_problems(record, system) if cls.action == "dock" else []

    def __init__(self, record: BehaviorRecord, context: BehaviorContext) -> None:
        super().__init__(record, context)
        problems = self.problems(record, None)
        if problems:
            raise ParamError(f"{self.owner}: {problems[0][1]}")

    def start(self) -> None:
        """Forget the last goal; the goal is sent at the first step."""
        super().start()
        self.goal_id: int | None = None

    def _goal(self) -> dict[str, Any]:
        if self.params["pose"]:
            x, y, yaw = _map_pose(str(self.params["pose"]), self.owner)
            return {"action": "dock", "dock": "", "x": x, "y": y, "yaw": yaw}
        return {"action": "dock", "dock": str(self.params["dock"]), "x": 0.0, "y": 0.0, "yaw": 0.0}

    def step(self) -> BehaviorStatus:
        """Send the goal once, then follow its status by id; progress by the approach's stage."""
        if self.goal_id is None:
            goal = self._goal()
            self.context.log(self.action, **{k: v for k, v in goal.items() if k != "action"})
            self.goal_id = self._send("dock_goal", goal)
        status = self.service("dock").output("status")
        state = _state(status, self.goal_id)
        progress = {"staging": 0.3, "docking": 0.7, "undocking": 0.5}.get(state or "", 0.0)
        return BehaviorStatus(progress=1.0 if state == self.until else progress, done=state == self.until,
                              failed=state == "failed",
                              detail=_failed(f"the {self.action}ing failed", status) if state == "failed" else "")


class UndockRobot(DockRobot):
    """Backs out of the dock it stands at, the docking service's staging distance."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params()
    action, until = "undock", "undocked"

    def _goal(self) -> dict[str, Any]:
        return {"action": "undock", "dock": "", "x": 0.0, "y": 0.0, "yaw": 0.0}
