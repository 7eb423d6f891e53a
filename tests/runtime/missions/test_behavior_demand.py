"""An agent asks for what a behavior reads only while its state is active (D245): before, the topic is
joined but only observed (a one-shot output still arrives), after, it is observed again, so a lazy
sensor or service works for the state and rests otherwise."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from ckmconf.loader import load
from runtime.missions.agent import AgentRunner
from runtime.network import open_transport
from tests.runtime.network.conftest import private_network

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="demand">
  <Topic name="/cam" type="string" reliability="reliable" history="1"/>
  <Node name="robot" kind="service"/>
  <Behavior name="IDLE" kind="timer"><Param name="duration" value="3"/></Behavior>
  <Behavior name="WATCH" kind="wait-input" timeout="2">
    <Input name="frame" topic="/cam"/>
  </Behavior>
  <Behavior name="REST" kind="timer"><Param name="duration" value="2"/></Behavior>
  <Mission name="Look" initial="IDLE">
    <State name="IDLE" behavior="IDLE"/>
    <State name="WATCH" behavior="WATCH"/>
    <State name="REST" behavior="REST"/>
    <Final name="seen"/>
    <Transition from="IDLE" to="WATCH" when="done()"/>
    <Transition from="WATCH" to="REST" when="done() or timeout()"/>
    <Transition from="REST" to="seen" when="done()"/>
  </Mission>
  <Plan name="solo"><Agent name="robot" node="robot" mission="Look"/></Plan>
</System>
"""


def test_a_behaviors_input_is_asked_for_only_while_its_state_is_active(tmp_path: Path) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    network = private_network()
    agent, camera = open_transport(network, name="agent"), open_transport(network, name="camera")
    seen: list[tuple[bool, bool]] = []  # (linked, asked) at the camera, each change once
    outcome: list[str | None] = []
    for transport in (agent, camera):
        transport.setup()
        transport.start()
    try:
        runner = AgentRunner(load(path), "solo", "robot", agent, tmp_path / "run")
        thread = threading.Thread(target=lambda: outcome.append(runner.run(30)))
        thread.start()
        deadline = time.monotonic() + 40
        while thread.is_alive() and time.monotonic() < deadline:
            state = (camera.wait_for_subscribers("/cam", 1, 0), camera.subscribed("/cam"))
            if not seen or seen[-1] != state:
                seen.append(state)
            time.sleep(0.01)
        thread.join(5)
        assert not thread.is_alive()
    finally:
        agent.stop()
        camera.stop()
    assert outcome == ["seen"]
    asked = seen.index((True, True))
    assert (True, False) in seen[:asked]  # joined at start, only observed while IDLE ran
    assert (True, False) in seen[asked:]  # observed again once WATCH was left
