"""Static mission checks (runtime.missions.validation.static): one defect per case, located exactly."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.expressions import TRANSITION, parse
from ckmconf.model import Mission, Plan, Signal, System, Transition
from runtime.missions.validation import Finding, check_mission, top_missions
from runtime.missions.validation.conditions import dnf, implies

DATA = Path(__file__).parents[2] / "data" / "missions"
USECASE = Path(__file__).parents[3] / "configs" / "usecase" / "lab.xml"


def line_of(path: Path, needle: str) -> int:
    """The line of the one line of ``path`` holding ``needle``."""
    lines = [n for n, text in enumerate(path.read_text().splitlines(), start=1) if needle in text]
    assert len(lines) == 1, f"{needle!r} is on lines {lines} of {path.name}"
    return lines[0]


def summary(findings: list[Finding]) -> set[tuple[str, str, int]]:
    return {(f.kind, f.severity, f.line) for f in findings}


def load(name: str) -> System:
    return ckmconf.load(DATA / name)


# ----------------------------------------------------------------------------- files, one defect each

FILE_CASES: list[tuple[str, str, list[tuple[str, str, str]]]] = [
    ("unreachable_state.xml", "Patrol", [("unreachable-state", "error", '<State name="TURN"')]),
    (
        "non_terminating.xml",
        "Patrol",
        [("non-terminating", "error", '<State name="TURN"'), ("non-terminating", "error", '<State name="STOP"')],
    ),
    ("dead_end.xml", "Patrol", [("dead-end", "error", '<State name="STOP"')]),
    (
        "shadowed_transition.xml",
        "Patrol",
        [
            ("shadowed-transition", "error", 'to="done" when="done() and'),
            ("unreachable-final", "warning", '<Final name="done"'),
        ],
    ),
    ("redundant_condition.xml", "Patrol", [("redundant-condition", "warning", 'when="done() or failed()"')]),
    ("unhandled_failure.xml", "Patrol", [("unhandled-failure", "warning", '<State name="GO"')]),
    ("unhandled_outcome.xml", "Patrol", [("unhandled-outcome", "warning", '<State name="DRIVE"')]),
    ("unmeetable_requirement.xml", "Patrol", [("unmeetable-requirement", "error", 'upper="0.1"')]),
    (
        "unreachable_outcome.xml",
        "Patrol",
        [
            ("unreachable-outcome", "error", "when=\"outcome('blocked')\""),
            ("unreachable-final", "warning", '<Final name="blocked"'),
        ],
    ),
]


@pytest.mark.parametrize(("name", "mission", "expected"), FILE_CASES, ids=[c[0] for c in FILE_CASES])
def test_defect_file(name: str, mission: str, expected: list[tuple[str, str, str]]) -> None:
    path = DATA / name
    findings = check_mission(load(name), mission)
    assert summary(findings) == {(kind, severity, line_of(path, needle)) for kind, severity, needle in expected}
    assert {f.file for f in findings} == {str(path)}
    for f in findings:
        assert f.format().startswith(f"{path}:{f.line}:{f.column}: {f.xpath}: [{f.kind}] ")
        assert f.mission in ("Patrol", "Drive")


def test_clean_file_passes_even_strict() -> None:
    assert check_mission(load("clean.xml"), "Patrol", strict=True) == []


def test_messages_name_the_culprits() -> None:
    (shadowed,) = [f for f in check_mission(load("shadowed_transition.xml"), "Patrol") if f.severity == "error"]
    assert shadowed.transition == "GO -> done"
    assert shadowed.state == "GO"
    assert shadowed.message == (
        "transition GO -> done can never fire: it comes after GO -> failed (line 9), whose condition"
        " 'done() or failed() or timeout()' holds whenever 'done() and nav.dispersion < 0.3' does; put the more"
        " specific transition first, or merge them"
    )
    assert shadowed.xpath == "/System[@name='shadowed-transition']/Mission[@name='Patrol']/Transition[2]"
    assert shadowed.to_json()["kind"] == "shadowed-transition"
    (unmeetable,) = check_mission(load("unmeetable_requirement.xml"), "Patrol")
    assert "no scenario keeps it there (LOC allows [-inf, 0.3])" in unmeetable.message


# ----------------------------------------------------------------------------- in memory: what the loader refuses


def edit_mission(system: System, name: str, /, **changes: Any) -> System:
    missions = tuple(dataclasses.replace(m, **changes) if m.name == name else m for m in system.missions)
    return dataclasses.replace(system, missions=missions)


def edit_transition(system: System, mission: str, index: int, /, **changes: Any) -> System:
    found = system.mission(mission)
    assert found is not None
    transitions = list(found.transitions)
    transitions[index] = dataclasses.replace(transitions[index], **changes)
    return edit_mission(system, mission, transitions=tuple(transitions))


def edit_state(system: System, mission: str, state: str, /, **changes: Any) -> System:
    found = system.mission(mission)
    assert found is not None
    states = tuple(dataclasses.replace(s, **changes) if s.name == state else s for s in found.states)
    return edit_mission(system, mission, states=states)


def edit_behavior(system: System, name: str, /, **changes: Any) -> System:
    behaviors = tuple(dataclasses.replace(b, **changes) if b.name == name else b for b in system.behaviors)
    return dataclasses.replace(system, behaviors=behaviors)


CLEAN = DATA / "clean.xml"
COMMON = DATA / "common.xml"
GO_FAILED = 'to="failed" when="done() or failed() or timeout()"'
GO_STOP = 'to="STOP" when="done() and nav.dispersion'


def clean() -> System:
    return load("clean.xml")


def with_plan(system: System) -> System:
    plan = Plan(name="p", signals=(Signal(name="go", agent="robot", state="GO"),))
    return dataclasses.replace(system, plans=(plan,))


def uses_record(system: System) -> Any:
    behavior = system.behavior("GO")
    assert behavior is not None
    return behavior.uses[0]


MEMORY_CASES: list[tuple[str, Any, list[tuple[str, str, Path, str]]]] = [
    (
        "missing-target",
        lambda s: edit_transition(s, "Patrol", 1, to="NOWHERE"),
        [("missing-target", "error", CLEAN, GO_FAILED)],
    ),
    (
        "missing-source",
        lambda s: edit_transition(s, "Patrol", 1, from_="GHOST"),
        [
            ("missing-source", "error", CLEAN, GO_FAILED),
            # GO lost its way out on failure and on a poor localisation, and says so.
            ("unhandled-failure", "warning", CLEAN, '<State name="GO"'),
            ("unhandled-done", "warning", CLEAN, '<State name="GO"'),
        ],
    ),
    (
        "transition-from-final",
        lambda s: edit_transition(s, "Patrol", 2, from_="failed"),
        [
            ("transition-from-final", "error", CLEAN, '<Transition from="STOP" to="done"'),
            ("unreachable-final", "warning", CLEAN, '<Final name="done"'),
        ],
    ),
    (
        "missing-initial",
        lambda s: edit_mission(s, "Patrol", initial="START"),
        [("missing-initial", "error", CLEAN, '<Mission name="Patrol"')],
    ),
    (
        "missing-behavior",
        lambda s: edit_state(s, "Patrol", "STOP", behavior="HALT"),
        [("missing-behavior", "error", CLEAN, '<State name="STOP"')],
    ),
    (
        "missing-mission",
        lambda s: edit_state(s, "Patrol", "STOP", behavior=None, mission="Parking", timeout=5.0),
        [("missing-mission", "error", CLEAN, '<State name="STOP"')],
    ),
    (
        "invalid-state",
        lambda s: edit_state(s, "Patrol", "STOP", mission="Patrol"),
        [("invalid-state", "error", CLEAN, '<State name="STOP"')],
    ),
    (
        "recursive-mission",
        lambda s: edit_state(s, "Patrol", "STOP", behavior=None, mission="Patrol", timeout=5.0),
        [("recursive-mission", "error", CLEAN, '<State name="STOP"')],
    ),
    (
        "outcome-not-nested",
        lambda s: edit_transition(s, "Patrol", 1, when="outcome('x') or failed() or timeout()"),
        [("outcome-not-nested", "error", CLEAN, 'to="failed" when="done() or failed()')],
    ),
    (
        "unknown-signal",
        lambda s: edit_transition(with_plan(s), "Patrol", 1, when="signal('stop') or failed() or timeout()"),
        [("unknown-signal", "error", CLEAN, 'to="failed" when="done() or failed()')],
    ),
    (
        "unknown-signal-input",
        lambda s: edit_behavior(
            with_plan(s), "GO", inputs=(dataclasses.replace(s.behavior("GO").inputs[0], topic=None, signal="stop"),)
        ),
        [("unknown-signal", "error", COMMON, '<Input name="pose" topic="/pose"/>')],
    ),
    (
        "timeout-never-fires",
        lambda s: edit_behavior(s, "STOP", timeout=None),
        [("timeout-never-fires", "warning", CLEAN, '<Transition from="STOP" to="failed"')],
    ),
    (
        "service-not-provided",
        lambda s: edit_behavior(s, "GO", uses=(dataclasses.replace(uses_record(s), service="Nav.Lok"),)),
        [("service-not-provided", "error", COMMON, '<Uses service="Nav.Loc"')],
    ),
    (
        "unmeetable-measure",
        lambda s: edit_behavior(
            s,
            "GO",
            uses=(
                dataclasses.replace(
                    uses_record(s), requires=(dataclasses.replace(uses_record(s).requires[0], measure="speed"),)
                ),
            ),
        ),
        [("unmeetable-requirement", "error", COMMON, '<Require measure="dispersion"')],
    ),
    (
        "unknown-alias",
        lambda s: edit_transition(s, "Patrol", 0, when="done() and nv.dispersion < 0.3"),
        [("unknown-alias", "error", CLEAN, GO_STOP)],
    ),
    (
        "unknown-field",
        lambda s: edit_transition(s, "Patrol", 0, when="done() and nav.dispersal < 0.3"),
        [("unknown-field", "error", CLEAN, GO_STOP)],
    ),
    (
        "invalid-condition",
        lambda s: edit_transition(s, "Patrol", 1, when="done() or failed() or"),
        [("invalid-condition", "error", CLEAN, GO_FAILED)],
    ),
    (
        "same-condition-twice",
        lambda s: edit_transition(s, "Patrol", 0, when="done() or failed() or timeout()"),
        [("shadowed-transition", "error", CLEAN, GO_FAILED)],
    ),
    (
        "never-true",
        lambda s: edit_transition(s, "Patrol", 3, when="elapsed > 5 and elapsed < 2"),
        [
            ("never-true", "error", CLEAN, '<Transition from="STOP" to="failed"'),
            ("unhandled-failure", "warning", CLEAN, '<State name="STOP"'),
        ],
    ),
    (
        "contradictory-part",
        lambda s: edit_transition(s, "Patrol", 3, when="(done() and failed()) or failed() or timeout()"),
        [("redundant-condition", "warning", CLEAN, '<Transition from="STOP" to="failed"')],
    ),
]


@pytest.mark.parametrize(("case", "edit", "expected"), MEMORY_CASES, ids=[c[0] for c in MEMORY_CASES])
def test_defect_in_memory(case: str, edit: Any, expected: list[tuple[str, str, Path, str]]) -> None:
    findings = check_mission(edit(clean()), "Patrol")
    assert summary(findings) == {(kind, sev, line_of(path, needle)) for kind, sev, path, needle in expected}
    files = {kind: str(path) for kind, _, path, _ in expected}
    assert all(f.file == files[f.kind] for f in findings)


def test_records_without_location() -> None:
    mission = Mission(
        name="M",
        initial="A",
        states=(),
        transitions=(Transition(from_="A", to="end"),),
    )
    findings = check_mission(System(name="s", version="1", missions=(mission,)), "M")
    assert {(f.kind, f.file, f.line, f.xpath) for f in findings} == {
        ("missing-source", "<memory>", 0, "/Transition"),
        ("missing-target", "<memory>", 0, "/Transition"),
        ("missing-initial", "<memory>", 0, "/Mission"),
        ("no-final", "<memory>", 0, "/Mission"),
    }


def test_unknown_mission() -> None:
    (found,) = check_mission(clean(), "Nope")
    assert found.kind == "unknown-mission"
    assert "(missions: Patrol)" in found.message


def test_nested_missions_are_checked_once() -> None:
    system = load("unhandled_outcome.xml")
    broken = edit_transition(system, "Drive", 1, when="failed()")  # GO no longer handles its timeout…
    findings = check_mission(broken, "Patrol")
    assert [f.kind for f in findings] == ["unhandled-outcome"]  # …but failed() still reaches "blocked"
    assert check_mission(system, "Drive") == []


@pytest.mark.parametrize(
    ("earlier", "later", "shadowed"),
    [
        ("done()", "done() and nav.x > 1", True),
        ("done() and nav.x > 1", "done()", False),
        ("done() or failed()", "failed()", True),
        ("elapsed > 10", "elapsed > 30 and progress < 0.1", True),
        ("elapsed > 30", "elapsed > 10", False),
        ("not (done() and nav.x)", "not done()", True),
        ("0 < nav.x < 1", "nav.x == 0.5", True),
        ("nav.x >= 1", "nav.x > 1", True),
        ("nav.x > 1", "nav.x >= 1", False),
    ],
)
def test_implication(earlier: str, later: str, shadowed: bool) -> None:
    a, b = dnf(parse(later, TRANSITION)), dnf(parse(earlier, TRANSITION))
    assert a is not None and b is not None
    assert implies(a, b) is shadowed


# ----------------------------------------------------------------------------- the use case


@pytest.fixture(scope="module")
def usecase() -> System:
    return ckmconf.load(USECASE)


def test_usecase_missions_pass(usecase: System) -> None:
    for mission in usecase.missions:
        assert check_mission(usecase, mission.name) == [], mission.name


def test_usecase_strict_only_adds_unproven_requirements(usecase: System) -> None:
    """The lab's unproven requirements are the recognisers' reliability ones: no scenario bounds a
    recognition's reliability (their policies bound deadline and CPU); the mobile base's, the arm's
    and the Nao's services bound the measures the behaviors require."""
    findings = check_mission(usecase, "Agent1FetchCoop", strict=True)
    assert {f.kind for f in findings} == {"unproven-requirement"}
    assert len(findings) == 4
    assert all("reliability in" in f.message for f in findings)


def test_top_missions(usecase: System) -> None:
    assert top_missions(usecase) == ["Agent1Fetch", "Agent1FetchCoop", "Agent2Spot"]
