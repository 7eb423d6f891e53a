"""A recorded bag replayed into a running system in place of a device (issue L point 2, D156).

``ckm-run --record`` records a small loopback system whose sensor reads a noisy plant (every value
distinct); a second configuration replaces that device by the bag (``backend="bag"``), its sensor
feeding a PID controller, and is recorded in turn. What the replay's topic carried (what its
controller read) is the recorded sequence: the same values in the same order. Both bags are read
with ``rosbags``' own reader and type store. Runs use a private network on 127.0.0.1.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

SOURCE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="source">
  {network}
  <Node name="source" kind="light">
    <HWChannel name="probe" direction="in" kind="analog">
      <Param name="noise" value="1.0"/>
      <Param name="seed" value="7"/>
    </HWChannel>
    <Topic name="level" type="float64" scope="internal"/>
    <Sensor name="level" channel="probe" topic="level" period="0.02"/>
  </Node>
</System>
"""

REPLAY = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="replay">
  {network}
  <Node name="replay" kind="light">
    <HWChannel name="probe" direction="in" kind="analog" backend="bag">
      <Param name="bag" value="{bag}"/>
      <Param name="topic" value="/source/level"/>
      <Param name="type" value="std_msgs/msg/Float64"/>
      <Param name="rate" value="0.5"/>
    </HWChannel>
    <HWChannel name="valve" direction="out" kind="pwm" min="-1" max="1"/>
    <Topic name="level" type="float64" scope="internal"/>
    <Topic name="setpoint" type="float64" scope="internal"/>
    <Topic name="command" type="float64" scope="internal"/>
    <Sensor name="level" channel="probe" topic="level" period="0.01"/>
    <Controller name="pid" kind="pid" period="0.01">
      <Param name="kp" value="0.1"/>
      <Input topic="level" role="measure"/>
      <Input topic="setpoint" role="setpoint"/>
      <Output topic="command"/>
    </Controller>
    <Actuator name="valve" channel="valve" topic="command" min="-1" max="1" safeValue="0"/>
  </Node>
</System>
"""


def _write(path: Path, template: str, **values: str) -> Path:
    net = private_network()
    network = f'<Network group="{net.group}" discoveryPort="{net.discovery_port}" basePort="{net.base_port}"/>'
    path.write_text(template.format(network=network, **values))
    return path


def _ckm_run(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "runtime.cli", *args], capture_output=True, text=True, timeout=timeout, cwd=REPO
    )


def _values(bag: Path, topic: str) -> list[float]:
    """The ``data`` of every Float64 message of ``topic``, in time order, read by rosbags alone."""
    store = get_typestore(Stores.ROS2_JAZZY)
    with Reader(bag) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        assert connections, f"{bag} has no topic {topic}"
        messages: list[Any] = [store.deserialize_cdr(data, c.msgtype) for c, _, data in reader.messages(connections)]
    return [float(m.data) for m in messages]


@pytest.mark.timeout(120)
def test_a_replayed_bag_feeds_the_controller_the_recorded_values_in_order(tmp_path: Path) -> None:
    source = _write(tmp_path / "source.xml", SOURCE)
    done = _ckm_run(str(source), "--duration", "2", "--log-dir", str(tmp_path / "rec"), "--record", "level")
    assert done.returncode == 0, done.stderr
    recorded = _values(tmp_path / "rec" / "bag", "/source/level")
    assert len(recorded) > 20 and len(set(recorded)) == len(recorded)  # 50 Hz for 2 s, every value distinct

    replay = _write(tmp_path / "replay.xml", REPLAY, bag="rec/bag")  # relative to the configuration file
    done = _ckm_run(str(replay), "--duration", "3", "--log-dir", str(tmp_path / "play"), "--record", "level,command")
    assert done.returncode == 0, done.stderr
    played = _values(tmp_path / "play" / "bag", "/replay/level")
    commands = _values(tmp_path / "play" / "bag", "/replay/command")
    assert commands and any(c != 0.0 for c in commands)  # the controller acted on what it read
    # the sensor samples 4 times per replayed message (period 0.01 s, messages 0.04 s apart at rate 0.5):
    # collapsed, its values are the recording's, in order, from the first on
    collapsed = [v for i, v in enumerate(played) if i == 0 or v != played[i - 1]]
    assert collapsed[0] == recorded[0]
    indices = [recorded.index(v) for v in collapsed]  # every value played is a recorded one …
    assert indices == sorted(indices) and len(set(indices)) == len(indices)  # … in the recorded order
    reached = indices[-1] + 1
    assert reached >= len(recorded) // 3  # 3 s at half speed: 1.5 s of the 2 s recording (loaded host)
    assert len(indices) >= 0.8 * reached  # at most a few skipped by a stalled sampler
    stats = json.loads((tmp_path / "play" / "stats.json").read_text())["recording"]
    assert stats["topics"]["/replay/~level"]["dropped"] == 0


def test_a_missing_bag_stops_the_run_before_it_starts(tmp_path: Path) -> None:
    replay = _write(tmp_path / "replay.xml", REPLAY, bag="no-such-bag")
    done = _ckm_run(str(replay), "--duration", "1", "--log-dir", str(tmp_path / "play"))
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1] == (
        f"{replay}:6:25: /System[@name='replay']/Node[@name='replay']/HWChannel[@name='probe']/Param[@name='bag']"
        f"/@value: bag channel 'probe': the bag {tmp_path / 'no-such-bag'} does not exist"
    )
