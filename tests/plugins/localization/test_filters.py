"""The localization filters (issue I point 4): Algorithm 3 and the AMCL-like MCL on runs with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.localization import play, settled_from
from benchmarks.localization_worlds import Run, corridor_grid, drive, simulate, standard_runs
from plugins.localization.estimate import best_cluster
from plugins.localization.mcl import AmclFilter, MclSettings, kld_count, low_variance_indices
from plugins.localization.odometry import OdometryNoise
from plugins.localization.raycast import LaserSpec
from plugins.localization.reliability_filter import ReliabilityFilter, ReliabilitySettings

Filter = AmclFilter | ReliabilityFilter


def _make(name: str, run: Run, particles: int, seed: int) -> Filter:
    rng = np.random.default_rng(seed)
    if name == "mcl":
        return AmclFilter(run.grid, run.laser.angles(), MclSettings(particles=particles), rng)
    return ReliabilityFilter(run.grid, run.laser.angles(), ReliabilitySettings(particles=particles), rng)


def _errors(flt: Filter, run: Run) -> np.ndarray:
    out = []
    for k in range(len(run.truth)):
        pose = flt.update(run.odometry[k], run.scans[k]).pose
        out.append(np.hypot(pose[0] - run.truth[k, 0], pose[1] - run.truth[k, 1]))
    return np.array(out)


@pytest.fixture(scope="module")
def corridor() -> Run:
    grid = corridor_grid()
    return simulate("corridor", grid, [drive(((1.0, 1.0), (13.0, 1.0)))], LaserSpec(), OdometryNoise(), seed=11)


@pytest.fixture(scope="module")
def runs() -> list[Run]:
    return standard_runs(seed=1)


@pytest.mark.parametrize("name", ["reliability", "mcl"])
def test_each_filter_converges_on_a_straight_corridor_run(corridor: Run, name: str) -> None:
    flt = _make(name, corridor, 1000, seed=4)
    wrong = corridor.truth[0] + np.array([0.4, -0.3, 0.2])  # a poor initial guess, within the prior's spread
    flt.reset(wrong, sigma=(0.5, 0.3))
    errors = _errors(flt, corridor)
    assert errors[0] > 0.05
    assert errors[len(errors) // 2 :].max() < 0.3
    assert errors[-10:].mean() < 0.15


@pytest.mark.parametrize("name", ["reliability", "mcl"])
def test_each_filter_localizes_globally_on_the_lab_tour(runs: list[Run], name: str) -> None:
    played = play(name, runs[0], 2500, seed=7)
    assert played["converged"] is not None and played["converged"] < 20.0
    assert np.sqrt(np.mean(played["errors"][played["tracked"]] ** 2)) < 0.15


def test_reliability_filter_recovers_from_a_kidnapping(runs: list[Run]) -> None:
    kidnap = runs[1]
    played = play("reliability", kidnap, 2500, seed=7)
    assert played["converged"] is not None
    assert played["errors"][kidnap.kidnap_step] > 2.0  # the robot was carried away
    assert played["recovered"] is not None and played["recovered"] < 20.0


def test_mcl_injects_random_particles_after_a_kidnapping(runs: list[Run]) -> None:
    """AMCL's recovery: once w_fast falls below w_slow, uniform random particles enter the set."""
    kidnap = runs[1]
    assert kidnap.kidnap_step is not None
    flt = _make("mcl", kidnap, 2500, seed=7)
    assert isinstance(flt, AmclFilter)
    injected = []
    for k in range(kidnap.kidnap_step + 40):
        flt.update(kidnap.odometry[k], kidnap.scans[k])
        injected.append(flt.injected)
    assert sum(injected[kidnap.kidnap_step - 40 : kidnap.kidnap_step]) == 0  # tracking: no injection
    assert sum(injected[kidnap.kidnap_step :]) > 0


def test_algorithm3_weights_reference_and_reliability(runs: list[Run]) -> None:
    run = runs[0]
    flt = _make("reliability", run, 500, seed=3)
    assert isinstance(flt, ReliabilityFilter)
    for k in range(30):
        estimate = flt.update(run.odometry[k], run.scans[k])
    x_ref, z_ref = flt.last_reference
    assert 0.0 < flt.reliability <= z_ref <= 1.0  # eq. 6.25: x_ref is at least as coherent as any particle
    assert np.hypot(*(x_ref[:2] - run.truth[29, :2])) < 0.1
    assert estimate.covariance.shape == (3, 3)
    assert np.all(np.linalg.eigvalsh(estimate.covariance) >= -1e-12)


def test_low_variance_resampling_and_kld_count() -> None:
    rng = np.random.default_rng(0)
    assert set(low_variance_indices(np.array([0.0, 1.0, 0.0]), 50, rng)) == {1}
    counts = np.bincount(low_variance_indices(np.array([0.25, 0.75]), 1000, rng))
    assert counts.tolist() == [250, 750]  # systematic resampling is exact to one draw
    settings = MclSettings(particles=5000, min_particles=100, kld=True)
    tight = np.column_stack([rng.normal(5.25, 0.03, 5000), rng.normal(5.25, 0.03, 5000), rng.normal(0.087, 0.01, 5000)])
    wide = np.column_stack([rng.uniform(0, 20, 5000), rng.uniform(0, 20, 5000), rng.uniform(-3, 3, 5000)])
    assert kld_count(tight, settings) == 100  # one bin: the minimum
    assert kld_count(wide, settings) == 5000


def test_best_cluster_keeps_the_heavier_hypothesis() -> None:
    poses = np.array([[0.0, 0.0, 0.0]] * 10 + [[5.0, 5.0, 0.0]] * 10)
    weights = np.array([1.0] * 10 + [3.0] * 10)
    assert best_cluster(poses, weights).tolist() == [False] * 10 + [True] * 10


def test_recovery_criterion_needs_more_than_ten_seconds() -> None:
    times = np.arange(100, dtype=np.float64) * 0.2
    errors = np.full(100, 1.0)
    errors[10:30] = 0.1  # 4 s: not recovered
    errors[40:] = 0.1  # 12 s from t = 8 s
    assert settled_from(errors, times, 0) == pytest.approx(8.0)
    assert settled_from(errors[:80], times[:80], 0) is None  # 40..79: 7.8 s only
