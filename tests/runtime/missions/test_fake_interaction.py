"""The fake interaction (§7.5.1, Fig. 7.21): forced transitions cover every state and transition
of the use-case missions; a transition that can never fire first is found; the runs are recorded."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.expressions import TRANSITION, parse
from ckmconf.model import System
from runtime.missions.fake import explore, record_into
from runtime.missions.recording import read_run
from runtime.missions.solver import solve

REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def lab() -> System:
    return ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")


@pytest.mark.parametrize("mission", ["Agent1Fetch", "Agent1FetchCoop", "Agent2Spot"])
def test_the_use_case_missions_are_fully_covered(lab: System, mission: str) -> None:
    coverage = explore(lab, mission, step=0.1, horizon=1800)
    assert coverage.share() == (1.0, 1.0)
    assert coverage.uncovered() == []
    assert all(e.problem is None and e.outcome is not None for e in coverage.episodes)
    assert coverage.episodes[0].outcome == lab.mission(mission).finals[0].name  # type: ignore[union-attr]


def test_the_first_episode_follows_the_success_path_of_fig_7_12(lab: System, tmp_path: Path) -> None:
    coverage = explore(lab, "Agent1Fetch", recorder=record_into(tmp_path))
    first = [p.split("/", 1)[1] for p in coverage.episodes[0].states]
    assert first == [
        "INIT", "Navigation/NAV", "Navigation/WAIT", "ObjectInteraction/SPOT", "ObjectInteraction/APPR",
        "ObjectInteraction/PICK", "ObjectPlace/NAV", "ObjectPlace/WAIT", "ObjectPlace/DOCK", "ObjectPlace/PLACE",
        "ObjectPlace/BACK", "END",
    ]  # fmt: skip
    run = read_run(tmp_path / "episode-1")
    assert [e.fields["outcome"] for e in run.events if e.kind == "end"] == ["succeeded"]
    progress = [e.fields["mission_progress"] for e in run.events if e.kind == "progress"]
    assert progress[-1] == 1.0 and len(list(tmp_path.iterdir())) == len(coverage.episodes)


def test_a_shadowed_transition_is_never_covered(tmp_path: Path) -> None:
    text = (REPO / "tests" / "data" / "missions" / "nested_timers.xml").read_text()
    text = text.replace(
        '<Transition from="B" to="ok" when="done()"/>',
        '<Transition from="B" to="ok" when="done()"/>\n'
        '    <Transition from="B" to="late" when="done() and progress &gt; 0.5"/>',
    )
    path = tmp_path / "shadowed.xml"
    path.write_text(text)
    system = ckmconf.load(path)
    coverage = explore(system, "Top")
    uncovered = sorted((m.name, t.from_, t.to) for m, t in coverage.uncovered())
    assert uncovered == [("Inner", "B", "late"), ("Top", "FIRST", "failure")]
    assert coverage.share()[1] < 1.0


def test_the_solver_makes_exactly_one_transition_the_first_to_hold() -> None:
    conditions = [parse(t, TRANSITION) for t in ("done() and nav.d < 0.3", "done() or timeout()", "failed()")]
    first = solve(conditions, 0, {})
    assert first is not None and first[("call", "done")] is True and first[("attr", "nav", "d")] < 0.3
    second = solve(conditions, 1, {})
    assert second is not None and (second[("attr", "nav", "d")] >= 0.3 or not second[("call", "done")])
    third = solve(conditions, 2, {})
    assert third is not None and not third.get(("call", "done")) and not third.get(("call", "timeout"))
    shadowing = [parse("done()", TRANSITION), parse("done() and progress > 0.5", TRANSITION)]
    assert solve(shadowing, 1, {}) is None
    assert solve([parse("outcome('a')", TRANSITION)], 0, {("call", "outcome", "a"): False}) is None
