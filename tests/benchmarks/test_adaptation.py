"""The adaptation benchmark (§7.2): its workload, its calibration, its report keys and its figures.

A short schedule only (the full one takes minutes): the checks are on structure and on facts
that hold on any machine, never on timings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import adaptation
from benchmarks.adaptation_report import _moments, figures, series, summarize
from benchmarks.cli import main


def test_the_workload_is_the_use_case_rgb_service() -> None:
    resource = adaptation.rgb_resource()
    assert [s.name for s in resource.services] == ["RGBRecog"]
    assert [p.name for p in resource.profiles] == ["VGA", "QVGA", "QQVGA"]
    assert {p.kind for p in resource.plugins} == {
        "camera-acquisition",
        "image-resize",
        "orb-keypoints",
        "keypoint-matching",
    }


def test_scaling_multiplies_every_bound_of_the_measure() -> None:
    resource = adaptation.rgb_resource()
    scaled = adaptation.scaled(resource, {"deadline": 2.0})
    for before, after in zip(resource.services[0].scenarios, scaled.services[0].scenarios, strict=True):
        for p, q in zip(before.policies, after.policies, strict=True):
            factor = 2.0 if p.measure == "deadline" else 1.0
            assert p.upper is not None and q.upper == pytest.approx(p.upper * factor)
            assert q.probability == p.probability


def test_calibration_orders_the_profiles_by_cost() -> None:
    resource = adaptation.rgb_resource()
    costs = adaptation.calibrate(resource, adaptation.camera(6), repeats=1)
    assert set(costs) == {"VGA", "QVGA", "QQVGA"}
    assert costs["VGA"] > costs["QQVGA"] > 0  # CPU time: a fraction of the 4x pixel ratio at least


def test_moments_match_hand_computed_values() -> None:
    moments = _moments([1.0, 2.0, 3.0, 4.0])
    assert moments["variance"] == pytest.approx(1.25)
    assert moments["skewness"] == pytest.approx(0.0)
    assert moments["kurtosis"] == pytest.approx(np.mean((np.arange(1, 5) - 2.5) ** 4) / 1.25**2)


def test_a_short_run_reports_table_7_3_and_writes_the_figures(tmp_path: Path) -> None:
    resource = adaptation.scaled(adaptation.rgb_resource(), {"deadline": 1.0})
    frames = adaptation.camera(6)
    run = adaptation.experiment(resource, frames, (1, 2), 2.5, baseline=False)
    baseline = adaptation.experiment(resource, frames, (1, 2), 2.5, baseline=True)
    assert [count for _, count in run["timeline"]] == [1, 2, 0]
    assert set(run["clients"]) == {"client1", "client2"}
    assert run["frames"]["processed"] > 0
    result = summarize([run], baseline, resource, (1, 2))
    assert [row["clients"] for row in result["clients"]] == [1, 2]
    for row in result["clients"]:
        assert set(row) >= {"clients", "activation", "events", "alarms", "qos_deadline_s", "qoc_cpu", "penalty"}
        assert set(row["activation"]) == {"VGA", "QVGA", "QQVGA"}
        assert sum(row["activation"].values()) == pytest.approx(1.0)
    assert result["switches_tcm"] >= 0 and result["switches_threshold_baseline"] >= 0
    assert all(0.25 <= r["resolution"] <= 1.0 for r in series(run, 0.5))
    paths = figures(run, baseline, resource, tmp_path)
    assert [p.name for p in paths] == ["fig7_8_clients_alarms.png", "fig7_9_results.png", "fig7_10_scatter.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)


def test_cli_rejects_a_bad_schedule(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["adaptation", "--schedule", "0,2"])
    assert "client counts between 1 and 16" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["config", "--phase", "2"])  # options belong to the adaptation benchmark only


def test_json_contract_keys_are_in_the_summary() -> None:
    resource = adaptation.rgb_resource()
    empty = {"timeline": [(0.0, 1)], "clients": {}, "frames": {}}
    result = summarize([empty], empty, resource, (1,))
    assert json.loads(json.dumps(result))["clients"][0]["activation"] == {"VGA": 0.0, "QVGA": 0.0, "QQVGA": 0.0}
    assert {"switches_tcm", "switches_threshold_baseline", "statistics"} <= set(result)
