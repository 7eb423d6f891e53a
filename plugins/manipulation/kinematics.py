"""The predefined positions of Fig. 7.20 (thesis §7.4.2) and their inverse kinematics on the arm's URDF.

The pose file (the Param ``poses``, a small YAML subset read here: no PyYAML)
names each arm pose by an end-effector target in the robot base frame — the tool point's
``x y z`` (m) and the tool's ``pitch`` from the vertical (rad: π/2 points the gripper forward,
π straight down; optional on an arm that cannot set it, see below) — and each gripper pose by a
share of the gripper joint's range (0 closed, 1 open), so one file serves any unit the gripper joint
has (rad on an AX-12, m on prismatic fingers)::

    version: 1
    tool: gripper_tool_link
    arm:
      resting: 0.17 0.0 0.17 2.8
    gripper:
      open: 1.0

:class:`ArmModel` loads the URDF in a PRIVATE pybullet client (DIRECT, no world, fixed base): it
only computes. The arm is a pan joint and two or three parallel pitch joints; the tool's pitch is
the angle from the vertical of the line from the last pitch joint to the tool point. A 4-DOF arm
(three pitch joints) cannot meet an arbitrary 6-D pose, so the target is split as MoveIt!'s
position-plus-approach goals are on such arms: pybullet's IK puts the wrist joint at the point
``tool_length`` behind the tool target along the approach direction (pan, shoulder, elbow), and the
wrist joint takes the rest of the pitch. A 3-DOF arm (two pitch joints, the station arm) has no
freedom left for the pitch once the point is given (D264): its IK is on the tool point alone, from
both elbow branches; a target without a pitch takes the branch nearest the seed (the arm's present
posture), a target with one takes the branch whose pitch is nearest and is refused if that is more
than ``pitch_tolerance`` off. The IK is re-run from its own answer until the solved point is within
0.5 mm (it linearises about the current state); the solution is then checked by forward kinematics
and against the URDF's joint limits.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p

from plugins.urdf_model import load_urdf

MODELS = Path(__file__).resolve().parents[1] / "sim" / "models"
"""The robot models shipped with the simulator (``model="turtlebot"`` names ``turtlebot.urdf`` there)."""
GROUPS = ("arm", "gripper")


@dataclass(frozen=True)
class ArmTarget:
    """An end-effector target: the tool point in the base frame (m) and the tool's pitch (rad)."""

    x: float
    y: float
    z: float
    pitch: float | None = None
    """None: any pitch (only on an arm that cannot set it)."""


@dataclass(frozen=True)
class PoseFile:
    """A parsed pose file: the tool link, the arm targets and the gripper openings (shares 0..1)."""

    path: str
    tool: str
    arm: Mapping[str, ArmTarget]
    gripper: Mapping[str, float]


def parse_poses(text: str, path: str = "<memory>") -> PoseFile:
    """A PoseFile from pose-file text; a problem raises ValueError ``PATH:LINE: message``."""
    top: dict[str, str] = {}
    groups: dict[str, dict[str, list[float]]] = {"arm": {}, "gripper": {}}
    section: str | None = None
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.split("#", 1)[0].strip()
        if not stripped:
            continue
        key, sep, raw = stripped.partition(":")
        key, raw = key.strip(), raw.strip()
        where = f"{path}:{number}"
        if not sep or not key:
            raise ValueError(f"{where}: expected 'key: value', got {stripped!r}")
        if not line[:1].isspace():
            section = None
            if key in GROUPS:
                if raw:
                    raise ValueError(f"{where}: {key!r} takes indented 'name: values' lines, not a value")
                section = key
            elif key in ("version", "tool"):
                top[key] = raw
            else:
                raise ValueError(f"{where}: unknown key {key!r} (known: version, tool, arm, gripper)")
            continue
        if section is None:
            raise ValueError(f"{where}: an indented line must follow 'arm:' or 'gripper:'")
        if key in groups[section]:
            raise ValueError(f"{where}: {section} pose {key!r} is defined twice")
        try:
            values = [float(v) for v in raw.split()]
        except ValueError:
            raise ValueError(f"{where}: {section} pose {key!r}: {raw!r} is not a list of numbers") from None
        wanted = (3, 4) if section == "arm" else (1,)
        if len(values) not in wanted or not all(math.isfinite(v) for v in values):
            what = "x y z [pitch]" if section == "arm" else "one opening share"
            raise ValueError(f"{where}: {section} pose {key!r} needs {what}, got {raw!r}")
        if section == "gripper" and not 0.0 <= values[0] <= 1.0:
            raise ValueError(f"{where}: gripper pose {key!r}: opening share {values[0]} is not in [0, 1]")
        groups[section][key] = values
    if top.get("version", "1") != "1":
        raise ValueError(f"{path}: unsupported pose file version {top['version']!r} (this release reads 1)")
    if not groups["arm"] and not groups["gripper"]:
        raise ValueError(f"{path}: no arm or gripper poses")
    if not top.get("tool"):  # no robot's link is a default: the targets are this link's positions
        raise ValueError(f"{path}: no 'tool': the URDF link whose point the arm poses place (tool: LINK)")
    return PoseFile(
        path,
        top["tool"],
        {name: ArmTarget(*v) for name, v in groups["arm"].items()},
        {name: v[0] for name, v in groups["gripper"].items()},
    )


def read_poses(path: str | Path) -> PoseFile:
    """The pose file at ``path``; OSError if it cannot be read, ValueError if it is malformed."""
    with open(path, encoding="utf-8") as stream:
        return parse_poses(stream.read(), str(path))


def target_of(value: Any) -> ArmTarget | str:
    """A goal's Cartesian ``target`` ``{x, y, z[, pitch]}``, or why it is not one."""
    if not isinstance(value, Mapping):
        return f"target is {type(value).__name__}, not {{x, y, z, pitch}}"
    numbers: dict[str, float | None] = {}
    for key in ("x", "y", "z", "pitch"):
        item = value.get(key)
        if item is None and key == "pitch":
            numbers[key] = None
            continue
        if isinstance(item, bool) or not isinstance(item, int | float) or not math.isfinite(item):
            return f"target {key} = {item!r} is not a finite number"
        numbers[key] = float(item)
    x, y, z = (float(numbers[k] or 0.0) for k in ("x", "y", "z"))  # each checked above
    return ArmTarget(x, y, z, numbers["pitch"])


def target_text(target: Mapping[str, float | None]) -> str:
    """A target ``{x, y, z, pitch}`` in words, for a refusal's reason."""
    pitch = target.get("pitch")
    point = f"({target['x']:.3f}, {target['y']:.3f}, {target['z']:.3f}"
    return point + (")" if pitch is None else f", pitch {pitch:.3f})")


@dataclass(frozen=True)
class Solution:
    """Joint angles for an arm target (in ``ArmModel.arm`` order), or why there are none."""

    joints: tuple[float, ...]
    error: str = ""
    """Empty when the solution is usable; else why not (unreachable, out of the joint limits)."""
    residual: float = 0.0
    """Distance (m) between the target and the tool point the angles give."""


class ArmModel:
    """A robot arm's kinematics in a private pybullet client (see the module docstring).

    ``arm``: the pan joint and the two or three pitch joints, in chain order; ``gripper``: the
    gripper joint moved with the arm's poses (None: the gripper is a service of its own); ``tool``:
    the tool-point link. Call :meth:`close` when done (the client holds memory).
    """

    def __init__(self, urdf: str | Path, arm: Sequence[str], gripper: str | None, tool: str) -> None:
        if len(arm) not in (3, 4):
            raise ValueError(f"the arm needs a pan joint and two or three pitch joints, got {list(arm)}")
        model = load_urdf(urdf)
        self.client, self.body = model.client, model.body
        joints, links = model.joints, model.links
        self.movable: list[int] = model.movable
        names = (*arm, *([gripper] if gripper else []))
        missing = [name for name in names if name not in joints] + ([tool] if tool not in links else [])
        if missing:
            self.close()
            raise ValueError(f"the robot model {urdf} has no joint or link {', '.join(missing)}")
        self.arm = [joints[name] for name in arm]
        self.gripper = joints[gripper] if gripper else None
        self.tool = links[tool]
        info = [p.getJointInfo(self.body, joints[name], physicsClientId=self.client) for name in names]
        self.lower = [float(i[8]) for i in info]
        self.upper = [float(i[9]) for i in info]
        self.velocity = [float(i[11]) or 1.0 for i in info]
        """Velocity limits of the URDF (arm joints, then the gripper's), 1 where it gives none."""
        self.wrist = self.arm[-1]  # a joint's child link has the joint's index: the last pitch joint's origin
        self.reset([0.0] * len(self.arm))
        self.tool_length = float(np.linalg.norm(np.subtract(self._link(self.tool), self._link(self.wrist))))
        pan = self._link(self.arm[0])
        self.pan_origin = (float(pan[0]), float(pan[1]))

    @property
    def sets_pitch(self) -> bool:
        """Whether the arm can choose the tool's pitch at a point (three pitch joints)."""
        return len(self.arm) == 4

    def _link(self, link: int) -> np.ndarray:
        state = p.getLinkState(self.body, link, computeForwardKinematics=True, physicsClientId=self.client)
        return np.asarray(state[4], dtype=float)

    def reset(self, angles: Sequence[float]) -> None:
        """Put the arm's joints at ``angles`` in the private client."""
        for joint, angle in zip(self.arm, angles, strict=False):
            p.resetJointState(self.body, joint, float(angle), physicsClientId=self.client)

    def tool_point(self, angles: Sequence[float]) -> tuple[float, float, float]:
        """Forward kinematics: the tool point (base frame) for the arm ``angles``."""
        self.reset(angles)
        x, y, z = self._link(self.tool)
        return float(x), float(y), float(z)

    def tool_pitch(self, angles: Sequence[float]) -> float:
        """Forward kinematics: the tool's pitch from the vertical (rad) for the arm ``angles``."""
        self.reset(angles)
        tool, wrist = self._link(self.tool), self._link(self.wrist)
        heading = math.atan2(tool[1] - self.pan_origin[1], tool[0] - self.pan_origin[0])
        dx, dy, dz = tool - wrist
        return math.atan2(dx * math.cos(heading) + dy * math.sin(heading), dz)

    def gripper_position(self, share: float) -> float:
        """The gripper joint's position for an opening ``share`` (0 closed = lower limit, 1 = upper)."""
        low, high = self.lower[-1], self.upper[-1]
        return low + share * (high - low)

    def solve(self, target: ArmTarget, seed: Sequence[float] | None = None, tolerance: float = 0.005,
              pitch_tolerance: float = 0.1) -> Solution:
        """The arm angles putting the tool point at ``target`` with its pitch (see the module docstring)."""
        if self.sets_pitch:
            if target.pitch is None:
                return Solution((), "this arm sets the tool's pitch: the target needs one")
            return self._checked(self._solve_with_pitch(target, seed or (0.0, 0.3, 1.2, 0.0)), target, tolerance)
        start = list(seed or (0.0, 0.3, 1.2))
        flipped = [start[0], start[1], -start[2] if abs(start[2]) > 0.1 else -1.2]
        branches = [self._checked(self._reach(self.tool, target, s), target, tolerance) for s in (start, flipped)]
        usable = [b for b in branches if not b.error] or branches
        if target.pitch is None:
            return min(usable, key=lambda b: sum((a - s) ** 2 for a, s in zip(b.joints, start, strict=True)))
        pitch = target.pitch
        best = min(usable, key=lambda b: abs(math.remainder(self.tool_pitch(b.joints) - pitch, 2 * math.pi)))
        achieved = self.tool_pitch(best.joints)
        if not best.error and abs(math.remainder(achieved - pitch, 2 * math.pi)) > pitch_tolerance:
            return Solution(best.joints, f"this arm cannot set the pitch at that point: the tool points at "
                                         f"{achieved:.3f} rad there, not {pitch:.3f}", best.residual)
        return best

    def _solve_with_pitch(self, target: ArmTarget, seed: Sequence[float]) -> tuple[float, ...]:
        """Three pitch joints: the wrist joint to the point behind the target, the wrist takes the rest."""
        assert target.pitch is not None
        heading = math.atan2(target.y - self.pan_origin[1], target.x - self.pan_origin[0])
        along = np.array([math.sin(target.pitch) * math.cos(heading), math.sin(target.pitch) * math.sin(heading),
                          math.cos(target.pitch)])
        wrist = np.array([target.x, target.y, target.z]) - self.tool_length * along
        angles = self._iterate(self.wrist, wrist, seed)
        return (*angles, target.pitch - angles[1] - angles[2])

    def _reach(self, link: int, target: ArmTarget, seed: Sequence[float]) -> tuple[float, ...]:
        return tuple(self._iterate(link, np.array([target.x, target.y, target.z]), seed))

    def _iterate(self, link: int, point: np.ndarray, seed: Sequence[float]) -> list[float]:
        """Pan and the first two pitch angles bringing ``link`` to ``point``, IK re-run from its own answer."""
        self.reset(seed)
        angles = [float(a) for a in seed[:3]]
        for _ in range(30):
            answer = p.calculateInverseKinematics(self.body, link, point.tolist(), maxNumIterations=100,
                                                  residualThreshold=1e-6, physicsClientId=self.client)
            by_joint = dict(zip(self.movable, answer, strict=True))
            angles = [float(by_joint[j]) for j in self.arm[:3]]
            self.reset(angles)
            if np.linalg.norm(self._link(link) - point) < 5e-4:
                break
        # angles differing by whole turns are the same posture: take the one nearest zero
        return [math.remainder(a, 2 * math.pi) for a in angles]

    def _checked(self, solution: tuple[float, ...], target: ArmTarget, tolerance: float) -> Solution:
        """The solution, or why it is none: out of reach (by forward kinematics) or beyond a joint limit."""
        residual = math.dist(self.tool_point(solution), (target.x, target.y, target.z))
        if residual > tolerance:
            return Solution(solution, f"out of reach: the nearest tool point is {residual * 100:.1f} cm away", residual)
        names = ("pan", "shoulder", "elbow", "wrist")
        for name, angle, low, high in zip(names, solution, self.lower, self.upper, strict=False):
            if not low - 1e-6 <= angle <= high + 1e-6:
                return Solution(solution, f"the {name} joint would be at {angle:.3f} rad, outside its limits "
                                          f"[{low:.3f}, {high:.3f}]", residual)
        return Solution(solution, "", residual)

    def close(self) -> None:
        """Disconnect the private client (idempotent)."""
        if self.client >= 0:
            p.disconnect(physicsClientId=self.client)
            self.client = -1
