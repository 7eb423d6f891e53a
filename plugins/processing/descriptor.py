"""The shape descriptor of depth recognition (thesis §7.4.1): a point-cloud cluster → the vector the
KD-tree classifier (``plugin.kdtree-shape-classifier``) searches.

Sizes are measured against the support plane (scale-aware) and profile measures of the visible
surface (view-robust), see ``DESCRIPTOR_FIELDS``. Frames: the camera optical frame, x right,
y down, z forward (metres).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
AnyFloats = npt.NDArray[np.floating[Any]]
Plane = tuple[float, float, float, float]
"""A plane n·p + d = 0 in the camera frame, unit normal n pointing up (towards the camera side)."""

DESCRIPTOR_FIELDS = ("height", "width", "depth", "top_ratio", "hinge_residual", "circle_residual", "curvature")
"""The shape descriptor, in the order of the PCD fields. Lengths are in decimetres, so that 1 cm
weighs as much as 0.1 of a ratio in the KD-tree's Euclidean distance:

- ``height``: top of the cluster above the support plane (99th percentile), dm;
- ``width``: extent across the line of sight, horizontally (1st–99th percentile), dm;
- ``depth``: extent along the line of sight of the middle band (25–75 % of the height), dm;
- ``top_ratio``: width of the top band (above 90 % of the height) over ``width``: near 1 for
  boxes and cylinders, lower for spheres;
- ``hinge_residual``, ``circle_residual``, ``curvature``: how the middle band's horizontal
  profile, seen from above, fits straight faces or an arc (see ``_profile_fits``).

The three sizes make it scale-aware (a desk is no box of Fig. 7.5). All are taken against the
support plane and the horizontal line of sight, so they do not depend on the camera's height or
tilt, and the profile is the median of 8 lateral bins, so neither the number of points
(resolution) nor the sensor's noise weighs much.
"""


def describe(points: npt.ArrayLike, plane: Plane | None) -> FloatArray:
    """The descriptor (``DESCRIPTOR_FIELDS``) of a cluster of camera-frame points standing on ``plane``.

    Without a plane, "up" is the image's up (−y) and heights start at the cluster's lowest point.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if plane is None:
        n = np.array([0.0, -1.0, 0.0])
        h = p @ n
        h -= h.min()
    else:
        n = np.asarray(plane[:3], dtype=np.float64)
        h = p @ n + plane[3]
    centre = p.mean(axis=0)
    view = centre - (centre @ n) * n
    view /= max(float(np.linalg.norm(view)), 1e-9)
    u, v = p @ np.cross(view, n), p @ view
    top = float(np.percentile(h, 99))
    u1, u99 = np.percentile(u, [1, 99])
    width = max(float(u99 - u1), 1e-4)
    body = (h > 0.25 * top) & (h < 0.75 * top)
    if np.count_nonzero(body) < 5:
        body = np.ones_like(h, dtype=bool)
    ub, vb = u[body] - u[body].mean(), v[body] - v[body].mean()
    v1, v99 = np.percentile(vb, [1, 99])
    depth = float(v99 - v1)
    upper = u[h > 0.9 * top]
    top_ratio = float(upper.max() - upper.min()) / width if upper.size > 1 else 0.0
    # The horizontal profile seen from above, as medians of 8 lateral bins (sensor noise averages out).
    lo, hi = float(ub.min()), float(ub.max())
    bins = np.minimum(((ub - lo) / max(hi - lo, 1e-9) * 8).astype(np.intp), 7)
    profile = np.stack([_bin_medians(bins, ub), _bin_medians(bins, vb)], axis=1)
    return np.array([10 * top, 10 * width, 10 * depth, min(top_ratio, 1.5), *_profile_fits(profile, width / 2)])


def _bin_medians(bins: npt.NDArray[np.intp], values: FloatArray) -> FloatArray:
    """The (lower) median of ``values`` in each non-empty bin, by increasing bin."""
    counts = np.bincount(bins)
    counts = counts[counts > 0]
    first = np.cumsum(counts) - counts
    ordered = values[np.lexsort((values, bins))]
    medians: FloatArray = ordered[first + (counts - 1) // 2]
    return medians


def _profile_fits(profile: FloatArray, half: float) -> tuple[float, float, float]:
    """Hinge and circle residuals (×10, over ``half``) and the curvature of the horizontal profile.

    A box's visible faces are straight: one line, or two meeting at its corner, fit them (small
    hinge residual). A cylinder's or sphere's side is an arc (small circle residual). A line is a
    circle of infinite radius, which the algebraic fit cannot reach, so the circle residual is at
    most the line residual: a box seen square on is then small on both, and told by its depth.
    """
    u, v = profile[:, 0], profile[:, 1]
    ones = np.ones_like(u)

    def rms(design: AnyFloats, target: AnyFloats) -> tuple[AnyFloats, float]:
        fit, *_ = np.linalg.lstsq(design, target, rcond=None)
        return fit, float(np.sqrt(np.mean((design @ fit - target) ** 2)))

    line = rms(np.stack([ones, u], axis=1), v)[1]
    hinge = min([line, *(rms(np.stack([ones, u, np.maximum(u - knot, 0.0)], axis=1), v)[1] for knot in u[1:-1])])
    # Kåsa fit: u² + v² = 2au + 2bv + c, radius² = c + a² + b².
    (a, b, c), _ = rms(np.stack([2 * u, 2 * v, ones], axis=1), u * u + v * v)
    radius = math.sqrt(max(c + a * a + b * b, 0.0))
    circle = min(float(np.sqrt(np.mean((np.hypot(u - a, v - b) - radius) ** 2))), line)
    # Curvature: the u² coefficient of a parabola fitted with u and v in half-widths.
    curvature = float(rms(np.stack([ones, u / half, (u / half) ** 2], axis=1), v / half)[0][2])
    return 10 * hinge / half, 10 * circle / half, curvature
