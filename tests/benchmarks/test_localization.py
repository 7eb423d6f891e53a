"""``ckm-bench localization`` (issue I point 6): the JSON contract and the plot, on a small particle count."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import BENCHMARKS, TAKES_OPTIONS, main
from benchmarks.localization_worlds import aisles_grid, aisles_routes, drive
from plugins.localization.raycast import LaserSpec, cast

KEYS = {
    "name",
    "particles",
    "beams",
    "rmse_m",
    "heading_rmse_rad",
    "converge_s",
    "recover_s",
    "failure_rate",
    "ms_per_update",
}


def test_bench_reports_both_filters_per_particle_count(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "localization" in BENCHMARKS and "localization" in TAKES_OPTIONS
    out = tmp_path / "bench"
    assert main(["localization", "--json", "--seeds", "1", "--particles", "200", "--out", str(out)]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    rows = result["filters"]
    assert [(r["name"], r["particles"]) for r in rows] == [("reliability", 200), ("mcl", 200)]
    for row in rows:
        assert set(row) >= KEYS
        assert row["beams"] == 60
        assert 0.0 <= row["failure_rate"] <= 1.0
        assert row["ms_per_update"] > 0
        assert row["recover_s"] is None or row["recover_s"] >= 0
        assert set(row["worlds"]) == {"lab", "floor-plan", "aisles"}
        for world in row["worlds"].values():  # global localization per world: 2 runs each (tour, kidnapping)
            assert world["runs"] == 2 and 0.0 <= world["converged_rate"] <= 1.0
            assert 0.0 <= world["failure_rate"] <= 1.0 and world["failure_rate"] >= 1.0 - world["converged_rate"]
    assert result["runs"] == ["lab-tour", "lab-kidnap", "floor-plan-tour", "floor-plan-kidnap", "aisles-tour",
                              "aisles-kidnap"]
    assert (out / "localization-error.png").stat().st_size > 10_000
    assert json.loads((out / "results.json").read_text())["filters"] == rows


def test_bench_runs_a_larger_floor_plan_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    argv = ["localization", "--json", "--seeds", "1", "--particles", "100", "--worlds", "floor-plan", "--rooms", "4",
            "--out", str(out)]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["runs"] == ["floor-plan-tour", "floor-plan-kidnap"] and result["rooms"] == 4
    assert all(set(row["worlds"]) == {"floor-plan"} for row in result["filters"])
    with pytest.raises(SystemExit) as refused:
        main(["localization", "--rooms", "1", "--out", str(out)])
    assert refused.value.code == 2 and "--rooms must be at least 2" in capsys.readouterr().err


def test_the_aisles_repeat_and_their_routes_keep_clear_of_the_racks() -> None:
    """The warehouse aliases: a robot in the middle of one rack segment sees what it sees one segment on, or
    one aisle over; every pose of its tour and kidnapping legs keeps 0.3 m from the racks."""
    grid = aisles_grid()
    for route in aisles_routes():
        poses = drive(route)
        assert grid.is_free(poses[:, 0], poses[:, 1], clearance=0.3).all()
    laser = LaserSpec()
    here, one_on, one_over = ((3.5, 3.3, 0.0), (6.9, 3.3, 0.0), (6.9, 6.1, 0.0))
    scans = cast(grid, np.array([here, one_on, one_over]), laser.angles(), laser.max_range)
    assert np.median(np.abs(scans[0] - scans[1])) < 0.05 and np.median(np.abs(scans[1] - scans[2])) < 0.05
