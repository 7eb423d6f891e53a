"""The lidar's map at a scan height (D294): a ``<Geometry2D height="0">`` marking is no wall, a
``<Geometry2D height>`` is one only up to that height, no height stays a wall at every height, and
prisms are cut at their heights above the object's ``<Pose>`` z (where the simulated world puts them);
the distance field agrees with the simulated lidar."""

from __future__ import annotations

import numpy as np
import pytest
from ckm_lab.devices import HOKUYO

from ckmconf.model import Environment, MapBounds
from ckmconf.model.environment import (
    Circle,
    EnvObject,
    Geometry2D,
    Geometry25D,
    Pose,
    Prism,
    Rectangle,
    Semantic,
)
from plugins.localization.raster import GridMap, object_shapes
from plugins.sim.robots import Robot
from plugins.sim.sensors import Lidar
from plugins.sim.world import World


def thing(name: str, x: float, y: float, geometry: Geometry2D | Geometry25D, z: float = 0.0) -> EnvObject:
    return EnvObject(name=name, tag="thing", pose=Pose(x=x, y=y, z=z), geometry=geometry)


PAD = thing("pad", 2.0, 2.0, Geometry2D(height=0.0, atoms=(Rectangle(width=0.8, depth=0.8),)))
DESK = thing("desk", 4.0, 1.0, Geometry2D(atoms=(Rectangle(width=0.6, depth=0.6),)))
STEP = thing("step", 4.0, 3.0, Geometry2D(height=0.3, atoms=(Circle(radius=0.3),)))
LAMP = thing("lamp", 1.0, 3.2, Geometry25D(prism=Prism(zmin=0.0, zmax=0.1, base=Circle(radius=0.2))), z=0.6)
ENV = Environment(
    name="heights",
    map=MapBounds(xmin=0.0, ymin=0.0, xmax=5.0, ymax=4.0, height=2.0),
    semantics=(Semantic(tag="thing"),),
    objects=(PAD, DESK, STEP, LAMP),
)


def occupied(grid: GridMap, x: float, y: float) -> bool:
    return not bool(grid.is_free(np.array([x]), np.array([y]))[0])


def test_what_each_scan_height_cuts() -> None:
    assert object_shapes(PAD, 0.0) == [] and object_shapes(PAD, 0.2) == []
    assert len(object_shapes(DESK, 0.2)) == 1 and len(object_shapes(DESK, 1.9)) == 1
    assert len(object_shapes(STEP, 0.2)) == 1 and object_shapes(STEP, 0.4) == []
    assert object_shapes(LAMP, 0.05) == [] and len(object_shapes(LAMP, 0.65)) == 1  # 0.6 m up, 0.1 m tall
    low, high = GridMap.from_environment(ENV, 0.05, 0.2), GridMap.from_environment(ENV, 0.05, 0.4)
    assert not occupied(low, 2.0, 2.0) and not occupied(high, 2.0, 2.0)  # the marking: never
    assert occupied(low, 4.0, 1.0) and occupied(high, 4.0, 1.0)  # the desk of no height: always
    assert occupied(low, 4.0, 3.0) and not occupied(high, 4.0, 3.0)  # the 0.3 m step: below it only


def test_the_distance_field_agrees_with_the_simulated_lidar() -> None:
    with World(ENV, seed=1) as world:
        tb = Robot(world, "turtlebot", world.load_robot("turtlebot", "turtlebot", (0.6, 2.0, 0.0)))
        world.step(24)
        lidar = Lidar(tb, "hokuyo_link", **HOKUYO)
        ahead = float(lidar.scan()[341])  # along +x over the marking to the east wall
        laser_x = tb.link_pose(tb.link("hokuyo_link"))[0][0]
    assert ahead == pytest.approx(5.0 - laser_x, abs=0.02)
    grid = GridMap.from_environment(ENV, 0.02, 0.2)
    xs = np.arange(laser_x, 5.0, 0.01)
    free = grid.is_free(xs, np.full_like(xs, 2.0))
    assert free[xs < 4.95].all()  # the grid holds nothing on that line either, the marking included
