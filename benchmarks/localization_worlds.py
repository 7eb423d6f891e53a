"""Test worlds and runs for the localization filters (§6.2): use-case lab, corridor, symmetric floor plan,
repeating aisles.

A :class:`Run` is everything a filter consumes and is scored against: the true poses, the noisy
odometry readings and the simulated scans at each step, generated once from a seed so that every
filter sees the same data. A kidnapping teleports the robot between two steps while the odometry
reports no motion (Fox et al.'s kidnapped-robot test).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry.base import BaseGeometry

import ckmconf
from plugins.localization.odometry import OdometryNoise, OdometrySimulator, wrap
from plugins.localization.raster import GridMap
from plugins.localization.raycast import LaserSpec, simulate_scan

Array = npt.NDArray[np.float64]
LAB = Path(__file__).resolve().parents[1] / "configs" / "usecase" / "environment.xml"

LAB_WAYPOINTS = (
    (1.5, 0.8),
    (3.0, 2.8),
    (6.2, 2.8),
    (7.0, 4.6),
    (9.4, 4.4),
    (9.4, 2.9),
    (6.5, 3.0),
    (3.8, 2.6),
    (3.0, 4.0),
    (1.5, 5.4),
    (2.8, 5.5),
    (2.0, 3.2),
    (1.8, 0.8),
)
"""A tour of the lab's areas (Home → Office → Workbench → Shelf → Home), every leg clear of obstacles."""


def lab_grid(resolution: float = 0.05) -> GridMap:
    """The use-case lab (configs/usecase/environment.xml) rasterised at laser height."""
    env = ckmconf.load(LAB).environment
    if env is None:
        raise ValueError(f"{LAB} holds no <Environment>")
    return GridMap.from_environment(env, resolution)


def corridor_grid(length: float = 14.0, width: float = 2.0, resolution: float = 0.05) -> GridMap:
    """A straight corridor with irregularly spaced alcoves and pillars (so a straight run is observable along it)."""
    shapes: list[BaseGeometry] = []
    # side walls leave alcoves (0.5 m deep) at irregular places; pillars narrow the corridor elsewhere
    for x0, x1 in ((1.0, 2.0), (4.5, 5.0), (8.0, 9.5), (12.0, 12.4)):
        shapes.append(shapely.box(x0, width - 0.15, x1, width))
    for x in (3.0, 6.5, 10.5):
        shapes.append(shapely.box(x, 0.0, x + 0.3, 0.35))
    return GridMap.from_shapes((0.0, 0.0, length, width), shapes, resolution)


def floor_plan_shapes(
    rooms: int = 3, room: float = 4.0, corridor: float = 2.0
) -> tuple[tuple[float, float, float, float], list[BaseGeometry]]:
    """Bounds and walls of ``rooms`` identical rooms on each side of a corridor, each with the same table.

    The rooms are translated and mirrored copies of one another: inside a room a scan cannot tell
    which of the 2·rooms it is in. Only a cabinet at the corridor's west end breaks the symmetry.
    """
    width, depth, wall, door = room * rooms, 2 * room + corridor, 0.1, 1.0
    shapes: list[BaseGeometry] = []
    for side, (y_wall, y_table) in enumerate(((room, room * 0.35), (room + corridor, depth - room * 0.35))):
        for k in range(rooms):
            x0 = k * room
            door_x = x0 + room / 2
            shapes.append(shapely.box(x0, y_wall - wall / 2, door_x - door / 2, y_wall + wall / 2))
            shapes.append(shapely.box(door_x + door / 2, y_wall - wall / 2, x0 + room, y_wall + wall / 2))
            # every room is walled on its east side (the last one too): all interiors are [x0, x0 + room - wall]
            y0, y1 = (0.0, room) if side == 0 else (room + corridor, depth)
            shapes.append(shapely.box(x0 + room - wall, y0, x0 + room, y1))
            shapes.append(shapely.box(x0 + room * 0.3, y_table - 0.3, x0 + room * 0.6, y_table + 0.3))
    shapes.append(shapely.box(0.0, room + 0.05, 0.5, room + 0.6))  # the cabinet breaking the symmetry
    return (0.0, 0.0, width, depth), shapes


def floor_plan_grid(rooms: int = 3, resolution: float = 0.05) -> GridMap:
    """The generated floor plan of :func:`floor_plan_shapes` rasterised."""
    bounds, shapes = floor_plan_shapes(rooms)
    return GridMap.from_shapes(bounds, shapes, resolution)


Waypoints = tuple[tuple[float, float], ...]

AISLES_SIZE = (14.0, 10.0)
"""The warehouse's length and depth (m)."""
RACK_ROWS, RACK_DEPTH = (1.9, 4.7, 7.5), 0.8
RACK_SEGMENTS = ((2.0, 5.0), (5.4, 8.4), (8.8, 11.8))
"""Three rows of racks (0.8 m deep) along x, each of three identical 3 m segments with 0.4 m gaps between
them, and four aisles: y 0.75, 3.3, 6.1 and 8.9; cross-aisles at both ends."""


def aisles_shapes() -> tuple[tuple[float, float, float, float], list[BaseGeometry]]:
    """Bounds and racks of the repeating-aisles warehouse (issue N point 4): every aisle looks like every
    other, and along an aisle every rack segment like the next. Only a pallet in the north-west corner
    breaks the symmetry."""
    half = RACK_DEPTH / 2
    shapes: list[BaseGeometry] = [shapely.box(x0, y - half, x1, y + half)
                                  for y in RACK_ROWS for x0, x1 in RACK_SEGMENTS]
    shapes.append(shapely.box(0.3, 9.2, 0.9, 9.8))  # the pallet
    return (0.0, 0.0, *AISLES_SIZE), shapes


def aisles_grid(resolution: float = 0.05) -> GridMap:
    """The repeating-aisles warehouse of :func:`aisles_shapes` rasterised."""
    bounds, shapes = aisles_shapes()
    return GridMap.from_shapes(bounds, shapes, resolution)


def aisles_routes() -> tuple[Waypoints, Waypoints, Waypoints]:
    """A serpentine tour up and down every aisle, and the two legs of a kidnapping from the second
    aisle's east end to the third aisle's west end (the places a fetch through the aisles goes)."""
    west, east = 1.0, 13.0
    tour = ((west, 0.75), (east, 0.75), (east, 3.3), (west, 3.3), (west, 6.1), (east, 6.1), (east, 8.9),
            (west + 1.0, 8.9))
    before = ((west, 3.3), (east - 0.1, 3.3))
    after = ((west, 6.1), (east, 6.1), (east, 8.9), (7.0, 8.9))
    return tour, before, after


def floor_plan_routes(
    rooms: int = 3, room: float = 4.0, corridor: float = 2.0
) -> tuple[Waypoints, Waypoints, Waypoints]:
    """Waypoints through the floor plan of :func:`floor_plan_shapes`: a tour, and the two legs of a kidnapping.

    The tour runs east along the corridor, into the last south room through its door and back,
    into the middle north room and back, then west to the start. The kidnapping's first leg ends in
    the last north room; the robot is carried to the last south room, walks out and west along
    the corridor, visits the first south room and goes east again. Every leg keeps clear of the
    walls and the tables (doors are ``room / 2`` along each room).
    """
    if rooms < 2:
        raise ValueError(f"a floor plan needs at least 2 rooms per side, not {rooms}")
    mid_y, width = room + corridor / 2, room * rooms
    last, middle = (rooms - 0.5) * room, (rooms // 2 + 0.5) * room  # door abscissas
    south, north = room * 0.6, room + corridor + room * 0.4  # inside a room, past its table's side
    tour = ((1.5, mid_y), (last, mid_y), (last, south), (last, mid_y), (middle, mid_y), (middle, north),
            (middle, mid_y), (1.5, mid_y))
    before = ((3.0, mid_y + 0.2), (last, mid_y + 0.2), (last, north))
    after = ((last, south), (last, mid_y - 0.1), (middle - 0.5, mid_y), (room / 2, mid_y), (room / 2, room * 0.55),
             (room / 2, mid_y), (width - 3.0, mid_y))
    return tour, before, after


def drive(
    waypoints: Sequence[tuple[float, float]],
    dt: float = 0.2,
    speed: float = 0.5,
    turn_rate: float = 1.2,
    start_yaw: float | None = None,
) -> Array:
    """True poses (T, 3) every ``dt`` s: turn in place towards the next waypoint, then go straight to it."""
    points = np.asarray(waypoints, dtype=np.float64)
    first = np.arctan2(*(points[1] - points[0])[::-1]) if start_yaw is None else start_yaw
    poses = [np.array([points[0, 0], points[0, 1], first])]
    for target in points[1:]:
        x, y, yaw = poses[-1]
        goal_yaw = float(np.arctan2(target[1] - y, target[0] - x))
        turn = float(wrap(goal_yaw - yaw))
        for k in range(1, int(np.ceil(abs(turn) / (turn_rate * dt))) + 1):
            poses.append(np.array([x, y, float(wrap(yaw + turn * min(1.0, k * turn_rate * dt / abs(turn))))]))
        dist = float(np.hypot(target[0] - x, target[1] - y))
        steps = max(1, int(np.ceil(dist / (speed * dt))))
        for k in range(1, steps + 1):
            f = k / steps
            poses.append(np.array([x + f * (target[0] - x), y + f * (target[1] - y), goal_yaw]))
    return np.stack(poses)


@dataclass(frozen=True)
class Run:
    """One simulated run: step times (s), true poses, odometry readings and scans, and the kidnapping step."""

    name: str
    grid: GridMap
    laser: LaserSpec
    dt: float
    truth: Array
    odometry: Array
    scans: Array
    kidnap_step: int | None = None

    @property
    def times(self) -> Array:
        """The time (s) of each step from the start, ``dt`` apart: one per true pose (§6.2 test runs)."""
        result: Array = np.arange(len(self.truth), dtype=np.float64) * self.dt
        return result


def simulate(
    name: str, grid: GridMap, legs: Sequence[Array], laser: LaserSpec, noise: OdometryNoise, seed: int, dt: float = 0.2
) -> Run:
    """Scans and odometry along ``legs`` (pose arrays); between two legs the robot is kidnapped (teleported)."""
    rng = np.random.default_rng(seed)
    truth = np.concatenate(legs)
    odometer = OdometrySimulator(truth[0], noise, rng)
    odometry = [odometer.reading.copy()]
    jumps = set(np.cumsum([len(leg) for leg in legs])[:-1].tolist())
    for k in range(1, len(truth)):
        # a kidnapped robot's wheels did not turn: its odometry holds still across the jump
        odometry.append(odometer.reading.copy() if k in jumps else odometer.step(truth[k - 1], truth[k]))
    scans = np.stack([simulate_scan(grid, pose, laser, rng) for pose in truth])
    kidnap = min(jumps) if jumps else None
    return Run(name, grid, laser, dt, truth, np.stack(odometry), scans, kidnap)


WORLDS = ("lab", "floor-plan", "aisles")
"""The benchmark's worlds: the use-case lab, the generated floor plan of symmetric rooms, the warehouse
of repeating aisles."""


def standard_runs(
    seed: int, laser: LaserSpec | None = None, noise: OdometryNoise | None = None, *, rooms: int = 3,
    worlds: Sequence[str] = WORLDS,
) -> list[Run]:
    """The benchmark's runs: a tour and a kidnapping in the lab, in the floor plan of ``rooms`` symmetric
    rooms per side and in the repeating aisles (``worlds``: which of them)."""
    unknown = sorted(set(worlds) - set(WORLDS))
    if unknown:
        raise ValueError(f"unknown worlds {unknown}: choose among {', '.join(WORLDS)}")
    laser = laser or LaserSpec()
    noise = noise or OdometryNoise()
    runs = []
    if "lab" in worlds:
        lab = lab_grid()
        lab_after = ((2.8, 5.5), (2.0, 3.2), (1.8, 0.8), (3.0, 2.8), (6.2, 2.8), (7.0, 4.6))
        runs += [
            simulate("lab-tour", lab, [drive(LAB_WAYPOINTS)], laser, noise, seed),
            simulate("lab-kidnap", lab, [drive(LAB_WAYPOINTS[:6]), drive(lab_after)], laser, noise, seed + 1),
        ]
    if "floor-plan" in worlds:
        plan = floor_plan_grid(rooms)
        tour, before, after = floor_plan_routes(rooms)
        runs += [
            simulate("floor-plan-tour", plan, [drive(tour)], laser, noise, seed + 2),
            simulate("floor-plan-kidnap", plan, [drive(before), drive(after)], laser, noise, seed + 3),
        ]
    if "aisles" in worlds:
        warehouse = aisles_grid()
        tour, before, after = aisles_routes()
        runs += [
            simulate("aisles-tour", warehouse, [drive(tour)], laser, noise, seed + 4),
            simulate("aisles-kidnap", warehouse, [drive(before), drive(after)], laser, noise, seed + 5),
        ]
    return runs
