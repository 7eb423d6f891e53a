"""``plugin.laser-scan``: the Laser Sensor's Scan service (thesis §7.1, Table 7.1: Scan_time, Resolution).

Input: the raw sweep the lidar's sensor publishes — a ``LaserScan`` whose only filled fields may be
``stamp`` and ``ranges`` (one value per step, the shape runtime/kernel/vectors.py gives a vector
read; decision D99). The sweep's geometry is the scanner's own and so the plugin's required Params
(``fov``, ``rangeMax``; the lab's Hokuyo URG-04LX has 683 steps over 240° and 0.02–5.6 m), unless
the raw message carries a non-zero ``angle_increment`` of its own.

Output: a ``sensor_msgs/LaserScan`` with every field filled, as ROS's urg_node publishes it. The
Param ``resolution`` or the service Parameter of that name (rad, Table 7.1 "Resolution") decimates
the sweep: every k-th step with k = round(resolution / native step), so the native step keeps every
step and ten times it every tenth; without either, every step is kept. Invalid readings follow
REP 117: no return (a reading at or beyond ``rangeMax``) is +inf, too close (below ``rangeMin``) is
-inf, an unusable value (NaN, negative) is NaN — consumers keep only finite ranges within [range_min, range_max).

``scan_time`` (s) is the time between the last two sweeps, measured on their stamps (the
``scanTime`` Param until two have arrived): the Table 7.1 quality measure, which a lagging
sensor or a late acquisition raises. It is a field of the LaserScan message, so the one-output
service publishes the message and the runtime reads the measure from the same field.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from ckmconf.model.resources import Plugin
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context, ProcessingPlugin
from runtime.verification.manifest import MAPPING, REQUIRED, P, Params, Ports

MAX_STEPS = 100_000
"""Most steps a sweep may hold (a URG-04LX has 683, a UTM-30LX 1081)."""
NO_RETURN = 1e-4
"""A reading within this of ``rangeMax`` (m) is the sensor's no-return value (float32 ranges round it)."""


class LaserScanService(ProcessingPlugin):
    """``plugin.laser-scan``: a raw lidar sweep as a decimated, ROS-style LaserScan.

    Params: ``fov`` (rad), ``rangeMin``/``rangeMax`` (m), ``scanTime`` (s, one sweep), ``resolution``
    (rad, the default angular step; the service Parameter ``resolution`` overrides it at run time).
    """

    PORTS = Ports(inputs={"*": MAPPING}, outputs={"*": MAPPING})
    PROVIDES = "laser-scan"  # docs/interfaces.md
    PARAMS: ClassVar[Mapping[str, Any]] = Params(
        P("fov", REQUIRED, "Field of view of the raw sweep, steps spread evenly from -fov/2 to +fov/2 "
          "(the scanner's data sheet).", type=float, unit="rad", above=0.0, max=2 * math.pi),
        P("rangeMin", 0.0, "Shortest valid range (the scanner's data sheet).", unit="m", min=0.0),
        P("rangeMax", REQUIRED, "Longest valid range: a reading at it is no return (the scanner's data sheet).",
          type=float, unit="m", above=0.0),
        P("scanTime", 0.1, "Duration of one sweep, until measured from the stamps.", unit="s", above=0.0),
        P("resolution", None, "Angular step of the output (Table 7.1 Resolution; default: the sweep's own "
          "step, every step kept); the service Parameter 'resolution' overrides it.", type=float, unit="rad",
          above=0.0),
    )

    def __init__(self, record: Plugin) -> None:
        super().__init__(record)
        p = self.params
        if not p["rangeMax"] > p["rangeMin"]:
            raise ParamError(
                f"{self.owner}: parameter 'rangeMax' = {p['rangeMax']} must exceed 'rangeMin' = {p['rangeMin']}"
            )
        self.resolution: float | None = (
            None if p["resolution"] is None else self._resolution(p["resolution"], "parameter 'resolution'")
        )
        self._last_stamp: float | None = None
        self.scan_time: float = p["scanTime"]

    def _resolution(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"{self.owner}: {where} = {value!r} must be a positive angle in rad")
        return float(value)

    def apply_service_parameters(self, parameters: Mapping[str, Any]) -> None:
        """The service's ``resolution`` Parameter (Table 7.1) sets the output's angular step."""
        if "resolution" in parameters:
            self.resolution = self._resolution(parameters["resolution"], "service parameter 'resolution'")

    def _ranges(self, raw: Mapping[str, Any]) -> npt.NDArray[np.float64]:
        values = raw.get("ranges")
        if values is None or isinstance(values, str | bytes | Mapping):
            raise ValueError(f"{self.owner}: the raw scan has no 'ranges' vector (got {type(values).__name__})")
        try:
            ranges = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{self.owner}: the raw scan's 'ranges' is not a vector of numbers") from None
        if ranges.ndim != 1 or not 2 <= ranges.size <= MAX_STEPS:
            raise ValueError(f"{self.owner}: the raw scan's 'ranges' must be a vector of 2 to {MAX_STEPS} "
                             f"values, got shape {ranges.shape}")
        return ranges

    def _geometry(self, raw: Mapping[str, Any], steps: int) -> tuple[float, float]:
        """(angle_min, native step) of the raw sweep: its own when it carries them, else the Params'."""
        increment, start = raw.get("angle_increment"), raw.get("angle_min")
        if (isinstance(increment, int | float) and isinstance(start, int | float) and not isinstance(increment, bool)
                and math.isfinite(increment) and increment > 0 and math.isfinite(start)):
            return float(start), float(increment)
        fov = self.params["fov"]
        return -fov / 2, fov / (steps - 1)

    def _stamp(self, raw: Mapping[str, Any], context: Context) -> float:
        stamp = raw.get("stamp")
        if isinstance(stamp, int | float) and not isinstance(stamp, bool) and math.isfinite(stamp) and stamp > 0:
            return float(stamp)
        return context.stamp

    def process(self, data: Any, context: Context) -> dict[str, Any]:
        """The LaserScan of one raw sweep (see the module docstring)."""
        if not isinstance(data, Mapping):
            raise ValueError(f"{self.owner} expects the raw LaserScan message (a mapping), got {type(data).__name__}")
        ranges = self._ranges(data)
        start, native = self._geometry(data, ranges.size)
        stamp = self._stamp(data, context)
        if self._last_stamp is not None and 0 < stamp - self._last_stamp < 10 * self.params["scanTime"]:
            self.scan_time = stamp - self._last_stamp  # a gap (sensor restart) is not a sweep time
        self._last_stamp = stamp
        every = 1 if self.resolution is None else max(1, round(self.resolution / native))
        kept = ranges[::every]
        lo, hi = self.params["rangeMin"], self.params["rangeMax"]
        out = kept.copy()
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(kept) | (kept < 0)
            out[(kept >= hi - NO_RETURN) & ~bad] = np.inf
            out[(kept < lo) & ~bad] = -np.inf
        out[bad] = np.nan
        intensities = data.get("intensities")
        levels = np.asarray(intensities, dtype=np.float32) if intensities is not None else np.zeros(0, np.float32)
        levels = levels[::every] if levels.ndim == 1 and levels.size == ranges.size else np.zeros(0, np.float32)
        increment = native * every
        sweep = self.params["scanTime"]
        return {
            "stamp": stamp,
            "angle_min": float(start),
            "angle_max": float(start + increment * (kept.size - 1)),
            "angle_increment": float(increment),
            "time_increment": float(sweep / ranges.size * every),
            "scan_time": float(self.scan_time),
            "range_min": float(lo),
            "range_max": float(hi),
            "ranges": out.astype(np.float32),
            "intensities": levels,
        }


def valid_beams(scan: Mapping[str, Any], owner: str) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(ranges, angles) of the beams of a LaserScan message that hit something (REP 117: finite, in range)."""
    try:
        ranges = np.asarray(scan.get("ranges"), dtype=np.float64)
        start, step = float(scan["angle_min"]), float(scan["angle_increment"])
        lo, hi = float(scan["range_min"]), float(scan["range_max"])
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"{owner}: the scan is not a LaserScan (ranges, angle_min, angle_increment, "
                         f"range_min, range_max)") from None
    if ranges.ndim != 1 or ranges.size == 0 or not step > 0 or not hi > lo:
        raise ValueError(f"{owner}: the scan has no ranges or a bad geometry (increment {step}, range {lo}–{hi})")
    angles = start + step * np.arange(ranges.size, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        keep = np.isfinite(ranges) & (ranges >= lo) & (ranges < hi - NO_RETURN)
    return ranges[keep], angles[keep]
