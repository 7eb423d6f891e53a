"""CKM payloads ⇄ ROS 2 messages for the types the simulation publishes (issue L point 1)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic

from runtime.resources import codec
from runtime.ros.convert import decode_payload, encode_payload, image_array, to_message
from runtime.ros.types import RosTypeError, RosTypes


@pytest.fixture(scope="module")
def ros() -> RosTypes:
    return RosTypes()


def _independent(ros: RosTypes, type_name: str, data: bytes) -> Any:
    """The message as mcap-ros2-support decodes it from the schema text alone."""
    return generate_dynamic(type_name, ros.msgdef(type_name))[type_name](data)


def test_laser_scan_round_trip_and_independent_decode(ros: RosTypes) -> None:
    ranges = np.linspace(0.2, 4.0, 360, dtype=np.float32)
    scan = {
        "header": {"stamp": 1700000000.25, "frame_id": "laser"},
        "angle_min": -np.pi,
        "angle_max": np.pi,
        "angle_increment": 2 * np.pi / 360,
        "range_min": 0.1,
        "range_max": 8.0,
        "ranges": ranges,
    }
    data = encode_payload(ros, "sensor_msgs/msg/LaserScan", scan)
    back = decode_payload(ros, "sensor_msgs/msg/LaserScan", data)
    assert back["header"] == {"stamp": 1700000000.25, "frame_id": "laser"}
    assert back["ranges"].dtype == np.float32 and np.array_equal(back["ranges"], ranges)
    assert back["intensities"].shape == (0,)
    other = _independent(ros, "sensor_msgs/msg/LaserScan", data)
    assert (other.header.stamp.sec, other.header.stamp.nanosec) == (1700000000, 250000000)
    assert other.header.frame_id == "laser" and len(other.ranges) == 360
    assert other.ranges[359] == pytest.approx(4.0)
    # The payload travels through the runtime's own codec unchanged.
    assert np.array_equal(codec.decode(codec.encode(back))["ranges"], ranges)


@pytest.mark.parametrize(
    ("image", "encoding"),
    [
        (np.arange(2 * 3 * 3, dtype=np.uint8).reshape(2, 3, 3), "rgb8"),
        (np.arange(12, dtype=np.uint8).reshape(3, 4), "mono8"),
        (np.arange(16, dtype=np.uint8).reshape(2, 2, 4), "rgba8"),
        (np.array([[1000, 65535], [0, 7]], dtype=np.uint16), "16UC1"),
        (np.linspace(0.0, 3.5, 6, dtype=np.float32).reshape(2, 3), "32FC1"),
    ],
)
def test_images_are_arrays_both_ways(ros: RosTypes, image: np.ndarray, encoding: str) -> None:
    data = encode_payload(ros, "sensor_msgs/msg/Image", image)
    other = _independent(ros, "sensor_msgs/msg/Image", data)
    assert (other.height, other.width, other.encoding, other.is_bigendian) == (*image.shape[:2], encoding, 0)
    assert other.step == image.shape[1] * image.itemsize * (image.shape[2] if image.ndim == 3 else 1)
    assert bytes(other.data) == image.astype(image.dtype.newbyteorder("<")).tobytes()
    back = decode_payload(ros, "sensor_msgs/msg/Image", data)
    assert back.dtype == image.dtype and np.array_equal(back, image)


def test_an_image_with_header_and_chosen_encoding(ros: RosTypes) -> None:
    bgr = np.zeros((2, 2, 3), dtype=np.uint8)
    bgr[..., 0] = 255
    payload = {"header": {"stamp": 3.5, "frame_id": "camera"}, "encoding": "bgr8", "data": bgr}
    message = to_message(ros, "sensor_msgs/msg/Image", payload)
    assert (message.encoding, message.header.frame_id, message.header.stamp.sec) == ("bgr8", "camera", 3)
    assert np.array_equal(image_array(message), bgr)


def test_a_padded_image_row_is_cut_to_its_pixels(ros: RosTypes) -> None:
    padded = to_message(
        ros,
        "sensor_msgs/msg/Image",
        {
            "height": 2,
            "width": 2,
            "encoding": "mono8",
            "step": 4,
            "data": np.array([1, 2, 0, 0, 3, 4, 0, 0], dtype=np.uint8),
        },
    )
    assert image_array(padded).tolist() == [[1, 2], [3, 4]]


def test_camera_info_odometry_joint_state_tf_twist_and_pose(ros: RosTypes) -> None:
    k = [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]
    info = decode_payload(
        ros,
        "sensor_msgs/msg/CameraInfo",
        encode_payload(
            ros, "sensor_msgs/msg/CameraInfo", {"width": 640, "height": 480, "distortion_model": "plumb_bob", "k": k}
        ),
    )
    assert info["k"].tolist() == k and info["d"].shape == (0,) and info["p"].shape == (12,)

    odometry = {
        "header": {"frame_id": "odom"},
        "child_frame_id": "base_link",
        "pose": {
            "pose": {"position": {"x": 1.5, "y": -2.0}, "orientation": {"z": 0.0, "w": 1.0}},
            "covariance": np.eye(6).reshape(-1),
        },
        "twist": {"twist": {"linear": {"x": 0.3}, "angular": {"z": 0.1}}},
    }
    data = encode_payload(ros, "nav_msgs/msg/Odometry", odometry)
    back = decode_payload(ros, "nav_msgs/msg/Odometry", data)
    assert back["pose"]["pose"]["position"] == {"x": 1.5, "y": -2.0, "z": 0.0}
    assert back["pose"]["covariance"].reshape(6, 6).trace() == 6.0
    assert _independent(ros, "nav_msgs/msg/Odometry", data).twist.twist.angular.z == pytest.approx(0.1)

    joints = decode_payload(
        ros,
        "sensor_msgs/msg/JointState",
        encode_payload(ros, "sensor_msgs/msg/JointState", {"name": ["shoulder", "elbow"], "position": [0.5, -0.25]}),
    )
    assert joints["name"] == ["shoulder", "elbow"] and joints["position"].tolist() == [0.5, -0.25]

    tf = {
        "transforms": [
            {
                "header": {"stamp": 2.0, "frame_id": "map"},
                "child_frame_id": "odom",
                "transform": {"translation": {"x": 1.0}, "rotation": {"w": 1.0}},
            }
        ]
    }
    tf_back = decode_payload(ros, "tf2_msgs/msg/TFMessage", encode_payload(ros, "tf2_msgs/msg/TFMessage", tf))
    assert tf_back["transforms"][0]["child_frame_id"] == "odom"
    assert tf_back["transforms"][0]["transform"]["rotation"]["w"] == 1.0

    twist = decode_payload(
        ros,
        "geometry_msgs/msg/Twist",
        encode_payload(ros, "geometry_msgs/msg/Twist", {"linear": {"x": 0.2}, "angular": {"z": -0.5}}),
    )
    assert twist == {"linear": {"x": 0.2, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": -0.5}}

    pose = decode_payload(
        ros,
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        encode_payload(
            ros,
            "geometry_msgs/msg/PoseWithCovarianceStamped",
            {"header": {"stamp": {"sec": 4, "nanosec": 5}}, "pose": {"pose": {"position": {"x": 3.0}}}},
        ),
    )
    assert pose["header"]["stamp"] == pytest.approx(4.000000005) and pose["pose"]["covariance"].shape == (36,)


def test_bytes_fields_come_back_as_bytes(ros: RosTypes) -> None:
    packed = {"format": "png", "data": b"\x89PNG"}
    back = decode_payload(
        ros, "sensor_msgs/msg/CompressedImage", encode_payload(ros, "sensor_msgs/msg/CompressedImage", packed)
    )
    assert back["data"] == b"\x89PNG" and back["format"] == "png"


@pytest.mark.parametrize(
    ("type_name", "payload", "error"),
    [
        (
            "geometry_msgs/msg/Twist",
            {"linear": {"w": 1.0}},
            r"payload.linear has fields w that geometry_msgs/msg/Vector3 lacks \(x, y, z\)",
        ),
        ("sensor_msgs/msg/CameraInfo", {"k": [1.0] * 8}, "payload.k has 8 items, the type declares exactly 9"),
        ("sensor_msgs/msg/Image", {"height": -1}, "payload.height is -1, outside the range of uint32"),
        ("sensor_msgs/msg/Image", {"height": 2.5}, r"payload.height is 2.5, not a whole uint32"),
        ("std_msgs/msg/String", {"data": 5}, "payload.data is 5, not a string"),
        ("std_msgs/msg/Bool", {"data": 1}, "payload.data is 1, not a bool"),
        ("std_msgs/msg/Header", {"stamp": float("nan")}, r"payload.stamp is nan, not seconds"),
        (
            "geometry_msgs/msg/Twist",
            [1.0, 2.0],
            r"payload is list, not a geometry_msgs/msg/Twist \(a dict",
        ),
        (
            "sensor_msgs/msg/Image",
            np.zeros((2, 2, 2), dtype=np.uint8),
            "no image encoding for dtype uint8 with 2",
        ),
        ("sensor_msgs/msg/Image", np.zeros(4, dtype=np.uint8), r"not an image \(H, W\) or \(H, W, C\)"),
    ],
)
def test_payloads_that_do_not_fit_name_the_field(ros: RosTypes, type_name: str, payload: Any, error: str) -> None:
    with pytest.raises(RosTypeError, match=error):
        encode_payload(ros, type_name, payload)


def test_an_image_too_short_for_its_size_is_refused(ros: RosTypes) -> None:
    short = to_message(
        ros,
        "sensor_msgs/msg/Image",
        {"height": 2, "width": 2, "encoding": "mono8", "step": 2, "data": np.zeros(3, dtype=np.uint8)},
    )
    with pytest.raises(RosTypeError, match="step 2 and 3 bytes do not hold it"):
        image_array(short)
    odd = to_message(ros, "sensor_msgs/msg/Image", {"height": 1, "width": 1, "encoding": "yuv422", "step": 2})
    with pytest.raises(RosTypeError, match="image encoding 'yuv422' is not supported"):
        image_array(odd)
