"""ROS 2 type store: CDR bytes, RIHS01 hashes, DDS names and custom .msg types (issue L point 1)."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap_ros2._dynamic import generate_dynamic

from runtime.ros.types import CDR_LE_HEADER, RosTypeError, RosTypes, dds_type_name, ros_type_name

STRING_RIHS01 = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
"""std_msgs/msg/String, as published in rmw_zenoh's docs/design.md (chatter examples)."""


@pytest.fixture(scope="module")
def ros() -> RosTypes:
    return RosTypes()


def test_the_rihs01_of_string_is_the_published_value(ros: RosTypes) -> None:
    assert ros.rihs01("std_msgs/msg/String") == STRING_RIHS01


def test_our_rihs01_agrees_with_rosbags_for_every_standard_type(ros: RosTypes) -> None:
    names = ros.names()
    assert len(names) > 100 and "tf2_msgs/msg/TFMessage" in names and "nav_msgs/msg/Odometry" in names
    assert {n: ros.rihs01(n) for n in names} == {n: ros.store.hash_rihs01(n) for n in names}


def test_the_type_description_lists_referenced_types_sorted_without_the_type_itself(ros: RosTypes) -> None:
    description = ros.type_description("geometry_msgs/msg/PoseStamped")
    assert description["type_description"]["type_name"] == "geometry_msgs/msg/PoseStamped"
    referenced = [d["type_name"] for d in description["referenced_type_descriptions"]]
    assert referenced == [
        "builtin_interfaces/msg/Time",
        "geometry_msgs/msg/Point",
        "geometry_msgs/msg/Pose",
        "geometry_msgs/msg/Quaternion",
        "std_msgs/msg/Header",
    ]
    stamp = description["referenced_type_descriptions"][4]["fields"][0]
    assert stamp == {
        "name": "stamp",
        "type": {"type_id": 1, "capacity": 0, "string_capacity": 0, "nested_type_name": "builtin_interfaces/msg/Time"},
    }


def test_string_encodes_to_the_cdr_bytes_written_out_by_hand(ros: RosTypes) -> None:
    message = ros.message_class("std_msgs/msg/String")(data="hi")
    # encapsulation CDR_LE, uint32 length 3 (with the NUL), "hi\0"
    assert ros.encode("std_msgs/msg/String", message) == bytes.fromhex("0001000003000000686900")
    assert ros.decode("std_msgs/msg/String", bytes.fromhex("00010000030000006869000000")).data == "hi"


def test_header_encodes_to_the_cdr_bytes_written_out_by_hand(ros: RosTypes) -> None:
    time = ros.message_class("builtin_interfaces/msg/Time")(sec=1, nanosec=2)
    header = ros.message_class("std_msgs/msg/Header")(stamp=time, frame_id="map")
    data = ros.encode("std_msgs/msg/Header", header)
    assert data[:4] == CDR_LE_HEADER
    assert data == bytes.fromhex("000100000100000002000000040000006d617000")


def test_cdr_decodes_with_the_independent_mcap_ros2_reader(ros: RosTypes) -> None:
    twist = ros.message_class("geometry_msgs/msg/Twist")
    vector = ros.message_class("geometry_msgs/msg/Vector3")
    data = ros.encode("geometry_msgs/msg/Twist", twist(linear=vector(x=0.5, y=0.0, z=0.0), angular=vector(0, 0, -1.25)))
    decoder = generate_dynamic("geometry_msgs/msg/Twist", ros.msgdef("geometry_msgs/msg/Twist"))
    decoded = decoder["geometry_msgs/msg/Twist"](data)
    assert (decoded.linear.x, decoded.angular.z) == (0.5, -1.25)


def test_dds_type_names() -> None:
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert dds_type_name("example_interfaces/srv/AddTwoInts") == "example_interfaces::srv::dds_::AddTwoInts_"
    assert ros_type_name("sensor_msgs::msg::dds_::LaserScan_") == "sensor_msgs/msg/LaserScan"
    with pytest.raises(RosTypeError, match="not a ROS 2 type name"):
        dds_type_name("LaserScan")
    with pytest.raises(RosTypeError, match="not a DDS type name"):
        ros_type_name("sensor_msgs/msg/LaserScan")


def test_unknown_types_and_bad_bytes_are_clear_errors(ros: RosTypes) -> None:
    with pytest.raises(RosTypeError, match=r"unknown ROS 2 type 'Pose2D' \(ROS 2 types are named package/msg/Name\)"):
        ros.msgdef("Pose2D")
    with pytest.raises(RosTypeError, match="without a plain CDR encapsulation header"):
        ros.decode("std_msgs/msg/String", b"\x07\x07\x00\x00\x01\x00\x00\x00\x00")
    with pytest.raises(RosTypeError, match="cannot deserialise 6 bytes"):
        ros.decode("std_msgs/msg/String", bytes.fromhex("00010000ff7f"))
    with pytest.raises(RosTypeError, match="expected a std_msgs/msg/String message"):
        ros.encode("std_msgs/msg/String", ros.message_class("std_msgs/msg/Bool")(data=True))


def test_custom_msg_types_from_text_and_files(tmp_path: Path) -> None:
    ros = RosTypes()
    ros.add_msg("ckm_msgs/msg/Detection", "string label\nfloat32 reliability\ngeometry_msgs/Point centroid\n")
    folder = tmp_path / "ckm_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "DetectionList.msg").write_text("std_msgs/Header header\nckm_msgs/Detection[] detections\n")
    assert ros.add_msg_file(folder / "DetectionList.msg") == "ckm_msgs/msg/DetectionList"
    detection = ros.message_class("ckm_msgs/msg/Detection")
    point = ros.message_class("geometry_msgs/msg/Point")(x=1.0, y=2.0, z=3.0)
    header = ros.message_class("std_msgs/msg/Header")(
        stamp=ros.message_class("builtin_interfaces/msg/Time")(0, 0), frame_id=""
    )
    message = ros.message_class("ckm_msgs/msg/DetectionList")(header=header, detections=[detection("cup", 0.75, point)])
    data = ros.encode("ckm_msgs/msg/DetectionList", message)
    back = ros.decode("ckm_msgs/msg/DetectionList", data)
    assert back.detections[0].label == "cup" and back.detections[0].centroid.z == 3.0
    assert "MSG: ckm_msgs/Detection" in ros.msgdef("ckm_msgs/msg/DetectionList")
    assert ros.rihs01("ckm_msgs/msg/DetectionList").startswith("RIHS01_")


def test_custom_msg_errors_name_the_type(tmp_path: Path) -> None:
    ros = RosTypes()
    with pytest.raises(RosTypeError, match="ckm_msgs/msg/Bad: field 'thing' names unknown type 'ckm_msgs/msg/Nowhere'"):
        ros.add_msg("ckm_msgs/msg/Bad", "ckm_msgs/Nowhere thing\n")
    with pytest.raises(RosTypeError, match=r"ckm_msgs/msg/Broken: cannot parse the \.msg definition"):
        ros.add_msg("ckm_msgs/msg/Broken", "float32[ x\n")
    loose = tmp_path / "Loose.msg"
    loose.write_text("int32 a\n")
    with pytest.raises(RosTypeError, match=r"name the type, or keep the file in <package>/msg/"):
        ros.add_msg_file(loose)
    assert ros.add_msg_file(loose, "ckm_msgs/msg/Loose") == "ckm_msgs/msg/Loose"
