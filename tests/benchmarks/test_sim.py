"""ckm-bench sim: the contract keys, on a short simulated time (figures are not asserted)."""

from __future__ import annotations

import benchmarks.sim as bench
from benchmarks.cli import BENCHMARKS


def test_sim_is_a_benchmark() -> None:
    assert BENCHMARKS["sim"] == ("benchmarks.sim", "run", "describe")


def test_run_reports_the_contract_keys() -> None:
    result = bench.run(duration=0.2)
    assert {"world_steps_per_s", "realtime_factor", "camera_resolution"} <= set(result)
    assert result["world_steps_per_s"] > 0 and result["realtime_factor"] > 0
    assert result["camera_resolution"] == {"xtion_rgb": "VGA", "xtion_depth": "QVGA", "nao_top": "QVGA"}
    assert [row["resolution"] for row in result["per_resolution"]] == ["VGA", "QVGA", "QQVGA"]
    # 0.2 simulated s: the Xtion renders at t = 0, 0.0333 … 0.1665 (the release at 0.1998 falls in
    # the last physics step, which ends the run), the nao's camera at 0, 0.0667 and 0.1334
    assert all(row["renders"] == 6 + 3 for row in result["per_resolution"])
    assert result["periods_s"]["rgb_camera"] == 0.0333
    rows = bench.describe(result)
    assert len(rows) == 2 + 3
