"""``ckm-bench rates --run RUN_DIR`` (issue J point 8, D191): the real services' publication rates read
from a recorded run's bag, beside the stand-in device's and the thesis' Table 7.8."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.rates_run import REAL_TOPICS, describe, from_run, run_cli
from runtime.ros.bag import BagRecorder


def _record(bag: Path, periods: dict[str, float], count: int) -> None:
    """A bag as ckm-run --record writes one: each service's messages at its period (publisher stamps)."""
    start = 1_795_000_000.0
    messages = sorted((start + k * periods[topic], topic) for topic in periods for k in range(count))
    with BagRecorder(bag) as recorder:
        for topic in periods:  # only these in the bag
            recorder.add_topic(topic, "std_msgs/msg/Float64")
        for stamp, topic in messages:
            recorder.write(topic, {"data": float(stamp)}, stamp)


def test_a_recorded_runs_services_give_their_rates_and_an_unrecorded_one_says_so(tmp_path: Path) -> None:
    run = tmp_path / "run"
    _record(run / "bag", {"/pantilt/objects": 0.5, "/nav/pose": 0.8}, 21)
    result = from_run(run)
    services = {s["name"]: s for s in result["services"]}
    camera, navigation, fusion = services["Pan-Tilt Camera"], services["Navigation"], services["Global Recog."]
    assert camera["samples"] == 20 and camera["avg_rate_s"] == pytest.approx(0.5) and camera["rate_std_s"] < 1e-6
    assert navigation["avg_rate_s"] == pytest.approx(0.8) and navigation["set_rate_s"] == 0.8
    assert fusion["recorded"] is False and fusion["samples"] == 0
    rows = dict(describe({"real_runs": [result]}))
    assert rows["Global Recog. (real): /recog/objects"] == "not recorded"
    assert rows["Navigation (real, /nav/pose): avg. rate / std."].startswith("0.8000 s")


def test_a_directory_without_a_bag_is_refused_before_any_measurement(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="no bag"):
        from_run(tmp_path)
    with pytest.raises(SystemExit):
        run_cli(["--run", str(tmp_path)])
    assert "--run:" in capsys.readouterr().err


def test_ckm_bench_rates_reads_recorded_runs_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = tmp_path / "run"
    _record(run / "bag", dict.fromkeys(REAL_TOPICS.values(), 0.8), 5)
    assert main(["rates", "--no-stand-in", "--run", str(run), "--json"]) == 0
    out = capsys.readouterr().out
    assert "Global Recog. (real, /recog/objects)" in out and '"real_runs"' in out
