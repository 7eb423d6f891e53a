"""The odometry motion model (Thrun, Burgard & Fox, Probabilistic Robotics §5.4), vectorised.

A displacement between two poses is decomposed into a first rotation, a translation and a second
rotation; noise on each has variance ``a1·rot² + a2·trans²`` (rotations) and ``a3·trans² +
a4·(rot1² + rot2²)`` (translation), as AMCL's ``diff`` model with alpha1..alpha4. The simulator
uses it to corrupt the true motion, the filters to spread their particles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def wrap(angle: Array | float) -> Array:
    """Angles wrapped to [-π, π)."""
    result: Array = (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi
    return result


@dataclass(frozen=True)
class OdometryNoise:
    """alpha1..alpha4 of the odometry motion model (AMCL's odom_alpha1..4; variances per unit squared)."""

    rot_rot: float = 0.02
    rot_trans: float = 0.02
    trans_trans: float = 0.02
    trans_rot: float = 0.02

    def scaled(self, factor: float) -> OdometryNoise:
        """The same model with every variance multiplied by ``factor``² (standard deviations by ``factor``)."""
        f2 = factor * factor
        return OdometryNoise(self.rot_rot * f2, self.rot_trans * f2, self.trans_trans * f2, self.trans_rot * f2)


def decompose(before: Array, after: Array) -> tuple[Array, Array, Array]:
    """(rot1, trans, rot2) of the motion from ``before`` to ``after`` (…, 3 arrays)."""
    dx, dy = after[..., 0] - before[..., 0], after[..., 1] - before[..., 1]
    trans = np.hypot(dx, dy)
    rot1 = np.where(trans < 1e-6, 0.0, wrap(np.arctan2(dy, dx) - before[..., 2]))
    rot2 = wrap(after[..., 2] - before[..., 2] - rot1)
    return rot1, trans, rot2


def sample_motion(
    poses: Array, odom_before: Array, odom_after: Array, noise: OdometryNoise, rng: np.random.Generator
) -> Array:
    """``poses`` (P, 3) moved by the odometry displacement ``odom_before → odom_after``, one noise draw each."""
    rot1, trans, rot2 = decompose(np.asarray(odom_before), np.asarray(odom_after))
    # backwards motion: AMCL takes the smaller of the heading change and its opposite for the noise
    r1, r2 = np.minimum(np.abs(rot1), np.pi - np.abs(rot1)), np.minimum(np.abs(rot2), np.pi - np.abs(rot2))
    n = len(poses)
    sd_rot1 = np.sqrt(noise.rot_rot * r1 * r1 + noise.rot_trans * trans * trans)
    sd_trans = np.sqrt(noise.trans_trans * trans * trans + noise.trans_rot * (r1 * r1 + r2 * r2))
    sd_rot2 = np.sqrt(noise.rot_rot * r2 * r2 + noise.rot_trans * trans * trans)
    h1 = rot1 - rng.normal(0.0, 1.0, n) * sd_rot1
    t = trans - rng.normal(0.0, 1.0, n) * sd_trans
    h2 = rot2 - rng.normal(0.0, 1.0, n) * sd_rot2
    heading = poses[:, 2] + h1
    moved = np.empty_like(poses)
    moved[:, 0] = poses[:, 0] + t * np.cos(heading)
    moved[:, 1] = poses[:, 1] + t * np.sin(heading)
    moved[:, 2] = wrap(heading + h2)
    return moved


class OdometrySimulator:
    """Integrates noisy odometry along a true trajectory (what a wheel encoder would report)."""

    def __init__(self, start: Array, noise: OdometryNoise, rng: np.random.Generator) -> None:
        self.noise = noise
        self.rng = rng
        self.reading = np.asarray(start, dtype=np.float64).copy()

    def step(self, true_before: Array, true_after: Array) -> Array:
        """The new odometry reading after the robot moved from ``true_before`` to ``true_after``."""
        self.reading = sample_motion(self.reading[None, :], true_before, true_after, self.noise, self.rng)[0]
        return self.reading.copy()
