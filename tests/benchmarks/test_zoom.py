"""ckm-bench zoom on a tiny size: the contract keys, the figures, and the same work done both ways."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks import zoom
from benchmarks.cli import main


def test_measure_manages_the_same_perceptions_both_ways() -> None:
    row = zoom.measure(3000, updates=40, seed=2)
    assert row["objects"] == 3000 and row["updates"] == 40
    applied = {k: v for k, v in row["zoom_counts"].items() if k != "outside"}
    seen = sum(row["full_counts"].values())
    assert seen == row["perceptions_per_update"] * 40 > 0
    assert sum(applied.values()) + row["zoom_counts"]["outside"] == seen
    assert row["full_counts"]["added"] == 0 == applied["added"]  # every perception is of a known object
    assert 0 < row["zoom_managed_mean"] <= (zoom.ZOOM.max_objects or 0)
    assert row["full_ms"] > 0 and row["zoom_ms"] > 0 and row["zoom_moves"] >= 1


def test_cli_json_carries_sizes_fits_and_figures(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "bench"
    assert main(["zoom", "--json", "--sizes", "200", "2000", "--updates", "20", "--out", str(out)]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert [row["objects"] for row in report["sizes"]] == [200, 2000]
    for row in report["sizes"]:
        assert {"objects", "full_ms", "zoom_ms", "full_model_ms", "zoom_model_ms"} <= set(row)
    assert set(report["model"]) == {"full", "zoom"}
    assert report["lab_tour"]["moves"][0]["reason"] == "start" and report["lab_tour"]["goals"] == 6
    for name in ("zoom_areas.png", "zoom_times.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_options_are_refused() -> None:
    with pytest.raises(SystemExit):
        zoom.run(["--sizes", "0"])
