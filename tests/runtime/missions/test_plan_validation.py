"""Plan-level validation (issue G point 4): the wait-for graph of a plan's agents, and
``ckm-mission validate`` listing every load problem (point 10)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import ckmconf
from runtime.missions.cli import main
from runtime.missions.validation.plans import assumable_signals, check_plans

REPO = Path(__file__).resolve().parents[3]
PLANS = REPO / "tests" / "data" / "plans"


def _located(path: Path) -> list[tuple[str, int, str]]:
    return [(f.kind, f.line, f.xpath.rsplit("/", 1)[-1]) for f in check_plans(ckmconf.load(path))]


def test_a_two_agent_deadlock_is_reported_at_both_dependencies() -> None:
    found = check_plans(ckmconf.load(PLANS / "deadlock_two.xml"))
    assert [(f.kind, f.line, f.column) for f in found] == [("deadlock", 29, 5), ("deadlock", 30, 5)]
    assert "deadlock among 2 agent(s) (a, b)" in found[0].message
    assert "a waits at WAIT for 'from_b' before it can send 'from_a'" in found[0].message
    assert found[0].format().startswith(f"{PLANS / 'deadlock_two.xml'}:29:5: ")


def test_a_three_agent_circle_written_in_conditions_is_reported_at_each_transition() -> None:
    found = _located(PLANS / "deadlock_three.xml")
    assert found[:3] == [("deadlock", 12, "Transition[1]"), ("deadlock", 21, "Transition[1]"),
                         ("deadlock", 30, "Transition[1]")]  # fmt: skip
    message = check_plans(ckmconf.load(PLANS / "deadlock_three.xml"))[0].message
    assert "deadlock among 3 agent(s) (a, b, c)" in message


def test_a_deadlock_through_a_nested_mission_is_found(tmp_path: Path) -> None:
    text = (PLANS / "two_agents.xml").read_text()
    assert check_plans(ckmconf.load(PLANS / "two_agents.xml")) == []
    # The spotter now waits at TRACK for the fetcher's `ready`, sent when the fetcher's nested
    # NAVIGATION mission enters GO — which happens only after `spotted`, sent after TRACK.
    text = text.replace('<Transition from="TRACK" to="FIX"/>', "<Transition from=\"TRACK\" to=\"FIX\" "
                        "when=\"signal('ready') and done()\"/>")  # fmt: skip
    text = text.replace('<Signal name="spotted" agent="spotter" state="FIX" on="done"/>',
                        '<Signal name="spotted" agent="spotter" state="FIX" on="done"/>'
                        '<Signal name="ready" agent="fetcher" state="NAVIGATION/GO" on="entry"/>')  # fmt: skip
    path = tmp_path / "nested.xml"
    path.write_text(text)
    found = check_plans(ckmconf.load(path))
    assert {f.kind for f in found} == {"deadlock"}
    assert "fetcher waits at NAVIGATION/NAV for 'spotted' before it can send 'ready'" in found[0].message
    assert "spotter waits at TRACK for 'ready' before it can send 'spotted'" in found[0].message


def test_a_dependency_on_a_signal_off_the_senders_success_path_is_reported() -> None:
    found = _located(PLANS / "deadlock_three.xml")
    assert ("signal-off-success-path", 60, "Dependency") in found


def test_a_wait_for_a_signal_that_needs_the_waiters_own_later_signal_is_a_deadlock(tmp_path: Path) -> None:
    text = (PLANS / "deadlock_two.xml").read_text()
    # a no longer waits at WAIT: the plan is coherent.
    fixed = text.replace('<Dependency agent="a" state="WAIT" signal="from_b"/>', "").replace(
        "signal('from_b') and done()", "done()"
    )
    path = tmp_path / "ok.xml"
    path.write_text(fixed)
    assert check_plans(ckmconf.load(path)) == []
    # a waits at WAIT for `late`, which b sends only after from_a, which a sends at SEND — after WAIT.
    late = fixed.replace(
        '<Signal name="from_b" agent="b" state="SEND" on="entry"/>',
        '<Signal name="from_b" agent="b" state="SEND" on="entry"/><Signal name="late" agent="b" state="SEND"/>',
    ).replace("</Plan>", '<Dependency agent="a" state="WAIT" signal="late"/></Plan>')
    late = late.replace('<Transition from="WAIT" to="SEND" when="done()"/>',
                        '<Transition from="WAIT" to="SEND" when="signal(\'late\')"/>'
                        '<Transition from="WAIT" to="SEND" when="elapsed &gt; 1"/>', 1)  # fmt: skip
    path.write_text(late)
    found = check_plans(ckmconf.load(path))
    assert [(f.kind, f.line) for f in found] == [("deadlock", 30), ("deadlock", 31)]  # a Dependency blocks
    assert "deadlock among 2 agent(s) (a, b)" in found[0].message


def test_a_signal_that_needs_what_its_receiver_sends_only_after_waiting_is_late() -> None:
    found = check_plans(ckmconf.load(PLANS / "late_signal.xml"))
    assert [(f.kind, f.line, f.column) for f in found] == [("late-signal", 33, 5)]
    assert found[0].message == (
        "a waits at WAITX for 'late', which can only be sent after a has sent 'from_a' at SEND, after which it "
        "never waits at WAITX again: the signal arrives too late"
    )


def test_a_typed_signal_whose_state_writes_no_payload_is_reported(tmp_path: Path) -> None:
    text = (PLANS / "late_signal.xml").read_text()
    path = tmp_path / "typed.xml"
    path.write_text(text.replace('state="SEND" on="entry"/>\n    <Signal name="late"',
                                 'state="SEND" on="entry" type="string"/>\n    <Signal name="late"'))  # fmt: skip
    found = [f for f in check_plans(ckmconf.load(path)) if f.kind == "signal-without-payload"]
    assert [f.line for f in found] == [31]
    assert "behavior 'WORK' of a's SEND writes no <Output signal='from_a'>" in found[0].message


def test_a_typed_signal_of_a_nested_mission_state_has_no_behavior_to_supply_it(tmp_path: Path) -> None:
    text = (PLANS / "two_agents.xml").read_text()
    path = tmp_path / "typed.xml"
    spotted = '<Signal name="spotted" agent="spotter" state="FIX" on="done"/>'
    going = '<Signal name="going" agent="fetcher" state="NAVIGATION" type="string"/>'
    path.write_text(text.replace(spotted, spotted + going))
    found = check_plans(ckmconf.load(path))
    assert [f.kind for f in found] == ["signal-without-payload"]
    assert "fetcher's NAVIGATION runs the mission 'Go', not a behavior that could write it" in found[0].message


def test_a_payload_written_where_the_signal_is_not_sent_is_a_warning(tmp_path: Path) -> None:
    text = (PLANS / "payload.xml").read_text()
    path = tmp_path / "elsewhere.xml"
    path.write_text(text.replace('state="SPOT" on="done" type="ObjectPosition"', 'state="SPOT" on="entry"'))
    assert check_plans(ckmconf.load(path)) == []  # untyped, same state: fine
    other = '<Agent name="other" node="fetcher-pc" mission="Spot"/>'  # runs SPOT too, sends nothing
    path.write_text(text.replace('<Agent name="fetcher"', other + '<Agent name="fetcher"'))
    found = check_plans(ckmconf.load(path))
    assert [(f.kind, f.severity, f.line) for f in found] == [("payload-never-sent", "warning", 43)]
    assert "behavior 'SPOT' writes the payload of 'spotted' in other's SPOT, which does not send it" in found[0].message


def test_the_fake_interaction_assumes_no_signal_of_a_deadlock() -> None:
    system = ckmconf.load(PLANS / "deadlock_two.xml")
    assert assumable_signals(system, "A") == set()
    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    assert assumable_signals(lab, "Agent1FetchCoop") == {"object_spotted"}
    assert assumable_signals(ckmconf.load(REPO / "configs" / "usecase" / "missions.xml"), "Agent1FetchCoop") is None


def test_ckm_mission_validate_reports_the_deadlock_and_fails(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(PLANS / "deadlock_two.xml"), "--json"]) == 1
    out = capsys.readouterr().out
    assert f"{PLANS / 'deadlock_two.xml'}:29:5: /System[@name='deadlock-two']/Plan[@name='stuck']/Dependency[1]: " \
           "[deadlock] deadlock among 2 agent(s) (a, b)" in out  # fmt: skip
    assert "plan stuck: NOT coherent (2 agents)" in out
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["plans"][0]["plan"] == "stuck" and not summary["plans"][0]["ok"]


def test_the_use_case_plans_are_coherent() -> None:
    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    assert check_plans(lab) == []


def test_ckm_mission_validate_lists_every_load_problem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = (PLANS / "deadlock_two.xml").read_text()
    broken = text.replace('mission="A"', 'mission="Nope"')
    first_state = 'behavior="WORK"/>\n    <State name="SEND"'
    broken = broken.replace(first_state, first_state.replace("WORK", "MISSING"), 1)
    path = tmp_path / "broken.xml"
    path.write_text(broken)
    assert main(["validate", str(path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) >= 2 and all(line.startswith(f"{path}:") for line in err)
    assert any("Nope" in line for line in err) and any("MISSING" in line for line in err)


def test_missions_alone_say_in_one_line_where_their_validation_settings_come_from(
    capsys: pytest.CaptureFixture[str],
) -> None:
    main(["validate", str(REPO / "configs" / "usecase" / "missions.xml"), "--mission", "Agent2Spot"])
    notes = [line for line in capsys.readouterr().err.splitlines() if "<Validation>" in line]
    assert len(notes) == 1 and "when a plan file includes this one and sets them, validate that file" in notes[0]
