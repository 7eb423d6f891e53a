"""Where a robot's sensor is in the map (thesis §6.3.1, f' of eq. 6.34): URDF mounts and planar poses.

The GlobalRecog.Fusion service places each observation with the pose of the sensor that made
it. A sensor rides on a robot: its pose in the map is the robot's planar pose (x, y, yaw of the
base in the map, from localization or a Param) composed with the sensor's mount on the robot,
the chain of URDF joints from ``base_link`` to the sensor's link (fixed joints, and revolute
ones such as the Nao's HeadYaw/HeadPitch at the angles last reported). This is forward
kinematics of the robot model only: the service never touches a simulator, it reads the same
URDF file the robot (real or simulated) is described by.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lxml import etree

from .geometry import Matrix, Pose, Vector

MODELS = Path(__file__).resolve().parents[1] / "sim" / "models"
"""The robot models shipped with CKM: a bare model name ``turtlebot`` is ``MODELS/turtlebot.urdf``."""
MAX_URDF_BYTES = 4 * 1024 * 1024
JOINT_KINDS = ("fixed", "revolute", "continuous")


@dataclass(frozen=True)
class Joint:
    """One URDF joint of a mount's chain: its origin in the parent link and, if it turns, its axis."""

    name: str
    origin: Pose
    axis: Vector | None
    """Unit rotation axis in the joint frame; None for a fixed joint."""


def _rotation(axis: Vector, angle: float) -> Matrix:
    """Rodrigues' rotation of ``angle`` rad about the unit ``axis``."""
    x, y, z = axis
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    rotation: Matrix = np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)
    return rotation


def compose(a: Pose, b: Pose) -> Pose:
    """The pose ``b`` given in frame ``a``, expressed in ``a``'s parent frame (a ∘ b)."""
    return Pose(a.rotation @ b.rotation, a.rotation @ b.translation + a.translation)


def planar(x: float, y: float, yaw: float) -> Pose:
    """A robot base's pose in the map: on the floor at (x, y), turned by ``yaw`` about z."""
    return Pose.from_xyzrpy(x, y, 0.0, 0.0, 0.0, yaw)


@dataclass(frozen=True)
class Mount:
    """The chain of joints from a robot's ``base_link`` to a sensor's link (URDF forward kinematics)."""

    model: Path
    link: str
    chain: tuple[Joint, ...]

    @property
    def joints(self) -> tuple[str, ...]:
        """The names of the chain's moving joints, base first."""
        return tuple(j.name for j in self.chain if j.axis is not None)

    def pose(self, angles: Mapping[str, float] | None = None) -> Pose:
        """The sensor link's pose in the base frame with the moving joints at ``angles`` (rad).

        A moving joint missing from ``angles`` raises KeyError naming it.
        """
        pose = Pose(np.eye(3), np.zeros(3))
        for joint in self.chain:
            pose = compose(pose, joint.origin)
            if joint.axis is not None:
                if angles is None or joint.name not in angles:
                    raise KeyError(f"no angle for joint {joint.name!r} of {self.model.name}")
                pose = Pose(pose.rotation @ _rotation(joint.axis, angles[joint.name]), pose.translation)
        return pose


def _numbers(text: str | None, where: str) -> list[float]:
    values = (text or "0 0 0").split()
    try:
        numbers = [float(v) for v in values]
    except ValueError:
        numbers = []
    if len(numbers) != 3 or not all(math.isfinite(v) for v in numbers):
        raise ValueError(f"{where} is not three finite numbers: {text!r}")
    return numbers


def read_mount(model: Path, link: str) -> Mount:
    """The chain from ``base_link`` (the URDF's root) to ``link`` in the URDF file ``model``.

    ValueError names the file and what is wrong (unreadable, not a URDF, no such link, a joint
    kind a sensor mount cannot have).
    """
    try:
        if model.stat().st_size > MAX_URDF_BYTES:
            raise ValueError(f"robot model {model}: larger than {MAX_URDF_BYTES} bytes")
        parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
        root = etree.fromstring(model.read_bytes(), parser)
    except OSError as exc:
        raise ValueError(f"robot model {model}: cannot read it: {exc.strerror}") from None
    except etree.XMLSyntaxError as exc:
        raise ValueError(f"robot model {model}: not XML: {exc}") from None
    if root.tag != "robot":
        raise ValueError(f"robot model {model}: the root element is <{root.tag}>, not <robot>")
    by_child: dict[str, etree._Element] = {}
    for joint in root.iter("joint"):
        child = joint.find("child")
        if child is not None and child.get("link"):
            by_child[str(child.get("link"))] = joint
    links = {str(e.get("name")) for e in root.iter("link")}
    if link not in links:
        raise ValueError(f"robot model {model}: no link {link!r} (links: {', '.join(sorted(links))})")
    chain: list[Joint] = []
    current = link
    while current in by_child:
        element = by_child[current]
        name, kind = str(element.get("name")), str(element.get("type"))
        where = f"robot model {model}: joint {name!r}"
        if kind not in JOINT_KINDS:
            raise ValueError(f"{where} is {kind!r}: a sensor mount has only {', '.join(JOINT_KINDS)} joints")
        origin = element.find("origin")
        xyz = _numbers(origin.get("xyz") if origin is not None else None, f"{where} origin xyz")
        rpy = _numbers(origin.get("rpy") if origin is not None else None, f"{where} origin rpy")
        axis: Vector | None = None
        if kind != "fixed":
            given = element.find("axis")
            axis = np.array(_numbers(given.get("xyz") if given is not None else "1 0 0", f"{where} axis"))
            if not np.linalg.norm(axis) > 0:
                raise ValueError(f"{where} axis is zero")
            axis = axis / np.linalg.norm(axis)
        chain.append(Joint(name, Pose.from_xyzrpy(*xyz, *rpy), axis))
        if len(chain) > len(by_child):
            raise ValueError(f"{where}: the joints form a loop")
        parent = element.find("parent")
        current = str(parent.get("link")) if parent is not None else ""
    if current != "base_link":
        raise ValueError(f"robot model {model}: link {link!r} hangs from {current!r}, not from base_link")
    return Mount(model, link, tuple(reversed(chain)))


def model_path(name: str, base: Path) -> Path:
    """A robot model named in a Param: a bare name is a shipped model, else a file relative to ``base``."""
    if "/" not in name and "\\" not in name and not name.endswith(".urdf"):
        return MODELS / f"{name}.urdf"
    return base / name
