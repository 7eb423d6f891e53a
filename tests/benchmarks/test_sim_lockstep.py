"""``ckm-bench sim``'s lock-step figure (benchmarks.sim_lockstep, D192): a whole system run by
``ckm-run --lockstep`` twice on a private network, its real-time factor without the start-up."""

from __future__ import annotations

from pathlib import Path

from benchmarks import sim as bench
from benchmarks.sim_lockstep import SHORT, STEP, lockstep_factor

ROVER = Path(__file__).resolve().parent.parent / "data" / "lockstep" / "rover.xml"


def test_a_lockstep_run_reports_its_factor_and_start_up() -> None:
    result = lockstep_factor(ROVER, duration=3.0)
    assert result["system"] == "rover.xml" and result["simulated_s"] == 3.0 and result["step_s"] == STEP
    assert result["wall_s"] > 0 and result["startup_wall_s"] > 0
    assert result["factor"] > 0  # (how fast depends on the machine's load: no bound asserted)
    rows = dict(bench.describe({"world_steps_per_s": 1.0, "realtime_factor": 1.0, "render_ms": 0.0,
                                "camera_resolution": {}, "per_resolution": [], "lockstep": result}))  # fmt: skip
    assert any(label.startswith("ckm-run --lockstep 0.01 of rover.xml") for label in rows)
    assert SHORT < 3.0
