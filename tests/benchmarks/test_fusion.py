"""``ckm-bench fusion`` (issue J point 7): the JSON contract, the tables and the plots, on a few renders."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import BENCHMARKS, TAKES_OPTIONS, main

METHOD_KEYS = {"detected", "accuracy", "recall", "mean", "std"}


def test_bench_reports_every_object_and_method(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert "fusion" in BENCHMARKS and "fusion" in TAKES_OPTIONS
    out = tmp_path / "bench"
    argv = ["fusion", "--json", "--observations", "3", "--approach-steps", "3", "--out", str(out)]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    names = [o["name"] for o in result["objects"]]
    assert names == ["cylinder_red_stripes", "cylinder_blue_dots", "cylinder_green_checker", "box_cereal", "box_orange"]
    for obj in result["objects"]:
        assert obj["observations"] == 3
        for method in ("depth", "rgb", "fused"):
            assert set(obj[method]) == METHOD_KEYS and 0.0 <= obj[method]["detected"] <= 1.0
        assert 0.0 <= obj["fused_at_bound"] <= obj["fused_near_bound"] <= 1.0
        assert set(obj["paired"]) == {"views", "depth", "rgb", "fused"}
    track = result["approach"]["track"]
    assert [row["step"] for row in track] == [0, 1, 2]
    assert track[0]["distance"] == pytest.approx(1.8, abs=0.01)
    assert track[-1]["distance"] == pytest.approx(0.6, abs=0.01)
    assert result["renders"] >= 3 + 3 and result["ms_per_render"] > 0
    for png in result["plots"]:
        assert Path(png).stat().st_size > 10_000
    assert json.loads((out / "results.json").read_text()) == result
    assert "cylinders told apart" in (out / "results.txt").read_text()


def test_bench_refuses_bad_options(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["fusion", "--observations", "0"])
    assert "--observations must be at least 1" in capsys.readouterr().err
