"""The simulated robots of a configuration, as ``ckm-bench mission`` randomises them (thesis §7.5, D301).

A robot is a ``body`` Param of ``sim`` HWChannels (docs/simulation.md). Its start is the ``pose`` Param
its channels give ("x y yaw"; every channel of the body that gives one must give the same). It is
*mobile* when one of its ``out`` channels can move the whole body: a ``multirotor`` actuator, or a
joint (``joint`` or ``mirror``) that its URDF declares ``continuous`` — a wheel, which turns without
limit. Every other body is fixed-base for the bench: an arm bolted to a station, the Nao standing
behind the workbench (its head joints are revolute), a robot only watched through sensors. Its radius
is the reach of its URDF's root link (:func:`plugins.hardware.sim_checks.base_radius`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from ckmconf.model import HWChannel, System
from plugins.hardware.sim_checks import base_radius, robot_model

Pose2D = tuple[float, float, float]


@dataclass(frozen=True)
class Body:
    """A simulated robot: its start (None: no ``pose`` Param), whether it moves itself, and why."""

    name: str
    start: Pose2D | None
    mobile: bool
    why: str  # what makes it mobile ("wheel joints left_wheel_joint, …", "a multirotor") or fixed-base
    radius: float | None  # m; None: its URDF has no root collision (or cannot be read)


def parse_pose(text: str) -> Pose2D | None:
    """``"x y yaw"`` (or ``"x y"``, yaw 0) as numbers; None when it is not a planar pose."""
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        return None
    if len(values) == 2:
        values.append(0.0)
    return (values[0], values[1], values[2]) if len(values) == 3 else None


@lru_cache(maxsize=32)
def _continuous_joints(path: str, mtime: float) -> frozenset[str]:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError):
        return frozenset()
    return frozenset(str(j.get("name")) for j in root.findall("joint") if j.get("type") == "continuous")


def _values(channel: HWChannel) -> dict[str, str]:
    return {p.name: p.value for p in channel.params}


def bodies(system: System) -> list[Body]:
    """Every ``sim`` body of ``system``, in the order their first channel appears.

    Raises:
        ValueError: two channels of one body give different ``pose`` Params.
    """
    channels: dict[str, list[HWChannel]] = {}
    for node in system.nodes:
        for channel in node.channels:
            body = _values(channel).get("body") if channel.backend == "sim" else None
            if body:
                channels.setdefault(body, []).append(channel)
    found = []
    for name, own in channels.items():
        poses = {_values(c)["pose"] for c in own if _values(c).get("pose")}
        starts = {parse_pose(p) for p in poses}
        if len(starts) > 1:
            raise ValueError(f"the channels of body {name!r} give different 'pose' Params: {sorted(poses)}")
        start = starts.pop() if starts else None
        model = robot_model(own[0], system)
        try:
            wheels = _continuous_joints(str(model), model.stat().st_mtime)
        except OSError:
            wheels = frozenset()
        driven = sorted(
            {
                joint
                for c in own
                if c.direction == "out"
                for joint in (_values(c).get("joint"), _values(c).get("mirror"))
                if joint in wheels
            }
        )
        flies = any(c.direction == "out" and _values(c).get("actuator") == "multirotor" for c in own)
        if flies:
            why = "a multirotor"
        elif driven:
            why = "wheel joints " + ", ".join(driven)
        else:
            why = "no out channel drives a continuous (wheel) joint or a multirotor: fixed-base"
        found.append(Body(name, start, flies or bool(driven), why, base_radius(Path(model))))
    return found
