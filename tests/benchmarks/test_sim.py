"""ckm-bench sim: the contract keys, on a short simulated time (figures are not asserted)."""

from __future__ import annotations

import math

import benchmarks.sim as bench
import ckmconf
from benchmarks.cli import BENCHMARKS


def test_sim_is_a_benchmark() -> None:
    assert BENCHMARKS["sim"] == ("benchmarks.sim", "run", "describe")


def _config_periods() -> dict[str, float]:
    """The use case's camera Sensors' periods (s), read from lab.xml (D126 made them 0.5 s)."""
    system = ckmconf.load(bench.USECASE / "lab.xml", strict=False).system
    assert system is not None
    return {s.name: s.period for node in system.nodes for s in node.sensors if s.name in ("rgb_camera", "top_camera")}


def _releases(period: float, duration: float, step: float = 1.0 / 240.0) -> int:
    """Releases of a device at ``period`` in a run of ``duration`` simulated s: at 0, period, 2 period …
    up to the last physics step's start (the bench checks releases before each step)."""
    last = (math.ceil(duration / step - 1e-9) - 1) * step
    return math.floor(last / period + 1e-9) + 1


def test_run_reports_the_contract_keys() -> None:
    periods = _config_periods()
    duration = 0.6  # past the cameras' second release at the use case's periods
    result = bench.run(duration=duration, lockstep_s=0)
    assert {"world_steps_per_s", "realtime_factor", "camera_resolution"} <= set(result)
    assert result["world_steps_per_s"] > 0 and result["realtime_factor"] > 0
    assert result["camera_resolution"] == {"xtion_rgb": "VGA", "xtion_depth": "QVGA", "nao_top": "QVGA"}
    assert [row["resolution"] for row in result["per_resolution"]] == ["VGA", "QVGA", "QQVGA"]
    # the Xtion and the Nao's camera each render once per release of their Sensor's period
    renders = _releases(periods["rgb_camera"], duration) + _releases(periods["top_camera"], duration)
    assert all(row["renders"] == renders for row in result["per_resolution"])
    assert result["periods_s"]["rgb_camera"] == periods["rgb_camera"]
    assert result["periods_s"]["top_camera"] == periods["top_camera"]
    rows = bench.describe(result)
    assert len(rows) == 2 + 3
