"""The reliability-based particle filter of thesis §6.2.1 (Algorithm 3, eq. 6.14–6.30), vectorised.

One step, as Algorithm 3 numbers it:

1–2. prediction: every particle moves by the odometry increment with noise scaled by the
     reliability (eq. 6.15; the noise grows as R falls, decision D80);
3.   z_i = p(S|x_i), the coherence of the scan with the map seen from x_i (eq. 6.16–6.18);
6–9. p(x_i|S) (eq. 6.19–6.20), the reliability R (eq. 6.21, decision D80), min and max;
11.  x_ref from the coherence system: scan matching around the previous estimate moved by the
     odometry and around the best particle (eq. 6.22–6.25, decision D81), with p(x_ref|S) ≥ p(x_i|S);
12.  weights scaled between the minimum and p(x_ref|S) (eq. 6.27);
13.  their variance s (eq. 6.29);
15.  the threshold W_threshold = f(s, R) (eq. 6.28, decision D82);
16–19. every particle below it is replaced by a copy of x_ref — or, when x_ref itself is
     incoherent with the scan, by a random particle, the thesis's forced re-initialisation (D82);
20.  the estimate E_k fuses x_ref and the best particles (eq. 6.30, decision D83).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from .estimate import Estimate, dispersion, weighted_covariance, weighted_pose
from .likelihood import coherence, match
from .odometry import OdometryNoise, decompose, sample_motion, wrap
from .raster import GridMap, random_poses

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ReliabilitySettings:
    """Parameters of Algorithm 3 (defaults used by the benchmark and the Navigation service)."""

    particles: int = 2500
    sigma: float = 0.15
    """Coherence scale (m): a beam endpoint this far from an obstacle counts exp(-1/2) explained."""
    noise: OdometryNoise = field(default_factory=OdometryNoise)
    noise_gain: float = 3.0
    """The odometry noise's standard deviations are multiplied by ``1 + noise_gain·(1 - R)``."""
    coherent: float = 0.85
    """p(S|x_ref) at or above which x_ref is trusted: weak particles become copies of it."""
    lost: float = 0.6
    """p(S|x_ref) at or below which x_ref is incoherent: weak particles become random ones."""
    copy_sigma: tuple[float, float] = (0.05, 0.03)
    """Spread (m, rad) of the copies of x_ref, times ``1 + noise_gain·(1 - R)``."""
    gate: tuple[float, float] = (0.5, 0.5)
    """Particles fused into E_k lie within this distance (m, rad) of x_ref."""
    max_range: float = 8.0
    clearance: float = 0.1


class ReliabilityFilter:
    """Algorithm 3 of the thesis: particles weighted by their closeness in coherence to a scan-matched x_ref."""

    name = "reliability"

    def __init__(self, grid: GridMap, angles: Array, settings: ReliabilitySettings, rng: np.random.Generator) -> None:
        self.grid, self.angles, self.settings, self.rng = grid, np.asarray(angles), settings, rng
        self.free = grid.free_cells(settings.clearance)
        self.reliability = 0.0
        self.estimate: Array | None = None
        self.odometry: Array | None = None
        self.particles = self.random_poses(settings.particles)
        self.last_reference = (np.zeros(3), 0.0)

    def random_poses(self, count: int) -> Array:
        """``count`` poses uniform over the free cells, with uniform headings."""
        return random_poses(self.free, self.grid.resolution, self.rng, count)

    def reset(self, pose: Array | None = None, sigma: tuple[float, float] = (0.3, 0.2)) -> None:
        """A uniform prior (``pose`` None: global localization) or a Gaussian one around ``pose``."""
        n = self.settings.particles
        if pose is None:
            self.particles, self.estimate = self.random_poses(n), None
        else:
            noise = self.rng.normal(0.0, 1.0, (n, 3)) * np.array([sigma[0], sigma[0], sigma[1]])
            self.particles, self.estimate = np.asarray(pose)[None, :] + noise, np.asarray(pose, dtype=np.float64)
        self.reliability = 0.0

    def _spread(self) -> float:
        return 1.0 + self.settings.noise_gain * (1.0 - self.reliability)

    def _predicted_estimate(self, odometry: Array) -> Array | None:
        """E_{k-1} moved by the odometry increment (noise-free), the seed of the coherence system."""
        if self.estimate is None or self.odometry is None:
            return self.estimate
        rot1, trans, rot2 = decompose(self.odometry, odometry)
        x, y, yaw = self.estimate
        heading = yaw + float(rot1)
        return np.array(
            [x + float(trans) * np.cos(heading), y + float(trans) * np.sin(heading), wrap(heading + float(rot2))]
        )

    def update(self, odometry: Array, ranges: Array, angles: Array | None = None) -> Estimate:
        """One iteration of Algorithm 3 for the odometry reading and the scan ``ranges``; E_k with its covariance.

        ``angles``: this scan's beam bearings from the robot's centre (they vary per scan for a laser
        off the centre, plugins/localization/beams.py); None: the fixed ``self.angles``.
        """
        s = self.settings
        bearings = self.angles if angles is None else np.asarray(angles, dtype=np.float64)
        odometry = np.asarray(odometry, dtype=np.float64)
        seed = self._predicted_estimate(odometry)
        if self.odometry is not None:  # lines 1-2, eq. 6.15
            noise = s.noise.scaled(self._spread())
            self.particles = sample_motion(self.particles, self.odometry, odometry, noise, self.rng)
        self.odometry = odometry.copy()
        n = len(self.particles)
        z = coherence(self.grid, self.particles, ranges, bearings, s.sigma, s.max_range)  # line 3, eq. 6.17
        total = float(z.sum())
        p_success = n * z / total if total > 0 else np.ones(n)  # line 6, eq. 6.20
        self.reliability = float(np.mean(z))  # line 7, eq. 6.21 against the ideal coherence (D80)
        best = int(np.argmax(z))
        seeds = [self.particles[best]] if seed is None else [seed, self.particles[best]]
        x_ref, z_ref = match(self.grid, np.stack(seeds), ranges, bearings, s.sigma, s.max_range)  # line 11
        if z_ref < z[best]:  # eq. 6.25: no particle may be more coherent than x_ref
            x_ref, z_ref = self.particles[best].copy(), float(z[best])
        self.last_reference = (x_ref, z_ref)
        p_ref = n * z_ref / total if total > 0 else 1.0
        p_min = float(p_success.min())
        span = p_ref - p_min
        weights = (p_success - p_min) / span if span > 1e-12 else np.ones(n)  # line 12, eq. 6.27
        spread = float(np.std(weights, ddof=1)) if n > 1 else 0.0  # line 13, eq. 6.29
        threshold = float(np.clip(np.mean(weights) + spread * (1.0 - 2.0 * self.reliability), 0.0, 1.0))  # line 15
        weak = weights < threshold  # lines 16-19
        estimate = self._fuse(x_ref, weights, ~weak)  # line 20 (from the particles that stay)
        self._replace(weak, x_ref, z_ref)
        self.estimate = estimate.pose
        return estimate

    def _replace(self, weak: npt.NDArray[np.bool_], x_ref: Array, z_ref: float) -> None:
        """Weak particles become copies of x_ref; the less coherent x_ref is, the more of them are random."""
        s = self.settings
        count = int(weak.sum())
        if not count:
            return
        random_share = float(np.clip((s.coherent - z_ref) / (s.coherent - s.lost), 0.0, 1.0))
        random = self.rng.random(count) < random_share
        spread = np.array([s.copy_sigma[0], s.copy_sigma[0], s.copy_sigma[1]]) * self._spread()
        new = x_ref[None, :] + self.rng.normal(0.0, 1.0, (count, 3)) * spread
        if random.any():
            new[random] = self.random_poses(int(random.sum()))
        new[:, 2] = wrap(new[:, 2])
        self.particles[weak] = new

    def _fuse(self, x_ref: Array, weights: Array, strong: npt.NDArray[np.bool_]) -> Estimate:
        """E_k of eq. 6.30: x_ref (weight 1) and the strong particles in its neighbourhood, weighted by W."""
        s = self.settings
        near = strong & (np.hypot(self.particles[:, 0] - x_ref[0], self.particles[:, 1] - x_ref[1]) <= s.gate[0])
        near &= np.abs(wrap(self.particles[:, 2] - x_ref[2])) <= s.gate[1]
        poses = np.concatenate([x_ref[None, :], self.particles[near]])
        w = np.concatenate([[1.0], weights[near]])
        mean = weighted_pose(poses, w)
        return Estimate(mean, weighted_covariance(poses, w, mean), dispersion(self.particles))
