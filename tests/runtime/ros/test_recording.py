"""ckm-run --record: a run's topics as a rosbag2 bag, read back by independent readers (issue L point 2).

The bags are read with the ``mcap`` library and its ROS 2 decoder (``mcap-ros2-support``), plain
``sqlite3`` with ``mcap_ros2``'s dynamic decoder for ``.db3`` bags, and ``rosbags``' own reader and
type store: none of them is CKM code. Runs use a private multicast group and ports on 127.0.0.1.
"""

from __future__ import annotations

import json
import math
import re
import resource
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import ckmconf
from runtime import cli
from runtime.network import open_transport
from runtime.network.api import TopicQoS
from runtime.ros.recording import RecordingError, RunRecorder, bag_topic_name
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

CLOSED_LOOP = REPO / "configs" / "examples" / "closed_loop.xml"
ROS_DATA = REPO / "tests" / "data" / "ros"
LOOP_TOPICS = {"/motor_node/speed", "/motor_node/setpoint", "/motor_node/command"}


def _private_copy(config: Path, tmp_path: Path) -> Path:
    """``config`` with a <Network> of its own, so no other run on this machine is heard."""
    net = private_network()
    element = f'<Network group="{net.group}" discoveryPort="{net.discovery_port}" basePort="{net.base_port}"/>'
    text = re.sub(r"(<System [^>]*>)", lambda m: m.group(1) + "\n  " + element, config.read_text(), count=1)
    copy = tmp_path / config.name
    copy.write_text(text)
    return copy


def _ckm_run(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "runtime.cli", *args], capture_output=True, text=True, timeout=timeout, cwd=REPO
    )


def _rosbags_messages(bag: Path, extra: dict[str, str] | None = None) -> Counter[str]:
    """Every message of ``bag`` deserialised by rosbags' reader and Jazzy store; counts per topic."""
    store = get_typestore(Stores.ROS2_JAZZY)
    counts: Counter[str] = Counter()
    with Reader(bag) as reader:
        for connection in reader.connections:
            if connection.msgtype not in store.fielddefs:
                store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
        for connection, _stamp, data in reader.messages():
            message = store.deserialize_cdr(data, connection.msgtype)
            assert getattr(message, "__msgtype__", None) == connection.msgtype
            counts[connection.topic] += 1
    return counts


@pytest.mark.timeout(60)
@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_recorded_run_reads_back_with_independent_readers(storage: str, tmp_path: Path) -> None:
    config = _private_copy(CLOSED_LOOP, tmp_path)
    run_dir = tmp_path / "run"
    done = _ckm_run(
        str(config), "--duration", "2", "--log-dir", str(run_dir), "--record", "all", "--record-format", storage
    )
    assert done.returncode == 0, done.stderr
    recording = json.loads((run_dir / "stats.json").read_text())["recording"]
    assert recording["format"] == storage and recording["failure"] is None
    written = {t["bagTopic"]: t["written"] for t in recording["topics"].values()}
    assert set(written) == LOOP_TOPICS and all(t["dropped"] == 0 for t in recording["topics"].values())
    assert written["/motor_node/speed"] > 20 and written["/motor_node/command"] > 20  # 100 Hz for 2 s, loaded host
    assert written["/motor_node/setpoint"] == 0  # nothing publishes it: declared, empty
    bag = run_dir / "bag"
    decoded: list[tuple[str, Any]] = []
    if storage == "mcap":
        with (bag / "bag.mcap").open("rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            assert reader.get_header().profile == "ros2"
            summary = reader.get_summary()
            assert summary is not None
            assert {c.topic for c in summary.channels.values()} == LOOP_TOPICS
            assert {s.name for s in summary.schemas.values()} == {"std_msgs/msg/Float64"}
            decoded = [(channel.topic, message) for _, channel, _, message in reader.iter_decoded_messages()]
    else:
        with sqlite3.connect(bag / "bag.db3") as db:
            topics = {i: (n, t) for i, n, t in db.execute("SELECT id, name, type FROM topics")}
            definitions = dict(db.execute("SELECT topic_type, encoded_message_definition FROM message_definitions"))
            rows = db.execute("SELECT topic_id, data FROM messages ORDER BY timestamp").fetchall()
        assert {n for n, _ in topics.values()} == LOOP_TOPICS
        decoders = {t: generate_dynamic(t, text)[t] for t, text in definitions.items()}
        decoded = [(topics[i][0], decoders[topics[i][1]](data)) for i, data in rows]
    assert Counter(topic for topic, _ in decoded) == Counter({t: n for t, n in written.items() if n})
    assert all(isinstance(m.data, float) and math.isfinite(m.data) for _, m in decoded)
    assert decoded and all(math.isfinite(m.data) for _, m in decoded)
    assert _rosbags_messages(bag) == Counter({t: n for t, n in written.items() if n})


def _small_files() -> None:
    """In the child: files may not grow past 16 KiB (EFBIG instead of SIGXFSZ), a full disk for the bag."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384))


@pytest.mark.timeout(60)
def test_a_failing_bag_reaches_stderr_and_the_exit_code(tmp_path: Path) -> None:
    config = _private_copy(CLOSED_LOOP, tmp_path)
    command = [sys.executable, "-m", "runtime.cli", str(config), "--duration", "3", "--log-dir", str(tmp_path / "run")]
    done = subprocess.run(
        [*command, "--record", "all"], capture_output=True, text=True, timeout=50, cwd=REPO, preexec_fn=_small_files
    )
    assert done.returncode == 5, done.stderr
    assert "the bag" in done.stderr and "File too large" in done.stderr
    recording = json.loads((tmp_path / "run" / "stats.json").read_text())["recording"]
    assert "File too large" in recording["failure"]
    assert "ERROR ckm.record" in (tmp_path / "run" / "ckm.log").read_text()


def test_record_problems_stop_before_the_run_starts(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # in this process: each case returns before any transport, node or bag exists
    assert cli.main([str(CLOSED_LOOP), "--log-dir", str(tmp_path / "a"), "--record", "speed,odom"]) == 1
    assert "no topic 'odom' here (topics: command, setpoint, speed)" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    (tmp_path / "b" / "bag").mkdir(parents=True)
    assert cli.main([str(CLOSED_LOOP), "--log-dir", str(tmp_path / "b"), "--record", "all"]) == 1
    assert "exists already" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:
        cli.main([str(CLOSED_LOOP), "--record", "all", "--record-format", "rosbag1"])
    assert usage.value.code == 2 and "--record-format" in capsys.readouterr().err


def test_bag_topic_names_are_ros_names() -> None:
    assert bag_topic_name("/motor-node/~speed") == "/motor_node/speed"
    assert bag_topic_name("speed") == "/speed" and bag_topic_name("/robot1/scan") == "/robot1/scan"
    assert bag_topic_name("/n/~3d-points") == "/n/t3d_points"


@pytest.mark.timeout(30)
def test_values_that_do_not_fit_are_dropped_and_counted_never_fatal(tmp_path: Path) -> None:
    shutil.copytree(ROS_DATA / "ckm_test_msgs", tmp_path / "ckm_test_msgs")
    config = _private_copy(ROS_DATA / "ros_typed_loop.xml", tmp_path)
    system = ckmconf.load(config)
    network = system.network
    assert network is not None
    recorder = RunRecorder.in_run(
        system, system.nodes, tmp_path, None, "/wheels,/scan,/reading,/clock_time,/bumper", "mcap"
    )
    assert [t.ros_type for t in recorder.topics] == [
        "sensor_msgs/msg/LaserScan",
        "ckm_test_msgs/msg/Reading",
        "ckm_msgs/msg/WheelState",
        "builtin_interfaces/msg/Time",
        "std_msgs/msg/Bool",
    ]
    transport = open_transport(network, name="recorder-test")
    transport.setup()
    transport.start()
    try:
        recorder.start(transport)
        publish = {t.name: transport.publisher(TopicQoS.of(t)) for t in system.topics}
        now = time.time()
        wheels = {"stamp": now, "wheelSpeeds": [1.0, 2.0], "history": [0.5], "raw": b"\x07", "pose": {"x": 3.0}}
        publish["/wheels"].publish(wheels)
        publish["/wheels"].publish({**wheels, "wheelSpeeds": [1.0, 2.0, 3.0]})  # 3 values for float64[2]
        publish["/wheels"].publish({**wheels, "colour": "red"})  # a field the type lacks
        publish["/scan"].publish({"header": {"frame_id": "laser"}, "ranges": np.ones(4, np.float32)})
        publish["/scan"].publish("not a scan")
        publish["/reading"].publish({"label": "cup", "value": 1.5, "quality": {"reliability": 0.9}})
        publish["/clock_time"].publish(now)
        publish["/clock_time"].publish(float("nan"))
        publish["/bumper"].publish(1.0)  # a digital channel's read: numbers fit bool topics
        publish["/bumper"].publish(False)
    finally:
        recorder.stop()
        transport.stop()
    stats = recorder.statistics()["topics"]
    assert {n: (s["written"], s["dropped"]) for n, s in stats.items()} == {
        "/wheels": (1, 2),
        "/scan": (1, 1),
        "/reading": (1, 0),
        "/clock_time": (1, 1),
        "/bumper": (2, 0),
    }
    assert "exactly 2" in stats["/wheels"]["firstDrop"] and recorder.failure is None
    with (tmp_path / "bag" / "bag.mcap").open("rb") as stream:
        messages = list(make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages())
    decoded = {c.topic: m for _, c, _, m in messages}  # the last of each topic
    assert [m.data for _, c, _, m in messages if c.topic == "/bumper"] == [True, False]
    assert list(decoded["/wheels"].wheel_speeds) == [1.0, 2.0] and decoded["/wheels"].pose.x == 3.0
    assert bytes(decoded["/wheels"].raw) == b"\x07" and decoded["/wheels"].stamp.sec == math.floor(now)
    assert decoded["/reading"].label == "cup" and decoded["/reading"].quality.reliability == pytest.approx(0.9)
    assert decoded["/scan"].header.frame_id == "laser" and list(decoded["/scan"].ranges) == [1.0] * 4
    assert _rosbags_messages(tmp_path / "bag") == Counter(
        {"/wheels": 1, "/scan": 1, "/reading": 1, "/clock_time": 1, "/bumper": 2}
    )


def test_unknown_topics_are_refused_with_the_known_ones() -> None:
    system = ckmconf.load(CLOSED_LOOP)
    with pytest.raises(RecordingError, match=r"no topic '/nope' here \(topics: command, setpoint, speed\)"):
        RunRecorder.in_run(system, system.nodes, Path("/nonexistent-run-dir"), None, "/nope", "mcap")
