"""What the runtime cannot run is refused at its element when the node is built, never skipped
silently (issue G): Smart Resources on a ROS kernel, services without scenarios."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import pytest

import ckmconf
from ckmconf.errors import ConfigError
from runtime.kernel.interfaces import Backend
from runtime.kernel.node import NodeRuntime
from runtime.network import Transport, open_transport
from runtime.registry import Registry
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


class _Opened(Backend):
    """A device that records being opened and closed; the one named 'broken' cannot open."""

    log: ClassVar[list[str]] = []

    def setup(self) -> None:
        if self.channel.name == "broken":
            raise OSError("device busy")
        _Opened.log.append(f"open {self.channel.name}")

    def read(self) -> float:
        return 0.0

    def write(self, value: Any) -> None:
        return None

    def stop(self) -> None:
        _Opened.log.append(f"close {self.channel.name}")


HARDWARE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="half-open">
  <Node name="n" kind="light">
    <HWChannel name="first" direction="in" kind="analog" backend="opened"/>
    <HWChannel name="second" direction="in" kind="analog" backend="opened"/>
    <HWChannel name="broken" direction="in" kind="analog" backend="opened"/>
  </Node>
</System>
"""


def test_a_failed_set_up_closes_the_devices_it_had_opened(tmp_path: Path, transport: Transport) -> None:
    path = tmp_path / "system.xml"
    path.write_text(HARDWARE)
    system = ckmconf.load(path)
    registry = Registry(load_entry_points=False)
    registry.register("hardware", "opened", _Opened)
    runtime = NodeRuntime(system.nodes[0], system, transport, registry=registry)
    _Opened.log.clear()
    with pytest.raises(OSError, match="device busy"):
        runtime.setup()
    assert _Opened.log == ["open first", "open second", "close first", "close second"]
