"""Camera intrinsics from a ``sensor_msgs/msg/CameraInfo`` input, carried with each frame (issue M point 2).

A ROS camera driver publishes its image and its CameraInfo side by side (image_transport's camera
pair). ``plugin.depth-acquisition`` given ``cameraInfo`` (the name of the stream's Input carrying the
CameraInfo) pairs them into a *camera frame*: the mapping ``{"image": <depth, metres>, "camera_info":
<the CameraInfo>}``. ``plugin.image-resize`` resizes the image of a camera frame and passes its
CameraInfo on, and the clustering kinds take the intrinsics of each frame's CameraInfo — ``k`` (or
ROS 1's ``K``) at the CameraInfo's ``width`` × ``height`` — scaled to the image they receive, as they
scale Param intrinsics. The CameraInfo's distortion is not applied (a rectified image is expected, as
ROS' ``image_rect`` topics carry).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from ckmconf.model import System
from ckmconf.model.resources import Plugin, SmartResource, Use

from .cameras import Camera

IMAGE, CAMERA_INFO = "image", "camera_info"
"""The keys of a camera frame."""
ACQUISITION = "depth-acquisition"
"""The kind that pairs a depth image with its CameraInfo (Param ``cameraInfo``)."""


def camera_of_info(info: Any, owner: str) -> Camera:
    """The pinhole of a CameraInfo mapping: fx, fy, cx, cy of its ``k`` at its ``width`` × ``height``.

    Raises:
        ValueError: not a mapping, no 3 × 3 ``k``, a focal length or the size not positive, or a value
            not finite.
    """
    if not isinstance(info, Mapping):
        raise ValueError(f"{owner}: the camera info is {type(info).__name__}, not a sensor_msgs/CameraInfo mapping")
    k = info.get("k", info.get("K"))
    try:
        values = [float(v) for v in k]
        width, height = int(info["width"]), int(info["height"])
    except (TypeError, ValueError, KeyError) as exc:
        raise ValueError(f"{owner}: the camera info has no 3 × 3 'k' with 'width' and 'height' ({exc})") from None
    if len(values) != 9:
        raise ValueError(f"{owner}: the camera info's 'k' has {len(values)} values, not 9")
    fx, cx, fy, cy = values[0], values[2], values[4], values[5]
    if not all(math.isfinite(v) for v in (fx, fy, cx, cy)) or fx <= 0 or fy <= 0 or width <= 0 or height <= 0:
        raise ValueError(
            f"{owner}: the camera info gives no camera (fx {fx}, fy {fy}, cx {cx}, cy {cy}, size {width} × {height});"
            " an uncalibrated camera publishes k of zeros"
        )
    return Camera(fx, fy, cx, cy, width, height)


def is_camera_frame(data: Any) -> bool:
    """Whether ``data`` is a camera frame (module docstring) rather than a bare image."""
    return isinstance(data, Mapping) and IMAGE in data and CAMERA_INFO in data


def _chain_to(use: Use, name: str, above: tuple[str, ...] = ()) -> tuple[str, ...] | None:
    """The plugin names from ``use`` down to ``name`` (inclusive), None when ``name`` is not below."""
    here = (*above, use.plugin)
    if use.plugin == name:
        return here
    for child in use.uses:
        found = _chain_to(child, name, here)
        if found is not None:
            return found
    return None


def resource_of(record: Plugin, system: System) -> SmartResource | None:
    """The Smart Resource whose ``<Plugin>`` ``record`` is."""
    return next((r for r in system.resources if any(p is record for p in r.plugins)), None)


def fed_camera_info(record: Plugin, system: System | None) -> bool:
    """Whether every profile that runs ``record`` has, above it, a depth-acquisition pairing each frame
    with a CameraInfo (so the frames it receives carry their intrinsics)."""
    if system is None:
        return False
    resource = resource_of(record, system)
    if resource is None:
        return False
    kinds = {p.name: p for p in resource.plugins}
    chains = [c for c in (_chain_to(pr.root, record.name) for pr in resource.profiles) if c is not None]

    def pairs(name: str) -> bool:
        plugin = kinds.get(name)
        return plugin is not None and plugin.kind == ACQUISITION and any(
            p.name == "cameraInfo" and p.value.strip() for p in plugin.params)

    return bool(chains) and all(any(pairs(name) for name in chain[:-1]) for chain in chains)


def stream_input_problems(record: Plugin, system: System | None) -> list[tuple[Any, str]]:
    """A depth-acquisition's ``cameraInfo`` that names none of its stream's Inputs, or a stream with
    other than two Inputs (the image and its CameraInfo)."""
    given = next((p for p in record.params if p.name == "cameraInfo" and p.value.strip()), None)
    if given is None or system is None:
        return []
    resource = resource_of(record, system)
    if resource is None:
        return []
    rooted = {pr.name for pr in resource.profiles if pr.root.plugin == record.name}
    services = [s for s in resource.services if any(sc.profile in rooted for sc in s.scenarios)]
    if not services:
        return []
    inputs = list(dict.fromkeys(i.name for s in services for i in s.inputs))
    if given.value not in inputs:
        return [(given, f"Param 'cameraInfo' = {given.value!r} names no Input of the stream's services "
                        f"(their Inputs: {', '.join(inputs) or 'none'})")]
    if len(inputs) != 2:
        return [(given, f"with 'cameraInfo' the stream reads two Inputs, the depth image and its CameraInfo; "
                        f"it has {len(inputs)}: {', '.join(inputs)}")]
    return []
