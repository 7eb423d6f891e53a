"""World disturbances (issue K point 3, D178): the shipped scenarios of ``ckm-bench mission --scenario``
fire in the pybullet laboratory (the world in-process, a few simulated seconds) and do what they say;
bad scenarios are refused at FILE:LINE:COL; a render worker's mirror built from the same plan holds
the scenario's bodies with the same ids."""

from __future__ import annotations

import math
import pickle
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

import ckmconf
from plugins.sim.disturbances import PARK, Disturbances, DisturbedPlan, Fired
from plugins.sim.plan import WorldPlan
from plugins.sim.render import restore, snapshot
from plugins.sim.robots import Robot
from plugins.sim.scenario import ScenarioError, parse, read
from plugins.sim.sensors import Lidar
from plugins.sim.world import World
from tests.conftest import REPO

LAB = REPO / "configs" / "usecase" / "lab.xml"
SCENARIOS = REPO / "benchmarks" / "scenarios"
START = (1.5, 1.5, 0.785)


@pytest.fixture(scope="module")
def environment() -> object:
    system = ckmconf.load(LAB)
    assert system.environment is not None
    return system.environment


@pytest.fixture
def lab(environment: object) -> Iterator[World]:
    world = World(environment, seed=1)  # type: ignore[arg-type]
    world.load_robot("turtlebot", "turtlebot", START)
    yield world
    world.close()


def _place(world: World, name: str, x: float, y: float, yaw: float) -> None:
    body = world.robots[name]
    z = world.pose(body)[0][2]
    p.resetBasePositionAndOrientation(body, [x, y, z], p.getQuaternionFromEuler([0, 0, yaw]),
                                      physicsClientId=world.client)  # fmt: skip


def _install(world: World, name: str) -> list[Fired]:
    fired: list[Fired] = []
    Disturbances(read(SCENARIOS / f"{name}.scenario"), fired.append).install(world)
    return fired


def test_blocked_path_drops_a_crate_ahead_of_the_turtlebot_that_its_scan_sees(lab: World) -> None:
    fired = _install(lab, "blocked-path")
    robot = Robot(lab, "turtlebot", lab.robots["turtlebot"])
    lidar = Lidar(robot, "hokuyo_link", beams=181, fov=math.pi, range_min=0.02, range_max=5.6, noise=0.0)

    def ahead() -> float:
        return float(lidar.scan()[90])  # the beam straight ahead

    lab.step(240)
    assert fired == [] and ahead() > 1.5  # nothing ahead at the start
    _place(lab, "turtlebot", 2.7, 2.4, 0.6)  # on its way to the workbench, 1.5 m from the start
    lab.step(240)  # 1 s: the crate lands and settles
    assert [f.body for f in fired] == ["crate"]
    x, y, z = fired[0].position
    assert math.hypot(x - (2.7 + 1.2 * math.cos(0.6)), y - (2.4 + 1.2 * math.sin(0.6))) < 0.02
    assert z == pytest.approx(0.25, abs=0.01)
    assert 0.75 < ahead() < 1.0  # the crate's near face, about 1.2 − 0.25 m ahead of the base
    lab.step(240)
    assert len(fired) == 1  # an event fires once


def test_moved_object_shifts_the_cylinder_once_the_turtlebot_is_close(lab: World) -> None:
    fired = _install(lab, "moved-object")
    cylinder = lab.objects["cylinder_red_stripes"]
    before = lab.pose(cylinder)[0]
    _place(lab, "turtlebot", before[0], before[1] - 0.75, math.pi / 2)  # NAV's stop: 0.6 m clear
    lab.step(240)
    assert fired == []
    _place(lab, "turtlebot", before[0], before[1] - 0.45, math.pi / 2)  # APPR closing in (0.41 m from its side)
    lab.step(480)  # 2 s: it stands where it was put, on the workbench
    assert len(fired) == 1
    after = lab.pose(cylinder)[0]
    assert (after[0] - before[0], after[1] - before[1]) == pytest.approx((0.05, 0.03), abs=0.005)
    assert after[2] == pytest.approx(before[2], abs=0.01)


def test_dropped_object_falls_from_the_gripper_to_the_floor_on_the_way_home(lab: World) -> None:
    fired = _install(lab, "dropped-object")
    cylinder, turtlebot = lab.objects["cylinder_red_stripes"], lab.robots["turtlebot"]
    _place(lab, "turtlebot", 7.6, 5.3, math.pi / 2)  # at the workbench, the cylinder within reach
    lab.step(240)
    assert fired == []  # close to the workbench: not carried yet
    # Carried: held to the wrist by a fixed constraint, as the gripper's grasp holds it (D187).
    _place(lab, "turtlebot", 5.0, 4.5, -2.4)
    (rx, ry, _), _ = lab.pose(turtlebot)
    robot = Robot(lab, "turtlebot", turtlebot)
    wrist = robot.link("arm_wrist_flex_link")
    (wx, wy, wz), wrist_orientation = robot.link_pose(wrist)
    p.resetBasePositionAndOrientation(cylinder, [wx, wy, wz], [0, 0, 0, 1], physicsClientId=lab.client)
    inverse = p.invertTransform([wx, wy, wz], wrist_orientation)
    offset, turn = p.multiplyTransforms(*inverse, [wx, wy, wz], [0, 0, 0, 1])
    grasp = p.createConstraint(turtlebot, wrist, cylinder, -1, p.JOINT_FIXED, [0, 0, 0], offset, [0, 0, 0],
                               parentFrameOrientation=turn, physicsClientId=lab.client)  # fmt: skip
    lab.step(480)
    assert [f.body for f in fired] == ["cylinder_red_stripes"]
    assert p.getNumConstraints(physicsClientId=lab.client) == 0, grasp  # the grasp let go
    x, y, z = lab.pose(cylinder)[0]
    heading = -2.4
    expected = (
        rx + 0.35 * math.cos(heading) - 0.3 * math.sin(heading),
        ry + 0.35 * math.sin(heading) + 0.3 * math.cos(heading),
    )
    assert math.hypot(x - expected[0], y - expected[1]) < 0.06  # the base settles a few cm after the teleport
    assert z == pytest.approx(0.06, abs=0.01)  # standing on the floor (12 cm tall)


def test_of_start_measures_from_where_the_body_stood_when_the_world_was_built(environment: object) -> None:
    """D209: ``of start`` follows the layout (the compact copy starts the Turtlebot at (6.3, 4.6), 5.8 m
    from the lab's start): nothing fires there at the start, the crate lands once it has gone 1.5 m."""
    world = World(environment, seed=1)  # type: ignore[arg-type]
    try:
        world.load_robot("turtlebot", "turtlebot", (6.3, 4.6, 0.785))
        fired = _install(world, "blocked-path")
        world.step(240)
        assert fired == []  # "beyond 1.5 of point 1.5 1.5" had dropped the crate here at once
        _place(world, "turtlebot", 6.3, 3.3, -1.57)
        world.step(240)
        assert fired == []  # 1.3 m from its start
        _place(world, "turtlebot", 6.3, 2.9, -1.57)
        world.step(240)
        assert [f.body for f in fired] == ["crate"]
        x, y, _ = fired[0].position
        assert math.hypot(x - 6.3, y - (2.9 - 1.2)) < 0.05  # 1.2 m ahead of it
    finally:
        world.close()


def test_start_is_a_keyword_not_a_body_name() -> None:
    with pytest.raises(ScenarioError, match=r"s.scenario:1:14: the new box.s name must be a name, not .start."):
        parse("at 1 add box start 1 1 1 at 2 2", "s.scenario")


def test_remove_and_move_to_and_time_triggers(lab: World) -> None:
    fired: list[Fired] = []
    text = "at 0.5 remove box_orange\nwhen after 1 and turtlebot within 5 of point 1 1 move cylinder_blue_dots to 2 3"
    scenario = parse(text, "t.scenario")
    Disturbances(scenario, fired.append).install(lab)
    lab.step(100)
    assert fired == []
    lab.step(40)  # past 0.5 s
    assert [f.body for f in fired] == ["box_orange"] and fired[0].position[0] < PARK[0]
    lab.step(240)
    assert [f.body for f in fired] == ["box_orange", "cylinder_blue_dots"]
    assert fired[1].position[:2] == pytest.approx([2.0, 3.0], abs=1e-6) and fired[1].time >= 1.0


@pytest.mark.parametrize(
    ("text", "where", "message"),
    [
        ("at 1 move table_x by 0 1", "s.scenario:1:11", "no body 'table_x' in the world"),
        ("\nat 1 move workbench by 0 1", "s.scenario:2:11", "'workbench' cannot move (no mass)"),
        ("at 1 add box desk 1 1 1 at 2 2", "s.scenario:1:14", "box 'desk': the world has a body of that name"),
        ("when turtlebot within 1 of nowhere remove box_orange", "s.scenario:1:28", "no body 'nowhere'"),
    ],
)
def test_names_are_checked_against_the_world(lab: World, text: str, where: str, message: str) -> None:
    with pytest.raises(ScenarioError) as caught:
        Disturbances(parse(text, "s.scenario")).install(lab)
    assert str(caught.value).startswith(f"{where}: {message}")


def test_the_shipped_scenarios_parse_and_bad_files_are_located(tmp_path: Path) -> None:
    assert sorted(p.stem for p in SCENARIOS.glob("*.scenario")) == ["blocked-path", "dropped-object", "moved-object"]
    bad = tmp_path / "bad.scenario"
    bad.write_text("# fine\nat 2 move crate sideways 1 2\n")
    with pytest.raises(ScenarioError, match=rf"^{bad}:2:17: expected 'to' or 'by', not 'sideways'"):
        read(bad)
    with pytest.raises(ScenarioError, match=r":1:1: cannot read the scenario"):
        read(tmp_path / "missing.scenario")


def test_a_render_mirror_built_from_the_same_plan_sees_the_added_crate() -> None:
    plan = WorldPlan.of(list(ckmconf.load(LAB).nodes))
    assert plan is not None
    text = (SCENARIOS / "blocked-path.scenario").read_text()
    disturbed = DisturbedPlan.around(plan, parse(text, "blocked-path.scenario"), text)
    assert disturbed.cameras == plan.cameras == {"turtlebot", "nao"}  # one render worker per camera robot
    assert disturbed.scenario_source == "blocked-path.scenario" and disturbed.scenario_text == text
    server = disturbed.build()
    mirror_plan = pickle.loads(pickle.dumps(disturbed))  # what the spawned render worker receives
    assert mirror_plan.installed is None
    mirror = mirror_plan.build()
    try:
        assert disturbed.installed is not None
        crate = disturbed.installed.bodies["crate"]
        _place(server.world, "turtlebot", 2.7, 2.4, 0.6)
        server.world.step(240)
        assert [f.body for f in disturbed.installed.fired] == ["crate"]
        restore(mirror.world, snapshot(server.world))
        assert np.allclose(mirror.world.pose(crate)[0], server.world.pose(crate)[0])
    finally:
        server.world.close()
        mirror.world.close()


def test_object_poses_give_each_objects_position_and_tilt(lab: World) -> None:
    """The trace's ``objects`` (plugins.sim.evidence): a standing cylinder's tilt is 0, one laid down's π/2."""
    lab.step(60)
    standing = lab.object_poses()["cylinder_red_stripes"]
    assert standing[3] == pytest.approx(0.0, abs=0.02) and standing[:3] == pytest.approx(
        lab.movable_positions()["cylinder_red_stripes"], abs=1e-3)
    cylinder = lab.objects["cylinder_red_stripes"]
    p.resetBasePositionAndOrientation(cylinder, [5.0, 4.0, 0.04], p.getQuaternionFromEuler([math.pi / 2, 0, 0.3]),
                                      physicsClientId=lab.client)  # fmt: skip
    lab.step(120)
    assert lab.object_poses()["cylinder_red_stripes"][3] == pytest.approx(math.pi / 2, abs=0.05)  # lying
    assert "turtlebot" not in lab.object_poses()  # robots are in the trace's ``robots``
