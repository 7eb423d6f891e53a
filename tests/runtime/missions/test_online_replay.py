"""Off-line, then on-line (§7.5; runtime/missions/validation/online.py): a live run's recorded states
reproduce the off-line validation's success episode; a run that takes a step no episode took is
reported at that step; the HTML report says which."""

from __future__ import annotations

from pathlib import Path

from ckmconf.loader import load
from runtime.missions.html_report import Options, build_html
from runtime.missions.recording import Event, read_run
from runtime.missions.validation.online import replay
from tests.runtime.missions.test_behavior_topics import SYSTEM, run_handover


def test_a_live_run_reproduces_the_off_line_success_episode(tmp_path: Path) -> None:
    system = load(run_handover(tmp_path)[0])
    run = read_run(tmp_path / "run")
    verdict = replay(system, "Handover", "robot", run.of("robot"))
    assert verdict.online == ("Handover/GIVE", "Handover/TAKE") and verdict.outcome == "taken"
    assert verdict.reproduced and verdict.divergence is None
    assert verdict.describe().startswith("robot: reproduces off-line episode ")


def _enter(path: str, t: float) -> Event:
    return Event(t, "robot", "enter", {"path": path, "nested": None}, t, "test:1")


def test_a_step_no_episode_took_is_named(tmp_path: Path) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    system = load(path)
    events = [_enter("Handover/TAKE", 0.0), _enter("Handover/GIVE", 1.0)]
    verdict = replay(system, "Handover", "robot", events)
    assert not verdict.reproduced and verdict.divergence == "the start, Handover/TAKE"
    assert "diverges from every off-line episode at the start, Handover/TAKE" in verdict.describe()


def test_the_html_report_says_whether_the_run_followed_the_validation(tmp_path: Path) -> None:
    config, _ = run_handover(tmp_path)
    html, _ = build_html(tmp_path / "run", Options(config=config))
    assert "Off-line vs on-line" in html and "robot: reproduces off-line episode" in html


def test_the_html_report_shows_where_the_world_was_left(tmp_path: Path) -> None:
    config, _ = run_handover(tmp_path)
    final = '{"time": 85.5, "positions": {"cylinder_red_stripes": [1.2, 1.9, 0.36]}}'
    (tmp_path / "run" / "sim-final.json").write_text(final)
    html, _ = build_html(tmp_path / "run", Options(config=config))
    assert "World at the end" in html and "cylinder_red_stripes (1.20, 1.90, 0.36)" in html
