"""Scan scoring on a likelihood field (Thrun et al. §6.4), shared by both filters, and the scan matcher.

Every beam endpoint of every pose is looked up in the map's distance field in one array operation.
Two scores come out of the same lookup:

- ``amcl_weights``: AMCL's likelihood-field model, ``p = 1 + Σ pz³`` with ``pz = z_hit·N(d; σ) +
  z_rand / max_range`` (AMCL's ``LikelihoodFieldModel``: the cube sharpens the beam likelihoods
  without the over-confidence of their product).
- ``coherence``: the fraction of beams the map explains, ``mean exp(-d²/2σ²)`` in [0, 1]: the
  probability of a successful estimation of the static features, z_i of eq. 6.17.

``match`` is the "coherence system" of eq. 6.22 (decision D81): a correlative scan matcher that
searches a pose window around a seed, coarse to fine, for the pose of maximum coherence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .raster import GridMap

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class FieldModel:
    """Parameters of the likelihood-field model (AMCL's laser_sigma_hit, laser_z_hit, laser_z_rand)."""

    sigma_hit: float = 0.2
    z_hit: float = 0.95
    z_rand: float = 0.05
    max_range: float = 8.0


def endpoint_distances(grid: GridMap, poses: Array, ranges: Array, angles: Array) -> Array:
    """Distance (P, B') from each valid beam endpoint of each pose to the nearest obstacle.

    Beams at max range or beyond are dropped by the caller (``ranges``/``angles`` already filtered).
    Endpoints off the map read 2 m (far from anything).
    """
    theta = poses[:, 2:3] + angles[None, :]
    x = poses[:, 0:1] + ranges[None, :] * np.cos(theta)
    y = poses[:, 1:2] + ranges[None, :] * np.sin(theta)
    result: Array = grid.distance_at(x, y, outside=2.0).astype(np.float64)
    return result


def valid_beams(ranges: Array, angles: Array, max_range: float) -> tuple[Array, Array]:
    """The beams that hit something (range below max range)."""
    keep = np.asarray(ranges) < max_range - 1e-6
    return np.asarray(ranges)[keep], np.asarray(angles)[keep]


def amcl_weights(grid: GridMap, poses: Array, ranges: Array, angles: Array, model: FieldModel) -> Array:
    """AMCL's likelihood-field weight ``1 + Σ pz³`` of each pose (P,)."""
    r, a = valid_beams(ranges, angles, model.max_range)
    if r.size == 0:
        return np.ones(len(poses))
    d = endpoint_distances(grid, poses, r, a)
    pz = model.z_hit * np.exp(-(d * d) / (2 * model.sigma_hit**2)) + model.z_rand / model.max_range
    result: Array = 1.0 + np.sum(pz * pz * pz, axis=1)
    return result


def coherence(grid: GridMap, poses: Array, ranges: Array, angles: Array, sigma: float, max_range: float) -> Array:
    """z_i (eq. 6.17) of each pose (P,): the mean over valid beams of ``exp(-d²/2σ²)``; 0 with no valid beam."""
    r, a = valid_beams(ranges, angles, max_range)
    if r.size == 0:
        return np.zeros(len(poses))
    d = endpoint_distances(grid, poses, r, a)
    result: Array = np.mean(np.exp(-(d * d) / (2 * sigma * sigma)), axis=1)
    return result


def _window(center: Array, half_xy: float, half_yaw: float, steps: int) -> Array:
    offsets = np.linspace(-1.0, 1.0, steps)
    dx, dy, dt = np.meshgrid(offsets * half_xy, offsets * half_xy, offsets * half_yaw, indexing="ij")
    result: Array = center[None, :] + np.stack([dx.ravel(), dy.ravel(), dt.ravel()], axis=1)
    return result


def match(
    grid: GridMap,
    seeds: Array,
    ranges: Array,
    angles: Array,
    sigma: float,
    max_range: float,
    window: tuple[float, float] = (0.3, 0.3),
    levels: int = 3,
    steps: int = 7,
) -> tuple[Array, float]:
    """The pose of maximum coherence near any of ``seeds`` (S, 3), and its coherence (eq. 6.22).

    Each level evaluates a ``steps``³ lattice over ±``window`` (m, rad) around the best pose so far
    and the next level searches a window ``steps - 1`` times smaller around the winner: a
    correlative scan matcher (Olson 2009) on the likelihood field.
    """
    r, a = valid_beams(ranges, angles, max_range)
    seeds = np.atleast_2d(seeds)
    if r.size == 0:
        return seeds[0].copy(), 0.0
    half_xy, half_yaw = window
    candidates = np.concatenate([_window(s, half_xy, half_yaw, steps) for s in seeds])
    best, best_score = seeds[0].copy(), -1.0
    for _ in range(levels):
        d = endpoint_distances(grid, candidates, r, a)
        scores = np.mean(np.exp(-(d * d) / (2 * sigma * sigma)), axis=1)
        k = int(np.argmax(scores))
        if scores[k] > best_score:
            best, best_score = candidates[k].copy(), float(scores[k])
        half_xy, half_yaw = half_xy / (steps - 1) * 2, half_yaw / (steps - 1) * 2
        candidates = _window(best, half_xy, half_yaw, steps)
    best[2] = (best[2] + np.pi) % (2 * np.pi) - np.pi
    return best, best_score
