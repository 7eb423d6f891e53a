"""CKM MessageTypes checked against ROS 2 types (issue L point 1: the helper ``verify`` will use)."""

from __future__ import annotations

from pathlib import Path

import pytest

import ckmconf
from ckmconf.model import Field, MessageType
from runtime.ros.compat import compatibility_problems, snake_case
from runtime.ros.types import RosTypes

EXAMPLE = Path(__file__).resolve().parents[3] / "configs" / "examples" / "message_types.xml"


@pytest.fixture(scope="module")
def ros() -> RosTypes:
    return RosTypes()


def _types(*messages: MessageType) -> dict[str, MessageType]:
    return {m.name: m for m in messages}


def _message(name: str, *fields: tuple[str, str, int]) -> MessageType:
    return MessageType(name=name, fields=tuple(Field(name=n, type=t, count=c) for n, t, c in fields))


def test_snake_case() -> None:
    assert [snake_case(n) for n in ("angleMin", "x", "rangeMax2D", "frame_id")] == [
        "angle_min",
        "x",
        "range_max2_d",
        "frame_id",
    ]


def test_the_example_vector3_fits_geometry_msgs_vector3(ros: RosTypes) -> None:
    system = ckmconf.load(EXAMPLE)
    types = {m.name: m for m in system.message_types}
    assert compatibility_problems("Vector3", "geometry_msgs/msg/Vector3", ros, types) == []
    assert compatibility_problems("LaserScan", "sensor_msgs/msg/LaserScan", ros, types) == [
        "LaserScan.stamp: sensor_msgs/msg/LaserScan has no field 'stamp'",
        "LaserScan.angleStep: sensor_msgs/msg/LaserScan has no field 'angleStep' or 'angle_step'",
    ]


def test_a_ckm_scan_type_shaped_like_the_ros_one_fits(ros: RosTypes) -> None:
    header = _message("Header", ("stamp", "time", 1), ("frameId", "string", 1))
    scan = _message(
        "Scan",
        ("header", "Header", 1),
        ("angleMin", "float32", 1),
        ("angleIncrement", "float32", 1),
        ("ranges", "float32", 0),
        ("intensities", "float32", 0),
    )
    assert compatibility_problems("Scan", "sensor_msgs/msg/LaserScan", ros, _types(header, scan)) == []


def test_number_widths_arrays_and_nesting(ros: RosTypes) -> None:
    info = _message(
        "Info",
        ("width", "uint16", 1),
        ("height", "float64", 1),
        ("k", "float64", 9),
        ("d", "float64", 0),
        ("p", "float64", 3),
        ("r", "float32", 0),
    )
    assert compatibility_problems("Info", "sensor_msgs/msg/CameraInfo", ros, _types(info)) == [
        "Info.height: a float64 does not fit a uint32 without loss",
        "Info.p: 3 values do not fit an array of 12",
        "Info.r: a variable-length list cannot fill an array of 9",
    ]
    flags = _message("Flags", ("data", "int32", 1))
    assert compatibility_problems("Flags", "std_msgs/msg/Bool", ros, _types(flags)) == [
        "Flags.data: a int32 cannot fill a bool"
    ]
    many = _message("Many", ("x", "float64", 2))
    assert compatibility_problems("Many", "geometry_msgs/msg/Vector3", ros, _types(many)) == [
        "Many.x: 2 values of float64 cannot fill a single field"
    ]
    listed = _message("Listed", ("name", "string", 1))
    assert compatibility_problems("Listed", "sensor_msgs/msg/JointState", ros, _types(listed)) == [
        "Listed.name: one string cannot fill an array or sequence"
    ]


def test_bytes_time_and_nested_types(ros: RosTypes) -> None:
    packed = _message("Packed", ("format", "string", 1), ("data", "bytes", 1))
    assert compatibility_problems("Packed", "sensor_msgs/msg/CompressedImage", ros, _types(packed)) == []
    wrong = _message("Wrong", ("header", "float64", 1), ("data", "bytes", 1), ("format", "time", 1))
    assert compatibility_problems("Wrong", "sensor_msgs/msg/CompressedImage", ros, _types(wrong)) == [
        "Wrong.header: a float64 cannot fill a std_msgs/msg/Header message",
        "Wrong.format: a time cannot fill a string",
    ]
    stamp = _message("Stamp", ("stamp", "float64", 1))
    header = _message("H", ("stamp", "Stamp", 1))
    assert compatibility_problems("H", "std_msgs/msg/Header", ros, _types(stamp, header)) == [
        "H.stamp.stamp: builtin_interfaces/msg/Time has no field 'stamp'"
    ]
    assert compatibility_problems("time", "builtin_interfaces/msg/Time", ros, {}) == []
    assert compatibility_problems("float64", "std_msgs/msg/Float64", ros, {}) == [
        "float64: a float64 is not a std_msgs/msg/Float64 message"
    ]


def test_unknown_types(ros: RosTypes) -> None:
    assert compatibility_problems("Nope", "geometry_msgs/msg/Twist", ros, {}) == [
        "Nope: unknown CKM message type 'Nope'"
    ]
    assert compatibility_problems("Nope", "geometry_msgs/msg/Twist3", ros, {}) == [
        "Nope: unknown ROS 2 type 'geometry_msgs/msg/Twist3'"
    ]
