"""Randomised copies of the use case's configuration for ``ckm-bench mission`` (issue K point 4, thesis §7.5).

Per seed ``k`` the whole configuration directory (its Parts include each other by relative
``href``, its Params name model files relatively) is copied and, in the copy:

- the interaction objects (``<Object name="cylinder_red_stripes">`` and ``cylinder_blue_dots`` of
  the ``<Environment>``, §7.4.1, Fig. 7.5) move by up to ±3 cm in x and y and ±0.3 rad in yaw,
  staying on the object they stand on (the workbench: its footprint, inset by the object's
  radius) and clear of the other objects;
- the Turtlebot's start pose moves by up to ±0.15 m and ±0.2 rad, consistently in every ``sim``
  ``<HWChannel>`` of its body that gives a ``pose`` Param and in the Navigation resource's
  ``initialPose`` Param (the operator's RViz estimate, §6.2), staying inside the ``<Area>`` it
  starts in and clear of every object's footprint by the robot's radius;
- sensor noise: every input ``sim`` channel's ``noise`` Param (its standard deviation; a lidar
  or wheel encoder without one gets :data:`DEFAULT_NOISE`) is scaled by one factor drawn per seed,
  and every ``sim`` channel's ``seed`` Param is set: ``k`` on the channels naming the ``world``
  (the world's seed, D101), ``1000 k + i`` on the others (their noise streams differ).

The draws come from ``numpy.random.default_rng(k)`` only: the same seed gives the same copy.
The XML is edited with ElementTree (namespace ``urn:ckm:1``); comments are not kept. The copy is
validated with :func:`ckmconf.load` before it is handed out. Decision D162.
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import ckmconf
from ckmconf.model.environment import Circle, Environment, EnvObject, Geometry2D, Geometry3D, Rectangle

NS = "urn:ckm:1"
Q = f"{{{NS}}}"
OBJECTS = ("cylinder_red_stripes", "cylinder_blue_dots")
ROBOT = "turtlebot"
NAVIGATION_PARAM = "initialPose"
ROBOT_RADIUS = 0.2  # the Kobuki base is 0.354 m across; 2 cm of margin
DEFAULT_NOISE = {"lidar": 0.01, "counter": 20.0}  # Hokuyo ±1 cm; ~0.25 % of the top wheel speed in ticks/s
TRIES = 500


@dataclass(frozen=True)
class Jitter:
    """How far each randomised quantity may move (half-widths of uniform draws)."""

    object_xy: float = 0.03
    object_yaw: float = 0.3
    start_xy: float = 0.15
    start_yaw: float = 0.2
    noise_low: float = 0.5  # the per-seed noise factor is drawn in [low, high] × scale
    noise_high: float = 1.5
    noise_scale: float = 1.0


@dataclass
class Randomised:
    """A randomised copy: where it is and what moved (for the run's record and the tests)."""

    config: Path
    seed: int
    objects: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # name → x, y, yaw
    start: tuple[float, float, float] | None = None
    noise_factor: float = 1.0
    noise: dict[str, float] = field(default_factory=dict)  # node/channel → noise s.d.

    def to_json(self) -> dict[str, object]:
        """What this seed changed, as JSON-ready values."""
        return {
            "seed": self.seed,
            "objects": {k: [round(v, 4) for v in p] for k, p in self.objects.items()},
            "start": None if self.start is None else [round(v, 4) for v in self.start],
            "noise_factor": round(self.noise_factor, 4),
            "noise": {k: round(v, 6) for k, v in self.noise.items()},
        }


def _rotate(x: float, y: float, yaw: float) -> tuple[float, float]:
    c, s = math.cos(yaw), math.sin(yaw)
    return c * x - s * y, s * x + c * y


def _atoms(obj: EnvObject) -> list[Circle | Rectangle]:
    """The object's circles and rectangles (polygons are bounded by their vertices' circle)."""
    geometry = obj.geometry
    if isinstance(geometry, Geometry2D):
        bases = list(geometry.atoms)
    elif isinstance(geometry, Geometry3D):
        bases = [p.base for p in geometry.prisms]
    else:
        bases = [geometry.prism.base]
    atoms: list[Circle | Rectangle] = []
    for base in bases:
        if isinstance(base, Circle | Rectangle):
            atoms.append(base)
        else:
            cx = sum(v.x for v in base.vertices) / len(base.vertices)
            cy = sum(v.y for v in base.vertices) / len(base.vertices)
            radius = max(math.hypot(v.x - cx, v.y - cy) for v in base.vertices)
            atoms.append(Circle(x=cx, y=cy, radius=radius))
    return atoms


def footprint_distance(obj: EnvObject, x: float, y: float, pose: tuple[float, float, float] | None = None) -> float:
    """Distance (m) from the point (x, y) to ``obj``'s footprint at ``pose`` (default its own); < 0 inside."""
    ox, oy, oyaw = pose if pose is not None else (obj.pose.x, obj.pose.y, obj.pose.yaw)
    lx, ly = _rotate(x - ox, y - oy, -oyaw)  # the point in the object's frame
    best = math.inf
    for atom in _atoms(obj):
        if isinstance(atom, Circle):
            best = min(best, math.hypot(lx - atom.x, ly - atom.y) - atom.radius)
            continue
        ax, ay = _rotate(lx - atom.x, ly - atom.y, -atom.yaw)
        dx, dy = abs(ax) - atom.width / 2, abs(ay) - atom.depth / 2
        outside = math.hypot(max(dx, 0.0), max(dy, 0.0))
        best = min(best, outside if outside > 0 else max(dx, dy))
    return best


def radius(obj: EnvObject) -> float:
    """The radius of a circle around ``obj``'s pose that holds its footprint."""
    out = 0.0
    for atom in _atoms(obj):
        centre = math.hypot(atom.x, atom.y)
        reach = atom.radius if isinstance(atom, Circle) else math.hypot(atom.width, atom.depth) / 2
        out = max(out, centre + reach)
    return out


def _inside(points: list[tuple[float, float]], x: float, y: float) -> bool:
    inside = False
    for (x1, y1), (x2, y2) in zip(points, points[1:] + points[:1], strict=True):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _edge_distance(points: list[tuple[float, float]], x: float, y: float) -> float:
    best = math.inf
    for (x1, y1), (x2, y2) in zip(points, points[1:] + points[:1], strict=True):
        vx, vy = x2 - x1, y2 - y1
        t = max(0.0, min(1.0, ((x - x1) * vx + (y - y1) * vy) / (vx * vx + vy * vy or 1.0)))
        best = min(best, math.hypot(x - x1 - t * vx, y - y1 - t * vy))
    return best


def params_named(root: ET.Element, owner: str, name: str) -> list[tuple[ET.Element, ET.Element]]:
    """(owner element, Param element) pairs for ``<owner>`` elements with a ``<Param name=name>`` below them."""
    return [
        (element, param)
        for element in root.iter(Q + owner)
        for param in element.iter(Q + "Param")
        if param.get("name") == name
    ]


def param_values(channel: ET.Element) -> dict[str, str]:
    """The ``<Param>`` name → value pairs directly under ``channel``."""
    return {p.get("name", ""): p.get("value", "") for p in channel.findall(Q + "Param")}


def set_param(channel: ET.Element, name: str, value: str) -> None:
    """Set ``channel``'s ``<Param name>`` to ``value``, adding it after the other Params if missing."""
    for param in channel.findall(Q + "Param"):
        if param.get("name") == name:
            param.set("value", value)
            return
    # a new Param goes after the existing ones (the schema wants Params first in a HWChannel)
    params = channel.findall(Q + "Param")
    index = list(channel).index(params[-1]) + 1 if params else 0
    param = ET.Element(Q + "Param", {"name": name, "value": value})
    param.tail = channel[index - 1].tail if index else None
    channel.insert(index, param)


def _fmt(value: float) -> str:
    return f"{value:.4f}".rstrip("0").rstrip(".") if value != 0 else "0"


def sim_channels(root: ET.Element) -> list[tuple[ET.Element, ET.Element]]:
    """(node, channel) for every ``sim`` HWChannel of the document, in document order."""
    return [
        (node, channel)
        for node in root.iter(Q + "Node")
        for channel in node.findall(Q + "HWChannel")
        if channel.get("backend") == "sim"
    ]


def _object_poses(
    env_objects: dict[str, EnvObject], rng: np.random.Generator, jitter: Jitter
) -> dict[str, tuple[float, float, float]]:
    """New poses of :data:`OBJECTS`: jittered, on the object under each, clear of the others."""
    placed: dict[str, tuple[float, float, float]] = {}
    for name in OBJECTS:
        obj = env_objects.get(name)
        if obj is None:
            raise ValueError(f"the environment has no <Object name={name!r}> to move")
        supports = [
            o for o in env_objects.values() if o.name != name and footprint_distance(o, obj.pose.x, obj.pose.y) < 0
        ]
        own = radius(obj)
        for _ in range(TRIES):
            x = obj.pose.x + rng.uniform(-jitter.object_xy, jitter.object_xy)
            y = obj.pose.y + rng.uniform(-jitter.object_xy, jitter.object_xy)
            yaw = obj.pose.yaw + rng.uniform(-jitter.object_yaw, jitter.object_yaw)
            on_support = all(footprint_distance(s, x, y) <= -own for s in supports)
            others = [o for o in env_objects.values() if o.name != name and o not in supports]
            clear = all(footprint_distance(o, x, y, placed.get(o.name)) > own + 0.005 for o in others)
            if on_support and clear:
                placed[name] = (x, y, yaw)
                break
        else:
            raise ValueError(
                f"no pose of {name} within ±{jitter.object_xy} m stays on its table and clear of the others"
            )
    return placed


def _start_pose(
    nominal: tuple[float, float, float], env: Environment, rng: np.random.Generator, jitter: Jitter
) -> tuple[float, float, float]:
    """A jittered start pose inside the Area holding ``nominal``, ``ROBOT_RADIUS`` clear of every object."""
    x0, y0, yaw0 = nominal
    areas = [a.points() for a in env.areas if _inside(a.points(), x0, y0)]
    if not areas:
        raise ValueError(f"the start pose {x0} {y0} is in no <Area> of the environment")
    for _ in range(TRIES):
        x = x0 + rng.uniform(-jitter.start_xy, jitter.start_xy)
        y = y0 + rng.uniform(-jitter.start_xy, jitter.start_xy)
        yaw = yaw0 + rng.uniform(-jitter.start_yaw, jitter.start_yaw)
        in_area = _inside(areas[0], x, y) and _edge_distance(areas[0], x, y) >= ROBOT_RADIUS
        if in_area and all(footprint_distance(o, x, y) >= ROBOT_RADIUS for o in env.objects):
            return x, y, yaw
    raise ValueError(f"no start pose within ±{jitter.start_xy} m of {x0} {y0} is clear of the objects")


def randomise(config: Path, seed: int, out_dir: Path, jitter: Jitter | None = None) -> Randomised:
    """Copy ``config``'s directory to ``out_dir`` and randomise it for ``seed``; the copy's System file.

    Raises:
        ValueError: the configuration lacks what is moved (an object, the robot's pose, an Area
            around it), or no draw satisfies the constraints; ckmconf.ConfigError: the copy is invalid.
    """
    jitter = jitter or Jitter()
    config = Path(config)
    system = ckmconf.load(config)
    env = system.environment
    if env is None:
        raise ValueError(f"{config}: no <Environment> to randomise")
    if out_dir.exists():
        shutil.rmtree(out_dir)
    shutil.copytree(config.parent, out_dir)
    copy = out_dir / config.name
    rng = np.random.default_rng(seed)
    result = Randomised(copy, seed)
    result.objects = _object_poses({o.name: o for o in env.objects}, rng, jitter)
    result.noise_factor = jitter.noise_scale * float(rng.uniform(jitter.noise_low, jitter.noise_high))
    ET.register_namespace("", NS)
    trees = {path: ET.parse(path) for path in sorted(out_dir.glob("*.xml"))}
    nominal = next(
        (
            tuple(float(v) for v in param_values(ch)["pose"].split())
            for tree in trees.values()
            for _, ch in sim_channels(tree.getroot())
            if param_values(ch).get("body") == ROBOT and param_values(ch).get("pose")
        ),
        None,
    )
    if nominal is None or len(nominal) != 3:
        raise ValueError(f"{config}: no sim channel of body {ROBOT!r} gives its 'pose' as 'x y yaw'")
    result.start = _start_pose((nominal[0], nominal[1], nominal[2]), env, rng, jitter)
    start_text = " ".join(_fmt(v) for v in result.start)
    changed: set[Path] = set()
    index = 0
    for path, tree in trees.items():
        root = tree.getroot()
        for obj in root.iter(Q + "Object"):
            if obj.get("name") in result.objects and (pose := obj.find(Q + "Pose")) is not None:
                x, y, yaw = result.objects[obj.get("name", "")]
                for key, value in (("x", x), ("y", y), ("yaw", yaw)):
                    pose.set(key, _fmt(value))
                changed.add(path)
        for node, channel in sim_channels(root):
            values = param_values(channel)
            if values.get("body") == ROBOT and values.get("pose"):
                set_param(channel, "pose", start_text)
            set_param(channel, "seed", str(seed if values.get("world") else 1000 * seed + index))
            index += 1
            base = (
                float(values["noise"])
                if values.get("noise")
                else DEFAULT_NOISE.get(values.get("sensor") or channel.get("kind") or "", 0.0)
            )
            if channel.get("direction") == "in" and base > 0:
                result.noise[f"{node.get('name')}/{channel.get('name')}"] = base * result.noise_factor
                set_param(channel, "noise", repr(base * result.noise_factor))
            changed.add(path)
        for _, param in params_named(root, "SmartResource", NAVIGATION_PARAM):
            param.set("value", start_text)
            changed.add(path)
    for path in changed:
        trees[path].write(path, encoding="UTF-8", xml_declaration=True)
    ckmconf.load(copy)  # the copy must be a valid configuration before anything runs it
    return result
