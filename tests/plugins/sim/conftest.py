"""Small simulated worlds for the plugins/sim tests: an empty 6 × 4 m room and helpers."""

from __future__ import annotations

from collections.abc import Iterator

import pybullet as p
import pytest

from ckmconf.model import Environment, MapBounds
from plugins.sim.robots import Robot
from plugins.sim.world import World

ROOM = Environment(name="room", map=MapBounds(xmin=0.0, ymin=0.0, xmax=6.0, ymax=4.0, height=1.5))
"""An empty 6 × 4 m room: walls only."""


@pytest.fixture
def world() -> Iterator[World]:
    made = World(ROOM, seed=3)
    yield made
    made.close()


def add_box(world: World, centre: tuple[float, float, float], half: float, rgba: list[float], mass: float = 0.0) -> int:
    """A cube of half-size ``half`` at ``centre``."""
    cid = world.client
    col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[half] * 3, physicsClientId=cid)
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[half] * 3, rgbaColor=rgba, physicsClientId=cid)
    body = int(p.createMultiBody(mass, col, vis, list(centre), physicsClientId=cid))
    p.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=cid)
    return body


def robot(world: World, model: str, pose: tuple[float, float, float]) -> Robot:
    """Load ``model`` at ``pose`` (x, y, yaw) and let it settle."""
    made = Robot(world, model, world.load_robot(model, model, pose))
    world.step(24)
    return made
