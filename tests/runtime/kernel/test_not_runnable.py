"""What the runtime cannot run is refused at its element when the node is built, never skipped
silently (issue G): Smart Resources on a ROS kernel, services without scenarios."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

import ckmconf
from ckmconf.errors import ConfigError
from runtime.kernel.node import NodeRuntime
from runtime.network import Transport, open_transport
from tests.runtime.network.conftest import private_network

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="not-runnable">
  <Topic name="/arm/goal" type="string"/>
  <Topic name="/arm/state" type="string"/>
  <Node name="arm-pc" kind="service"/>
  <Node name="scan-pc" kind="service"/>
  <SmartResource name="RoboticArm" node="arm-pc" kernel="ros">
    <Service name="MoveIt" function="kinematics" performance="active">
      <Input name="goal" topic="/arm/goal"/>
      <Output name="state" topic="/arm/state"/>
      <QualityMeasure name="active" kind="qos" domain="performance" source="active"/>
    </Service>
  </SmartResource>
  <SmartResource name="Laser" node="scan-pc">
    <Service name="Scan" function="ranges" performance="active">
      <Output name="state" topic="/arm/state"/>
      <QualityMeasure name="active" kind="qos" domain="performance" source="active"/>
    </Service>
  </SmartResource>
</System>
"""


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="refusals")
    running.setup()
    running.start()
    yield running
    running.stop()


@pytest.mark.parametrize(
    ("node", "line", "text"),
    [("arm-pc", 7, "'ros' kernel"), ("scan-pc", 15, "service 'Laser.Scan' has no Scenario")],
)
def test_a_node_refuses_what_it_cannot_run_at_its_element(
    node: str, line: int, text: str, tmp_path: Path, transport: Transport
) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    system = ckmconf.load(path)
    runtime = NodeRuntime(next(n for n in system.nodes if n.name == node), system, transport)
    with pytest.raises(ConfigError) as refused:
        runtime.setup()
    assert str(refused.value).startswith(f"{path}:{line}:") and text in str(refused.value)
