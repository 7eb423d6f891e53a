"""A camera's intrinsics from its own HWChannel (issue M point 2: "camera intrinsics from the camera's
channel"), for the depth clustering kinds' ``camera`` Param.

A simulated camera (``<HWChannel backend="sim">`` with ``sensor`` rgb or depth) renders an ideal
pinhole of its ``fov`` at ``width`` × ``height`` (plugins/sim/sensors.py ``pinhole``, which this
module calls): square pixels, the principal point at the image's centre. Naming that channel
keeps the numbers in one place: change the camera's field of view or resolution and every plugin
that reads its frames follows.
"""

from __future__ import annotations

from typing import Any

from ckmconf.model import HWChannel, System
from ckmconf.model.resources import Plugin
from plugins.hardware.sim import SimBackend
from plugins.sim.ros_messages import sim_channel
from plugins.sim.sensors import pinhole
from runtime.kernel.interfaces import ParamError, read_params

from .cameras import Camera


def camera_channels(system: System, name: str) -> list[HWChannel]:
    """The HWChannels of ``system`` called ``name``."""
    return [c for n in system.nodes for c in n.channels if c.name == name]


def channel_problem(channel: HWChannel) -> str | None:
    """Why ``channel`` gives no camera's intrinsics, None when it does."""
    values = {p.name: p.value for p in channel.params}
    if channel.backend != "sim" or values.get("sensor") not in ("rgb", "depth"):
        return (f"HWChannel {channel.name!r} is not a simulated camera (backend sim, sensor rgb or depth): give "
                "the intrinsics as fx, calibrationWidth and calibrationHeight instead")
    if "fov" not in values:
        return f"HWChannel {channel.name!r} gives no 'fov'"
    return None


def pinhole_of(channel: HWChannel) -> Camera:
    """The ideal pinhole a simulated camera channel renders (module docstring)."""
    v = read_params(channel.params, SimBackend.PARAMS, owner=f"sim channel {channel.name!r}")
    width, height = int(v["width"]), int(v["height"])
    return Camera(*pinhole(width, height, float(v["fov"])), width, height)


def channel_camera(record: Plugin, name: str, owner: str) -> Camera:
    """The intrinsics of the camera HWChannel ``name`` of the configuration ``record`` was read from."""
    channel = sim_channel(record, name, owner, param="camera")
    problem = channel_problem(channel)
    if problem is not None:
        raise ParamError(f"{owner}: Param 'camera': {problem}")
    return pinhole_of(channel)


def intrinsics_problems(record: Plugin, system: System | None) -> list[tuple[Any, str]]:
    """A clustering plugin with neither its intrinsics (fx and the calibration size) nor a ``camera``
    channel, or a ``camera`` naming no simulated camera of the system."""
    given = {p.name: p for p in record.params}
    camera = given.get("camera")
    if camera is None or not camera.value.strip():
        missing = [n for n in ("fx", "calibrationWidth", "calibrationHeight") if n not in given]
        if missing:
            return [(record, "give the camera's intrinsics: Params fx, calibrationWidth and calibrationHeight "
                             f"(missing: {', '.join(missing)}), or camera naming its HWChannel")]
        return []
    if system is None:
        return []
    found = camera_channels(system, camera.value)
    if len(found) != 1:
        names = sorted({c.name for n in system.nodes for c in n.channels if c.backend == "sim"})
        return [(camera, f"Param 'camera' = {camera.value!r} names {'no' if not found else len(found)} HWChannel "
                         f"of the system (its sim channels: {', '.join(names) or 'none'})")]
    problem = channel_problem(found[0])
    return [] if problem is None else [(camera, f"Param 'camera': {problem}")]
