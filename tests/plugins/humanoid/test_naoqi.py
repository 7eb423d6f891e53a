"""plugin.naoqi-bridge (Nao.NaoQi, Table 7.2) on its messages: the image and head state it passes on,
its availability when an input goes stale, and bad frames and angles named."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from plugins.humanoid.naoqi import NaoQiBridge
from plugins.processing.recognition import CameraAcquisition
from runtime.kernel.interfaces import ParamError
from runtime.resources.spt import Context

from .head_loop import plugin

W, H = 8, 6


def frame(stamp: float, **changes: Any) -> dict[str, Any]:
    """A camera_raw Image as the sim sensor publishes it (D99)."""
    data = (np.arange(W * H * 3) % 251).astype(np.uint8).tobytes()
    return {"stamp": stamp, "width": W, "height": H, "encoding": "rgb8", "data": data, **changes}


def run(bridge: NaoQiBridge, now: float, camera: Any, yaw: Any = 0.1, pitch: Any = -0.2) -> dict[str, Any]:
    result: dict[str, Any] = bridge.process({"camera": camera, "head_yaw": yaw, "head_pitch": pitch},
                                            Context(0, now, "Nao"))
    return result


@pytest.fixture
def bridge() -> NaoQiBridge:
    made: NaoQiBridge = plugin(NaoQiBridge, "naoqi-bridge", timeout=0.5)
    return made


def test_the_image_and_head_state_pass_on_and_the_service_is_available(bridge: NaoQiBridge) -> None:
    result = run(bridge, 0.0, frame(0.0))
    assert result["head_state"] == {"pan": 0.1, "tilt": -0.2}
    assert result["available"] == 1
    assert result["status"] == {"stamp": 0.0, "available": True, "camera": True, "head": True, "error": ""}
    image = CameraAcquisition(plugin(CameraAcquisition, "camera-acquisition").record).process(
        result["image"], Context(0, 0.0, "PanTiltCamera"))
    assert image.shape == (H, W, 3)  # what the Recog's acquisition reads
    assert image.tobytes() == frame(0.0)["data"]
    again = run(bridge, 0.03, frame(0.0), yaw=0.12)
    assert "image" not in again  # the same frame is not published twice
    assert again["available"] == 1


def test_a_camera_without_new_frames_goes_stale(bridge: NaoQiBridge) -> None:
    run(bridge, 0.0, frame(0.0))
    for k in range(1, 20):  # the head keeps moving, the camera repeats its last frame
        result = run(bridge, 0.05 * k, frame(0.0), yaw=0.1 + 0.01 * k)
    assert result["available"] == 0
    assert result["status"]["camera"] is False and result["status"]["head"] is True
    assert "camera stale: no new frame for 0.9" in result["status"]["error"]
    assert run(bridge, 1.0, frame(1.0))["available"] == 1  # a new frame brings it back


def test_head_angles_that_stop_updating_go_stale_but_a_still_head_does_not(bridge: NaoQiBridge) -> None:
    # a still head: the frames without a new camera image were triggered by head samples
    for k in range(20):
        result = run(bridge, 0.03 * k, frame(0.06 * (k // 2)))
    assert result["available"] == 1
    # the head sensors stop: every frame now brings a new image and the same angles
    for k in range(20, 40):
        result = run(bridge, 0.06 * k, frame(0.06 * k))
    assert result["available"] == 0 and result["status"]["head"] is False
    assert "head stale" in result["status"]["error"]


def test_nothing_received_yet_is_not_available(bridge: NaoQiBridge) -> None:
    result = run(bridge, 0.0, None, yaw=None)
    assert result["available"] == 0 and result["status"]["error"] == "no camera frame"
    assert run(bridge, 0.1, frame(0.1), yaw=None)["status"]["error"] == "no head angles"


@pytest.mark.parametrize(
    ("camera", "error"),
    [
        (frame(0.0, data=b"short"), "camera frame rgb8 8x6 needs 144 bytes, got 5"),
        (frame(0.0, encoding="yuv422"), "encoding 'yuv422' is not one of rgb8, bgr8, mono8"),
        (frame(0.0, width=0), "size 0 x 6 is not two positive integers"),
        (frame(0.0, data=[1, 2, 3]), "data is list, not bytes"),
        ("image", "camera frame is str, not an Image"),
    ],
)
def test_a_bad_frame_is_named_and_not_passed_on(bridge: NaoQiBridge, camera: Any, error: str) -> None:
    result = run(bridge, 0.0, camera)
    assert "image" not in result
    assert result["available"] == 0 and error in result["status"]["error"]


@pytest.mark.parametrize(("yaw", "pitch", "error"), [(float("nan"), 0.0, "head_yaw = nan"),
                                                     (0.0, "up", "head_pitch = 'up'"), (True, 0.0, "head_yaw = True")])
def test_bad_head_angles_are_named(bridge: NaoQiBridge, yaw: Any, pitch: Any, error: str) -> None:
    result = run(bridge, 0.0, frame(0.0), yaw=yaw, pitch=pitch)
    assert "head_state" not in result and result["available"] == 0
    assert f"{error} is not a finite angle" in result["status"]["error"]


def test_bad_input_shapes_and_params_are_refused(bridge: NaoQiBridge) -> None:
    with pytest.raises(ValueError, match=r"naoqi-bridge.*expects"):
        bridge.process([1, 2], Context(0, 0.0, "Nao"))
    with pytest.raises(ParamError, match="encoding"):
        plugin(NaoQiBridge, "naoqi-bridge", encoding="yuv")
