"""A robot model (URDF) in a private pybullet client, for the plugins that compute forward or inverse
kinematics on it without a simulated world (the humanoid's head, the manipulation arm): the loaded
body and its joints and links by name."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pybullet as p


@dataclass(frozen=True)
class UrdfModel:
    """``client``: the private DIRECT client (the caller disconnects it); ``body``: the model, fixed base;
    ``joints``: joint name → index; ``links``: link name → index (a link's index is its parent joint's);
    ``movable``: the indices of the joints that are not fixed, in order."""

    client: int
    body: int
    joints: dict[str, int]
    links: dict[str, int]
    movable: list[int]


def load_urdf(urdf: str | Path) -> UrdfModel:
    """``urdf`` loaded with a fixed base in a new DIRECT client; a ValueError naming the file if it cannot be."""
    client = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=client)
    except p.error as exc:
        p.disconnect(physicsClientId=client)
        raise ValueError(f"cannot load the robot model {urdf}: {exc}") from None
    joints, links, movable = {}, {}, []
    for index in range(p.getNumJoints(body, physicsClientId=client)):
        info = p.getJointInfo(body, index, physicsClientId=client)
        joints[info[1].decode()] = index
        links[info[12].decode()] = index
        if info[2] != p.JOINT_FIXED:
            movable.append(index)
    return UrdfModel(client, body, joints, links, movable)


def jaw_opening(urdf: str | Path, fingers: Sequence[str]) -> float | None:
    """The full opening of a parallel jaw (m): the distance between the collision shapes of the first
    two finger joints' links with each joint at its upper limit (the fingers' travel from closed, D296);
    None when fewer than two fingers are named or they have no collision shape. ValueError when the
    model cannot be loaded or lacks a finger joint."""
    if len(fingers) < 2:
        return None
    model = load_urdf(urdf)
    try:
        missing = [f for f in fingers[:2] if f not in model.joints]
        if missing:
            raise ValueError(f"the robot model {urdf} has no joint {', '.join(missing)}")
        left, right = (model.joints[f] for f in fingers[:2])
        for joint in (left, right):
            upper = p.getJointInfo(model.body, joint, physicsClientId=model.client)[9]
            p.resetJointState(model.body, joint, upper, physicsClientId=model.client)
        p.performCollisionDetection(physicsClientId=model.client)
        points = p.getClosestPoints(model.body, model.body, 10.0, left, right, physicsClientId=model.client)
        return min((float(c[8]) for c in points), default=None)
    finally:
        p.disconnect(physicsClientId=model.client)
