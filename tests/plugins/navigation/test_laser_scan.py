"""laser-scan (LaserSensor.Scan, Table 7.1): the raw sweep as the lidar sensor publishes it becomes a
complete LaserScan, decimated by the resolution Parameter, with REP 117's invalid values and the
measured scan_time; bad input and bad Parameters are refused naming what is wrong."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from ckmconf.model.kernel import HWChannel
from plugins.navigation.laser_scan import LaserScanService, valid_beams
from runtime.kernel.interfaces import ParamError
from runtime.kernel.vectors import shaper
from runtime.resources import codec
from runtime.resources.spt import Context

from .loop import LIDAR, _laser_types, _no_ros, plugin

STEPS = 683
FOV = 4.1888


def raw(ranges: Any, stamp: float = 100.0) -> dict[str, Any]:
    """A sweep shaped as the hokuyo sensor publishes it on ``hokuyo_raw`` (runtime/kernel/vectors.py)."""
    channel = HWChannel(name="hokuyo", direction="in", kind="stream", backend="sim", units="m", size=STEPS)
    message: dict[str, Any] = shaper(LIDAR, "LaserScan", channel, _laser_types(), _no_ros)(np.asarray(ranges), stamp)
    return message


def sweep() -> np.ndarray:
    return np.linspace(0.5, 4.0, STEPS)


HOKUYO = {"fov": 4.1888, "rangeMin": 0.02, "rangeMax": 5.6}
"""The lab's URG-04LX data sheet (the kind has no default geometry: a scanner's is its own)."""


def service(**params: object) -> LaserScanService:
    made: LaserScanService = plugin("laser-scan", LaserScanService, **{**HOKUYO, **params})
    return made


def test_every_step_at_the_default_resolution_with_the_hokuyo_geometry() -> None:
    scan = service().process(raw(sweep()), Context(0, 1.0))
    assert set(scan) == {f.name for f in _laser_types()["LaserScan"].fields}
    assert scan["ranges"].dtype == np.float32 and scan["ranges"].size == STEPS
    assert np.allclose(scan["ranges"], sweep(), atol=1e-6)
    assert scan["angle_min"] == pytest.approx(-FOV / 2)
    assert scan["angle_max"] == pytest.approx(FOV / 2)
    assert scan["angle_increment"] == pytest.approx(0.00614, abs=1e-5)
    assert (scan["range_min"], scan["range_max"], scan["stamp"]) == (0.02, 5.6, 100.0)
    assert scan["scan_time"] == 0.1  # the Param until two sweeps have been seen
    assert codec.decode(codec.encode(scan))["ranges"].tolist() == scan["ranges"].tolist()


def test_the_resolution_parameter_keeps_every_kth_step() -> None:
    laser = service()
    laser.apply_service_parameters({"resolution": 0.0614})  # Table 7.1's coarsest: every tenth step
    scan = laser.process(raw(sweep()), Context(0, 1.0))
    assert scan["ranges"].size == 69
    assert np.allclose(scan["ranges"], sweep()[::10], atol=1e-6)
    assert scan["angle_increment"] == pytest.approx(10 * FOV / (STEPS - 1))
    assert scan["angle_max"] == pytest.approx(-FOV / 2 + 68 * 10 * FOV / (STEPS - 1))
    assert scan["time_increment"] == pytest.approx(0.1 / STEPS * 10)
    laser.apply_service_parameters({"other": 1})  # not this plugin's: ignored
    assert laser.resolution == 0.0614


def test_invalid_readings_follow_rep_117() -> None:
    ranges = sweep()
    ranges[[0, 1, 2, 3]] = [5.6, 0.01, np.nan, -1.0]  # no return, too close, unusable, unusable
    scan = service().process(raw(ranges), Context(0, 1.0))
    first = scan["ranges"][:5]
    assert first[0] == np.inf and first[1] == -np.inf and math.isnan(first[2]) and math.isnan(first[3])
    assert first[4] == pytest.approx(ranges[4])
    hits, angles = valid_beams(scan, "test")
    assert hits.size == STEPS - 4 and angles[0] == pytest.approx(scan["angle_min"] + 4 * scan["angle_increment"])


def test_scan_time_is_measured_between_sweeps_and_a_gap_is_not_a_sweep() -> None:
    laser = service()
    laser.process(raw(sweep(), 10.0), Context(0, 10.0))
    assert laser.process(raw(sweep(), 10.12), Context(1, 10.12))["scan_time"] == pytest.approx(0.12)
    assert laser.process(raw(sweep(), 15.0), Context(2, 15.0))["scan_time"] == pytest.approx(0.12)


def test_a_raw_scan_with_its_own_geometry_keeps_it() -> None:
    message = raw(sweep())
    message.update(angle_min=-1.0, angle_increment=0.01)
    scan = service().process(message, Context(0, 1.0))
    assert scan["angle_min"] == -1.0 and scan["angle_increment"] == 0.01
    assert scan["angle_max"] == pytest.approx(-1.0 + 0.01 * (STEPS - 1))


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ([1.0, 2.0], "expects the raw LaserScan message"),
        ({"stamp": 1.0}, "has no 'ranges' vector"),
        ({"ranges": "far"}, "has no 'ranges' vector"),
        ({"ranges": [[1.0, 2.0], [3.0, 4.0]]}, "must be a vector of 2 to"),
        ({"ranges": [1.0]}, "must be a vector of 2 to"),
        ({"ranges": ["a", "b"]}, "is not a vector of numbers"),
    ],
)
def test_bad_raw_scans_are_refused(data: Any, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        service().process(data, Context(0, 1.0))


@pytest.mark.parametrize("value", [0.0, -0.01, "fine", True, math.nan])
def test_a_bad_resolution_parameter_is_refused(value: object) -> None:
    laser = service()
    with pytest.raises(ValueError, match="service parameter 'resolution'"):
        laser.apply_service_parameters({"resolution": value})
    assert laser.resolution is None  # still the sweep's own step


def test_bad_params_are_refused_at_construction() -> None:
    with pytest.raises(ParamError, match=r"'rangeMax' = 0\.01 must exceed 'rangeMin'"):
        service(rangeMax=0.01)
    with pytest.raises(ParamError, match="fov"):
        service(fov=7.0)


def test_the_scanner_geometry_has_no_default() -> None:
    """Issue M: a scanner's field of view and range are its data sheet's, never the lab Hokuyo's."""
    for missing in ("fov", "rangeMax"):
        given = {k: v for k, v in HOKUYO.items() if k != missing}
        with pytest.raises(ParamError, match=f"needs parameter '{missing}'"):
            plugin("laser-scan", LaserScanService, **given)


def test_another_scanner_keeps_every_step_at_its_own_geometry() -> None:
    """A 270° scanner of 1081 steps and 30 m (not the lab's): every step, its own increment and range."""
    laser = plugin("laser-scan", LaserScanService, fov=4.7124, rangeMax=30.0)
    ranges = np.linspace(0.5, 29.0, 1081)
    scan = laser.process(raw(ranges), Context(0, 1.0))
    assert scan["ranges"].size == 1081 and scan["range_max"] == 30.0 and scan["range_min"] == 0.0
    assert scan["angle_increment"] == pytest.approx(4.7124 / 1080)
    assert np.isfinite(scan["ranges"]).all()
