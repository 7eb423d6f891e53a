"""PanTiltCamera.Track and Nao.NaoQi (Table 7.2, §7.3.2 OBJ_TRACK) against the real pybullet Nao: the
head centres a target, follows it when it moves, and the target's map position is within 10 cm, in
a test room and in the use case's laboratory."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pybullet as p
import pytest

from ckmconf.loader import load
from plugins.sim.robots import Robot
from plugins.sim.world import World
from tests.conftest import CONFIGS
from tests.plugins.sim.conftest import ROOM, add_box, robot

from .head_loop import HeadLoop

NAO = (1.0, 2.0, 0.3)
BLUE = (0, 0, 255)
HEIGHT = 0.3  # the target's centre above the floor: the plane its viewing ray is intersected with


@pytest.fixture
def world() -> Iterator[World]:
    made = World(ROOM, seed=2)
    yield made
    made.close()


def _offset(loop: HeadLoop) -> float:
    return float(loop.results[-1]["track"]["error"])


def test_the_head_centres_the_target_then_follows_it_and_places_it_on_the_map(world: World) -> None:
    nao = robot(world, "nao", NAO)
    target = add_box(world, (2.6, 1.92, HEIGHT), 0.04, [0.0, 0.0, 1.0, 1.0])  # 0.35 rad right of the head
    loop = HeadLoop(world, nao, NAO, planeHeight=HEIGHT)
    try:
        loop.run(6.0, BLUE, "blue_box")
        first = loop.results[0]["track"]
        assert first["in_view"] and first["error"] > 0.3  # it starts well off centre
        track = loop.results[-1]["track"]
        assert track["in_view"] and track["label"] == "blue_box" and track["moving"]
        assert loop.results[-1]["moving"] == 1
        assert _offset(loop) < 0.03  # centred (D90: 0.02 rad, plus a pixel of the QVGA detector)
        placed = loop.results[-1]["target"]
        assert placed["frame"] == "map" and placed["label"] == "blue_box"
        assert math.dist((placed["x"], placed["y"]), (2.6, 1.92)) < 0.10
        assert placed["z"] == pytest.approx(HEIGHT)
        # the speed Parameter (0.5 rad/s at one frame per 0.5 s) bounds each goal's step
        steps = [max(abs(b["pan"] - a["pan"]), abs(b["tilt"] - a["tilt"]))
                 for a, b in zip(loop.goals, loop.goals[1:], strict=False)]
        assert max(steps) <= 0.25 + 1e-9
        # the object slides 0.6 m to the left at 0.1 m/s: the head follows it
        start = len(loop.results)
        for k in range(12):
            y = 1.92 + 0.05 * (k + 1)
            p.resetBasePositionAndOrientation(target, (2.6, y, HEIGHT), (0, 0, 0, 1), physicsClientId=world.client)
            loop.run(0.5, BLUE, "blue_box")
        during = [r["track"]["error"] for r in loop.results[start:]]
        assert all(r["track"]["in_view"] for r in loop.results[start:])
        assert max(during) < 0.15
        loop.run(3.0, BLUE, "blue_box")
        assert _offset(loop) < 0.03
        placed = loop.results[-1]["target"]
        assert math.dist((placed["x"], placed["y"]), (2.6, 2.52)) < 0.10
        pan = loop.angles()[0]
        assert pan == pytest.approx(math.atan2(2.52 - 2.0, 1.6) - NAO[2], abs=0.05)
    finally:
        loop.close()


def test_the_head_holds_and_moving_drops_when_the_target_leaves_the_view(world: World) -> None:
    nao = robot(world, "nao", NAO)
    target = add_box(world, (2.6, 2.4, HEIGHT), 0.04, [0.0, 0.0, 1.0, 1.0])
    loop = HeadLoop(world, nao, NAO, planeHeight=HEIGHT)
    try:
        loop.run(3.0, BLUE, "blue_box")
        assert loop.results[-1]["moving"] == 1
        held = loop.angles()
        p.resetBasePositionAndOrientation(target, (0.3, 3.5, HEIGHT), (0, 0, 0, 1), physicsClientId=world.client)
        loop.run(2.0, BLUE, "blue_box")
        assert loop.results[-1]["moving"] == 0
        assert loop.results[-1]["track"]["in_view"] is False
        assert "head_goal" not in loop.results[-1] and "target" not in loop.results[-1]
        assert max(abs(a - b) for a, b in zip(loop.angles(), held, strict=True)) < 0.02  # the head stays put
    finally:
        loop.close()


def test_in_the_use_case_lab_the_nao_fixes_a_workbench_object_and_places_it_on_the_map() -> None:
    """The Nao at its nodes.xml pose in the environment.xml laboratory, the object's height from the
    environment model (Param ``environment``, D114), 2.1 m away on the workbench."""
    environment = load(CONFIGS / "usecase" / "environment.xml").environment
    with World(environment, seed=1) as lab:
        pose = (5.55, 5.15, 0.36)
        nao = Robot(lab, "nao", lab.load_robot("nao", "nao", pose))
        box = lab.objects["box_orange"]
        # painted a colour nothing else in the lab has, for the stand-in detector
        p.changeVisualShape(box, -1, rgbaColor=[0.0, 0.0, 1.0, 1.0], physicsClientId=lab.client)
        loop = HeadLoop(lab, nao, pose, environment="environment.xml")
        try:
            loop.run(4.0, BLUE, "box_orange")
            assert _offset(loop) < 0.03
            placed = loop.results[-1]["target"]
            truth = lab.pose(box)[0]
            assert placed["z"] == pytest.approx(0.35)  # the workbench top 0.30 m plus half the 0.10 m box
            assert math.dist((placed["x"], placed["y"]), truth[:2]) < 0.10
        finally:
            loop.close()
