"""Sparse recording (runtime.ros.sparse, D197): ``--record NAME@HZ:jpeg`` items, the rate limit,
and camera frames compressed into ``sensor_msgs/msg/CompressedImage`` read back by rosbags' own
Jazzy store (not CKM code). The image type is the use case's ``Image`` MessageType, as the lab's
cameras publish it (runtime.kernel.vectors: width and height from the channel, encoding rgb8)."""

from __future__ import annotations

import io
from typing import Any

import numpy as np
import pytest
from PIL import Image as PilImage
from rosbags.typesys import Stores, get_typestore

from ckmconf import load
from ckmconf.model import System
from runtime.ros.config import ConfigRosTypes
from runtime.ros.convert import to_message
from runtime.ros.recording import RecordingError, plan_recording
from runtime.ros.sparse import COMPRESSED, Item, SpecError, Throttle, compress, decompress, parse_spec
from runtime.ros.types import RosTypeError
from tests.conftest import REPO

LAB = REPO / "configs" / "usecase" / "lab.xml"


@pytest.fixture(scope="module")
def lab() -> tuple[System, ConfigRosTypes]:
    system = load(LAB)
    return system, ConfigRosTypes(system)


def test_items_name_a_topic_with_a_rate_and_a_compression() -> None:
    assert parse_spec(" /nav/pose, /nao/camera/image@0.5:jpeg ,/turtlebot/~xtion_rgb_raw:png,/odom@10") == [
        Item("/nav/pose"),
        Item("/nao/camera/image", 0.5, "jpeg"),
        Item("/turtlebot/~xtion_rgb_raw", None, "png"),
        Item("/odom", 10.0),
    ]
    assert parse_spec("all,/nao/camera/image@0.5") == [Item("all"), Item("/nao/camera/image", 0.5)]


@pytest.mark.parametrize(
    ("spec", "says"),
    [
        ("/odom@0", "@0 is not a rate in Hz"),
        ("/odom@fast", "@fast is not a rate in Hz"),
        ("/odom@inf", "@inf is not a rate in Hz"),
        ("/cam:gif", ":gif is not a compression (jpeg, png)"),
        ("all@1", "'all' takes no option"),
        ("/odom@1@2", "write NAME, NAME@HZ"),
    ],
)
def test_a_bad_item_is_refused_naming_it(spec: str, says: str) -> None:
    with pytest.raises(SpecError, match=f"--record item {spec!r}") as error:
        parse_spec(spec)
    assert says in str(error.value)


def test_the_throttle_lets_one_message_through_per_period() -> None:
    throttle = Throttle(0.5)
    stamps = [100.0 + 0.5 * k for k in range(13)]  # a 2 Hz camera for 6 s
    assert [s - 100 for s in stamps if throttle.admit(s)] == [0.0, 2.0, 4.0, 6.0]
    assert not throttle.admit(106.5) and throttle.admit(107.9995)  # a stamp rounded 0.5 ms early is still due
    assert throttle.admit(50.0)  # another publisher's clock far behind: the limit starts again from it
    assert not throttle.admit(51.0)


def _read(data: bytes) -> Any:
    """A CompressedImage's CDR bytes deserialised by rosbags' Jazzy store (an independent reader)."""
    return get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(data, COMPRESSED)


def _frame(width: int = 64, height: int = 48) -> np.ndarray:
    """A smooth colour picture (gradients), as a camera sees a room."""
    y, x = np.mgrid[0:height, 0:width]
    return np.stack([x * 255 // width, y * 255 // height, (x + y) * 255 // (width + height)], axis=2).astype(np.uint8)


def test_a_lab_camera_frame_becomes_a_jpeg_compressed_image(lab: tuple[System, ConfigRosTypes]) -> None:
    _, types = lab
    pixels = _frame(640, 480)
    value = {"stamp": 1_800_000_000.25, "width": 640, "height": 480, "encoding": "rgb8", "data": pixels.reshape(-1)}
    message = to_message(types.ros, "ckm_msgs/msg/Image", types.payload("ckm_msgs/msg/Image", value))
    data = compress(types.ros, message, "ckm_msgs/msg/Image", "jpeg", 1_800_000_001.0)
    assert len(data) < 921_600 / 10  # a VGA frame is 900 kB raw
    decoded = _read(data)
    assert decoded.format == "rgb8; jpeg compressed bgr8"  # compressed_image_transport's wording
    assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (1_800_000_000, 250_000_000)  # the frame's
    kind, picture = decompress({"format": decoded.format, "data": bytes(decoded.data)})
    assert kind == "image/jpeg"
    with PilImage.open(io.BytesIO(picture)) as opened:
        back = np.asarray(opened.convert("RGB")).astype(int)
    assert back.shape == (480, 640, 3) and np.abs(back - pixels).mean() < 3  # lossy, close


def test_png_is_lossless_and_bgr_and_16_bit_frames_keep_their_meaning() -> None:
    types = ConfigRosTypes(load(LAB)).ros
    pixels = _frame()
    bgr = to_message(types, "sensor_msgs/msg/Image", {"encoding": "bgr8", "data": pixels[:, :, ::-1].copy()})
    data = compress(types, bgr, "sensor_msgs/msg/Image", "png", 5.0)
    decoded = _read(data)
    assert decoded.format == "bgr8; png compressed bgr8" and decoded.header.stamp.sec == 0  # no stamp: zero time
    with PilImage.open(io.BytesIO(bytes(decoded.data))) as opened:
        assert np.array_equal(np.asarray(opened), pixels)  # stored as RGB, as PNG means it
    depth = (np.arange(48 * 64, dtype=np.uint16).reshape(48, 64) * 3).astype(np.uint16)
    mono16 = to_message(types, "sensor_msgs/msg/Image", {"encoding": "16UC1", "data": depth})
    data = compress(types, mono16, "sensor_msgs/msg/Image", "png", 5.0)
    decoded = _read(data)
    with PilImage.open(io.BytesIO(bytes(decoded.data))) as opened:
        assert np.array_equal(np.asarray(opened).astype(np.uint16), depth)
    with pytest.raises(RosTypeError, match="cannot be jpeg-compressed"):
        compress(types, mono16, "sensor_msgs/msg/Image", "jpeg", 5.0)


def test_the_lab_cameras_plan_as_compressed_streams_and_other_topics_are_refused(
    lab: tuple[System, ConfigRosTypes],
) -> None:
    system, types = lab
    nodes = system.nodes
    spec = "/nav/pose,/turtlebot/~xtion_rgb_raw@0.5:jpeg,/nao/camera/image@0.5:jpeg,/base/odom@5"
    planned = {t.bag_name: t for t in plan_recording(system, nodes, spec, types)}
    camera = planned["/turtlebot/xtion_rgb_raw/compressed"]
    assert (camera.ros_type, camera.source_type, camera.rate, camera.compression) == (
        COMPRESSED, "ckm_msgs/msg/Image", 0.5, "jpeg"
    )  # fmt: skip
    assert planned["/nao/camera/image/compressed"].rate == 0.5
    assert planned["/base/odom"].rate == 5.0 and planned["/base/odom"].compression is None
    assert planned["/nav/pose"].rate is None
    everything = plan_recording(system, nodes, "all,/nao/camera/image@0.5:jpeg", types)
    assert len(everything) > 20 and "/nao/camera/image/compressed" in {t.bag_name for t in everything}
    with pytest.raises(RecordingError, match=r"/nav/pose:jpeg: its type ckm_msgs/msg/PoseEstimate is not an image"):
        plan_recording(system, nodes, "/nav/pose:jpeg", types)
    with pytest.raises(RecordingError, match="no topic '/nowhere' here"):
        plan_recording(system, nodes, "/nowhere@1", types)
    with pytest.raises(RecordingError, match="not a rate in Hz"):
        plan_recording(system, nodes, "/nav/pose@-1", types)


def test_decompress_refuses_what_is_not_a_picture() -> None:
    with pytest.raises(ValueError, match="neither JPEG nor PNG"):
        decompress({"format": "rgb8; jpeg compressed bgr8", "data": b"not a picture"})
    with pytest.raises(ValueError, match="not a compressed image payload"):
        decompress({"format": "jpeg"})
