"""Service Parameters that reach the plugins (issue G, point 8): the Fusion service's ``max_sensors``
(Table 7.1) caps the observations fused per object, from its default at start and from a client's
configuration at run time, over a real transport on loopback with the real fusion plugin."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from ckmconf.loader import load
from ckmconf.model.resources import SmartResource
from plugins.processing.fusion import FeatureFusion
from runtime.network import Transport
from runtime.registry import Registry
from runtime.resources.client import ServiceClient, ServiceDirectory, ServiceError
from runtime.resources.resource import SmartResourceRuntime
from tests.plugins.processing.test_fusion import three_lines_and_a_point
from tests.runtime.resources.test_service_api import until

POSE = "pantilt: 0.9 0.05 1.2 0 -1.5707963267948966 0"
SYSTEM = f"""<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="fusion-parameters">
  <Topic name="/recog/objects" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="GlobalRecog" node="pc">
    <Plugin name="fusion" kind="feature-fusion">
      <Param name="inputs" value="rgb: line; depth: point; pantilt: line"/>
      <Param name="poses" value="{POSE}"/>
      <Param name="objects" value="cylinder_red_stripes: cylinder red_stripes"/>
      <Param name="fx" value="525"/>
      <Param name="calibrationWidth" value="640"/><Param name="calibrationHeight" value="480"/>
    </Plugin>
    <Profile name="FUSION"><Use plugin="fusion"/></Profile>
    <Service name="Fusion" rate="0.02" performance="reliability">
      <Output name="objects" topic="/recog/objects"/>
      <Parameter name="max_sensors" type="int" default="2" min="1" max="8"/>
      <QualityMeasure name="reliability" kind="qoc" domain="performance" source="reliability"/>
      <Scenario name="FUSION" profile="FUSION"><Policy measure="reliability" lower="0.5"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


@pytest.fixture
def resource(tmp_path: Path) -> SmartResource:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM, encoding="utf-8")
    record = load(path).resource("GlobalRecog")
    assert record is not None
    return record


def test_max_sensors_reaches_the_fusion_plugin(resource: SmartResource, pair: tuple[Transport, Transport]) -> None:
    server, remote = pair
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "feature-fusion", FeatureFusion)
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"fusion": three_lines_and_a_point}, announce_period=0.2
    )
    with runtime:
        plugin = runtime.streams["fusion"].topology.plugins["fusion"]
        assert isinstance(plugin, FeatureFusion) and plugin.max_sensors == 2  # the service's default, not the Param's 8
        entry = ServiceDirectory(remote).wait_for("GlobalRecog", "Fusion", timeout=10)
        with ServiceClient(remote, entry, "agent1") as client:
            received: list[Any] = []
            client.data("objects", received.append)
            client.connect(timeout=10)
            assert until(lambda: len(received) >= 2)
            assert {tuple(o["sources"]) for r in received for o in r["objects"]} == {("depth", "pantilt")}
            client.configure(parameters={"max_sensors": 3}, timeout=10)  # the cooperative SPOT (Table 7.7)
            assert plugin.max_sensors == 3
            count = len(received)
            assert until(lambda: len(received) > count + 1)
            assert received[-1]["objects"][0]["sources"] == ["depth", "pantilt", "rgb"]
            with pytest.raises(ServiceError, match="max_sensors"):
                client.configure(parameters={"max_sensors": 0}, timeout=10)  # refused by the Parameter's min
            assert plugin.max_sensors == 3


def test_a_value_the_plugin_refuses_is_an_error_naming_the_service(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    """Without min/max on the Parameter the service API lets 0 through; the plugin refuses it: at
    start (the default) the service fails to start, at run time the request is refused."""
    server, remote = pair
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "feature-fusion", FeatureFusion)
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.replace('default="2" min="1" max="8"', 'default="0"'), encoding="utf-8")
    record = load(path).resource("GlobalRecog")
    assert record is not None
    runtime = SmartResourceRuntime(record, server, registry=registry, sources={"fusion": three_lines_and_a_point})
    runtime.setup()
    try:
        with pytest.raises(ValueError, match=r"service GlobalRecog.Fusion: .*'max_sensors' = 0 must be a whole number"):
            runtime.start()
    finally:
        runtime.stop()

    path.write_text(SYSTEM.replace('default="2" min="1" max="8"', 'default="2"'), encoding="utf-8")
    record = load(path).resource("GlobalRecog")
    assert record is not None
    runtime = SmartResourceRuntime(
        record, server, registry=registry, sources={"fusion": three_lines_and_a_point}, announce_period=0.2
    )
    with runtime:
        entry = ServiceDirectory(remote).wait_for("GlobalRecog", "Fusion", timeout=10)
        with ServiceClient(remote, entry, "agent1") as client:
            client.connect(timeout=10)
            with pytest.raises(ServiceError, match="'max_sensors' = 0 must be a whole number"):
                client.configure(parameters={"max_sensors": 0}, timeout=10)
            plugin = runtime.streams["fusion"].topology.plugins["fusion"]
            assert isinstance(plugin, FeatureFusion) and plugin.max_sensors == 2
