"""A robot's URDF as a kinematic tree: its links, its joints and the transform each joint makes
(issue L point 1, thesis §4.4.1: the frames the simulation's ROS messages name).

ROS 2 names a sensor's data by the URDF link it is measured in (``header.frame_id``), and
``robot_state_publisher`` turns joint positions into the ``tf`` transforms between those links.
:class:`Kinematics` reads what that needs from the model ``hardware.sim`` loads
(``plugins/sim/models/<body>.urdf``): per joint its parent and child link, its ``origin`` (xyz, rpy)
and ``axis``, and its type; :meth:`Kinematics.transform` is the parent → child transform at a joint
position (a revolute or continuous joint turns about its axis, a prismatic one slides along it, a
fixed one is its origin). Quaternions are (x, y, z, w), as ``geometry_msgs/msg/Quaternion``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

MODELS = Path(__file__).resolve().parent / "models"
Vector = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]
MOVING = ("revolute", "continuous", "prismatic")


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> Quaternion:
    """The quaternion of URDF fixed-axis roll, pitch, yaw (R = Rz(yaw)·Ry(pitch)·Rx(roll))."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """The rotation ``a`` then, in its frame, ``b`` (the Hamilton product a·b)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def rotate(q: Quaternion, v: Vector) -> Vector:
    """``v`` rotated by the unit quaternion ``q``."""
    x, y, z, _ = quaternion_multiply(quaternion_multiply(q, (*v, 0.0)), (-q[0], -q[1], -q[2], q[3]))
    return (x, y, z)


@dataclass(frozen=True)
class Joint:
    """One ``<joint>`` of the model: what it links, where, about which axis."""

    name: str
    type: str
    parent: str
    child: str
    xyz: Vector
    rotation: Quaternion
    axis: Vector


class Kinematics:
    """The links and joints of a URDF file (see the module docstring).

    Raises:
        ValueError: the file is not a URDF robot (naming the file and what is wrong).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            root = ET.parse(self.path).getroot()
        except (OSError, ET.ParseError) as error:
            raise ValueError(f"{self.path}: cannot read the robot model: {error}") from None
        if root.tag != "robot":
            raise ValueError(f"{self.path}: not a URDF <robot>")
        self.name = root.get("name", self.path.stem)
        self.links = [str(link.get("name")) for link in root.findall("link")]
        self.joints: dict[str, Joint] = {}
        for element in root.findall("joint"):
            self.joints[str(element.get("name"))] = self._joint(element)
        children = {j.child for j in self.joints.values()}
        roots = [link for link in self.links if link not in children]
        if len(roots) != 1:
            raise ValueError(f"{self.path}: a robot has one root link, this one has {roots or 'none'}")
        self.root = roots[0]

    @classmethod
    def of_body(cls, body: str, model: str = "") -> Kinematics:
        """The model ``hardware.sim`` loads for ``body``: ``model`` if given, else ``models/<body>.urdf``."""
        return cls(Path(model) if model else MODELS / f"{body}.urdf")

    def _joint(self, element: ET.Element) -> Joint:
        name = str(element.get("name"))
        parent, child = element.find("parent"), element.find("child")
        if parent is None or child is None:
            raise ValueError(f"{self.path}: joint {name!r} has no <parent> or <child>")
        origin = element.find("origin")
        xyz = _triple(origin.get("xyz") if origin is not None else None, f"{self.path}: joint {name!r} origin xyz")
        rpy = _triple(origin.get("rpy") if origin is not None else None, f"{self.path}: joint {name!r} origin rpy")
        axis_element = element.find("axis")
        axis = _triple(axis_element.get("xyz") if axis_element is not None else "1 0 0", f"{self.path}: {name} axis")
        norm = math.sqrt(sum(a * a for a in axis)) or 1.0
        return Joint(
            name, str(element.get("type", "fixed")), str(parent.get("link")), str(child.get("link")),
            xyz, quaternion_from_rpy(*rpy), (axis[0] / norm, axis[1] / norm, axis[2] / norm),
        )

    def link(self, name: str, owner: str) -> str:
        """``name`` when it is a link of the model; ValueError naming ``owner`` and the links if not."""
        if name not in self.links:
            links = ", ".join(self.links)
            raise ValueError(f"{owner}: the model {self.path.name} has no link {name!r} (links: {links})")
        return name

    def transform(self, joint: Joint, position: float = 0.0) -> tuple[Vector, Quaternion]:
        """The parent → child transform of ``joint`` at ``position`` (rad or m): translation, rotation."""
        if joint.type in ("revolute", "continuous"):
            half = position / 2
            s = math.sin(half)
            motion = (joint.axis[0] * s, joint.axis[1] * s, joint.axis[2] * s, math.cos(half))
            return joint.xyz, quaternion_multiply(joint.rotation, motion)
        if joint.type == "prismatic":
            along = (joint.axis[0] * position, joint.axis[1] * position, joint.axis[2] * position)
            slide = rotate(joint.rotation, along)
            return (joint.xyz[0] + slide[0], joint.xyz[1] + slide[1], joint.xyz[2] + slide[2]), joint.rotation
        return joint.xyz, joint.rotation


def _triple(text: str | None, where: str) -> Vector:
    if text is None:
        return (0.0, 0.0, 0.0)
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        raise ValueError(f"{where}: {text!r} is not three numbers") from None
    if len(values) != 3:
        raise ValueError(f"{where}: {text!r} is not three numbers")
    return (values[0], values[1], values[2])
