"""A live agent whose behavior uses a Smart Resource service over the network: the behavior's
Configure/Require reach the service, its qualities are recorded, and the composed performance
(eq. 5.1) of the state follows whether the service meets the requirement."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

from ckmconf.loader import load
from runtime.missions.agent import AgentRunner
from runtime.missions.recording import read_run
from runtime.network import open_transport
from runtime.registry import Registry
from runtime.resources.resource import SmartResourceRuntime
from runtime.resources.spt import Context, ProcessingPlugin
from tests.runtime.network.conftest import private_network

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="live-services">
  <Topic name="/out" type="bytes"/>
  <Node name="robot" kind="service"/>
  <SmartResource name="Sensor" node="robot">
    <Plugin name="read" kind="count"/>
    <Profile name="ONLY" output="read"><Use plugin="read"/></Profile>
    <Service name="Measure" rate="0.02">
      <Output name="value" topic="/out"/>
      <Parameter name="gain" type="float" default="1" min="0" max="10"/>
      <QualityMeasure name="reliability" kind="qoc" domain="performance" source="reliability"/>
      <QualityMeasure name="deadline" kind="qos" domain="temporal" source="deadline" unit="s"/>
      <Scenario name="ONLY" profile="ONLY"><Policy measure="deadline" upper="1"/></Scenario>
      <TCM period="0.1" learning="none"/>
    </Service>
  </SmartResource>
  <Behavior name="OBSERVE" kind="timer">
    <Param name="duration" value="2"/>
    <Uses service="Sensor.Measure" as="sensor">
      <Configure parameter="gain" value="2.5"/>
      <Require measure="reliability" lower="0.5" probability="0.9"/>
    </Uses>
  </Behavior>
  <Mission name="Watch" initial="OBSERVE">
    <State name="OBSERVE" behavior="OBSERVE"/>
    <Final name="seen"/>
    <Transition from="OBSERVE" to="seen" when="done() and sensor.reliability &gt; 0.5"/>
  </Mission>
  <Plan name="solo"><Agent name="robot" node="robot" mission="Watch"/></Plan>
</System>
"""


class Count(ProcessingPlugin):
    def process(self, data: Any, context: Context) -> Any:
        return {"count": context.frame, "reliability": 0.9}


def test_a_behavior_configures_a_live_service_and_its_quality_is_recorded(tmp_path: Path) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    system = load(path)
    resource = system.resource("Sensor")
    assert resource is not None
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "count", Count)
    network = private_network()
    server, agent_side = open_transport(network, name="server"), open_transport(network, name="agent")
    for transport in (server, agent_side):
        transport.setup()
        transport.start()
    try:
        counter = iter(range(10**9))
        with SmartResourceRuntime(resource, server, registry=registry, sources={"read": lambda: next(counter)}) as live:
            runner = AgentRunner(system, "solo", "robot", agent_side, tmp_path / "run")
            outcome: list[str | None] = []
            thread = threading.Thread(target=lambda: outcome.append(runner.run(20)))
            thread.start()
            thread.join(30)
            instance = live.instance("Measure")
            assert instance is not None and instance.parameters["gain"] == 2.5  # the behavior's Configure
            assert [r.measure for r in instance.requirements] == ["reliability"]  # and its Require
    finally:
        for transport in (agent_side, server):
            transport.stop()
    assert outcome == ["seen"]
    run = read_run(tmp_path / "run")
    qualities = [e for e in run.events if e.kind == "quality"]
    assert qualities and qualities[-1].fields["service"] == "Sensor.Measure"
    assert qualities[-1].fields["measures"]["reliability"] == 0.9
    performance = [e.fields["performance"] for e in run.events if e.kind == "progress" and e.fields["performance"]]
    assert performance and performance[-1] == 1.0  # running and meeting its requirement
