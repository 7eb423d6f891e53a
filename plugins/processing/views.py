"""Keypoints learnt from rendered views of the textured objects (thesis §7.4.1, D175): the views file.

The flat texture images teach ORB what a print looks like face-on and sharp. The simulated
cameras see it smaller, curved round a cylinder, shaded and resampled by the renderer, and ORB
describes many of those corners differently. ``plugins.sim.orb_training`` therefore renders each
skinned object from around it at the distances the robots see it from, keeps the ORB keypoints
that fall on the object, and writes each one's descriptor with the texture position it shows (its
pixel in the print, through the skin's own texture mapping) to this file. The model file names it
(``views:``) and :func:`plugins.processing.textures.build_model` adds its keypoints to those of the
flat textures: they share one frame, so one homography places both.

Format (text, one keypoint a line, ``#`` comment lines first)::

    <object name> <x> <y> <descriptor: 64 hex digits>

``x``, ``y`` are pixels of the object's texture (``width`` × ``height`` of the model file). A
problem raises ValueError ``FILE:LINE: message``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt

DESCRIPTOR_BYTES = 32
"""An ORB descriptor's length (256 bits)."""

Views = tuple[npt.NDArray[np.uint8], npt.NDArray[np.float32], npt.NDArray[np.intp]]
"""Descriptors (N×32), texture positions (N×2) and object indices (N) of the learnt keypoints."""


def read_views(path: str | Path, names: Sequence[str]) -> Views:
    """The keypoints of a views file, their objects indexed as in ``names`` (the model file's order).

    Raises:
        OSError: the file cannot be read.
        ValueError: a malformed line, or an object the model does not list (``FILE:LINE: ...``).
    """
    index = {name: i for i, name in enumerate(names)}
    descriptors: list[bytes] = []
    points: list[tuple[float, float]] = []
    labels: list[int] = []
    with open(path, encoding="utf-8") as stream:
        for number, line in enumerate(stream, 1):
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            fields = text.split()
            try:
                if len(fields) != 4:
                    raise ValueError(f"expected 'object x y descriptor', got {len(fields)} fields")
                name, x, y, hexed = fields
                if name not in index:
                    raise ValueError(f"object {name!r} is not in the model (known: {', '.join(names)})")
                raw = bytes.fromhex(hexed)
                if len(raw) != DESCRIPTOR_BYTES:
                    raise ValueError(f"a descriptor has {DESCRIPTOR_BYTES} bytes, this one {len(raw)}")
                points.append((float(x), float(y)))
            except ValueError as exc:
                raise ValueError(f"{path}:{number}: {exc}") from None
            descriptors.append(raw)
            labels.append(index[name])
    if not descriptors:
        raise ValueError(f"{path}: no keypoints")
    return (
        np.frombuffer(b"".join(descriptors), np.uint8).reshape(-1, DESCRIPTOR_BYTES).copy(),
        np.array(points, np.float32).reshape(-1, 2),
        np.array(labels, np.intp),
    )


def write_views(path: str | Path, rows: Iterable[tuple[str, float, float, bytes]], header: Sequence[str]) -> int:
    """Write ``(object, x, y, descriptor)`` rows under ``header`` comment lines; the count written."""
    count = 0
    with open(path, "w", encoding="utf-8") as stream:
        for line in header:
            stream.write(f"# {line}\n".replace("# \n", "#\n"))
        for name, x, y, descriptor in rows:
            if len(descriptor) != DESCRIPTOR_BYTES:
                raise ValueError(f"{name}: a descriptor of {len(descriptor)} bytes")
            stream.write(f"{name} {x:.1f} {y:.1f} {descriptor.hex()}\n")
            count += 1
    return count
