"""Synthetic systems of any size, valid by construction, for load-time benchmarks and tests."""

from __future__ import annotations


def node_xml(i: int) -> str:
    """The ``<Node>`` ``n{i}`` (kernel.xsd ``NodeType``): partitions, channels, topics, a sensor, a PID, an actuator."""
    return f"""  <Node name="n{i}" kind="{"light" if i % 4 else "service"}" host="127.0.0.1">
    <Partition name="control" criticality="safety"/>
    <Partition name="extras" criticality="best-effort"/>
    <HWChannel name="enc" direction="in" kind="counter" units="tick"/>
    <HWChannel name="motor" direction="out" kind="pwm" min="-1" max="1"/>
    <Topic name="/n{i}/speed" type="float64" deadline="0.02"/>
    <Topic name="ref" type="float64" scope="internal"/>
    <Topic name="cmd" type="float64" scope="internal" lifespan="0.05"/>
    <Sensor name="speed" channel="enc" topic="/n{i}/speed" period="0.01" partition="control">
      <Adaptation><Linear gain="0.001"/><LowPass cutoff="20"/></Adaptation>
    </Sensor>
    <Controller name="pid" kind="pid" period="0.01" partition="control">
      <Param name="kp" value="0.8"/><Param name="ki" value="2"/>
      <Input topic="/n{i}/speed" role="measure"/><Input topic="ref" role="setpoint"/><Output topic="cmd"/>
      <Switch to="safe" when="alarm('slow')"/>
    </Controller>
    <Controller name="safe" kind="pid" period="0.02" active="false" partition="control">
      <Input topic="/n{i}/speed" role="measure"/><Output topic="cmd"/>
    </Controller>
    <Actuator name="motor" channel="motor" topic="cmd" min="-1" max="1" safeValue="0" rateLimit="5" partition="control">
      <Fallback><Action value="0" duration="0.1"/></Fallback>
    </Actuator>
    <Monitor>
      <Alarm name="cpu" measure="cpu" above="0.9"/>
      <Alarm name="slow" measure="jitter" task="pid" above="0.002" action="switch" target="safe"/>
    </Monitor>
  </Node>"""


def resource_xml(i: int) -> str:
    """The ``<SmartResource>`` ``R{i}`` (resources.xsd ``SmartResourceType``) of node ``n{i}``, with a TCM."""
    return f"""  <SmartResource name="R{i}" node="n{i}">
    <Plugin name="grab" kind="camera"/>
    <Plugin name="big" kind="resize"><Param name="width" value="640"/></Plugin>
    <Plugin name="small" kind="resize"><Param name="width" value="320"/></Plugin>
    <Profile name="HI"><Use plugin="grab"><Use plugin="big"/></Use></Profile>
    <Profile name="LO"><Use plugin="grab"><Use plugin="small"/></Use></Profile>
    <Service name="S" rate="0.1" performance="deadline">
      <Output name="out" topic="/n{i}/speed"/>
      <QualityMeasure name="deadline" kind="qos" domain="temporal" source="latency" unit="s"/>
      <Scenario name="hi" profile="HI" weight="2"><Policy measure="deadline" upper="0.05"/></Scenario>
      <Scenario name="lo" profile="LO"><Policy measure="deadline" upper="0.1"/></Scenario>
      <TCM initial="hi"/>
    </Service>
  </SmartResource>"""


def system_xml(nodes: int) -> str:
    """A valid System with ``nodes`` nodes, a Smart Resource on every tenth one, and a mission."""
    parts = ['<?xml version="1.0" encoding="UTF-8"?>', '<System xmlns="urn:ckm:1" version="1.0" name="generated">']
    parts.append('  <Network heartbeat="0.5"/>')
    parts.extend(node_xml(i) for i in range(nodes))
    parts.extend(resource_xml(i) for i in range(0, nodes, 10))
    parts.append('  <Behavior name="watch" kind="wait-goal"><Uses service="R0.S" as="r"/></Behavior>')
    parts.append(
        '  <Mission name="m" initial="a"><State name="a" behavior="watch"/><State name="b" behavior="watch"/>'
        '<Final name="ok"/><Transition from="a" to="b" when="r.deadline &lt; 0.05"/>'
        '<Transition from="b" to="ok"/></Mission>'
    )
    parts.append("</System>")
    return "\n".join(parts) + "\n"
