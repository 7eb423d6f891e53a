"""ROS 2 type names in <Topic type>: schema, loader, verify, generated ckm_msgs types (issue L point 1)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import ckmconf
from ckmconf import ConfigError
from ckmconf.model import Field, MessageType
from runtime.ros.config import BYTES_TYPE, ConfigRosTypes, message_definition, ros_field_name, ros_message_name
from runtime.ros.convert import decode_payload, to_message
from runtime.verification.verify import verify
from tests.conftest import REPO

DATA = REPO / "tests" / "data" / "ros"


def _lines(errors: list[ConfigError]) -> list[str]:
    return [str(e).replace(str(REPO) + "/", "") for e in errors]


def test_schema_accepts_ros_type_names_and_identifiers() -> None:
    for name in ("ros_typed_loop.xml", "ros_typed_mismatch.xml", "ros_type_unknown.xml", "ros_type_broken_msg.xml"):
        result = ckmconf.load(DATA / name, strict=False)
        assert not [e for e in result.errors if "schema" in str(e).lower() or "pattern" in str(e)], name


def test_a_ros_typed_system_loads_and_verifies_clean() -> None:
    system = ckmconf.load(DATA / "ros_typed_loop.xml")
    types = {t.name: t.type for t in system.topics}
    assert types["/scan"] == "sensor_msgs/msg/LaserScan" and types["/wheels"] == "wheel-state"
    assert verify(system) == []


def test_incompatible_producers_and_consumers_are_reported_at_file_line_col() -> None:
    errors = _lines(verify(ckmconf.load(DATA / "ros_typed_mismatch.xml")))
    where = "tests/data/ros/ros_typed_mismatch.xml"
    assert [e.split(": ", 1)[0] for e in errors] == [
        f"{where}:11:44",
        f"{where}:13:14",
        f"{where}:14:15",
        f"{where}:16:42",
    ]
    assert "sensor 'speed' writes single numbers" in errors[0] and "geometry_msgs/msg/Twist has no 'data'" in errors[0]
    assert "writes single numbers onto topic 'command' of ROS type sensor_msgs/msg/LaserScan" in errors[2]
    assert "actuator 'motor' takes single numbers" in errors[3]


def test_an_unknown_ros_type_is_a_located_load_error() -> None:
    with pytest.raises(ConfigError) as caught:
        ckmconf.load(DATA / "ros_type_unknown.xml")
    text = str(caught.value)
    assert text.startswith(f"{DATA / 'ros_type_unknown.xml'}:5:23:") or ":5:23:" in text
    assert "unknown ROS 2 message type 'sensor_msgs/msg/LaserScann'" in text and "LaserScann.msg" in text


def test_a_custom_msg_that_does_not_parse_is_reported_at_its_topic() -> None:
    errors = _lines(verify(ckmconf.load(DATA / "ros_type_broken_msg.xml")))
    assert len(errors) == 1 and ":4:25:" in errors[0] and "Broken.msg: cannot parse" in errors[0]


def test_custom_msg_files_load_with_the_custom_types_they_name() -> None:
    types = ConfigRosTypes(ckmconf.load(DATA / "ros_typed_loop.xml"))
    assert types.problems == {}
    fields = dict(types.ros.fields("ckm_test_msgs/msg/Reading"))
    assert fields["quality"][1] == "ckm_test_msgs/msg/Quality" and fields["where"][1] == "geometry_msgs/msg/Point"
    payload = {"label": "cup", "value": 2.5, "where": {"x": 1.0}, "quality": {"reliability": 0.5, "raw": b"\x01"}}
    cdr = types.ros.encode("ckm_test_msgs/msg/Reading", to_message(types.ros, "ckm_test_msgs/msg/Reading", payload))
    back = decode_payload(types.ros, "ckm_test_msgs/msg/Reading", cdr)
    assert back["label"] == "cup" and back["where"]["x"] == 1.0 and back["quality"]["raw"] == b"\x01"


def test_message_types_become_generated_ckm_msgs() -> None:
    system = ckmconf.load(DATA / "ros_typed_loop.xml")
    types = ConfigRosTypes(system)
    assert types.ros_type_of("wheel-state") == "ckm_msgs/msg/WheelState"
    assert types.ros_type_of("Pose2") == "ckm_msgs/msg/Pose2"
    assert (
        types.ros_type_of("float64") == "std_msgs/msg/Float64" and types.ros_type_of("uint16") == "std_msgs/msg/UInt16"
    )
    assert types.ros_type_of("time") == "builtin_interfaces/msg/Time" and types.ros_type_of("bytes") == BYTES_TYPE
    text, names = message_definition(next(m for m in system.message_types if m.name == "wheel-state"), types.generated)
    assert text.splitlines()[1:] == [
        "builtin_interfaces/Time stamp",
        "float64[2] wheel_speeds  # rad/s",
        "float32[] history",
        "uint8[] raw",
        "ckm_msgs/Pose2 pose",
    ]
    assert names["wheelSpeeds"] == "wheel_speeds"
    value = {"stamp": 1700000000.5, "wheelSpeeds": [1.0, 2.0], "history": np.arange(3, dtype=np.float32),
             "raw": b"ab", "pose": {"x": 1.0, "y": -1.0}}  # fmt: skip
    ros_type = types.ros_type_of("wheel-state")
    message = to_message(types.ros, ros_type, types.payload(ros_type, value))
    back = decode_payload(types.ros, ros_type, types.ros.encode(ros_type, message))
    assert back["stamp"] == 1700000000.5 and list(back["wheel_speeds"]) == [1.0, 2.0]
    assert back["raw"] == b"ab" and back["pose"] == {"x": 1.0, "y": -1.0} and list(back["history"]) == [0, 1, 2]


def test_names_are_made_ros_conform() -> None:
    assert ros_field_name("wheelSpeeds") == "wheel_speeds" and ros_field_name("max-speed") == "max_speed"
    assert ros_field_name("_private") == "private" and ros_field_name("3d") == "f_3d"
    assert ros_message_name("wheel-state") == "WheelState" and ros_message_name("_x") == "X"


def test_a_recursive_message_type_travels_as_bytes() -> None:
    tree = MessageType(
        name="Tree", fields=(Field(name="label", type="string"), Field(name="children", type="Tree", count=0))
    )
    system = ckmconf.load(DATA / "ros_typed_loop.xml")
    types = ConfigRosTypes(replace(system, message_types=(*system.message_types, tree)))
    assert types.ros_type_of("Tree") == BYTES_TYPE
    payload = types.payload(BYTES_TYPE, {"label": "root", "children": []})
    assert isinstance(payload["data"], bytes) and payload["data"]


def test_value_problems_use_the_compatibility_check_for_message_types() -> None:
    scan = MessageType(
        name="Scan", fields=(Field(name="angleMin", type="float32"), Field(name="ranges", type="float32", count=0))
    )
    wide = MessageType(name="WideScan", fields=(Field(name="ranges", type="float64", count=0),))
    system = ckmconf.load(DATA / "ros_typed_loop.xml")
    types = ConfigRosTypes(replace(system, message_types=(*system.message_types, scan, wide)))
    assert types.value_problems("Scan", "sensor_msgs/msg/LaserScan") == []
    assert types.value_problems("WideScan", "sensor_msgs/msg/LaserScan") == [
        "WideScan.ranges: a float64 does not fit a float32 without loss"
    ]
    assert types.value_problems("number", "std_msgs/msg/Float32") == []
    assert types.value_problems("numbers", "std_msgs/msg/Float64MultiArray") == []
    assert types.value_problems("float64", "std_msgs/msg/Float32") == [
        "std_msgs/msg/Float32.data: a float64 does not fit a float32 without loss"
    ]
    assert types.value_problems("array", "sensor_msgs/msg/Image") == []
    assert types.value_problems("mapping", "nav_msgs/msg/Odometry") == []
    assert types.value_problems("string", "std_msgs/msg/String") == []


def test_an_array_on_an_image_like_message_type_fills_its_size_fields() -> None:
    image = MessageType(
        name="Image",
        fields=(
            Field(name="stamp", type="time"),
            Field(name="width", type="uint32"),
            Field(name="height", type="uint32"),
            Field(name="encoding", type="string"),
            Field(name="data", type="bytes"),
        ),
    )
    depth = MessageType(
        name="Depth", fields=(Field(name="width", type="uint32"), Field(name="data", type="uint16", count=0))
    )
    system = ckmconf.load(DATA / "ros_typed_loop.xml")
    types = ConfigRosTypes(replace(system, message_types=(*system.message_types, image, depth)))
    rgb = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    ros_type = types.ros_type_of("Image")
    back = decode_payload(
        types.ros, ros_type, types.ros.encode(ros_type, to_message(types.ros, ros_type, types.payload(ros_type, rgb)))
    )
    assert (back["width"], back["height"], back["encoding"], back["data"]) == (4, 2, "rgb8", rgb.tobytes())
    frame = np.full((3, 5), 1234, np.uint16)
    ros_type = types.ros_type_of("Depth")
    back = decode_payload(
        types.ros, ros_type, types.ros.encode(ros_type, to_message(types.ros, ros_type, types.payload(ros_type, frame)))
    )
    assert back["width"] == 5 and list(back["data"]) == [1234] * 15


def test_smart_resource_topics_are_checked_against_ros_types() -> None:
    errors = _lines(verify(ckmconf.load(DATA / "ros_typed_service.xml")))
    assert len(errors) == 1 and errors[0].startswith("tests/data/ros/ros_typed_service.xml:13:28:")
    assert "publishes arrays onto topic '/camera/grey' of type sensor_msgs/msg/LaserScan" in errors[0]
