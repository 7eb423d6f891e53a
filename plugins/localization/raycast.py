"""Vectorised laser ray casting on a :class:`~plugins.localization.raster.GridMap` (the scan simulator, §6.2).

Sphere tracing on the distance field: a ray advances by the distance to the nearest obstacle (no
obstacle can be closer), so every ray of every pose advances together in one numpy array and a
few dozen steps reach walls metres away. The last approach is refined by a fixed step below one
cell, so ranges are exact to about half a cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .raster import GridMap

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class LaserSpec:
    """A planar laser: ``beams`` rays spread evenly over ``fov`` (rad) centred on the heading, up to ``max_range`` m."""

    beams: int = 60
    fov: float = 2 * np.pi
    max_range: float = 8.0
    min_range: float = 0.05
    sigma: float = 0.02
    """Standard deviation (m) of the Gaussian range noise of the simulator."""

    def angles(self) -> Array:
        """Beam angles relative to the heading (rad)."""
        if self.fov >= 2 * np.pi - 1e-9:
            return np.linspace(-np.pi, np.pi, self.beams, endpoint=False)
        return np.linspace(-self.fov / 2, self.fov / 2, self.beams)


def cast(grid: GridMap, poses: Array, angles: Array, max_range: float, iterations: int = 64) -> Array:
    """Ranges (P, B) of the rays from ``poses`` (P, 3: x, y, yaw) at relative ``angles`` (B,), capped at ``max_range``.

    A ray starting on an obstacle measures 0.
    """
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    theta = poses[:, 2:3] + angles[None, :]
    dx, dy = np.cos(theta), np.sin(theta)
    x0, y0 = poses[:, 0:1], poses[:, 1:2]
    t = np.zeros_like(theta)
    hit_eps = 0.5 * grid.resolution
    for _ in range(iterations):
        d = grid.distance_at(x0 + t * dx, y0 + t * dy).astype(np.float64)
        moving = (d > hit_eps) & (t < max_range)
        if not moving.any():
            break
        t = np.where(moving, t + np.maximum(d - hit_eps, 0.25 * grid.resolution), t)
    # refine: step forward by a quarter cell until the ray's point is on an occupied cell
    step = 0.25 * grid.resolution
    for _ in range(8):
        d = grid.distance_at(x0 + t * dx, y0 + t * dy).astype(np.float64)
        moving = (d > 0) & (t < max_range)
        if not moving.any():
            break
        t = np.where(moving, t + step, t)
    result: Array = np.minimum(t, max_range)
    return result


def simulate_scan(grid: GridMap, pose: Array, laser: LaserSpec, rng: np.random.Generator) -> Array:
    """One noisy scan (B,) from ``pose``: true ranges plus N(0, sigma²), beams at max range reported as max range."""
    true = cast(grid, np.asarray(pose)[None, :], laser.angles(), laser.max_range)[0]
    noisy = true + rng.normal(0.0, laser.sigma, true.shape)
    measured: Array = np.where(
        true >= laser.max_range, laser.max_range, np.clip(noisy, laser.min_range, laser.max_range)
    )
    return measured
