"""The dropped-object recovery's behavior kinds (plugins/behaviors/recovery.py, issue K point 3d)
against services simulated in memory: HALT cancels the navigation and stops the base; LOOK_FLOOR
counts a sighting only once the robot has stood still at a view, backs off first, turns between
views, backs off between rounds and gives up after its last view."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import pytest

import ckmconf
from ckmconf.model import Param, System
from runtime.kernel.interfaces import ParamError

from .test_usecase_behaviors import REPO, Rig

CYLINDER = {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "frame": "map",
            "x": 2.0, "y": 1.0, "z": 0.06, "reliability": 0.9, "sources": ["rgb", "depth"],
            "observer": [{"x": 1.5, "y": 1.2, "yaw": 0.3}]}  # fmt: skip


@pytest.fixture(scope="module")
def lab() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


def _done(rig: Rig, move: dict[str, Any]) -> None:
    rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": "done", "remaining": 0.0, "total": 1.0}


class _Changed:
    """The lab's behaviors, one of them with some Params changed (what Rig reads of a System)."""

    def __init__(self, lab: System, name: str, params: dict[str, str]) -> None:
        record = lab.behavior(name)
        assert record is not None
        given = {p.name: p for p in record.params}
        given.update({k: Param(name=k, value=v) for k, v in params.items()})
        self.record = dataclasses.replace(record, params=tuple(given.values()))

    def behavior(self, name: str) -> Any:
        return self.record


def _look(lab: System, **params: str) -> Rig:
    return Rig(_Changed(lab, "LOOK_FLOOR", params), "LOOK_FLOOR")  # type: ignore[arg-type]


def test_halt_cancels_the_navigation_goal_and_stops_the_base_with_a_zero_move(lab: System) -> None:
    rig = Rig(lab, "HALT")
    assert rig.services["nav"].configured[0][0] == {"goal": ""}  # the empty goal cancels it (amcl.py)
    move = rig.last("move")
    assert {k: move[k] for k in ("frame", "x", "y", "yaw")} == {"frame": "robot", "x": 0.0, "y": 0.0, "yaw": 0.0}
    assert not rig.behavior.step().done
    rig.services["base"].outputs["move_status"] = {"id": move["id"] - 1, "state": "done"}  # an older move's
    assert not rig.behavior.step().done
    _done(rig, move)
    assert rig.behavior.step().done
    rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": "failed"}
    assert rig.behavior.step().failed


def test_look_counts_a_sighting_only_after_settling_at_a_view(lab: System) -> None:
    rig = _look(lab, back="0")
    rig.inputs["objects"] = {"objects": [CYLINDER], "reliability": 0.9}  # seen while the robot was still turning
    rig.time = 2.0
    assert not rig.behavior.step().done  # under LOOK_FLOOR's settle time (2.5 s): the pose it was placed with is stale
    rig.time = 2.6
    status = rig.behavior.step()
    assert status.done
    target = rig.last("target")
    assert (target["label"], target["frame"], target["x"], target["y"]) == ("cylinder_red_stripes", "map", 2.0, 1.0)
    assert target["observer"] == CYLINDER["observer"]  # APPR places it with the pose it was seen from (D172)


def test_look_ignores_unreliable_sightings_and_other_objects(lab: System) -> None:
    rig = _look(lab, back="0")
    weak = {**CYLINDER, "reliability": 0.6}  # under LOOK_FLOOR's minReliability 0.8
    other = {**CYLINDER, "name": "cylinder_blue_dots", "texture": "blue_dots"}
    single = {**CYLINDER, "sources": ["rgb"]}  # under minSources 2
    rig.inputs["objects"] = {"objects": [weak, other, single]}
    rig.time = 3.0
    assert not rig.behavior.step().done


def test_look_backs_off_turns_between_views_and_between_rounds_and_fails_after_the_last(lab: System) -> None:
    rig = _look(lab, views="3", rounds="2", turn="0.7", settle="1", dwell="1", shift="0.3", back="0.2")
    moves: list[dict[str, Any]] = [rig.last("move")]  # backing off at once, before the first view
    rig.inputs["objects"] = {"objects": [CYLINDER], "reliability": 0.9}  # seen on the way back: not counted
    rig.time = 2.5
    assert not rig.behavior.step().done
    rig.inputs["objects"] = None
    _done(rig, moves[0])
    progress = []
    for _ in range(200):
        rig.time += 0.25
        status = rig.behavior.step()
        progress.append(status.progress)
        if status.failed:
            break
        move = next((v for n, v in reversed(rig.written) if n == "move"), None)
        if move is not None and (not moves or moves[-1]["id"] != move["id"]):
            moves.append(move)
            assert not rig.behavior.step().done  # waiting for the base
            _done(rig, move)
    else:
        pytest.fail("LOOK_FLOOR never gave up")
    assert [(m["x"], m["yaw"]) for m in moves] == [(-0.2, 0.0), (0.0, 0.7), (0.0, 0.7), (-0.3, 0.0), (0.0, 0.7),
                                                   (0.0, 0.7)]
    assert "not found in 6 views" in status.detail
    assert progress == sorted(progress)  # the share of views examined only grows


def test_look_looks_from_where_a_blocked_move_stopped_and_fails_after_two_in_a_row(lab: System) -> None:
    rig = _look(lab, settle="0", dwell="0", back="0")  # LOOK_FLOOR's blockedMoves: 2
    rig.time = 0.1

    def next_move(state: str) -> dict[str, Any]:
        rig.behavior.step()
        move: dict[str, Any] = rig.last("move")
        rig.services["base"].outputs["move_status"] = {"id": move["id"], "state": state}
        rig.time += 0.1
        return move

    move = next_move("failed")
    assert move["yaw"] == pytest.approx(0.7) and math.isclose(move["x"], 0.0)
    status = rig.behavior.step()  # blocked by a table: it looks from where the robot stopped
    assert not status.failed and not status.done
    assert rig.behavior.context.events[-1]["message"].startswith("the base could not move there")
    next_move("done")  # the next turn goes: the count starts again
    next_move("failed")
    assert not rig.behavior.step().failed
    next_move("failed")
    status = rig.behavior.step()
    assert status.failed and "2 moves failed in a row" in status.detail


def test_look_refuses_views_that_do_not_turn(lab: System) -> None:
    with pytest.raises(ParamError, match="'turn' must not be 0"):
        _look(lab, turn="0")


def test_look_looks_again_from_round_a_candidate_seen_by_its_shape_alone(lab: System) -> None:
    """A cylinder the depth recognition alone saw (no texture: its print faces away) 0.6 m ahead-left
    is looked at again from 0.5 rad round it, at the same distance and facing it, to either side of
    where the probes started in turn (one may be blocked: +0.5, then 1 rad back to -0.5, then 1 rad on
    to +0.5 again, D254); three times at most. The candidate is where the robot sees it from each probe:
    here the fused result does not change, so each move starts from the same view of it."""
    rig = _look(lab, back="0", settle="1", dwell="0", probe="0.5", probes="3", probeDistance="0")
    observer = {"x": 1.0, "y": 2.0, "yaw": 0.5}
    ahead, left = 0.5, 0.2  # the candidate in the robot's frame
    shape_only = {"name": "cylinder", "shape": "cylinder", "frame": "map", "reliability": 0.95, "sources": ["depth"],
                  "x": 1.0 + ahead * math.cos(0.5) - left * math.sin(0.5),
                  "y": 2.0 + ahead * math.sin(0.5) + left * math.cos(0.5), "observer": [observer]}  # fmt: skip
    blue = {**CYLINDER, "name": "cylinder_blue_dots", "texture": "blue_dots", "x": 1.3, "y": 2.1}  # told apart
    rig.inputs["objects"] = {"objects": [blue, shape_only]}
    moves = []
    for _ in range(4):
        rig.time += 1.1
        assert not rig.behavior.step().done
        moves.append(rig.last("move"))
        _done(rig, moves[-1])
        rig.time += 0.1
        rig.behavior.step()  # arrived: the next view starts
    probes, turn = moves[:3], moves[3]
    for move, angle in zip(probes, (0.5, -1.0, 1.0), strict=True):
        x, y, yaw = move["x"], move["y"], move["yaw"]
        assert math.dist((x, y), (ahead, left)) == pytest.approx(math.hypot(ahead, left))  # same distance
        assert math.atan2(left - y, ahead - x) == pytest.approx(yaw)  # facing it
        turned = math.remainder(math.atan2(-left, -ahead) - math.atan2(y - left, x - ahead), 2 * math.pi)
        assert turned == pytest.approx(-angle)  # round it, one side then the other
    assert (turn["x"], turn["y"], turn["yaw"]) == (0.0, 0.0, pytest.approx(0.7))  # then the search goes on


def test_look_probes_a_near_candidate_from_farther_off(lab: System) -> None:
    """D254: at 0.45 m the resting arm hides the print's band; probeDistance 0.7 takes the second look
    from 0.7 m, 0.5 rad round the candidate, facing it."""
    rig = _look(lab, back="0", settle="1", dwell="0", probe="0.5", probes="1", probeDistance="0.7")
    observer = {"x": 1.0, "y": 2.0, "yaw": 0.0}
    shape_only = {"name": "cylinder", "shape": "cylinder", "frame": "map", "reliability": 0.95, "sources": ["depth"],
                  "x": 1.45, "y": 2.0, "observer": [observer]}  # fmt: skip
    rig.inputs["objects"] = {"objects": [shape_only]}
    rig.time += 1.1
    rig.behavior.step()
    move = rig.last("move")
    x, y, yaw = move["x"], move["y"], move["yaw"]
    assert math.dist((x, y), (0.45, 0.0)) == pytest.approx(0.7)  # backed off to 0.7 m
    assert math.atan2(-y, 0.45 - x) == pytest.approx(yaw)  # facing it
    assert math.atan2(y, x - 0.45) == pytest.approx(-math.pi + 0.5)  # 0.5 rad round it (to the right)
