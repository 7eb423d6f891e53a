"""Behaviors' topics (runtime/missions/agent.py LiveFactory): a state's one-shot output reaches the next
state's input — the use case's SPOT writes the target once and APPR reads it — because every behavior's
topics are joined when the agent starts, not when their state is first entered."""

from __future__ import annotations

import threading
from pathlib import Path

from ckmconf.loader import load
from runtime.missions.agent import AgentRunner
from runtime.network import open_transport
from tests.runtime.network.conftest import private_network

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="handover">
  <Topic name="/hand" type="string" reliability="reliable" history="1"/>
  <Node name="robot" kind="service"/>
  <Behavior name="GIVE" kind="emit">
    <Param name="value" value="the target"/>
    <Output name="out" topic="/hand"/>
  </Behavior>
  <Behavior name="TAKE" kind="wait-input" timeout="3">
    <Input name="in" topic="/hand"/>
  </Behavior>
  <Mission name="Handover" initial="GIVE">
    <State name="GIVE" behavior="GIVE"/>
    <State name="TAKE" behavior="TAKE"/>
    <Final name="taken"/>
    <Final name="lost"/>
    <Transition from="GIVE" to="TAKE" when="done()"/>
    <Transition from="TAKE" to="taken" when="done()"/>
    <Transition from="TAKE" to="lost" when="timeout()"/>
  </Mission>
  <Plan name="solo"><Agent name="robot" node="robot" mission="Handover"/></Plan>
</System>
"""


def run_handover(tmp_path: Path) -> tuple[Path, str | None]:
    """Run SYSTEM's plan live on a private loopback network (recorded in ``tmp_path/run``): the
    configuration file and the agent's outcome."""
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    transport = open_transport(private_network(), name="agent")
    transport.setup()
    transport.start()
    outcome: list[str | None] = []
    try:
        runner = AgentRunner(load(path), "solo", "robot", transport, tmp_path / "run")
        thread = threading.Thread(target=lambda: outcome.append(runner.run(20)))
        thread.start()
        thread.join(30)
        assert not thread.is_alive()
    finally:
        transport.stop()
    return path, outcome[0] if outcome else None


def test_a_one_shot_output_reaches_the_next_states_input(tmp_path: Path) -> None:
    _, outcome = run_handover(tmp_path)
    assert outcome == "taken"
