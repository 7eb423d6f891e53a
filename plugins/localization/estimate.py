"""What a localization filter publishes (§6.2, Table 7.1): the pose, its covariance and the localization dispersion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .odometry import wrap

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Estimate:
    """A pose estimate (x, y, yaw), its 3×3 covariance, and the dispersion (m) of the whole particle set."""

    pose: Array
    covariance: Array
    dispersion: float

    def as_message(self) -> dict[str, object]:
        """The PoseEstimate fields a service publishes (plain floats, msgpack-able)."""
        return {
            "x": float(self.pose[0]),
            "y": float(self.pose[1]),
            "yaw": float(self.pose[2]),
            "covariance": [float(v) for v in self.covariance.ravel()],
            "dispersion": float(self.dispersion),
        }


def weighted_pose(poses: Array, weights: Array) -> Array:
    """Weighted mean of poses (P, 3); the heading is the circular mean."""
    w = weights / weights.sum()
    yaw = np.arctan2(np.sum(w * np.sin(poses[:, 2])), np.sum(w * np.cos(poses[:, 2])))
    return np.array([np.sum(w * poses[:, 0]), np.sum(w * poses[:, 1]), yaw])


def weighted_covariance(poses: Array, weights: Array, mean: Array) -> Array:
    """3×3 weighted covariance of poses around ``mean`` (heading differences wrapped)."""
    w = weights / weights.sum()
    diff = poses - mean[None, :]
    diff[:, 2] = wrap(diff[:, 2])
    result: Array = (diff * w[:, None]).T @ diff
    return result


def dispersion(poses: Array, weights: Array | None = None) -> float:
    """The localization dispersion: RMS distance (m) of the particles from their (weighted) centroid."""
    w = np.full(len(poses), 1.0 / len(poses)) if weights is None else weights / weights.sum()
    cx, cy = np.sum(w * poses[:, 0]), np.sum(w * poses[:, 1])
    return float(np.sqrt(np.sum(w * ((poses[:, 0] - cx) ** 2 + (poses[:, 1] - cy) ** 2))))


def best_cluster(poses: Array, weights: Array, cell: float = 0.5, radius: float = 0.75) -> npt.NDArray[np.bool_]:
    """The particles of the heaviest cluster: within ``radius`` of the ``cell``-sized square holding most weight.

    AMCL publishes the mean of its heaviest cluster, not of the whole set, so that two hypotheses
    do not average to a pose between them; this square-binning is the vectorised equivalent.
    """
    ix = np.floor(poses[:, 0] / cell).astype(np.int64)
    iy = np.floor(poses[:, 1] / cell).astype(np.int64)
    ix -= ix.min()
    iy -= iy.min()
    key = ix * (iy.max() + 1) + iy
    members = key == int(np.argmax(np.bincount(key, weights=weights)))
    center_x, center_y = np.mean(poses[members, 0]), np.mean(poses[members, 1])
    result: npt.NDArray[np.bool_] = np.hypot(poses[:, 0] - center_x, poses[:, 1] - center_y) <= radius
    return result


def publish(poses: Array, weights: Array) -> Estimate:
    """The estimate of a weighted particle set: the heaviest cluster's mean and covariance, the set's dispersion."""
    members = best_cluster(poses, weights)
    w = weights[members] + 1e-300
    mean = weighted_pose(poses[members], w)
    return Estimate(mean, weighted_covariance(poses[members], w, mean), dispersion(poses, weights))
