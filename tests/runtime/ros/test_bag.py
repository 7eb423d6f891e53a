"""rosbag2 recordings (MCAP and sqlite3, version 9) checked with independent readers, and replay
(issue L point 2)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader
from ruamel.yaml import YAML

from ckmconf.model import Topic
from runtime.network.api import Sample
from runtime.ros.bag import BagError, BagRecorder, BagSource, offered_qos
from runtime.ros.types import RosTypes

START = 1_700_000_000.0
TOPICS = {
    "/robot1/scan": "sensor_msgs/msg/LaserScan",
    "/robot1/camera/image": "sensor_msgs/msg/Image",
    "/robot1/odom": "nav_msgs/msg/Odometry",
    "/tf": "tf2_msgs/msg/TFMessage",
    "/ckm/detections": "ckm_msgs/msg/Detection",
}


def _types() -> RosTypes:
    ros = RosTypes()
    ros.add_msg("ckm_msgs/msg/Detection", "string label\nfloat32 reliability\ngeometry_msgs/Point centroid\n")
    return ros


def _record(path: Path, storage: str, steps: int = 5) -> None:
    with BagRecorder(path, storage=storage, types=_types()) as bag:  # type: ignore[arg-type]
        for topic, type_name in TOPICS.items():
            qos = offered_qos("best-effort", 5, deadline=0.2) if topic.endswith("scan") else None
            bag.add_topic(topic, type_name, qos=qos)
        for i in range(steps):
            t = START + 0.1 * i
            bag.write(
                "/robot1/scan",
                {"header": {"stamp": t, "frame_id": "laser"}, "ranges": np.full(90, 1.0 + i, np.float32)},
                t,
            )
            bag.write("/robot1/camera/image", np.full((4, 6, 3), i, np.uint8), t + 0.01)
            bag.write(
                "/robot1/odom",
                {"header": {"stamp": t, "frame_id": "odom"}, "pose": {"pose": {"position": {"x": 0.1 * i}}}},
                t + 0.02,
            )
            bag.write(
                "/tf",
                {"transforms": [{"child_frame_id": "base_link", "transform": {"rotation": {"w": 1.0}}}]},
                t + 0.03,
            )
            bag.write("/ckm/detections", {"label": f"cup{i}", "reliability": 0.5}, t + 0.04)


@pytest.fixture(params=["mcap", "sqlite3"])
def bag(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Path, str]:
    path = tmp_path / f"run_{request.param}"
    _record(path, request.param)
    return path, request.param


def test_metadata_is_rosbag2_version_9(bag: tuple[Path, str]) -> None:
    path, storage = bag
    info = YAML(typ="safe").load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == storage and info["message_count"] == 25
    assert info["starting_time"]["nanoseconds_since_epoch"] == 1_700_000_000_000_000_000
    topics = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    assert set(topics) == set(TOPICS) and all(t["message_count"] == 5 for t in topics.values())
    scan = topics["/robot1/scan"]["topic_metadata"]
    assert scan["type"] == "sensor_msgs/msg/LaserScan" and scan["serialization_format"] == "cdr"
    assert scan["type_description_hash"] == _types().rihs01("sensor_msgs/msg/LaserScan")
    assert scan["offered_qos_profiles"][0]["reliability"] == "best_effort"
    assert scan["offered_qos_profiles"][0]["deadline"] == {"sec": 0, "nsec": 200_000_000}
    files = info["relative_file_paths"]
    assert len(files) == 1 and (path / files[0]).is_file()
    assert files[0].endswith(".mcap" if storage == "mcap" else ".db3")


def test_mcap_reads_back_with_the_mcap_library_and_its_ros2_decoder(tmp_path: Path) -> None:
    path = tmp_path / "run"
    _record(path, "mcap")
    with (path / "run.mcap").open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        assert {s.name: s.encoding for s in summary.schemas.values()} == dict.fromkeys(TOPICS.values(), "ros2msg")
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == 25
    by_topic: dict[str, list[object]] = {}
    for _schema, channel, message, ros_msg in decoded:
        by_topic.setdefault(channel.topic, []).append(ros_msg)
        assert message.log_time >= 1_700_000_000_000_000_000
    assert [len(m) for m in by_topic.values()] == [5] * 5
    scan = by_topic["/robot1/scan"][3]
    assert scan.header.frame_id == "laser" and list(scan.ranges) == [4.0] * 90  # type: ignore[attr-defined]
    image = by_topic["/robot1/camera/image"][2]
    assert (image.width, image.height, image.encoding, bytes(image.data)) == (6, 4, "rgb8", bytes([2]) * 72)  # type: ignore[attr-defined]
    assert by_topic["/ckm/detections"][4].label == "cup4"  # type: ignore[attr-defined]
    assert by_topic["/robot1/odom"][1].pose.pose.position.x == pytest.approx(0.1)  # type: ignore[attr-defined]


def test_sqlite3_reads_back_with_plain_sqlite_and_the_mcap_ros2_decoder(tmp_path: Path) -> None:
    path = tmp_path / "run"
    _record(path, "sqlite3")
    with sqlite3.connect(path / "run.db3") as db:
        topics = {
            tid: (name, type_name, fmt, digest)
            for tid, name, type_name, fmt, digest in db.execute(
                "SELECT id, name, type, serialization_format, type_description_hash FROM topics"
            )
        }
        definitions = dict(
            db.execute(
                "SELECT topic_type, encoded_message_definition FROM message_definitions WHERE encoding = 'ros2msg'"
            )
        )
        rows = db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp").fetchall()
    assert {t[0] for t in topics.values()} == set(TOPICS) and {t[2] for t in topics.values()} == {"cdr"}
    assert set(definitions) == set(TOPICS.values())
    assert len(rows) == 25
    decoders = {t: generate_dynamic(t, text)[t] for t, text in definitions.items()}
    decoded = [(topics[tid][0], decoders[topics[tid][1]](data)) for tid, _stamp, data in rows]
    assert [d.label for topic, d in decoded if topic == "/ckm/detections"] == [f"cup{i}" for i in range(5)]
    assert [d.ranges[0] for topic, d in decoded if topic == "/robot1/scan"] == [1.0, 2.0, 3.0, 4.0, 5.0]


def test_rosbags_reader_sees_every_connection_with_its_hash(bag: tuple[Path, str]) -> None:
    path, _ = bag
    ros = _types()
    with Reader(path) as reader:
        assert {c.topic: (c.msgtype, c.digest) for c in reader.connections} == {
            t: (n, ros.rihs01(n)) for t, n in TOPICS.items()
        }
        assert sum(1 for _ in reader.messages()) == 25


def test_bag_source_replays_ckm_payloads_in_time_order(bag: tuple[Path, str]) -> None:
    path, _ = bag
    source = BagSource(path)  # a fresh store: the custom type comes from the bag itself
    assert source.topic_types() == TOPICS
    messages = list(source.messages())
    assert len(messages) == 25 and [m.time for m in messages] == sorted(m.time for m in messages)
    first = messages[0]
    assert (first.topic, first.type, first.time) == ("/robot1/scan", "sensor_msgs/msg/LaserScan", START)
    assert first.payload["header"] == {"stamp": START, "frame_id": "laser"}
    images = [m.payload for m in messages if m.topic == "/robot1/camera/image"]
    assert all(np.array_equal(img, np.full((4, 6, 3), i, np.uint8)) for i, img in enumerate(images))
    only = list(BagSource(path, topics=["/ckm/detections"]).messages())
    assert [m.payload["label"] for m in only] == [f"cup{i}" for i in range(5)]
    with pytest.raises(BagError, match="no topic /nowhere in the bag"):
        list(BagSource(path, topics=["/nowhere"]).messages())


def test_play_paces_messages_like_the_recording(tmp_path: Path) -> None:
    path = tmp_path / "run"
    _record(path, "mcap", steps=3)
    now = [50.0]
    waits: list[float] = []

    def sleep(seconds: float) -> None:
        waits.append(round(seconds, 6))
        now[0] += seconds

    played = list(BagSource(path, topics=["/robot1/scan"]).play(speed=2.0, clock=lambda: now[0], sleep=sleep))
    assert len(played) == 3 and waits == [0.05, 0.05]  # 0.1 s apart, played twice as fast
    with pytest.raises(BagError, match="replay speed must be positive"):
        next(BagSource(path).play(speed=0))


def test_recorder_errors(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="unknown bag storage 'rosbag1'"):
        BagRecorder(tmp_path / "a", storage="rosbag1")  # type: ignore[arg-type]
    bag = BagRecorder(tmp_path / "b")
    with pytest.raises(BagError, match="the bag is not open"):
        bag.add_topic("/x", "std_msgs/msg/String")
    with bag:
        bag.add_topic("/x", "std_msgs/msg/String")
        with pytest.raises(BagError, match=r"topic /x is declared already \(as std_msgs/msg/String\)"):
            bag.add_topic("/x", "std_msgs/msg/String")
        with pytest.raises(BagError, match="topic /y was not declared with add_topic"):
            bag.write("/y", {"data": "hi"}, 1.0)
        with pytest.raises(BagError, match="a message time must be non-negative seconds"):
            bag.write("/x", {"data": "hi"}, -1.0)
        bag.write("/x", {"data": "hi"}, 1.0)
    with pytest.raises(BagError, match="exists already: rosbag2 bags are never overwritten"):
        BagRecorder(tmp_path / "b").open()
    with pytest.raises(BagError, match="not a rosbag2 bag"):
        list(BagSource(tmp_path).messages())


def test_configured_topics_and_received_samples_are_recorded(tmp_path: Path) -> None:
    topics = [
        Topic(
            name="/robot1/scan", type="sensor_msgs/msg/LaserScan", reliability="best-effort", history=3, deadline=0.5
        ),
        Topic(name="/nav/pose", type="Pose2D"),  # a CKM MessageType: not a ROS type, left out
        Topic(name="/cmd_vel", type="geometry_msgs/msg/Twist"),
    ]
    with BagRecorder(tmp_path / "run", storage="sqlite3") as bag:
        assert bag.add_topics(topics) == ["/robot1/scan", "/cmd_vel"]
        assert bag.add_topics(topics) == []  # declared already
        sample = Sample(
            "/cmd_vel", {"linear": {"x": 0.25}}, stamp=START + 2.0, source=7, seq=1, received=START + 2.1, offset=0.5
        )
        bag.write_sample(sample)
    info = YAML(typ="safe").load((tmp_path / "run" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    qos = info["topics_with_message_count"][0]["topic_metadata"]["offered_qos_profiles"][0]
    assert (qos["reliability"], qos["depth"], qos["deadline"]) == ("best_effort", 3, {"sec": 0, "nsec": 500_000_000})
    (message,) = list(BagSource(tmp_path / "run").messages())
    assert (message.topic, message.time) == ("/cmd_vel", START + 1.5)  # publisher clock minus its offset
    assert message.payload["linear"]["x"] == 0.25
