"""python -m benchmarks.sim_server: the keys of its result, on a quick run (figures are not asserted,
the machine is shared)."""

from __future__ import annotations

import benchmarks.sim_server as bench


def test_quick_run_reports_round_trips_and_blocking() -> None:
    result = bench.run(["--seconds", "0.3", "--quick"])
    assert set(result["round_trip_ms"]) == set(bench.READS)
    for row in result["round_trip_ms"].values():
        assert row["server_ms"] > 0 and row["in_process_ms"] > 0
    for key in ("blocking", "blocking_without_worker"):
        assert result[key]["alone"]["reads"] > 0 and result[key]["with_vga_renders"]["reads"] > 0
        assert result[key]["render_ms"] > 0
    assert len(bench.describe(result)) == len(bench.READS) + 6
