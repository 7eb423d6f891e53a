"""The standard MCL baseline as AMCL does it (Thrun et al. ch. 8; ROS amcl), vectorised.

Prediction by the odometry motion model; correction by AMCL's likelihood-field model; low-variance
resampling every update; recovery by random particles drawn with probability
``max(0, 1 - w_fast / w_slow)`` (augmented MCL, alpha_slow / alpha_fast); optional KLD sampling
(Fox 2003) choosing the particle count from the number of occupied histogram bins.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .estimate import Estimate, publish
from .likelihood import FieldModel, amcl_weights
from .odometry import OdometryNoise, sample_motion
from .raster import GridMap, random_poses

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class MclSettings:
    """AMCL's parameters: particle bounds, recovery rates, KLD bounds, odometry and laser models."""

    particles: int = 2500
    min_particles: int = 500
    alpha_slow: float = 0.001
    alpha_fast: float = 0.1
    kld: bool = False
    kld_err: float = 0.05
    kld_z: float = 2.33
    bin_xy: float = 0.5
    bin_yaw: float = np.radians(10.0)
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    field: FieldModel = field(default_factory=FieldModel)
    clearance: float = 0.1


def low_variance_indices(weights: Array, count: int, rng: np.random.Generator) -> npt.NDArray[np.intp]:
    """Indices of ``count`` draws by low-variance (systematic) resampling of normalised ``weights``."""
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    points = (rng.random() + np.arange(count)) / count
    result: npt.NDArray[np.intp] = np.searchsorted(cumulative, points, side="left")
    return np.minimum(result, len(weights) - 1)


def kld_count(poses: Array, settings: MclSettings) -> int:
    """The KLD-sampling particle count for ``poses`` drawn in order (Fox 2003, AMCL's pf_resample_limit).

    The count needed after the i-th draw depends on the number k of distinct bins among the first i;
    sampling stops at the first i reaching it, computed here for all i at once.
    """
    bins = np.floor(
        np.stack([poses[:, 0] / settings.bin_xy, poses[:, 1] / settings.bin_xy, poses[:, 2] / settings.bin_yaw], axis=1)
    ).astype(np.int64)
    _, first = np.unique(bins, axis=0, return_index=True)
    new_bin = np.zeros(len(poses), dtype=np.int64)
    new_bin[first] = 1
    k = np.cumsum(new_bin).astype(np.float64)
    a = 2.0 / (9.0 * np.maximum(k - 1, 1))
    needed = np.where(k > 1, (k - 1) / (2 * settings.kld_err) * (1 - a + np.sqrt(a) * settings.kld_z) ** 3, 0)
    needed = np.clip(needed, settings.min_particles, settings.particles)
    reached = np.nonzero(np.arange(1, len(poses) + 1) >= needed)[0]
    return int(reached[0] + 1) if reached.size else len(poses)


class AmclFilter:
    """Augmented MCL with the likelihood-field model, low-variance resampling and optional KLD sampling."""

    name = "mcl"

    def __init__(self, grid: GridMap, angles: Array, settings: MclSettings, rng: np.random.Generator) -> None:
        self.grid, self.angles, self.settings, self.rng = grid, np.asarray(angles), settings, rng
        self.free = grid.free_cells(settings.clearance)
        self.w_slow = self.w_fast = 0.0
        self.particles = self.random_poses(settings.particles)
        self.weights = np.full(settings.particles, 1.0 / settings.particles)
        self.odometry: Array | None = None
        self.injected = 0
        """Random particles drawn at the last resampling (augmented MCL's recovery)."""

    def random_poses(self, count: int) -> Array:
        """``count`` poses uniform over the free cells, with uniform headings."""
        return random_poses(self.free, self.grid.resolution, self.rng, count)

    def reset(self, pose: Array | None = None, sigma: tuple[float, float] = (0.3, 0.2)) -> None:
        """A uniform prior (``pose`` None: global localization) or a Gaussian one around ``pose``."""
        n = self.settings.particles
        if pose is None:
            self.particles = self.random_poses(n)
        else:
            noise = self.rng.normal(0.0, 1.0, (n, 3)) * np.array([sigma[0], sigma[0], sigma[1]])
            self.particles = np.asarray(pose)[None, :] + noise
        self.weights = np.full(n, 1.0 / n)
        self.w_slow = self.w_fast = 0.0

    def update(self, odometry: Array, ranges: Array, angles: Array | None = None) -> Estimate:
        """One filter step: move by the odometry since the last call, weigh by the scan, publish, resample.

        ``angles``: this scan's beam bearings from the robot's centre (they vary per scan for a laser
        off the centre, plugins/localization/beams.py); None: the fixed ``self.angles``.
        """
        s = self.settings
        bearings = self.angles if angles is None else np.asarray(angles, dtype=np.float64)
        if self.odometry is not None:
            self.particles = sample_motion(self.particles, self.odometry, odometry, s.noise, self.rng)
        self.odometry = np.asarray(odometry, dtype=np.float64).copy()
        likelihood = amcl_weights(self.grid, self.particles, ranges, bearings, s.field)
        weights = self.weights * likelihood
        total = weights.sum()
        w_avg = float(np.mean(likelihood))  # AMCL's average weight, without its 1/n factor (the rates' ratio is kept)
        self.w_slow = w_avg if self.w_slow == 0.0 else self.w_slow + s.alpha_slow * (w_avg - self.w_slow)
        self.w_fast = w_avg if self.w_fast == 0.0 else self.w_fast + s.alpha_fast * (w_avg - self.w_fast)
        weights = weights / total if total > 0 else np.full(len(weights), 1.0 / len(weights))
        estimate = publish(self.particles, weights)
        self._resample(weights)
        return estimate

    def _resample(self, weights: Array) -> None:
        s = self.settings
        draws = s.particles
        chosen = self.particles[low_variance_indices(weights, draws, self.rng)]
        random_probability = max(0.0, 1.0 - self.w_fast / self.w_slow) if self.w_slow > 0 else 0.0
        replace = self.rng.random(draws) < random_probability
        self.injected = int(replace.sum())
        if replace.any():
            chosen[replace] = self.random_poses(int(replace.sum()))
        if s.kld:
            # draws are in random order after the shuffle, as AMCL's sequential draws are
            chosen = chosen[self.rng.permutation(draws)]
            chosen = chosen[: kld_count(chosen, s)]
        if random_probability > 0:  # AMCL restarts both averages once it has injected particles
            self.w_slow = self.w_fast = 0.0
        self.particles = chosen
        self.weights = np.full(len(chosen), 1.0 / len(chosen))
