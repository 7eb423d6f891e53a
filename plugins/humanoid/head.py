"""A robot's pan-tilt head carrying a camera (the lab's Nao: thesis §7.1, Fig. 7.6): where its camera
looks, and where a pixel's viewing ray meets a horizontal plane of the map.

:class:`HeadModel` loads the robot's URDF in a PRIVATE pybullet client (DIRECT, no world, fixed
base) and reads the camera's optical frame (z forward, x right, y down) for given head angles by
forward kinematics, so the neck's and the camera's offsets come from the model, not from
constants. The robot's pose in the map (``x y yaw``, its base ``z``) places that frame on the map.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pybullet as p

from plugins.urdf_model import load_urdf

Vector = npt.NDArray[np.float64]


class HeadModel:
    """Forward kinematics of a pan-tilt head carrying a camera (see the module docstring)."""

    def __init__(self, urdf: str | Path, pan: str, tilt: str, camera: str) -> None:
        model = load_urdf(urdf)
        self.client, self.body = model.client, model.body
        joints, links = model.joints, model.links
        missing = [n for n in (pan, tilt) if n not in joints] + ([camera] if camera not in links else [])
        if missing:
            self.close()
            raise ValueError(f"the robot model {urdf} has no joint or link {', '.join(missing)}")
        self.pan, self.tilt, self.camera = joints[pan], joints[tilt], links[camera]
        self.limits = tuple(self._limits(joint) for joint in (self.pan, self.tilt))
        """(lower, upper) of the pan and the tilt joint, from the URDF (None where it gives none)."""

    def _limits(self, joint: int) -> tuple[float, float] | None:
        info = p.getJointInfo(self.body, joint, physicsClientId=self.client)
        lower, upper = float(info[8]), float(info[9])
        return (lower, upper) if lower < upper else None  # a continuous joint: no limit

    def camera_pose(self, pan: float, tilt: float) -> tuple[Vector, Vector]:
        """Position and rotation (columns: the optical x, y, z axes) of the camera in the base frame."""
        p.resetJointState(self.body, self.pan, pan, physicsClientId=self.client)
        p.resetJointState(self.body, self.tilt, tilt, physicsClientId=self.client)
        state = p.getLinkState(self.body, self.camera, computeForwardKinematics=True, physicsClientId=self.client)
        rotation = np.array(p.getMatrixFromQuaternion(state[5]), dtype=float).reshape(3, 3)
        return np.asarray(state[4], dtype=float), rotation

    def close(self) -> None:
        """Disconnect the private client (idempotent)."""
        if self.client >= 0:
            p.disconnect(physicsClientId=self.client)
            self.client = -1


def on_plane(origin: Vector, direction: Vector, height: float, min_range: float = 0.1,
             max_range: float = 20.0) -> Vector | None:
    """Where the ray ``origin + t·direction`` (t > 0) meets the plane z = ``height``, or None when it
    runs parallel, away from it, or meets it nearer than ``min_range`` or beyond ``max_range``."""
    if abs(direction[2]) < 1e-9:
        return None
    t = (height - origin[2]) / direction[2]
    distance = t * float(np.linalg.norm(direction))
    if t <= 0 or not min_range <= distance <= max_range:
        return None
    hit: Vector = origin + t * direction
    return hit


def map_frame(x: float, y: float, yaw: float, z: float, point: Vector) -> Vector:
    """A base-frame point on the map, for a robot at (x, y, yaw) whose base is ``z`` above the floor."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * point[0] - s * point[1], y + s * point[0] + c * point[1], z + point[2]])
