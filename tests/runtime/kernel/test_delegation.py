"""Code delegation: a running controller moves to a node in another process, with no gap and no overlap."""

from __future__ import annotations

import itertools
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import Network
from runtime.kernel.node import NodeRuntime
from runtime.network import Sample, Transport, open_transport
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

PERIOD = 0.02

CONFIG = """<System xmlns="urn:ckm:1" version="1.0" name="delegation">
  <Network group="{group}" discoveryPort="{dport}" basePort="{base}" portTries="48" heartbeat="0.1"/>
  <Node name="plant" kind="light">
    <HWChannel name="y" direction="in"><Param name="plant" value="p"/></HWChannel>
    <HWChannel name="u" direction="out" min="-10" max="10">
      <Param name="plant" value="p"/><Param name="gain" value="1"/><Param name="timeConstant" value="0.2"/>
    </HWChannel>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="u" type="float64" scope="internal"/>
    <Topic name="r" type="float64" scope="internal"/>
    <Sensor name="y" channel="y" topic="y" period="0.01"/>
    <Controller name="pid" kind="pid" period="{period}" delegable="true">
      <Param name="kp" value="0.8"/><Param name="ki" value="4"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
    </Controller>
    <Actuator name="u" channel="u" topic="u" min="-10" max="10" safeValue="0" commandTimeout="0.2"/>
  </Node>
  <Node name="idle" kind="service"/>
</System>"""


@pytest.fixture
def setup(tmp_path: Path) -> Iterator[tuple[NodeRuntime, Transport, Path]]:
    network: Network = private_network(heartbeat=0.1)
    path = tmp_path / "delegation.xml"
    path.write_text(
        CONFIG.format(group=network.group, dport=network.discovery_port, base=network.base_port, period=PERIOD)
    )
    system = ckmconf.load(path)
    transport = open_transport(system.network or network, name="giver")
    transport.setup()
    transport.start()
    runtime = NodeRuntime(system.nodes[0], system, transport)
    runtime.setup()
    runtime.start()
    try:
        yield runtime, transport, path
    finally:
        runtime.stop()
        transport.stop()


def test_a_running_controller_moves_to_another_process_without_gap(
    setup: tuple[NodeRuntime, Transport, Path], tmp_path: Path
) -> None:
    runtime, transport, path = setup
    taker = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "runtime.cli",
            str(path),
            "--node",
            "idle",
            "--duration",
            "60",
            "--log-dir",
            str(tmp_path / "idle"),
        ],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        outputs: list[Sample] = []
        transport.subscribe(runtime.topic("u"), outputs.append)
        reference = transport.publisher(runtime.topic("r"))
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not transport.peers():
            reference.publish(1.0)
            time.sleep(0.02)
        assert transport.peers(), "the idle node never joined"
        for _ in range(25):
            reference.publish(1.0)
            time.sleep(0.02)
        assert runtime.delegation is not None
        assert runtime.delegation.give("pid", "idle")
        handed = len(outputs)
        for _ in range(50):
            reference.publish(1.0)
            time.sleep(0.02)
        assert "pid" not in runtime.controllers
        after = outputs[handed:]
        assert after and any(s.source != transport.guid for s in after), "the taker never published"
        stamps = [s.stamp for s in outputs[max(0, handed - 20) : handed + 40]]
        gaps = [b - a for a, b in itertools.pairwise(stamps)]
        assert max(gaps) < 1.9 * PERIOD, "a period went without an output"
        assert min(gaps) > 0.3 * PERIOD, "a period got two outputs"
        kinds = [e["kind"] for e in runtime.events]
        assert "delegated" in kinds
    finally:
        taker.terminate()
        try:
            taker.wait(20)
        finally:
            taker.kill()
