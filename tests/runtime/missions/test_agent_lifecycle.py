"""Agent lifecycle (issue G, points 3 and 6): a finished agent is finished, never lost; a signal to
it is recorded and dropped without touching the sender's outcome; a crash ends a mission as
``crashed`` and the caller can tell it from success (``AgentRunner.succeeded``)."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from ckmconf.loader import load
from runtime.missions.agent import AgentRunner
from runtime.missions.recording import read_run
from runtime.missions.signals import SignalError
from runtime.network import open_transport
from tests.runtime.network.conftest import private_network

# "early" is done at once; "late" emits `ping` (to everyone: no Dependency) after early has finished.
SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="lifecycle">
  <Node name="pc" kind="service"/>
  <Behavior name="QUICK" kind="timer"><Param name="duration" value="0.1"/></Behavior>
  <Behavior name="SLOW" kind="timer"><Param name="duration" value="1.5"/></Behavior>
  <Behavior name="TELL" kind="emit"><Param name="value" value="hello"/><Output name="o" signal="ping"/></Behavior>
  <Mission name="Early" initial="Q">
    <State name="Q" behavior="QUICK"/>
    <Final name="done"/>
    <Transition from="Q" to="done"/>
  </Mission>
  <Mission name="Late" initial="S">
    <State name="S" behavior="SLOW"/>
    <State name="T" behavior="TELL"/>
    <Final name="done"/>
    <Final name="failed"/>
    <Transition from="S" to="T"/>
    <Transition from="T" to="done"/>
  </Mission>
  <Plan name="p" lostAfter="0.6">
    <Agent name="early" node="pc" mission="Early"/>
    <Agent name="late" node="pc" mission="Late"/>
    <Signal name="ping" agent="late" state="T" on="done" type="TYPE"/>
  </Plan>
</System>
"""


def _run_both(tmp_path: Path, signal_type: str) -> dict[str, tuple[AgentRunner, list[object]]]:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.replace("TYPE", signal_type))
    system = load(path)
    transport = open_transport(private_network(), name="pc")  # one process, one transport: as ckm-run embeds
    transport.setup()
    transport.start()
    results: dict[str, tuple[AgentRunner, list[object]]] = {}
    try:
        threads = []
        for agent in ("early", "late"):
            runner = AgentRunner(system, "p", agent, transport, tmp_path / "run", heartbeat=0.1, period=0.05)
            answer: list[object] = []

            def target(runner: AgentRunner = runner, answer: list[object] = answer) -> None:
                try:
                    answer.append(runner.run(20))
                except Exception as error:  # what a caller's thread target does with a crash
                    answer.append(error)

            results[agent] = (runner, answer)
            threads.append(threading.Thread(target=target))
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(30)
            assert not thread.is_alive()
    finally:
        transport.stop()
    return results


def test_a_signal_to_a_finished_agent_is_dropped_and_the_sender_succeeds(tmp_path: Path) -> None:
    results = _run_both(tmp_path, "string")
    early, late = results["early"][0], results["late"][0]
    assert results["early"][1] == ["done"] and results["late"][1] == ["done"]
    assert early.succeeded and late.succeeded and late.error is None
    assert late.finished == {"early": "done"} and not late.lost  # finished, never lost
    events = read_run(tmp_path / "run").events
    ends = {e.agent: e.fields["outcome"] for e in events if e.kind == "end"}
    assert ends == {"early": "done", "late": "done"}
    assert not [e for e in events if e.kind == "agent-lost"]
    finished = [e for e in events if e.kind == "agent-finished" and e.agent == "late"]
    assert [(e.fields["finished"], e.fields["outcome"]) for e in finished] == [("early", "done")]
    dropped = [e for e in events if e.kind == "signal-dropped"]
    assert [(e.agent, e.fields["name"], e.fields["to"]) for e in dropped] == [("late", "ping", "early")]
    sent = next(e for e in events if e.kind == "signal" and e.fields["direction"] == "sent")
    assert sent.fields["value"]["data"] == "hello"  # the payload TELL's behavior supplied
    assert not [e for e in events if e.kind == "signal" and e.fields["direction"] == "received"]


def test_a_payload_that_breaks_the_signal_type_crashes_the_sender_loudly(tmp_path: Path) -> None:
    results = _run_both(tmp_path, "float64")  # TELL supplies a string
    late, answer = results["late"]
    assert len(answer) == 1 and isinstance(answer[0], SignalError)
    assert "signal 'ping' (type float64) sent by late at T: payload is 'hello', not a float64" in str(answer[0])
    assert late.outcome == "crashed" and not late.succeeded and late.error is answer[0]
    assert results["early"][0].succeeded
    events = read_run(tmp_path / "run").events
    assert {e.agent: e.fields["outcome"] for e in events if e.kind == "end"} == {"early": "done", "late": "crashed"}
    assert [e.fields["outcome"] for e in events if e.kind == "end" and e.agent == "late"] == ["crashed"]  # once
    error = next(e for e in events if e.kind == "error")
    assert error.agent == "late" and error.fields["error"].startswith("SignalError: signal 'ping'")


@pytest.mark.parametrize("outcome", ["failed"])
def test_only_the_success_final_counts_as_success(tmp_path: Path, outcome: str) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.replace("TYPE", "string").replace('<Transition from="T" to="done"/>',
                                                               f'<Transition from="T" to="{outcome}"/>'))  # fmt: skip
    system = load(path)
    transport = open_transport(private_network(), name="pc")
    transport.setup()
    transport.start()
    try:
        runner = AgentRunner(system, "p", "late", transport, tmp_path / "run", heartbeat=0.1, period=0.05)
        assert runner.run(20) == outcome
        assert not runner.succeeded
        stopped = AgentRunner(system, "p", "late", transport, tmp_path / "run2", heartbeat=0.1, period=0.05)
        assert stopped.run(0.2) == "stopped" and not stopped.succeeded
    finally:
        transport.stop()


def test_the_report_draws_finished_agents_as_finished(tmp_path: Path) -> None:
    from runtime.missions.report import build_report, lane_label, write_plots

    _run_both(tmp_path, "string")
    run = read_run(tmp_path / "run")
    report = build_report(run, "leaf")
    assert sorted(lane_label(a) for a in report.agents) == ["early\nfinished: done", "late\nfinished: done"]
    paths = write_plots(run, tmp_path / "plots")
    assert tmp_path / "plots" / "plan.png" in paths and (tmp_path / "plots" / "plan.png").stat().st_size > 0
    assert not [e for e in run.events if e.kind == "agent-lost"]


def test_progress_lines_follow_the_active_state(tmp_path: Path) -> None:
    """Issue K point 2: the terminal shows each agent's active state as it changes, then its outcome."""
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.replace("TYPE", "string"))
    system = load(path)
    transport = open_transport(private_network(), name="pc")
    transport.setup()
    transport.start()
    lines: list[str] = []
    try:
        runner = AgentRunner(system, "p", "late", transport, tmp_path / "run", heartbeat=0.1, period=0.05,
                             progress=lines.append)  # fmt: skip
        assert runner.run(20) == "done"
    finally:
        transport.stop()
    states = [line.split("late: ", 1)[1].split("  (")[0] for line in lines if "%" in line]
    assert states == ["Late/S", "Late/T"], lines
    assert lines[-1] == "late: mission ended: done"
