"""Heights in the simulated world (D294): a ``<Geometry2D height="0">`` marking is seen by the camera,
not by the lidar, and driven over; a ``<Geometry2D>`` of no height stays the 0.75 m block (D85); an
``<AvoidedArea height>`` lets a body above it pass and stops one below; an area of no height stands
the map's height."""

from __future__ import annotations

from collections.abc import Iterator

import pybullet as p
import pytest
from ckm_lab.arm import Arm
from ckm_lab.devices import HOKUYO, KOBUKI, XTION_FOV

from ckmconf.model import Environment, MapBounds
from ckmconf.model.environment import (
    AvoidedArea,
    EnvObject,
    Geometry2D,
    Pose,
    Rectangle,
    Semantic,
    Texture,
    Vertex,
)
from plugins.sim.robots import DiffDriveBase
from plugins.sim.sensors import Camera, Lidar
from plugins.sim.world import MARKING_THICKNESS, World

from .conftest import robot


def square(name: str, x0: float, y0: float, x1: float, y1: float, height: float | None = None) -> AvoidedArea:
    corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return AvoidedArea(name=name, vertices=tuple(Vertex(x=x, y=y) for x, y in corners), height=height)


def flat(name: str, x: float, y: float, height: float | None, size: float = 0.8) -> EnvObject:
    """A red square object of ``size`` m at ``(x, y)``, ``height`` m tall (None: no height given)."""
    return EnvObject(
        name=name,
        tag="mark",
        texture="red",
        pose=Pose(x=x, y=y),
        geometry=Geometry2D(height=height, atoms=(Rectangle(width=size, depth=size),)),
    )


def room(*objects: EnvObject, avoided: tuple[AvoidedArea, ...] = ()) -> Environment:
    """A 6 × 4 m room, 4 m tall, with red objects of tag ``mark``."""
    return Environment(
        name="heights",
        map=MapBounds(xmin=0.0, ymin=0.0, xmax=6.0, ymax=4.0, height=4.0),
        avoided=avoided,
        textures=(Texture(name="red", color="#ff0000"),),
        semantics=(Semantic(tag="mark"),),
        objects=objects,
    )


@pytest.fixture
def marked() -> Iterator[World]:
    """A red marking 0.8 m square at (2.5, 2); the turtlebot starts at (1, 2) facing it."""
    made = World(room(flat("pad", 2.5, 2.0, 0.0)), seed=3)
    yield made
    made.close()


def test_a_marking_is_a_thin_visual_slab_without_collision(marked: World) -> None:
    pad = marked.objects["pad"]
    assert p.getCollisionShapeData(pad, -1, physicsClientId=marked.client) == ()
    low, high = p.getAABB(pad, physicsClientId=marked.client)
    assert low == high and high[2] == pytest.approx(MARKING_THICKNESS / 2)  # no collision box: its origin, mid-slab
    visual = p.getVisualShapeData(pad, physicsClientId=marked.client)[0]
    assert visual[3][2] == pytest.approx(MARKING_THICKNESS)  # the box's extents: 0.8 × 0.8 × 4 mm
    assert visual[3][:2] == pytest.approx((0.8, 0.8))
    down = p.rayTest([2.5, 2.0, 1.0], [2.5, 2.0, -0.05], physicsClientId=marked.client)[0]
    assert down[0] == marked.floor  # a ray through the marking meets the floor


def test_the_camera_sees_a_marking_and_the_lidar_does_not(marked: World) -> None:
    tb = robot(marked, "turtlebot", (1.0, 2.0, 0.0))
    Arm(tb).go("rest")
    marked.step(240)
    camera = Camera(tb, "camera_rgb_optical_frame", fov=XTION_FOV)
    frame = camera.render(320, 240)
    u, v, _ = camera.project((2.5, 2.0, MARKING_THICKNESS))
    col, row = round(frame.fx * u + frame.cx), round(frame.fy * v + frame.cy)
    assert 0 <= col < 320 and 0 <= row < 240
    red, green, blue = (int(c) for c in frame.rgb[row, col])
    assert red > 120 and green < 60 and blue < 60  # the marking's red on the grey floor
    ahead = Lidar(tb, "hokuyo_link", **HOKUYO).scan()[341]
    assert ahead == pytest.approx(6.0 - 1.10, abs=0.02)  # the wall behind the marking


def test_a_geometry2d_without_height_is_still_the_075_m_block() -> None:
    with World(room(flat("desk", 2.5, 2.0, None)), seed=3) as world:
        desk = world.objects["desk"]
        low, high = p.getAABB(desk, physicsClientId=world.client)
        assert (low[2], high[2]) == (pytest.approx(0.0, abs=1e-6), pytest.approx(0.75, abs=1e-6))
        tb = robot(world, "turtlebot", (1.0, 2.0, 0.0))
        ahead = Lidar(tb, "hokuyo_link", **HOKUYO).scan()[341]
        assert ahead == pytest.approx(2.1 - 1.10, abs=0.02)  # the block's face at x = 2.1


def test_a_geometry2d_height_sets_the_block_height() -> None:
    with World(room(flat("step", 2.5, 2.0, 0.3)), seed=3) as world:
        low, high = p.getAABB(world.objects["step"], physicsClientId=world.client)
        assert (low[2], high[2]) == (pytest.approx(0.0, abs=1e-6), pytest.approx(0.3, abs=1e-6))


def _base_height(world: World, body: int) -> float:
    return float(world.pose(body)[0][2])


def test_the_robot_drives_over_a_marking_without_rising(marked: World) -> None:
    tb = robot(marked, "turtlebot", (1.0, 2.0, 0.0))
    base = DiffDriveBase(tb, **KOBUKI)
    start = _base_height(marked, tb.body)
    base.drive(0.3, 0.0)
    over: list[float] = []
    for _ in range(240 * 7 // 5):  # 7 s at 0.3 m/s: from x = 1 to beyond the marking's far edge (2.9)
        marked.step(5)
        base.update()
        x = tb.planar_pose()[0]
        if 2.2 < x < 2.8:
            over.append(_base_height(marked, tb.body))
    assert tb.planar_pose()[0] > 2.9  # it went across
    assert over, "the robot never stood on the marking"
    assert max(abs(z - start) for z in over) < 0.001  # a 4 mm slab with collision would lift it


def _fly(world: World, height: float, seconds: float = 2.0) -> tuple[float, float, float]:
    """A 0.1 m ball sent along +x at 1 m/s at ``height`` from x = 1 towards the area at x 2.5..3.5."""
    cid = world.client
    ball = p.createMultiBody(
        1.0,
        p.createCollisionShape(p.GEOM_SPHERE, radius=0.1, physicsClientId=cid),
        -1,
        [1.0, 2.0, height],
        physicsClientId=cid,
    )
    p.resetBaseVelocity(ball, [1.0, 0.0, 0.0], physicsClientId=cid)
    world.step(round(seconds * 240))
    position, _ = world.pose(ball)
    return position


def test_an_avoided_area_2_m_tall_lets_a_body_at_3_m_pass_and_stops_one_at_1_m() -> None:
    with World(room(avoided=(square("rack", 2.5, 1.0, 3.5, 3.0, height=2.0),)), seed=3) as world:
        low, high = p.getAABB(world.objects["rack"], physicsClientId=world.client)
        assert (low[2], high[2]) == (pytest.approx(0.0, abs=0.01), pytest.approx(2.0, abs=0.01))
        p.setGravity(0, 0, 0, physicsClientId=world.client)  # a hovering body: only the geometry decides
        above = _fly(world, 3.0, seconds=3.5)
        below = _fly(world, 1.0, seconds=3.5)
        assert above[0] > 4.0  # over the rack and beyond it
        assert below[0] < 2.5  # stopped at (or bounced off) the rack's face


def test_an_avoided_area_without_height_stands_the_map_height() -> None:
    with World(room(avoided=(square("column", 2.5, 1.0, 3.5, 3.0),)), seed=3) as world:
        low, high = p.getAABB(world.objects["column"], physicsClientId=world.client)
        assert (low[2], high[2]) == (pytest.approx(0.0, abs=0.01), pytest.approx(4.0, abs=0.01))
        p.setGravity(0, 0, 0, physicsClientId=world.client)
        assert _fly(world, 3.0, seconds=3.5)[0] < 2.5  # a wall to the ceiling, as before heights
