"""``ckm-mission validate`` and ``ckm-mission report`` from the outside (the DESIGN contract)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from runtime.missions.cli import main, top_missions

REPO = Path(__file__).resolve().parents[3]
LAB = REPO / "configs" / "usecase" / "lab.xml"
DATA = REPO / "tests" / "data" / "missions"


def test_the_use_case_missions_are_coherent_with_full_coverage(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(LAB), "--json"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    report = json.loads(lines[-1])
    assert report["ok"] is True
    assert [m["mission"] for m in report["missions"]] == ["Agent1Fetch", "Agent1FetchCoop", "Agent2Spot"]
    for mission in report["missions"]:
        assert mission["coverage"] == {"states": 1.0, "transitions": 1.0}
        assert [f for f in mission["findings"] if f["severity"] == "error"] == []
    assert "Agent1Fetch: coherent; coverage 100% of states, 100% of transitions" in lines[0]


@pytest.mark.parametrize(
    ("name", "kind"),
    [
        ("unreachable_state.xml", "unreachable-state"),
        ("non_terminating.xml", "non-terminating"),
        ("dead_end.xml", "dead-end"),
        ("shadowed_transition.xml", "shadowed-transition"),
        ("unmeetable_requirement.xml", "unmeetable-requirement"),
        ("low_probability.xml", "quality-flow"),
    ],
)
def test_each_defect_kind_is_rejected_with_its_location(name: str, kind: str) -> None:
    path = DATA / name
    result = subprocess.run(
        [sys.executable, "-m", "runtime.missions.cli", "validate", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 1, result.stdout + result.stderr
    located = [line for line in result.stdout.splitlines() if f"[{kind}]" in line]
    assert located and located[0].startswith(f"{path}:"), result.stdout
    assert "NOT coherent" in result.stdout


def test_the_shadowed_transition_is_also_left_uncovered_by_the_fake_interaction(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["validate", str(DATA / "shadowed_transition.xml"), "--json"]) == 1
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    kinds = {f["kind"] for m in report["missions"] for f in m["findings"]}
    assert {"shadowed-transition", "uncovered-transition"} <= kinds


def test_bad_input_is_one_clear_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(LAB), "--mission", "Nope"]) == 1
    assert "no mission 'Nope'" in capsys.readouterr().err
    broken = tmp_path / "broken.xml"
    broken.write_text("<System")
    assert main(["validate", str(broken)]) == 1
    assert "broken.xml:1" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "missing")]) == 1
    assert "no such run directory" in capsys.readouterr().err


def test_validation_runs_are_recorded_and_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(LAB), "--mission", "Agent2Spot", "--run-dir", str(tmp_path)]) == 0
    episode = tmp_path / "Agent2Spot" / "episode-1"
    assert main(["report", str(episode), "--out", str(tmp_path / "fig")]) == 0
    out = capsys.readouterr().out
    assert "OBJ_TRACK" in out and "OBJ_FIX" in out
    assert (tmp_path / "fig" / "mission-validation.png").read_bytes()[:4] == b"\x89PNG"


def test_top_missions_are_those_no_mission_nests() -> None:
    import ckmconf

    assert top_missions(ckmconf.load(LAB)) == ["Agent1Fetch", "Agent1FetchCoop", "Agent2Spot"]
