"""Live sensor poses of the GlobalRecog.Fusion service: observations placed in the MAP frame (§6.3.1).

A robot that moves has its cameras' observations placed with its current pose estimate (the
service's ``pose`` input, a PoseEstimate ``{"pose": {"x", "y", "yaw"}, …}``) composed with the
camera's mount in the robot's URDF. A robot standing still at a known map pose (Param ``bases``)
may turn its head: its camera's pose composes that base pose with the mount at the head angles
last reported (the ``head`` input, ``{"pan", "tilt"}``, driving the URDF joints named in
``headJoints``). The lab's Turtlebot and Nao are one of each, for example. An observation whose
sensor pose is not known yet (no pose estimate, no head state) cannot be placed: it is left out
and counted (the service's ``unplaced`` measure).

Params (owned by ``plugin.feature-fusion``, declared here: :data:`MOUNT`, :data:`BASE`, read by
``read_params``): ``mounts`` (``"input: MODEL LINK; …"``, MODEL a shipped robot model name or a
URDF file relative to the configuration file), ``bases`` (``"input: x y yaw; …"``, a fixed base
pose in the map; mounted inputs without one follow the pose input), ``poseInput``, ``headInput``
(the names of those two inputs), ``headJoints`` (the URDF joints the head message's pan and tilt
drive).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from runtime.kernel.interfaces import ParamError
from runtime.verification.manifest import Entries

from .fusion_model import number
from .geometry import Pose
from .mounts import Mount, compose, model_path, planar, read_mount

MOUNT = Entries("MODEL LINK", 2, of="inputs", noun="an input", need="a robot model and a link")
"""``mounts``: an input's robot (a shipped model name or a URDF file) and its sensor's link."""
BASE = Entries("x y yaw", 3, numbers=True, of="inputs", noun="an input")
"""``bases``: the fixed map pose (m, m, rad) of a mounted input's robot."""


class Placement:
    """Sensor poses in the map of the mounted inputs, from the latest pose estimate and head angles."""

    def __init__(self, params: Mapping[str, Any], inputs: Mapping[str, str], base: Path, owner: str) -> None:
        self.owner = owner
        self.pose_input: str = params["poseInput"]
        self.head_input: str = params["headInput"]
        for param in ("poseInput", "headInput"):
            if not params[param] or params[param] in inputs:
                raise ParamError(f"{owner}: parameter {param!r} = {params[param]!r} must name an input not in 'inputs'")
        if self.pose_input == self.head_input:
            raise ParamError(f"{owner}: parameters 'poseInput' and 'headInput' name the same input")
        joints = params["headJoints"].split()
        if joints and len(joints) != 2:
            raise ParamError(f"{owner}: parameter 'headJoints' needs the pan and the tilt joint names, got {joints}")
        self.head_joints = (joints[0], joints[1]) if joints else None
        self.mounts: dict[str, Mount] = {}
        for name, (model, link) in params["mounts"].items():
            try:
                self.mounts[name] = read_mount(model_path(model, base), link)
            except ValueError as exc:
                raise ParamError(f"{owner}: parameter 'mounts' for {name!r}: {exc}") from None
            if self.mounts[name].joints and self.head_joints is None:
                moved = " ".join(self.mounts[name].joints)
                raise ParamError(f"{owner}: the mount of input {name!r} moves joints {moved}: parameter 'headJoints' "
                                 "must name the joints the head input's pan and tilt drive")
        self.bases: dict[str, Pose] = {}
        for name, values in params["bases"].items():
            if name not in self.mounts:
                raise ParamError(f"{owner}: parameter 'bases' names {name!r}, which has no entry in 'mounts'")
            self.bases[name] = planar(*values)
        self.robot: Pose | None = None
        """The moving robot's latest base pose in the map (from the pose input)."""
        self.observer: dict[str, float] | None = None
        """That pose as ``{"x", "y", "yaw"}`` (a Pose2D): carried with the fused objects (D172)."""
        self.angles: dict[str, float] | None = None
        """The head joints' latest angles (from the head input)."""

    @property
    def active(self) -> bool:
        """Whether any input is mounted on a robot: the common frame is then the map."""
        return bool(self.mounts)

    def update(self, data: Mapping[str, Any]) -> None:
        """Take the newest pose estimate and head state in ``data`` (None: keep the last ones)."""
        if data.get(self.pose_input) is not None:
            self.observer = self._pose(data[self.pose_input])
            self.robot = planar(**self.observer)
        if data.get(self.head_input) is not None:
            self.angles = self._head(data[self.head_input])

    def _bad(self, source: str) -> Callable[[str, str], ValueError]:
        return lambda where, why: ValueError(f"{self.owner}: input {source!r} {where} {why}")

    def _pose(self, message: Any) -> dict[str, float]:
        bad = self._bad(self.pose_input)
        pose = message.get("pose") if isinstance(message, Mapping) else None
        if not isinstance(pose, Mapping):
            raise bad("field 'pose'", "is missing or not a mapping of x, y, yaw")
        return {k: number(pose.get(k), bad, f"field 'pose.{k}'") for k in ("x", "y", "yaw")}

    def _head(self, message: Any) -> dict[str, float]:
        bad = self._bad(self.head_input)
        if not isinstance(message, Mapping):
            raise bad("message", "is not a mapping of pan and tilt")
        pan, tilt = (number(message.get(k), bad, f"field {k!r}") for k in ("pan", "tilt"))
        if not (abs(pan) <= 2 * math.pi and abs(tilt) <= 2 * math.pi):
            raise bad("fields 'pan'/'tilt'", f"= {pan}, {tilt} are not angles in radians")
        if self.head_joints is None:  # no mount moves a joint: the angles place nothing
            return {}
        return {self.head_joints[0]: pan, self.head_joints[1]: tilt}

    def sensor_pose(self, source: str) -> Pose | None:
        """The map pose of mounted input ``source``'s sensor; None while it is unknown."""
        mount = self.mounts[source]
        base = self.bases.get(source, self.robot)
        if base is None:
            return None
        if mount.joints:
            if self.angles is None:
                return None
            missing = [j for j in mount.joints if j not in self.angles]
            if missing:
                raise ValueError(
                    f"{self.owner}: input {source!r}'s mount moves joint {missing[0]!r}, which parameter "
                    f"'headJoints' ({' '.join(self.head_joints or ())}) does not name"
                )
        return compose(base, mount.pose(self.angles))
