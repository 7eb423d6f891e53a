"""A laser's beams seen from the robot's centre, for the filters of §6.2.1 (Algorithm 3 and the MCL baseline).

Both filters model a beam as starting at the particle's pose. A laser mounted ``laser`` = (x, y,
yaw) off the base's centre (the URDF's laser joint) sees each hit from there, so each valid beam's
endpoint is re-expressed as a range and a bearing from the centre: the model stays exact whatever
the mount. Invalid beams (REP 117: not finite, or outside [range_min, range_max)) become +inf,
which both filters drop.

This is ``Localizer.robot_beams`` of plugins/navigation/localizer.py, copied: the import contract
keeps plugins/localization below plugins/navigation (it must not import it).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .raycast import LaserSpec

Array = npt.NDArray[np.float64]
Pose = tuple[float, float, float]
NO_RETURN = 1e-4
"""A reading within this of ``range_max`` (m) is the sensor's no-return value (float32 ranges round it)."""


@dataclass(frozen=True)
class LaserBeams:
    """One sweep in the laser's own frame: ranges, their angles and the valid range interval."""

    ranges: Array
    angles: Array
    range_min: float
    range_max: float


def scan_beams(scan: Mapping[str, Any], owner: str) -> LaserBeams:
    """The beams of a ``sensor_msgs/LaserScan`` mapping (its own geometry); ValueError naming ``owner`` if not one."""
    try:
        ranges = np.asarray(scan.get("ranges"), dtype=np.float64)
        start, step = float(scan["angle_min"]), float(scan["angle_increment"])
        lo, hi = float(scan["range_min"]), float(scan["range_max"])
    except (KeyError, TypeError, ValueError):
        raise ValueError(
            f"{owner}: input 'scan' is not a LaserScan (ranges, angle_min, angle_increment, range_min, range_max)"
        ) from None
    if ranges.ndim != 1 or ranges.size == 0 or not step > 0 or not hi > lo or not np.isfinite([start, lo, hi]).all():
        raise ValueError(f"{owner}: input 'scan' has no ranges or a bad geometry (increment {step}, range {lo}–{hi})")
    return LaserBeams(ranges, start + step * np.arange(ranges.size, dtype=np.float64), lo, hi)


def raw_beams(ranges: Array, fov: float, max_range: float) -> LaserBeams:
    """Raw ``ranges`` spread evenly over ``fov`` centred on the laser's heading (2π: a full turn from -π)."""
    angles = LaserSpec(beams=ranges.size, fov=fov, max_range=max_range).angles()
    return LaserBeams(np.asarray(ranges, dtype=np.float64), angles, 0.0, max_range)


def robot_beams(sweep: LaserBeams, laser: Pose, beams: int) -> tuple[Array, Array]:
    """(ranges, bearings) from the robot's centre of ``beams`` evenly spread beams of ``sweep``; invalid ones +inf."""
    index = np.unique(np.linspace(0, sweep.ranges.size - 1, min(beams, sweep.ranges.size)).round().astype(int))
    r = sweep.ranges[index]
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(r) & (r >= sweep.range_min) & (r < sweep.range_max - NO_RETURN)
    angles = sweep.angles[index] + laser[2]
    x = laser[0] + np.where(valid, r, 0.0) * np.cos(angles)
    y = laser[1] + np.where(valid, r, 0.0) * np.sin(angles)
    return np.where(valid, np.hypot(x, y), np.inf), np.where(valid, np.arctan2(y, x), angles)


def reach(range_max: float, laser: Pose) -> float:
    """The longest valid beam seen from the robot's centre: what the filters' models take as their range."""
    return range_max + float(np.hypot(laser[0], laser[1])) + 0.05
