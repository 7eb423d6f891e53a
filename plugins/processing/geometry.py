"""3D geometry of the feature fusion (thesis §6.3.1–6.3.2): sensor poses, observations, distances, MLE.

A 3D sensor's observation is a ``Point`` with a covariance; a 2D sensor's is a ``Ray``, the
projection line of eq. 6.32–6.33 from the sensor's centre f' through the pixel (eq. 6.34 solves
the missing depth with f' and the viewing angle; a pinhole back-projection gives the same line).
A ray is a half-line: features lie in front of the camera, beyond ``min_range``. Its error is
angular (σ rad), so its lateral standard deviation grows with the range: σ·t.

``distance`` is the Mahalanobis distance of eq. 6.38 between an observation and the current
estimate; ``estimate`` is θ̂_MLE of eq. 6.36 over the matched observations, in information form.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Vector = npt.NDArray[np.float64]
Matrix = npt.NDArray[np.float64]

ITERATIONS = 3
"""Re-weightings of the MLE: a ray's lateral σ depends on the range of the estimate it constrains."""


@dataclass(frozen=True)
class Pose:
    """A sensor frame in the common frame: ``p_common = rotation @ p_sensor + translation``."""

    rotation: Matrix
    translation: Vector

    @classmethod
    def from_xyzrpy(cls, x: float, y: float, z: float, roll: float, pitch: float, yaw: float) -> Pose:
        """The pose of translation (x, y, z) and fixed-axis roll, pitch, yaw (R = Rz·Ry·Rx, as ROS/URDF)."""
        cr, sr, cp, sp, cy, sy = (f(a) for a in (roll, pitch, yaw) for f in (math.cos, math.sin))
        rotation = np.array(
            [
                [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                [-sp, cp * sr, cp * cr],
            ]
        )
        return cls(rotation, np.array([x, y, z], dtype=np.float64))

    def point(self, p: Vector) -> Vector:
        """Point ``p`` of the sensor frame in the common frame."""
        return self.rotation @ p + self.translation

    def vector(self, v: Vector) -> Vector:
        """Direction ``v`` of the sensor frame in the common frame (rotated only)."""
        return self.rotation @ v


IDENTITY = Pose(np.eye(3), np.zeros(3))


@dataclass(frozen=True)
class Point:
    """A 3D point observation or estimate (eq. 6.32, P) with its covariance Σ (m²)."""

    mean: Vector
    cov: Matrix


@dataclass(frozen=True)
class Ray:
    """A 2D observation as a 3D projection half-line (eq. 6.32–6.33, L) from ``origin`` along unit ``direction``."""

    origin: Vector
    direction: Vector
    sigma: float
    """Angular standard deviation, radians."""
    min_range: float
    """The nearest a feature can be: ranges are clipped to it (and the lateral σ never reaches 0)."""

    def at(self, t: float) -> Vector:
        """The ray's point at distance ``t`` from its origin."""
        return self.origin + t * self.direction

    def range_of(self, p: Vector) -> float:
        """The (clipped) range of the ray's point closest to ``p``."""
        return max(float((p - self.origin) @ self.direction), self.min_range)

    def lateral(self, t: float) -> float:
        """The lateral standard deviation at range ``t`` (m)."""
        return self.sigma * max(t, self.min_range)


Geometry = Point | Ray


def _perpendicular(u: Vector) -> Matrix:
    """An orthonormal basis (3×2) of the plane perpendicular to unit ``u``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(u, e1)], axis=1)


def _mahalanobis(residual: Vector, cov: Matrix) -> float:
    return math.sqrt(max(float(residual @ np.linalg.solve(cov, residual)), 0.0))


def _point_ray(p: Point, ray: Ray) -> float:
    """Distance of a point to a ray, in the plane across the ray (its error there is σ·t)."""
    t = float((p.mean - ray.origin) @ ray.direction)
    if t < ray.min_range:  # behind or too near: compare with the ray's nearest valid point, in 3D
        s = ray.lateral(ray.min_range)
        return _mahalanobis(p.mean - ray.at(ray.min_range), p.cov + s * s * np.eye(3))
    basis = _perpendicular(ray.direction)
    s = ray.lateral(t)
    return _mahalanobis(basis.T @ (p.mean - ray.origin), basis.T @ p.cov @ basis + s * s * np.eye(2))


def closest_ranges(a: Ray, b: Ray) -> tuple[float, float]:
    """Ranges of the closest points of two rays, both clipped to their ``min_range``."""
    w = a.origin - b.origin
    c, d, e = float(a.direction @ b.direction), float(a.direction @ w), float(b.direction @ w)
    den = 1.0 - c * c
    t = (c * e - d) / den if den > 1e-12 else 0.0  # parallel: any pair, start at a's origin
    t = max(t, a.min_range)
    s = b.range_of(a.at(t))
    return a.range_of(b.at(s)), s


def _ray_ray(a: Ray, b: Ray) -> float:
    t, s = closest_ranges(a, b)
    spread = math.hypot(a.lateral(t), b.lateral(s))
    return float(np.linalg.norm(a.at(t) - b.at(s))) / spread


def distance(a: Geometry, b: Geometry) -> float:
    """The Mahalanobis distance of eq. 6.38 between two observations or estimates (symmetric).

    Eq. 6.38 weighs with the observation's Σ_i only; the estimate is uncertain too, so the
    covariance of the difference (Σ_a + Σ_b) is used: two points from sensors of σ = 3 cm are
    3 "σ" apart at 12.7 cm, not 9 cm.
    """
    if isinstance(a, Point) and isinstance(b, Point):
        return _mahalanobis(a.mean - b.mean, a.cov + b.cov)
    if isinstance(a, Point) and isinstance(b, Ray):
        return _point_ray(a, b)
    if isinstance(a, Ray) and isinstance(b, Point):
        return _point_ray(b, a)
    assert isinstance(a, Ray) and isinstance(b, Ray)
    return _ray_ray(a, b)


def estimate(parts: Sequence[Geometry]) -> Geometry:
    """θ̂_MLE of eq. 6.36, (AᵀΣ⁻¹A)⁻¹AᵀΣ⁻¹x, for the observations ``parts`` of one feature.

    A stacks one block per observation: I₃ for a point (information Σ⁻¹), the projector across
    the ray I − uuᵀ for a ray (information (I − uuᵀ)/(σt)², none along it). The sum is the
    information of the feature's position. A lone ray, or rays that are parallel (one viewpoint),
    leave the range unknown: the estimate is then the first part (x₁) itself.
    """
    points = [g for g in parts if isinstance(g, Point)]
    rays = [g for g in parts if isinstance(g, Ray)]
    if not points and len(rays) < 2:
        return parts[0]
    guess: Vector | None = None
    for _ in range(ITERATIONS):
        info, vector = np.zeros((3, 3)), np.zeros(3)
        for point in points:
            weight = np.linalg.inv(point.cov)
            info += weight
            vector += weight @ point.mean
        for ray in rays:
            s = ray.lateral(ray.range_of(guess)) if guess is not None else ray.sigma  # first pass: unit range
            across = (np.eye(3) - np.outer(ray.direction, ray.direction)) / (s * s)
            info += across
            vector += across @ ray.origin
        eigen = np.linalg.eigvalsh(info)
        if eigen[0] <= 1e-9 * eigen[-1]:
            return parts[0]
        cov = np.linalg.inv(info)
        guess = cov @ vector
    assert guess is not None
    return Point(guess, (cov + cov.T) / 2)
