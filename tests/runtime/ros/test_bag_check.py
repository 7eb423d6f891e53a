"""``ckm-bag check``: a recorded simulated run read back by independent readers (issue L point 2, D181).

Two simulated seconds of configs/examples/sim_ros_types.xml (the Turtlebot's lidar, RGB-D camera,
arm joints and odometry on ROS 2 types) are recorded by ``ckm-run --record all --record-format
mcap+sqlite3`` into an MCAP bag and its sqlite3 twin; the check reads them with ``mcap`` +
``mcap-ros2-support`` and with ``rosbags`` and must decode every message. Broken bags (another
format version, a truncated file, a message that is not CDR of its type) must be reported, naming
the file. Runs use a private network on 127.0.0.1.
"""

from __future__ import annotations

import json
import re
import sqlite3
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from runtime.missions.report_bag import find_bags as report_bags
from runtime.ros.bag import BagRecorder
from runtime.ros.check import check_bag, check_run
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

EXAMPLE = REPO / "configs" / "examples" / "sim_ros_types.xml"
ROS_TOPICS = {
    "/scan": "sensor_msgs/msg/LaserScan",
    "/camera/rgb/image_raw": "sensor_msgs/msg/Image",
    "/camera/rgb/camera_info": "sensor_msgs/msg/CameraInfo",
    "/camera/depth/image_raw": "sensor_msgs/msg/Image",
    "/camera/depth/camera_info": "sensor_msgs/msg/CameraInfo",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
}


def _private_copy(tmp_path: Path) -> Path:
    net = private_network()
    element = f'<Network group="{net.group}" discoveryPort="{net.discovery_port}" basePort="{net.base_port}"/>'
    text = re.sub(r"(<System [^>]*>)", lambda m: m.group(1) + "\n  " + element, EXAMPLE.read_text(), count=1)
    copy = tmp_path / EXAMPLE.name
    copy.write_text(text)
    return copy


def _run(*args: str, timeout: float = 90.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=REPO)


@pytest.mark.timeout(120)
def test_a_recorded_simulated_run_is_read_back_whole_by_the_independent_readers(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    done = _run("-m", "runtime.cli", str(_private_copy(tmp_path)), "--duration", "2", "--log-dir", str(run_dir),
                "--record", "all", "--record-format", "mcap+sqlite3")
    assert done.returncode == 0, done.stderr
    recording = json.loads((run_dir / "stats.json").read_text())["recording"]
    assert recording["failure"] is None and recording["bags"] == [str(run_dir / "bag"), str(run_dir / "bag-sqlite3")]
    assert all(t["dropped"] == 0 for t in recording["topics"].values()), recording["topics"]
    assert report_bags(run_dir) == [run_dir / "bag"]  # the report reads the messages once

    checked = _run("-m", "runtime.ros.bag_cli", "check", "--json", str(run_dir))
    assert checked.returncode == 0, checked.stderr
    results = {r["storage"]: r for r in (json.loads(line) for line in checked.stdout.splitlines())}
    assert sorted(results) == ["mcap", "sqlite3"]
    assert results["mcap"]["readers"] == ["mcap + mcap-ros2-support"] and results["sqlite3"]["readers"] == ["rosbags"]
    for result in results.values():
        assert result["ok"] and result["problems"] == [] and result["version"] == 9
        topics = result["topics"]
        for topic, ros_type in ROS_TOPICS.items():
            assert topics[topic]["type"] == ros_type
            assert topics[topic]["decoded"] == topics[topic]["announced"] > 0, (topic, topics[topic])
        assert result["messages"] == sum(t["written"] for t in recording["topics"].values())

    # what the sensors said, read by rosbags: frames from the URDF, stamps of the sensors' reads
    store = get_typestore(Stores.ROS2_JAZZY)
    frames: dict[str, set[str]] = {}
    with Reader(run_dir / "bag-sqlite3") as reader:
        wanted = [c for c in reader.connections if c.topic in ROS_TOPICS]
        for connection, logged, data in reader.messages(connections=wanted):
            message: Any = store.deserialize_cdr(data, connection.msgtype)
            head = message.transforms[0].header if connection.topic == "/tf" else message.header
            stamp = head.stamp.sec + head.stamp.nanosec * 1e-9
            assert 0 < logged * 1e-9 - stamp < 5.0  # read by the sensor, then published by its driver
            frames.setdefault(connection.topic, set()).add(head.frame_id)
    assert frames["/scan"] == {"hokuyo_link"} and frames["/camera/rgb/image_raw"] == {"camera_rgb_optical_frame"}
    assert frames["/camera/depth/camera_info"] == {"camera_depth_optical_frame"} and frames["/odom"] == {"odom"}


def _bag(tmp_path: Path, storage: str) -> Path:
    path = tmp_path / f"bag-{storage}"
    with BagRecorder(path, storage="mcap" if storage == "mcap" else "sqlite3") as bag:
        bag.add_topic("/chatter", "std_msgs/msg/String")
        for index in range(3):
            bag.write("/chatter", {"data": f"hello {index}"}, 10.0 + index)
    return path


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_a_broken_bag_is_reported_naming_the_file(storage: str, tmp_path: Path) -> None:
    bag = _bag(tmp_path, storage)
    assert check_bag(bag).ok and check_bag(bag).decoded["/chatter"] == 3
    metadata = bag / "metadata.yaml"
    metadata.write_text(metadata.read_text().replace("version: 9", "version: 8"))
    assert check_bag(bag).problems == [f"{bag}/metadata.yaml: version 8, expected 9"]

    bag = _bag(tmp_path / "again", storage)
    storage_file = next(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    if storage == "mcap":
        storage_file.write_bytes(storage_file.read_bytes()[:-200])  # the summary and footer cut off
    else:
        with sqlite3.connect(storage_file) as db:
            db.execute("UPDATE messages SET data = x'00010000ff' WHERE id = 2")  # 1 byte: not a String
    problems = check_bag(bag).problems
    assert problems and all(str(storage_file) in problem or "metadata.yaml" in problem for problem in problems)


def test_a_run_without_a_bag_says_so(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no rosbag2 bag"):
        check_run(tmp_path)
    done = _run("-m", "runtime.ros.bag_cli", "check", str(tmp_path))
    assert done.returncode == 2 and "no rosbag2 bag" in done.stderr
