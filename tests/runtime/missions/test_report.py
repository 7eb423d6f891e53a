"""build_report, format_table, write_plots and main on runs recorded with an injected clock."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from runtime.missions.recording import RunRecorder, read_run
from runtime.missions.report import build_report, format_table, main, write_plots

PNG = b"\x89PNG\r\n\x1a\n"


class FakeClock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


class Script:
    """Writes one agent's run through a RunRecorder, moving the clock to absolute run times."""

    def __init__(self, run_dir: Path, agent: str, mission: str, wall: float, plan: str | None = None) -> None:
        self.clock = FakeClock()
        self.start = self.clock.now
        self.recorder = RunRecorder(run_dir, agent, clock=self.clock)
        self.mission = mission
        self.recorder.write("start", mission=mission, plan=plan, wall=wall)

    def at(self, t: float, kind: str, **fields: object) -> None:
        self.clock.now = self.start + t
        self.recorder.write(kind, **fields)

    def enter(self, t: float, path: str, nested: str | None = None) -> None:
        owner, state = path.rsplit("/", 1)
        self.at(t, "enter", path=path, state=state, mission=owner.rsplit("/", 1)[-1], behavior=None, nested=nested)

    def exit(self, t: float, path: str, to: str = "next") -> None:
        owner, state = path.rsplit("/", 1)
        self.at(t, "exit", path=path, state=state, mission=owner, to=to, condition=None, reason="transition")

    def progress(self, t: float, path: str, progress: float, performance: float | None, mission: float) -> None:
        self.at(t, "progress", path=path, progress=progress, performance=performance, mission_progress=mission)


def fetch_run(run_dir: Path, *, end: bool = True) -> None:
    """Agent1's Table 7.9 mission: NAVIGATION (nested) twice around SPOT."""
    s = Script(run_dir, "Agent1", "Fetch", wall=1000.0, plan="Collaborate")
    s.enter(0.0, "Fetch/Navigation", nested="Nav")
    s.enter(0.0, "Fetch/Navigation/NAV")
    s.progress(0.0, "Fetch/Navigation/NAV", 0.0, 0.8, 0.0)
    s.progress(10.0, "Fetch/Navigation/NAV", 0.2, 1.0, 0.1)
    s.exit(56.676, "Fetch/Navigation/NAV", to="final")
    s.exit(56.676, "Fetch/Navigation", to="SPOT")
    s.enter(56.676, "Fetch/SPOT")
    s.progress(56.676, "Fetch/SPOT", 0.0, 0.5, 0.4)
    s.progress(60.676, "Fetch/SPOT", 0.5, None, 0.45)  # a null performance does not count
    s.progress(62.676, "Fetch/SPOT", 0.6, 1.0, 0.5)
    s.progress(75.327, "Fetch/SPOT", 1.0, 0.0, 0.55)  # zero weight: at the exit instant
    s.exit(75.327, "Fetch/SPOT", to="Navigation")
    s.enter(75.327, "Fetch/Navigation", nested="Nav")
    s.enter(75.327, "Fetch/Navigation/NAV")
    s.progress(80.0, "Fetch/Navigation/NAV", 0.7, 0.6, 0.9)
    s.exit(128.183, "Fetch/Navigation/NAV", to="final")
    s.exit(128.183, "Fetch/Navigation", to="final")
    s.at(128.183, "outcome", mission="Fetch", path="", outcome="done")
    s.at(128.183, "quality", service="Cam.Recog", client="Agent1", measures={"fps": 10, "cpu": 0.5}, scenario="VGA")
    s.at(128.183, "quality", service="Cam.Recog", client="Agent1", measures={"fps": 20, "cpu": 0.7}, scenario="VGA")
    if end:
        s.at(128.183, "end", outcome="done", wall=1128.183)
    s.recorder.close()


def nao_run(run_dir: Path) -> None:
    s = Script(run_dir, "Agent2", "Spot", wall=1002.0, plan="Collaborate")
    s.enter(0.0, "Spot/SPOT_TRACK")
    s.progress(1.0, "Spot/SPOT_TRACK", 0.5, 1.0, 0.25)
    s.exit(23.57, "Spot/SPOT_TRACK", to="SPOT_FIX")
    s.at(23.57, "signal", name="object", direction="sent", value=[1.0, 2.0])
    s.at(24.0, "agent-lost", lost="Agent1")
    s.at(25.0, "agent-found", found="Agent1")
    s.enter(23.57, "Spot/SPOT_FIX")
    s.progress(30.0, "Spot/SPOT_FIX", 0.5, 0.62, 0.75)
    s.exit(98.897, "Spot/SPOT_FIX", to="final")
    s.at(98.897, "end", outcome="done", wall=1100.897)
    s.recorder.close()


def test_times_per_visit_and_contributions_match_the_recording(tmp_path: Path) -> None:
    fetch_run(tmp_path)
    report = build_report(read_run(tmp_path))
    (agent,) = report.agents
    assert (agent.agent, agent.mission, agent.plan, agent.outcome) == ("Agent1", "Fetch", "Collaborate", "done")
    assert agent.total == pytest.approx(128.183)
    assert [(r.path, r.state) for r in agent.rows] == [("Fetch/Navigation/NAV", "NAV"), ("Fetch/SPOT", "SPOT")]
    nav, spot = agent.rows
    assert nav.visits == pytest.approx([56.676, 52.856])
    assert spot.visits == pytest.approx([18.651])
    assert nav.contribution == pytest.approx([56.676 / 128.183, 52.856 / 128.183])
    assert sum(nav.contribution + spot.contribution) == pytest.approx(1.0)
    assert report.notes == []


def test_performance_is_time_weighted_over_the_state_samples(tmp_path: Path) -> None:
    fetch_run(tmp_path)
    nav, spot = build_report(read_run(tmp_path)).rows
    # SPOT: 0.5 held 56.676→60.676 (4 s), null 2 s ignored, 1.0 held 62.676→75.327, 0.0 at the exit.
    assert spot.performance == pytest.approx((0.5 * 4 + 1.0 * 12.651) / (4 + 12.651))
    # NAV: 0.8 for 10 s, 1.0 for 46.676 s; second visit 0.6 from 80.0 to 128.183.
    assert nav.performance == pytest.approx((0.8 * 10 + 1.0 * 46.676 + 0.6 * 48.183) / (10 + 46.676 + 48.183))
    assert (nav.progress_end, spot.progress_end) == (0.7, 1.0)


def test_top_depth_counts_a_nested_mission_as_one_row(tmp_path: Path) -> None:
    fetch_run(tmp_path)
    (agent,) = build_report(read_run(tmp_path), "top").agents
    assert [r.label for r in agent.rows] == ["Navigation", "SPOT"]
    assert agent.rows[0].visits == pytest.approx([56.676, 52.856])
    leaf_nav = build_report(read_run(tmp_path)).rows[0]
    assert agent.rows[0].performance == pytest.approx(leaf_nav.performance)


def test_a_state_active_when_the_recording_stops_counts_until_the_last_event(tmp_path: Path) -> None:
    s = Script(tmp_path, "A", "M", wall=0.0)
    s.enter(0.0, "M/ONE")
    s.exit(2.0, "M/ONE")
    s.enter(2.0, "M/TWO")
    s.progress(5.5, "M/TWO", 0.5, 1.0, 0.7)  # then the process died: no exit, no end
    s.recorder.close()
    (agent,) = build_report(read_run(tmp_path)).agents
    assert agent.outcome is None and agent.total == 5.5
    assert [r.visits for r in agent.rows] == [[2.0], [3.5]]
    assert sum(c for r in agent.rows for c in r.contribution) == pytest.approx(1.0)


def test_unpaired_events_are_noted(tmp_path: Path) -> None:
    s = Script(tmp_path, "A", "M", wall=0.0)
    s.exit(1.0, "M/GHOST")
    s.enter(1.0, "M/ONE")
    s.enter(3.0, "M/ONE")
    s.at(4.0, "end", outcome="done", wall=4.0)
    s.recorder.close()
    report = build_report(read_run(tmp_path))
    assert report.rows[0].visits == [2.0, 1.0]
    assert report.notes == [
        "mission-A.jsonl:2: exit of M/GHOST without an enter; ignored",
        "mission-A.jsonl:4: M/ONE entered again before its exit; previous visit closed here",
    ]


def test_format_table_has_the_table_7_9_layout(tmp_path: Path) -> None:
    fetch_run(tmp_path)
    nao_run(tmp_path)
    text = format_table(build_report(read_run(tmp_path)))
    assert text.splitlines()[:4] == [
        "Agent1 (mission Fetch, plan Collaborate): 128.183 s, outcome done",
        "State           Execution Time (s)  Contribution to mission (%)  Avg. Performance",
        "Navigation/NAV  56.676+52.856       44.2+41.2                    0.80",
        "SPOT            18.651              14.6                         0.88",
    ]
    assert "  quality Cam.Recog: fps 15, cpu 0.6" in text
    assert "Agent2 (mission Spot, plan Collaborate): 98.897 s, outcome done" in text
    assert "SPOT_FIX        75.327              76.2                         0.62" in text


def test_plots_are_written_per_agent_and_for_the_plan(tmp_path: Path) -> None:
    fetch_run(tmp_path)
    nao_run(tmp_path)
    run = read_run(tmp_path)
    assert run.agents["Agent2"].start == 2.0
    paths = write_plots(run, tmp_path / "out")
    assert [p.name for p in paths] == ["mission-Agent1.png", "mission-Agent2.png", "plan.png"]
    for path in paths:
        assert path.read_bytes()[:8] == PNG


def test_main_prints_the_table_and_json_and_writes_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fetch_run(tmp_path, end=False)
    assert main(tmp_path, json=True, depth="top") == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "Agent1 (mission Fetch, plan Collaborate): 128.183 s, outcome none (no end event)"
    result = json.loads(out[-1])
    assert result["depth"] == "top"
    assert [r["state"] for r in result["agents"][0]["rows"]] == ["Navigation", "SPOT"]
    assert (tmp_path / "report" / "mission-Agent1.png").read_bytes()[:8] == PNG


def test_main_reports_a_half_written_line_as_a_note(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fetch_run(tmp_path)
    path = tmp_path / "mission-Agent1.jsonl"
    path.write_bytes(path.read_bytes()[:-5])
    assert main(tmp_path, out=tmp_path / "plots") == 0
    err = capsys.readouterr().err
    assert "note: mission-Agent1.jsonl:22: skipped: half-written last line" in err


@pytest.mark.parametrize("setup", ["missing", "empty", "garbage"])
def test_main_on_an_unusable_run_dir_fails_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], setup: str
) -> None:
    run_dir = tmp_path / "run"
    if setup != "missing":
        run_dir.mkdir()
    if setup == "garbage":
        (run_dir / "mission-A.jsonl").write_text("not json\n")
    assert main(run_dir) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert len(captured.err.splitlines()) == 1
    assert captured.err.startswith(f"ckm-mission report: {run_dir}: ")
    assert "Traceback" not in captured.err


def test_main_rejects_an_unknown_depth(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fetch_run(tmp_path)
    assert main(tmp_path, depth="middle") == 1
    assert capsys.readouterr().err == "ckm-mission report: depth must be 'leaf' or 'top', not 'middle'\n"
