"""hardware.bag: a rosbag2 bag played back as an input channel (issue L point 2, decision D156).

Bags are written with runtime.ros.bag.BagRecorder (the rosbags writer) in both storages, and played
on a ManualClock, so every expected value and time is exact. Configuration errors are checked as
``FILE:LINE:COL`` at the Param that causes them, from configurations read from files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ckmconf.errors import ConfigError
from ckmconf.loader import load
from ckmconf.model import HWChannel
from plugins.hardware.bag import BagBackend
from plugins.hardware.simulation import ManualClock, PlantScope
from runtime.kernel.interfaces import ParamError
from runtime.ros.bag import BagRecorder, Storage

T0 = 1_700_000_000.0
TIMES = (0.0, 0.1, 0.25, 0.4)
VALUES = (1.5, -2.0, 3.25, 4.0)


def _bag(path: Path, storage: Storage = "mcap") -> Path:
    with BagRecorder(path, storage=storage) as bag:
        bag.add_topic("/speed", "std_msgs/msg/Float64")
        bag.add_topic("/scan", "sensor_msgs/msg/LaserScan")
        bag.add_topic("/camera", "sensor_msgs/msg/Image")
        bag.add_topic("/odom", "nav_msgs/msg/Odometry")
        bag.add_topic("/empty", "std_msgs/msg/Float64")
        for t, v in zip(TIMES, VALUES, strict=True):
            bag.write("/speed", {"data": v}, T0 + t)
            bag.write("/scan", {"ranges": np.arange(5, dtype=np.float32) + v}, T0 + t)
            bag.write("/odom", {"pose": {"pose": {"position": {"x": v, "y": 2 * v}}}}, T0 + t)
        bag.write("/camera", np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3), T0)
    return path


def _config(tmp_path: Path, size: int = 1, **params: object) -> HWChannel:
    """The channel of a one-node configuration file whose HWChannel is served by the bag."""
    lines = "\n".join(f'      <Param name="{k}" value="{v}"/>' for k, v in params.items())
    path = tmp_path / "replay.xml"
    path.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        '<System xmlns="urn:ckm:1" version="1.0" name="replay">\n'
        '  <Node name="n" kind="light">\n'
        f'    <HWChannel name="ch" direction="in" backend="bag" size="{size}">\n'
        f"{lines}\n"
        "    </HWChannel>\n"
        "  </Node>\n"
        "</System>\n"
    )
    return load(path).nodes[0].channels[0]


def _backend(tmp_path: Path, clock: ManualClock, size: int = 1, **params: object) -> BagBackend:
    backend = BagBackend(_config(tmp_path, size, **params), scope=PlantScope(clock))
    backend.setup()
    return backend


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_values_play_at_their_recorded_offsets(storage: Storage, tmp_path: Path) -> None:
    _bag(tmp_path / "bag", storage)
    clock = ManualClock(50.0)
    backend = _backend(tmp_path, clock, bag="bag", topic="/speed")
    expected = {0.0: 1.5, 0.099: 1.5, 0.1: -2.0, 0.249: -2.0, 0.25: 3.25, 0.4: 4.0, 5.0: 4.0}  # then held
    for at, value in expected.items():
        clock.now = 50.0 + at
        assert backend.read() == value, at
    backend.stop()


def test_rate_loop_and_start(tmp_path: Path) -> None:
    _bag(tmp_path / "bag")
    clock = ManualClock()
    fast = _backend(tmp_path, clock, bag="bag", topic="/speed", rate=2.0)
    assert [fast.read() for _ in (0,)] == [1.5]
    clock.now = 0.05  # 0.1 s of the bag at twice the speed
    assert fast.read() == -2.0
    clock = ManualClock()
    looping = _backend(tmp_path, clock, bag="bag", topic="/speed", loop="true")
    period = 0.4 + 0.4 / 3  # the span and one mean interval
    assert looping.period == pytest.approx(period)
    seen = []
    for step in range(0, 120):
        clock.now = step * 0.01
        seen.append(looping.read())
    collapsed = [v for i, v in enumerate(seen) if i == 0 or v != seen[i - 1]]
    assert collapsed == [*VALUES, *VALUES, *VALUES[:2]]  # 1.2 s: twice round and into the third
    clock = ManualClock()
    skipping = _backend(tmp_path, clock, bag="bag", topic="/speed", start=0.2)
    assert skipping.read() == -2.0
    clock.now = 0.05
    assert skipping.read() == 3.25


def test_arrays_images_and_nested_fields(tmp_path: Path) -> None:
    _bag(tmp_path / "bag")
    clock = ManualClock()
    scan = _backend(tmp_path, clock, 5, bag="bag", topic="/scan", field="ranges", type="sensor_msgs/msg/LaserScan")
    assert scan.read() == (1.5, 2.5, 3.5, 4.5, 5.5)
    clock.now = 0.1
    assert scan.read() == (-2.0, -1.0, 0.0, 1.0, 2.0)
    image = _backend(tmp_path, ManualClock(), 18, bag="bag", topic="/camera")
    assert image.read() == tuple(float(i) for i in range(18))  # row-major, as hardware.sim's cameras
    odom = _backend(tmp_path, ManualClock(), bag="bag", topic="/odom", field="pose.pose.position.y")
    assert odom.read() == 3.0


def _error(tmp_path: Path, size: int = 1, **params: object) -> str:
    channel = _config(tmp_path, size, **params)
    with pytest.raises(ConfigError) as caught:
        BagBackend(channel, scope=PlantScope(ManualClock())).setup()
    return str(caught.value)


def test_configuration_errors_name_the_param(tmp_path: Path) -> None:
    bag = _bag(tmp_path / "bag").resolve()
    file = tmp_path / "replay.xml"
    where = "/System[@name='replay']/Node[@name='n']/HWChannel[@name='ch']/Param"
    assert _error(tmp_path, bag="nothing", topic="/speed") == (
        f"{file}:5:25: {where}[@name='bag']/@value: bag channel 'ch': the bag {tmp_path / 'nothing'} does not exist"
    )
    assert _error(tmp_path, bag="bag", topic="/sped") == (
        f"{file}:6:27: {where}[@name='topic']/@value: bag channel 'ch': the bag {bag} has no topic '/sped' (topics: "
        "/camera (sensor_msgs/msg/Image), /empty (std_msgs/msg/Float64), /odom (nav_msgs/msg/Odometry), "
        "/scan (sensor_msgs/msg/LaserScan), /speed (std_msgs/msg/Float64))"
    )
    assert _error(tmp_path, bag="bag", topic="/speed", type="std_msgs/msg/Float32").endswith(
        f"bag channel 'ch': topic /speed of the bag {bag} is a std_msgs/msg/Float64, not a std_msgs/msg/Float32"
    )
    assert _error(tmp_path, bag="bag", topic="/scan").endswith(
        "bag channel 'ch': sensor_msgs/msg/LaserScan has no 'data' field: name the one to read with Param 'field' "
        "(header, angle_min, angle_max, angle_increment, time_increment, scan_time, range_min, range_max, ranges, "
        "intensities)"
    )
    assert _error(tmp_path, bag="bag", topic="/odom", field="pose.pose.orientation.v").endswith(
        "field 'pose.pose.orientation.v': geometry_msgs/msg/Quaternion has no field 'v' (x, y, z, w)"
    )
    assert _error(tmp_path, bag="bag", topic="/odom", field="pose.pose").endswith(
        "field 'pose.pose' is a geometry_msgs/msg/Pose message, not numbers"
    )
    assert _error(tmp_path, bag="bag", topic="/odom", field="child_frame_id").endswith(
        "field 'child_frame_id' of nav_msgs/msg/Odometry holds no numbers to read"
    )
    size = _error(tmp_path, 4, bag="bag", topic="/scan", field="ranges")
    assert size.startswith(f"{file}:7:27: {where}[@name='field']/@value: ")
    assert size.endswith(
        "the channel's size is 4, but message 0 of /scan gives 5 value(s) (sensor_msgs/msg/LaserScan.ranges)"
    )
    assert _error(tmp_path, bag="bag", topic="/empty").endswith(
        f"bag channel 'ch': topic /empty of the bag {bag} has no message"
    )
    (tmp_path / "plain").mkdir()
    assert _error(tmp_path, bag="plain", topic="/speed").endswith("is not a rosbag2 bag (no metadata.yaml)")


def test_a_bag_serves_inputs_only(tmp_path: Path) -> None:
    channel = _config(tmp_path, bag="bag", topic="/speed")
    out = HWChannel(name=channel.name, direction="out", backend="bag", params=channel.params)
    with pytest.raises(ParamError, match="serves input channels only"):
        BagBackend(out)
