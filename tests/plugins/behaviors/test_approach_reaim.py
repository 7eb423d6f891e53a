"""APPR's re-aim (D207) against services simulated in memory: when it stops short, which sighting it
takes the last leg from, what it does when none comes, and what it leaves as it was; APPR_FLOOR's turn
to face the object first and its aim at the depth shape's centre (D253)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from runtime.missions.behaviors import BehaviorStatus
from tests.plugins.behaviors.test_usecase_behaviors import Rig

REPO = Path(__file__).resolve().parents[3]
STANDOFF, REAIM = 0.29, 0.16  # APPR's standoff and reaim in configs/usecase/behaviors.xml
LABEL = "cylinder_red_stripes"
HERE = {"x": 2.0, "y": 2.0, "yaw": math.pi / 2}  # the robot's pose estimate: facing +y


@pytest.fixture(scope="module")
def lab() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


class Appr(Rig):
    """APPR of the use case with its services in memory and a clock; the arm already reached."""

    def __init__(self, system: System, target: dict[str, Any], objects: dict[str, Any] | None,
                 name: str = "APPR") -> None:
        super().__init__(system, name, {"target": target, "pose": {"pose": dict(HERE)}, "objects": objects})
        arm = next(v for n, v in self.written if n == "arm_goal")
        self.services["arm"].outputs["status"] = {"id": arm["id"], "state": "reached"}

    def moves(self) -> list[dict[str, Any]]:
        return [v for n, v in self.written if n == "move"]

    def finish_move(self) -> BehaviorStatus:
        self.services["base"].outputs["move_status"] = {"id": self.moves()[-1]["id"], "state": "done"}
        return self.behavior.step()

    def wait(self, seconds: float) -> BehaviorStatus:
        end = self.time + seconds
        status = self.behavior.step()
        while self.time < end - 1e-9:
            self.time += 0.1
            status = self.behavior.step()
        return status


def _sighting(x: float, y: float, observer: dict[str, float], name: str = LABEL,
              centre: tuple[float, float] | None = None) -> dict[str, Any]:
    """A fused result holding one positioned sighting (map frame) placed with ``observer``; ``centre``:
    where its depth source saw the solid's centre."""
    found = {"name": name, "shape": "cylinder", "texture": "red_stripes", "frame": "map", "x": x, "y": y, "z": 0.36,
             "reliability": 0.99, "sources": ["depth", "rgb"], "observer": [dict(observer)],
             "centre": None if centre is None else [*centre, 0.06]}  # fmt: skip
    return {"objects": [found], "reliability": 0.99}


def _target(distance: float) -> dict[str, Any]:
    """SPOT's target ``distance`` m straight ahead of HERE, placed with HERE."""
    return {"label": LABEL, "frame": "map", "x": 2.0, "y": 2.0 + distance, "z": 0.36, "reliability": 0.99,
            "observer": [dict(HERE)]}  # fmt: skip


def test_a_long_drive_stops_short_and_takes_the_last_leg_from_a_fresh_sighting(lab: System) -> None:
    seen = _sighting(2.0, 2.7, HERE)  # what the fusion holds when APPR starts
    rig = Appr(lab, _target(0.7), seen)
    rig.behavior.step()
    (short,) = rig.moves()
    assert (short["x"], short["y"], short["yaw"]) == pytest.approx((0.7 - STANDOFF - REAIM, 0.0, 0.0), abs=1e-9)
    status = rig.finish_move()
    assert not status.done and status.detail == "looking again"
    assert status.progress == pytest.approx(0.2 + 0.8 * (0.7 - STANDOFF - REAIM) / (0.7 - STANDOFF))
    # the robot stands 0.25 m further on, turned 0.02 rad; the estimate follows
    stopped = {"x": 2.0, "y": 2.25, "yaw": math.pi / 2 + 0.02}
    rig.inputs["pose"] = {"pose": stopped}
    rig.inputs["objects"] = _sighting(1.99, 2.70, {"x": 2.0, "y": 2.0, "yaw": math.pi / 2})  # from before the stop
    assert rig.wait(3.0).detail == "looking again" and len(rig.moves()) == 1  # settling, then not placed from here
    rig.inputs["objects"] = _sighting(1.99, 2.70, stopped)  # a fresh one: the target 1 cm aside of the first
    rig.behavior.step()
    last = rig.moves()[-1]
    dx, dy = -0.01, 0.45  # the target from where the robot stands, in the map
    c, s = math.cos(stopped["yaw"]), math.sin(stopped["yaw"])
    x, y = c * dx + s * dy, -s * dx + c * dy
    keep = (math.hypot(x, y) - STANDOFF) / math.hypot(x, y)
    assert (last["x"], last["y"], last["yaw"]) == pytest.approx((x * keep, y * keep, math.atan2(y, x)), abs=1e-9)
    assert rig.behavior.context.events == [{"message": "re-aimed", "x": round(x, 4), "y": round(y, 4)}]
    assert rig.finish_move().done


def test_no_fresh_sighting_in_time_goes_straight_on(lab: System) -> None:
    seen = _sighting(2.0, 2.7, HERE)
    rig = Appr(lab, _target(0.7), seen)
    rig.behavior.step()
    rig.finish_move()
    assert rig.wait(2.5 + 5.0 - 0.2).detail == "looking again"  # the fusion's result never changes
    rig.wait(0.3)
    last = rig.moves()[-1]
    assert (last["x"], last["y"], last["yaw"]) == pytest.approx((REAIM, 0.0, 0.0), abs=1e-9)
    assert rig.behavior.context.events == [{"message": "no fresh sighting: straight on", "distance": REAIM}]
    assert rig.finish_move().done


@pytest.mark.parametrize(
    ("distance", "objects"),
    [
        (0.6, _sighting(2.0, 2.6, HERE)),  # NAV's goal, 0.31 m to drive: shorter than reaimAbove
        (0.7, None),  # no fused result to look again with
        (0.7, _sighting(2.0, 2.7, HERE, name="cylinder_blue_dots")),  # the fusion does not hold the target
    ],
)
def test_a_short_drive_or_no_sighting_of_the_target_is_one_move(
    lab: System, distance: float, objects: dict[str, Any] | None
) -> None:
    rig = Appr(lab, _target(distance), objects)
    rig.behavior.step()
    (move,) = rig.moves()
    assert (move["x"], move["y"], move["yaw"]) == pytest.approx((distance - STANDOFF, 0.0, 0.0), abs=1e-9)
    assert rig.finish_move().done and rig.behavior.context.events == []


FLOOR_STANDOFF = 0.31  # APPR_FLOOR's standoff in configs/usecase/behaviors.xml


def _in_robot(dx: float, dy: float, yaw: float) -> tuple[float, float]:
    """A map offset (dx, dy) in the frame of a robot heading ``yaw``."""
    return math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy


def test_the_floor_approach_faces_the_object_looks_again_and_aims_at_the_shape_centre(lab: System) -> None:
    """D253: a turn on the spot first, then each leg from a fresh sighting's centre, not its fused point."""
    bearing = 0.5  # the object 0.8 m away, 0.5 rad left of the heading
    target: dict[str, Any] = {"label": LABEL, "frame": "map", "x": 2.0 - 0.8 * math.sin(bearing),
                              "y": 2.0 + 0.8 * math.cos(bearing), "z": 0.06, "reliability": 0.99,
                              "observer": [dict(HERE)]}  # fmt: skip
    rig = Appr(lab, target, _sighting(target["x"], target["y"], HERE), name="APPR_FLOOR")
    rig.behavior.step()
    (turn,) = rig.moves()
    assert (turn["x"], turn["y"], turn["yaw"], turn["yaw_tolerance"]) == pytest.approx((0.0, 0.0, bearing, 0.01))
    assert rig.finish_move().detail == "looking again"
    # the odometry turned 0.04 rad too far; the fused point leans 2 cm aside of the depth shape's centre
    turned = {"x": 2.0, "y": 2.0, "yaw": math.pi / 2 + bearing + 0.04}
    rig.inputs["pose"] = {"pose": turned}
    assert rig.wait(2.6).detail == "looking again"  # settled: a sighting made from now on counts
    centre = (target["x"] + 0.005, target["y"] + 0.003)
    rig.inputs["objects"] = _sighting(centre[0] - 0.02, centre[1], turned, centre=centre)
    rig.behavior.step()
    short = rig.moves()[-1]
    x, y = _in_robot(centre[0] - 2.0, centre[1] - 2.0, turned["yaw"])
    keep = (math.hypot(x, y) - FLOOR_STANDOFF - REAIM) / math.hypot(x, y)  # 0.49 m to drive: over reaimAbove
    assert (short["x"], short["y"], short["yaw"]) == pytest.approx((x * keep, y * keep, math.atan2(y, x)), abs=1e-9)
    assert rig.finish_move().detail == "looking again"
    stopped = {"x": 2.0 + (centre[0] - 2.0) * keep, "y": 2.0 + (centre[1] - 2.0) * keep,
               "yaw": math.atan2(centre[1] - 2.0, centre[0] - 2.0)}  # where the short move took it  # fmt: skip
    rig.inputs["pose"] = {"pose": stopped}
    rig.wait(2.6)
    rig.inputs["objects"] = _sighting(centre[0] + 0.015, centre[1], stopped, centre=centre)
    rig.behavior.step()
    last = rig.moves()[-1]
    x, y = _in_robot(centre[0] - stopped["x"], centre[1] - stopped["y"], stopped["yaw"])
    keep = (math.hypot(x, y) - FLOOR_STANDOFF) / math.hypot(x, y)
    assert (last["x"], last["y"], last["yaw"]) == pytest.approx((x * keep, y * keep, math.atan2(y, x)), abs=1e-9)
    assert [e["message"] for e in rig.behavior.context.events] == ["re-aimed", "re-aimed"]
    assert rig.finish_move().done and len(rig.moves()) == 3


def test_the_floor_approach_without_a_centre_or_a_fresh_sighting(lab: System) -> None:
    """A sighting with no 3D source aims at the fused point; none at all after the turn: straight on."""
    target = {"label": LABEL, "frame": "map", "x": 1.7, "y": 2.4, "z": 0.06, "reliability": 0.99,
              "observer": [dict(HERE)]}  # fmt: skip
    rig = Appr(lab, target, _sighting(1.7, 2.4, HERE), name="APPR_FLOOR")
    rig.behavior.step()
    (turn,) = rig.moves()
    assert (turn["x"], turn["y"]) == (0.0, 0.0) and turn["yaw"] == pytest.approx(math.atan2(0.3, 0.4))
    rig.finish_move()
    rig.wait(2.5 + 5.0 + 0.1)  # the fusion's result never changes: straight on, 0.5 m less the standoff
    (_, last) = rig.moves()
    assert (last["x"], last["y"], last["yaw"]) == pytest.approx((0.5 - FLOOR_STANDOFF, 0.0, 0.0), abs=1e-9)
    assert rig.behavior.context.events == [{"message": "no fresh sighting: straight on",
                                            "distance": round(0.5 - FLOOR_STANDOFF, 4)}]  # fmt: skip
    assert rig.finish_move().done
    rig = Appr(lab, target, _sighting(1.7, 2.4, HERE), name="APPR_FLOOR")
    rig.behavior.step()
    rig.finish_move()
    turned = {"x": 2.0, "y": 2.0, "yaw": math.pi / 2 + math.atan2(0.3, 0.4)}
    rig.inputs["pose"] = {"pose": turned}
    rig.wait(2.6)
    rig.inputs["objects"] = _sighting(1.69, 2.41, turned)  # no centre: the fused point
    rig.behavior.step()
    x, y = _in_robot(1.69 - 2.0, 2.41 - 2.0, turned["yaw"])
    keep = (math.hypot(x, y) - FLOOR_STANDOFF) / math.hypot(x, y)
    last = rig.moves()[-1]
    assert (last["x"], last["y"]) == pytest.approx((x * keep, y * keep), abs=1e-9)


def test_a_floor_target_straight_ahead_needs_no_turn(lab: System) -> None:
    rig = Appr(lab, _target(0.6), _sighting(2.0, 2.6, HERE), name="APPR_FLOOR")
    rig.behavior.step()
    (move,) = rig.moves()  # 0.29 m to drive: one move, no turn and no stop short
    assert (move["x"], move["y"], move["yaw"]) == pytest.approx((0.6 - FLOOR_STANDOFF, 0.0, 0.0), abs=1e-9)
    assert rig.finish_move().done
