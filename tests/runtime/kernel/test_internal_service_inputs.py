"""A Smart Resource service whose Input is one of its node's internal topics (the use case's raw
sensor topics: hokuyo_raw, camera_raw, head_yaw_angle) reads it under the node-local name the
node's sensors publish it on, from the node's main process or a partition process alike."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, TopicQoS, Transport, open_transport
from runtime.resources import codec
from tests.runtime.network.conftest import private_network

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="internal-inputs">
  <MessageType name="PanTilt">
    <Field name="pan" type="float64"/>
    <Field name="tilt" type="float64"/>
  </MessageType>
  <Node name="nao" kind="service">
    <HWChannel name="yaw" direction="in" kind="analog" backend="loopback" min="-2" max="2"/>
    <HWChannel name="pitch" direction="in" kind="analog" backend="loopback" min="-1" max="1"/>
    <Topic name="head_yaw_angle" type="float64" scope="internal"/>
    <Topic name="head_pitch_angle" type="float64" scope="internal"/>
    <Topic name="/nao/head_state" type="PanTilt"/>
    <Topic name="/nao/status" type="bytes"/>
    <Sensor name="yaw_sensor" channel="yaw" topic="head_yaw_angle" period="0.02"/>
    <Sensor name="pitch_sensor" channel="pitch" topic="head_pitch_angle" period="0.02"/>
  </Node>
  <SmartResource name="Nao" node="nao">
    <Plugin name="naoqi" kind="naoqi-bridge"/>
    <Profile name="NAOQI" output="naoqi"><Use plugin="naoqi"/></Profile>
    <Service name="NaoQi" performance="available">
      <Input name="head_yaw" topic="head_yaw_angle"/>
      <Input name="head_pitch" topic="head_pitch_angle"/>
      <Output name="head_state" topic="/nao/head_state"/>
      <Output name="status" topic="/nao/status"/>
      <QualityMeasure name="available" kind="qos" domain="performance" source="available"/>
      <Scenario name="NAOQI" profile="NAOQI"><Policy measure="available" lower="0" probability="0.5"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


@pytest.fixture
def transport() -> Iterator[Transport]:
    running = open_transport(private_network(), name="internal-inputs")
    running.setup()
    running.start()
    yield running
    running.stop()


def test_a_service_reads_its_node_internal_sensor_topics(transport: Transport, tmp_path: Path) -> None:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    system = ckmconf.load(path)
    runtime = NodeRuntime(system.nodes[0], system, transport)
    assert runtime.topic("head_yaw_angle").name == "/nao/~head_yaw_angle"  # what the sensor publishes on
    states: list[Any] = []

    def keep(sample: Sample) -> None:
        states.append(codec.decode(sample.value))

    transport.subscribe(TopicQoS("/nao/head_state", "ckm/service-data"), keep)
    runtime.setup()
    runtime.start()
    try:
        deadline = time.monotonic() + 20.0
        while not states and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        runtime.stop()
    assert states, "the service never saw its internal inputs"
    assert set(states[-1]) >= {"pan", "tilt"}
