"""A lazy sensor reads only while a subscriber asks for its topic; its staleness watch only observes (D245)."""

from __future__ import annotations

import functools
from collections.abc import Iterator
from pathlib import Path

import pytest

from runtime.kernel.node import NodeRuntime
from runtime.network import Transport
from tests import waiting
from tests.runtime.kernel.conftest import running_node

until = functools.partial(waiting.until, interval=0.01)

LAZY = """<System xmlns="urn:ckm:1" version="1.0" name="lazy">
  <Node name="n">
    <HWChannel name="y" direction="in"><Param name="plant" value="p"/></HWChannel>
    <HWChannel name="u" direction="out" min="-10" max="10">
      <Param name="plant" value="p"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.1"/>
    </HWChannel>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="eager" type="float64" scope="internal"/>
    <Sensor name="camera" channel="y" topic="y" period="0.01" lazy="true"/>
    <Sensor name="gauge" channel="y" topic="eager" period="0.01"/>
    <Monitor period="0.05">
      <Alarm name="y_stale" measure="staleness" topic="y" above="0.3" severity="warning"/>
      <Alarm name="eager_stale" measure="staleness" topic="eager" above="0.3" severity="warning"/>
    </Monitor>
  </Node>
</System>"""


@pytest.fixture
def node(tmp_path: Path) -> Iterator[tuple[NodeRuntime, Transport]]:
    with running_node(LAZY, tmp_path, "lazy-test") as running:
        yield running


def test_a_lazy_sensor_reads_only_while_its_topic_is_asked_for(node: tuple[NodeRuntime, Transport]) -> None:
    runtime, transport = node
    camera, gauge = runtime.sensors["camera"], runtime.sensors["gauge"]
    assert until(lambda: camera.rested > 20 and len(gauge.samples) > 5)
    assert not camera.samples  # nobody asked: the channel was never read
    # the monitor's watch observes the topic without asking for it, and sees nothing stale
    watch = runtime._watched["y"]
    assert watch.passive and not runtime._watched["eager"].passive
    assert runtime.monitor is not None and not runtime.monitor.active("y_stale")

    reader = transport.subscribe(runtime.topic("y"))
    assert until(lambda: reader.received > 5)
    assert watch.received > 0  # what flows reaches the watch too
    reader.demand(False)
    assert until(lambda: not transport.subscribed(runtime.topic("y").name))
    read = len(camera.samples) and camera.samples[-1][0]
    rested = camera.rested
    assert until(lambda: camera.rested > rested + 10)
    assert camera.samples[-1][0] == read  # resting again: no new read
    assert not runtime.monitor.active("y_stale")


def test_a_lazy_topic_asked_for_but_silent_goes_stale_from_the_ask(node: tuple[NodeRuntime, Transport]) -> None:
    runtime, transport = node
    monitor = runtime.monitor
    assert monitor is not None
    runtime.scheduler.remove("n.camera")  # the sensor is gone: once asked, its topic stays silent
    assert until(lambda: monitor.alarms["eager_stale"].value > 0)  # the monitor has measured
    assert monitor.alarms["y_stale"].value == 0.0 and not monitor.active("y_stale")  # nobody asks: not stale
    transport.subscribe(runtime.topic("y"))
    assert until(lambda: monitor.active("y_stale"), timeout=15)
    assert not monitor.active("eager_stale")
