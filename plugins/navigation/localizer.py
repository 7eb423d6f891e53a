"""Localization of the Navigation service on its map (thesis §6.2.1, Algorithm 3; Table 7.1 AMCL).

Wraps the two filters of ``plugins/localization`` — Algorithm 3 (``reliability``) or the AMCL-like
baseline (``mcl``) — for LaserScan and Odometry messages:

- the scan's beams are thinned to ``beams`` evenly spread ones (AMCL's ``laser_max_beams``), the
  invalid ones (REP 117: not finite, or outside [range_min, range_max)) become +inf, which both
  filters drop, and the valid ones are moved from the laser's frame to the robot's (the Hokuyo is
  mounted ``laser_pose`` off the base's centre: each endpoint is re-expressed as a range and a
  bearing from the centre, so the filters' "beams from the pose" model stays exact);
- the filter moves its particles by the odometry increment and weighs them by the scan;
- the map→odom correction is E ⊕ odom⁻¹ (E the estimate in the map frame): what re-anchors a
  map-frame path in the odometry frame, and what dead-reckons the estimate between scans;
- beams that hit something the map lacks are ignored (decision D235): seen from the dead-reckoned
  pose, a beam more than ``unmapped`` metres shorter than the map's ray in its direction whose
  endpoint is more than ``unmapped`` metres from every mapped obstacle (a crate dropped in the
  corridor, a person). A 0.5 m crate 1 m ahead fills a quarter of the scan; scored as unexplained,
  it lowered every particle's coherence below Algorithm 3's trust level, random particles replaced
  the weak ones and the estimate jumped metres away. When more than half of the valid beams look
  so, the prediction is more likely off than the world crowded, and every beam is kept.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from plugins.localization.estimate import Estimate
from plugins.localization.likelihood import FieldModel, endpoint_distances
from plugins.localization.mcl import AmclFilter, MclSettings
from plugins.localization.raster import GridMap
from plugins.localization.raycast import cast
from plugins.localization.reliability_filter import ReliabilityFilter, ReliabilitySettings

from .frames import Pose, compose, inverse, wrap
from .laser_scan import NO_RETURN, valid_beams

Array = npt.NDArray[np.float64]
FILTERS = ("reliability", "mcl")
UNMAPPED_SHARE = 0.5
"""More of the valid beams than this look unmapped: trust them all (the prediction is off, D235)."""


def tuple_pose(values: Any) -> Pose:
    """Three numbers as a pose; ValueError otherwise."""
    x, y, yaw = (float(v) for v in values)
    return x, y, yaw


class Localizer:
    """One filter on one map, fed with Odometry poses and LaserScan messages."""

    def __init__(
        self, grid: GridMap, kind: str, *, particles: int, beams: int, laser: Pose, range_max: float, seed: int,
        owner: str = "localizer", unmapped: float = 0.0,
    ) -> None:
        if kind not in FILTERS:
            raise ValueError(f"{owner}: filter {kind!r} is not one of {', '.join(FILTERS)}")
        self.grid, self.kind, self.beams, self.laser, self.owner = grid, kind, beams, laser, owner
        rng = np.random.default_rng(seed)
        reach = range_max + float(np.hypot(laser[0], laser[1])) + 0.05  # a valid beam, seen from the centre
        self.reach, self.unmapped = reach, unmapped
        self.ignored = 0
        """Beams of the last scan ignored as hitting something the map lacks (D235)."""
        self.filter: AmclFilter | ReliabilityFilter
        if kind == "mcl":
            settings = MclSettings(particles=particles, min_particles=min(500, particles),
                                   field=FieldModel(max_range=reach))
            self.filter = AmclFilter(grid, np.zeros(1), settings, rng)
        else:
            self.filter = ReliabilityFilter(
                grid, np.zeros(1), ReliabilitySettings(particles=particles, max_range=reach), rng
            )
        self.estimate: Estimate | None = None
        self.correction: Pose | None = None
        """map→odom: the map-frame pose of the odometry frame's origin."""
        self.odom: Pose | None = None

    def reset(self, pose: Pose | None, spread: tuple[float, float]) -> None:
        """A Gaussian prior of ``spread`` (m, rad) around ``pose``, or a uniform one (global localization)."""
        self.filter.reset(None if pose is None else np.array(pose, dtype=np.float64), spread)
        self.estimate, self.correction = None, None

    def robot_beams(self, scan: Mapping[str, Any]) -> tuple[Array, Array]:
        """(ranges, bearings) from the robot's centre of ``beams`` evenly spread beams; invalid ones +inf."""
        ranges = np.asarray(scan.get("ranges"), dtype=np.float64)
        valid_beams(scan, self.owner)  # checks the message's fields and geometry
        start, step = float(scan["angle_min"]), float(scan["angle_increment"])
        index = np.unique(np.linspace(0, ranges.size - 1, min(self.beams, ranges.size)).round().astype(int))
        r = ranges[index]
        lo, hi = float(scan["range_min"]), float(scan["range_max"])
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(r) & (r >= lo) & (r < hi - NO_RETURN)
        angles = start + step * index + self.laser[2]
        x = self.laser[0] + np.where(valid, r, 0.0) * np.cos(angles)
        y = self.laser[1] + np.where(valid, r, 0.0) * np.sin(angles)
        return np.where(valid, np.hypot(x, y), np.inf), np.where(valid, np.arctan2(y, x), angles)

    def endpoints(self, scan: Mapping[str, Any], pose: Pose) -> Array:
        """Map-frame points (k, 2) where the scan's valid beams hit, the robot at ``pose``."""
        r, a = valid_beams(scan, self.owner)
        laser = compose(pose, self.laser)
        theta = laser[2] + a
        return np.stack([laser[0] + r * np.cos(theta), laser[1] + r * np.sin(theta)], axis=1)

    def unmapped_beams(self, ranges: Array, bearings: Array, odom: Pose) -> npt.NDArray[np.bool_]:
        """Per beam: did it hit something the map lacks, seen from the dead-reckoned pose (D235)?"""
        mask = np.zeros(ranges.shape, dtype=bool)
        valid = np.isfinite(ranges)
        if not self.unmapped > 0 or self.correction is None or not valid.any():
            return mask
        pose = np.array(compose(self.correction, odom), dtype=np.float64)[None, :]
        r, b = ranges[valid], bearings[valid]
        expected = cast(self.grid, pose, b, self.reach)[0]
        far = endpoint_distances(self.grid, pose, r, b)[0]
        short = (r < expected - self.unmapped) & (far > self.unmapped)
        if short.sum() > UNMAPPED_SHARE * valid.sum():
            return mask
        mask[np.flatnonzero(valid)[short]] = True
        return mask

    def update(self, odom: Pose, scan: Mapping[str, Any] | None) -> Estimate | None:
        """One step: the filter on the odometry increment and ``scan``; without a scan, dead reckoning."""
        if scan is None:
            if self.correction is not None and self.estimate is not None:
                moved = compose(self.correction, odom)
                self.estimate = Estimate(np.array(moved), self.estimate.covariance, self.estimate.dispersion)
            self.odom = odom
            return self.estimate
        ranges, bearings = self.robot_beams(scan)
        unmapped = self.unmapped_beams(ranges, bearings, odom)
        self.ignored = int(unmapped.sum())
        ranges = np.where(unmapped, np.inf, ranges)
        self.filter.angles = bearings  # this scan's beams (both filters read them at each update)
        self.estimate = self.filter.update(np.array(odom, dtype=np.float64), ranges)
        pose = self.estimate.pose
        self.correction = compose((float(pose[0]), float(pose[1]), float(wrap(float(pose[2])))), inverse(odom))
        self.odom = odom
        return self.estimate

    def state(self) -> dict[str, Any]:
        """The filter's particles, memory and random generator, and the last estimate (codec-able)."""
        f = self.filter
        rng = f.rng.bit_generator.state  # PCG64's 128-bit integers travel as text (msgpack has 64 bits)
        state: dict[str, Any] = {
            "kind": self.kind, "particles": f.particles.copy(),
            "odometry": None if f.odometry is None else f.odometry.copy(),
            "rng": {"state": str(rng["state"]["state"]), "inc": str(rng["state"]["inc"]),
                    "has_uint32": int(rng["has_uint32"]), "uinteger": int(rng["uinteger"])},
            "estimate": None if self.estimate is None else {
                "pose": self.estimate.pose.copy(), "covariance": np.asarray(self.estimate.covariance).copy(),
                "dispersion": float(self.estimate.dispersion)},
            "correction": None if self.correction is None else list(self.correction),
            "odom": None if self.odom is None else list(self.odom),
        }
        if isinstance(f, AmclFilter):
            state.update(weights=f.weights.copy(), w_slow=f.w_slow, w_fast=f.w_fast)
        else:
            state.update(reliability=f.reliability, filter_estimate=None if f.estimate is None else f.estimate.copy())
        return state

    def restore(self, state: Mapping[str, Any]) -> None:
        """Go on from :meth:`state` (of a localizer with the same filter); KeyError/ValueError if it is not one."""
        if state["kind"] != self.kind:
            raise ValueError(f"a {state['kind']!r} filter's state, not a {self.kind!r} one")
        f = self.filter
        particles = np.asarray(state["particles"], dtype=np.float64)
        if particles.ndim != 2 or particles.shape[1] != 3:
            raise ValueError(f"particles of shape {particles.shape}, not (n, 3)")
        f.particles = particles.copy()
        f.odometry = None if state["odometry"] is None else np.asarray(state["odometry"], dtype=np.float64)
        rng = state["rng"]
        f.rng.bit_generator.state = {
            "bit_generator": "PCG64", "state": {"state": int(rng["state"]), "inc": int(rng["inc"])},
            "has_uint32": int(rng["has_uint32"]), "uinteger": int(rng["uinteger"]),
        }
        estimate = state["estimate"]
        self.estimate = None if estimate is None else Estimate(
            np.asarray(estimate["pose"], dtype=np.float64), np.asarray(estimate["covariance"], dtype=np.float64),
            float(estimate["dispersion"]))
        self.correction = None if state["correction"] is None else tuple_pose(state["correction"])
        self.odom = None if state["odom"] is None else tuple_pose(state["odom"])
        if isinstance(f, AmclFilter):
            f.weights = np.asarray(state["weights"], dtype=np.float64)
            f.w_slow, f.w_fast = float(state["w_slow"]), float(state["w_fast"])
        else:
            f.reliability = float(state["reliability"])
            kept = state["filter_estimate"]
            f.estimate = None if kept is None else np.asarray(kept, dtype=np.float64)

    @property
    def reliability(self) -> float | None:
        """R of eq. 6.21 (Algorithm 3), None for the baseline."""
        return self.filter.reliability if isinstance(self.filter, ReliabilityFilter) else None
