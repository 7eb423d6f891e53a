"""The latest camera images of a running system, in the Monitor tab (issue K.5).

One tile per ``Image`` topic (configs/usecase/network.xml: ``{stamp, width, height, encoding,
data}``, ``data`` row-major bytes, as the simulated cameras publish them, D99): its title, the
newest frame scaled to the tile, and its size and encoding — or why the last message could not be
shown. :func:`image_of` does the decoding; a frame is decoded once, when it is new.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import QGridLayout, QLabel, QVBoxLayout, QWidget

CHANNELS: Mapping[str, tuple[int, QImage.Format]] = {
    "rgb8": (3, QImage.Format.Format_RGB888),
    "bgr8": (3, QImage.Format.Format_BGR888),
    "mono8": (1, QImage.Format.Format_Grayscale8),
    "rgba8": (4, QImage.Format.Format_RGBA8888),
    "bgra8": (4, QImage.Format.Format_ARGB32),  # little-endian ARGB32 is B, G, R, A in memory
}
TILE = 320  # px: the width a frame is shown at


def image_of(payload: Any) -> QImage:
    """The QImage of an Image message (a deep copy: it does not share the message's buffer).

    Raises:
        ValueError: not an Image message, an unknown encoding, or data too short for its size.
    """
    if not isinstance(payload, Mapping) or "data" not in payload:
        raise ValueError(f"not an Image message ({type(payload).__name__} without data)")
    encoding = str(payload.get("encoding") or "rgb8")
    if encoding not in CHANNELS:
        raise ValueError(f"image encoding {encoding!r} is not shown ({', '.join(CHANNELS)})")
    channels, form = CHANNELS[encoding]
    width, height = payload.get("width"), payload.get("height")
    if not isinstance(width, int | np.integer) or not isinstance(height, int | np.integer) or width <= 0 or height <= 0:
        raise ValueError(f"image size {width!r}×{height!r} is not positive integers")
    data = payload["data"]
    raw = np.frombuffer(data, dtype=np.uint8) if isinstance(data, bytes | bytearray) else np.asarray(data, np.uint8)
    size = int(width) * int(height) * channels
    if raw.size < size:
        raise ValueError(f"image of {width}×{height} {encoding}: {raw.size} bytes do not hold it ({size} needed)")
    pixels = np.ascontiguousarray(raw.reshape(-1)[:size])
    image = QImage(pixels.data, int(width), int(height), int(width) * channels, form)
    return image.copy()  # own the pixels: the message's buffer is not kept


class CameraPanel(QWidget):
    """A tile per camera topic with its newest frame (see the module docstring)."""

    def __init__(self, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.grid = QGridLayout()
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(self.grid)
        layout.addStretch(1)
        self.pictures: dict[str, QLabel] = {}
        self.captions: dict[str, QLabel] = {}
        self.images: dict[str, QImage] = {}  # the newest frame of each topic, full size
        self._shown: dict[str, int] = {}

    def show_topics(self, topics: tuple[str, ...]) -> None:
        """One tile per topic, in this order (two a row); the old tiles go."""
        while self.grid.count():
            item = self.grid.takeAt(0)
            widget = item.widget() if item is not None else None
            if widget is not None:
                widget.deleteLater()
        self.pictures, self.captions, self.images, self._shown = {}, {}, {}, {}
        for i, topic in enumerate(topics):
            tile = QWidget()
            column = QVBoxLayout(tile)
            title = QLabel(f"<b>{topic}</b>")
            picture = QLabel("no frame yet")
            picture.setAlignment(Qt.AlignmentFlag.AlignCenter)
            picture.setMinimumSize(TILE // 2, TILE * 3 // 8)
            caption = QLabel()
            for widget in (title, picture, caption):
                column.addWidget(widget)
            self.grid.addWidget(tile, i // 2, i % 2)
            self.pictures[topic], self.captions[topic] = picture, caption

    def show_frames(self, frames: Mapping[str, tuple[int, Any]]) -> None:
        """Show each topic's frame ``(count, Image message)`` unless it is the one already shown."""
        for topic, (count, payload) in frames.items():
            if topic not in self.pictures or self._shown.get(topic) == count:
                continue
            self._shown[topic] = count
            try:
                image = image_of(payload)
            except ValueError as exc:
                self.captions[topic].setText(f"✖ {exc}")
                continue
            self.images[topic] = image
            self.pictures[topic].setPixmap(QPixmap.fromImage(image).scaledToWidth(TILE))
            encoding = payload.get("encoding") or "rgb8"
            self.captions[topic].setText(f"{image.width()}×{image.height()} {encoding}, frame {count}")
