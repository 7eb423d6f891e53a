"""The Monitor tab's camera tiles (issue K.5): Image messages (configs/usecase/network.xml) decoded
to the pixels they carry, each frame once, and a bad message named with what is wrong with it."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest
from pytestqt.qtbot import QtBot

from editor.views.camera import TILE, CameraPanel, image_of
from editor.views.sim_feeds import plain
from runtime.resources import codec


def frame(pixels: np.ndarray, encoding: str, *, as_array: bool = False) -> dict[str, Any]:
    """An Image message as a camera publishes it (data bytes, D99) or as a codec array."""
    data = pixels.astype(np.uint8)
    return {"stamp": 1.0, "width": pixels.shape[1], "height": pixels.shape[0], "encoding": encoding,
            "data": data.reshape(-1) if as_array else data.tobytes()}  # fmt: skip


def rgb(image: Any, x: int, y: int) -> tuple[int, int, int]:
    colour = image.pixelColor(x, y)
    return colour.red(), colour.green(), colour.blue()


@pytest.mark.parametrize("encoding", ["rgb8", "bgr8"])
def test_colour_frames_show_their_pixels(encoding: str) -> None:
    pixels = np.zeros((3, 4, 3), dtype=np.uint8)
    pixels[0, 0] = (250, 10, 20)  # top left
    pixels[2, 3] = (5, 200, 100)  # bottom right
    image = image_of(frame(pixels, encoding))
    assert (image.width(), image.height()) == (4, 3)
    top_left, bottom_right = (250, 10, 20), (5, 200, 100)
    if encoding == "bgr8":  # the same bytes read blue first
        top_left, bottom_right = top_left[::-1], bottom_right[::-1]
    assert rgb(image, 0, 0) == top_left and rgb(image, 3, 2) == bottom_right
    assert rgb(image, 1, 1) == (0, 0, 0)


def test_a_grey_frame_through_the_codec_shows_its_levels() -> None:
    levels = np.arange(6, dtype=np.uint8).reshape(2, 3) * 40
    wire = codec.encode(frame(levels, "mono8", as_array=True))  # data as a tagged uint8 array
    image = image_of(plain(wire))
    assert [image.pixelColor(x, y).red() for y in range(2) for x in range(3)] == [0, 40, 80, 120, 160, 200]


@pytest.mark.parametrize(
    ("message", "error"),
    [
        ({"width": 2, "height": 2}, "not an Image message"),
        ({"width": 2, "height": 2, "encoding": "yuv422", "data": b"\0" * 8}, "encoding 'yuv422' is not shown"),
        ({"width": 0, "height": 2, "encoding": "rgb8", "data": b""}, "image size 0×2"),
        ({"width": 2, "height": 2, "encoding": "rgb8", "data": b"\0" * 11}, "11 bytes do not hold it (12 needed)"),
    ],
)
def test_bad_frames_say_what_is_wrong(message: dict[str, Any], error: str) -> None:
    with pytest.raises(ValueError, match=re.escape(error)):
        image_of(message)


def test_tiles_show_each_new_frame_once_and_keep_the_last_good_one(qtbot: QtBot) -> None:
    panel = CameraPanel()
    qtbot.addWidget(panel)
    panel.show_topics(("/nao/camera/image", "/turtlebot/~xtion_rgb_raw"))
    assert set(panel.pictures) == {"/nao/camera/image", "/turtlebot/~xtion_rgb_raw"}
    red = np.zeros((48, 64, 3), dtype=np.uint8)
    red[..., 0] = 255
    panel.show_frames({"/nao/camera/image": (1, frame(red, "rgb8"))})
    picture = panel.pictures["/nao/camera/image"].pixmap()
    assert picture.width() == TILE and picture.height() == TILE * 48 // 64  # scaled to the tile's width
    assert rgb(picture.toImage(), TILE // 2, 10) == (255, 0, 0)
    assert panel.captions["/nao/camera/image"].text() == "64×48 rgb8, frame 1"
    shown = panel.images["/nao/camera/image"]
    panel.show_frames({"/nao/camera/image": (1, frame(red, "rgb8"))})  # the same frame again: not decoded again
    assert panel.images["/nao/camera/image"] is shown
    panel.show_frames({"/nao/camera/image": (2, {"width": 64, "height": 48, "encoding": "rgb8", "data": b"\0"})})
    assert panel.captions["/nao/camera/image"].text().startswith("✖ image of 64×48 rgb8: 1 bytes do not hold it")
    assert panel.images["/nao/camera/image"] is shown  # the last good frame stays
    assert panel.pictures["/turtlebot/~xtion_rgb_raw"].text() == "no frame yet"
