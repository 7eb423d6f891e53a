"""The scan and odometry simulator of plugins/localization (issue I point 5): known distances and noise statistics."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import shapely

from benchmarks.localization_worlds import floor_plan_grid, floor_plan_routes, lab_grid, standard_runs
from plugins.localization.odometry import OdometryNoise, OdometrySimulator, sample_motion
from plugins.localization.raster import GridMap
from plugins.localization.raycast import LaserSpec, cast, simulate_scan


def test_ray_caster_measures_known_wall_distances() -> None:
    grid = GridMap.from_shapes((0.0, 0.0, 10.0, 5.0), [shapely.box(6.0, 2.0, 7.0, 3.0)])
    angles = np.array([0.0, np.pi / 2, np.pi, -np.pi / 2])
    ranges = cast(grid, np.array([[2.0, 2.5, 0.0]]), angles, 20.0)[0]
    # east: the box's face at x = 6; north/south: the walls at y = 5 and 0; west: the wall at x = 0
    assert ranges == pytest.approx([4.0, 2.5, 2.0, 2.5], abs=0.03)
    turned = cast(grid, np.array([[2.0, 2.5, np.pi / 2]]), angles, 3.0)[0]
    assert turned == pytest.approx([2.5, 2.0, 2.5, 3.0], abs=0.03)  # the box beyond max range: max range


def test_lab_map_sees_table_legs_not_table_tops_at_laser_height() -> None:
    grid = lab_grid()
    # drop table at (1.0, 1.9): legs at ±0.27 m reach the scan plane, its top (0.28-0.30 m) does not
    assert grid.distance_at(np.array([1.0]), np.array([1.9]))[0] > 0.2
    assert grid.distance_at(np.array([1.27]), np.array([2.17]))[0] == 0.0
    ranges = cast(grid, np.array([[2.0, 3.0, 0.0]]), np.array([np.pi, -np.pi / 2]), 20.0)[0]
    assert ranges == pytest.approx([2.0, 3.0], abs=0.03)  # the lab's west and south walls


def test_simulated_scan_noise_has_the_configured_sigma() -> None:
    grid = GridMap.from_shapes((0.0, 0.0, 10.0, 10.0), [])
    laser = LaserSpec(beams=4, sigma=0.05, max_range=20.0)
    rng = np.random.default_rng(3)
    scans = np.stack([simulate_scan(grid, np.array([5.0, 5.0, 0.0]), laser, rng) for _ in range(2000)])
    assert np.std(scans, axis=0) == pytest.approx([0.05] * 4, rel=0.1)
    assert np.mean(scans, axis=0) == pytest.approx([5.0] * 4, abs=0.03)


def test_odometry_noise_statistics_match_the_model() -> None:
    rng = np.random.default_rng(7)
    start = np.zeros((20000, 3))
    straight = sample_motion(start, np.zeros(3), np.array([1.0, 0.0, 0.0]), OdometryNoise(0, 0, 0.01, 0), rng)
    assert np.std(straight[:, 0]) == pytest.approx(0.1, rel=0.05)  # sqrt(0.01 · 1²)
    assert np.mean(straight[:, 0]) == pytest.approx(1.0, abs=0.005)
    assert np.std(straight[:, 2]) == 0.0
    turn = sample_motion(start, np.zeros(3), np.array([0.0, 0.0, np.pi / 2]), OdometryNoise(0.04, 0, 0, 0), rng)
    assert np.std(turn[:, 2]) == pytest.approx(0.2 * np.pi / 2, rel=0.05)
    assert np.abs(turn[:, :2]).max() == 0.0


def test_noise_free_odometry_integrates_the_true_motion() -> None:
    odo = OdometrySimulator(np.zeros(3), OdometryNoise(0, 0, 0, 0), np.random.default_rng(0))
    path = [np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, np.pi / 2]), np.array([1.0, 2.0, np.pi / 2])]
    for before, after in itertools.pairwise(path):
        reading = odo.step(before, after)
    assert reading == pytest.approx(path[-1], abs=1e-9)


def test_standard_runs_stay_clear_and_kidnap_without_odometry() -> None:
    runs = standard_runs(seed=5)
    assert [r.name for r in runs] == ["lab-tour", "lab-kidnap", "floor-plan-tour", "floor-plan-kidnap", "aisles-tour",
                                      "aisles-kidnap"]
    for run in runs:
        assert run.grid.distance_at(run.truth[:, 0], run.truth[:, 1]).min() >= 0.3, run.name
        assert run.scans.shape == (len(run.truth), 60)
        if run.kidnap_step is not None:
            k = run.kidnap_step
            assert np.hypot(*(run.truth[k, :2] - run.truth[k - 1, :2])) > 2.0  # teleported
            assert run.odometry[k] == pytest.approx(run.odometry[k - 1])  # the wheels did not turn


def test_floor_plan_rooms_are_copies_of_one_another() -> None:
    grid = floor_plan_grid(rooms=3)
    angles = LaserSpec().angles()
    # the same pose in two south rooms (4 m apart) sees the same scan
    a = cast(grid, np.array([[2.0, 2.4, 0.3]]), angles, 8.0)[0]
    b = cast(grid, np.array([[6.0, 2.4, 0.3]]), angles, 8.0)[0]
    inside = (a < 3.5) & (b < 3.5)  # beams staying in the room (not out through the door)
    assert inside.sum() > 45
    assert a[inside] == pytest.approx(b[inside], abs=0.03)


def test_a_larger_floor_plan_has_n_identical_rooms_and_its_runs_stay_clear() -> None:
    runs = standard_runs(seed=7, rooms=5, worlds=["floor-plan"])
    assert [r.name for r in runs] == ["floor-plan-tour", "floor-plan-kidnap"]
    grid = runs[0].grid
    assert grid.bounds == (0.0, 0.0, 20.0, 10.0)  # 5 rooms of 4 m along the corridor, on each side
    angles = LaserSpec().angles()
    scans = cast(grid, np.array([[2.0 + 4.0 * k, 2.4, 0.3] for k in range(5)]), angles, 8.0)
    inside = (scans < 3.5).all(axis=0)
    assert inside.sum() > 45 and np.ptp(scans[:, inside], axis=0).max() < 0.03  # five rooms, one scan
    for run in runs:
        assert run.grid.distance_at(run.truth[:, 0], run.truth[:, 1]).min() >= 0.3, run.name
        assert run.truth[:, 0].max() > 17.0  # the last rooms are visited
    with pytest.raises(ValueError, match="at least 2 rooms"):
        floor_plan_routes(1)
    with pytest.raises(ValueError, match="unknown worlds"):
        standard_runs(seed=1, worlds=["moon"])
