"""DOCK (ours, docs/decisions.md D196): the base to a known map pose.

ObjectPlace (Fig. 7.12) puts the object down on the drop table; the navigation arrives within its
tolerance (0.15 m) of a goal kept clear of the table's planning margin, so the arm's place pose
would reach the table's edge or miss it. DOCK turns the map pose ``pose`` into a relative move with
the latest pose estimate (its ``pose`` input, ``/nav/pose``: a few centimetres off) and sends it to
MobileBase.Displacement, which drives it on odometry — as APPR does with the camera's measurement.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.kernel.interfaces import ParamError
from runtime.missions.behaviors import BehaviorContext, BehaviorStatus
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
