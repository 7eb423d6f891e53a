"""Randomised copies of any configuration for ``ckm-bench mission`` (issue N, thesis §7.5; D162, D301).

Per seed ``k`` the whole configuration directory (its Parts include each other by relative
``href``, its Params name model files relatively) is copied and, in the copy:

- objects: the ``<Environment>`` Objects that ``<Validation><Randomise objects>`` names, else every
  movable one (:func:`benchmarks.mission_placement.movable`: not a marking, its Semantic not a
  landmark), move by up to ±``objectXY`` in x and y and ±``objectYaw`` in yaw, staying on what they
  stand on (its footprint, inset by their radius) or on the floor, and clear of the other objects;
- starts: every mobile robot (:mod:`benchmarks.mission_bodies`: it drives a wheel joint or flies)
  moves by up to ±``startXY`` and ±``startYaw``, the same in every ``sim`` ``<HWChannel>`` of its body
  that gives a ``pose`` Param and in every Smart Resource Param equal to that pose (a localization's
  ``initialPose`` or ``initial_pose``: the operator's estimate, §6.2), staying inside the ``<Area>``
  it starts in, on the pad it starts on and clear of every object and robot by its URDF's base radius
  plus :data:`START_MARGIN`; fixed-base bodies (an arm on a station, the Nao) stay;
- sensor noise: every input ``sim`` channel's ``noise`` Param (its standard deviation; a device
  without one gets its device-table row's ``typical_noise``, if it has one) is scaled by one factor
  drawn per seed, and every ``sim`` channel's ``seed`` Param is set: ``k`` on the channels naming the
  ``world`` (the world's seed, D101), ``1000 k + i`` on the others (their noise streams differ).

The draws come from ``numpy.random.default_rng(k)`` only, objects first, then the noise factor, then
the starts in body order: the same seed gives the same copy. The XML is edited with ElementTree
(namespace ``urn:ckm:1``); comments are not kept. The copy is validated with :func:`ckmconf.load`.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import ckmconf
from benchmarks.mission_bodies import Body, Pose2D, bodies, parse_pose
from benchmarks.mission_placement import footprint_distance, movable, place_objects, place_start
from ckmconf.model import Environment, Randomise
from plugins.sim.device_table import find

__all__ = ["NS", "Jitter", "Q", "Randomised", "footprint_distance", "randomise"]
NS = "urn:ckm:1"
Q = f"{{{NS}}}"
START_MARGIN = 0.025  # m beyond the URDF base's reach: the Kobuki's 0.175 m makes D162's 0.2 m
START_TOLERANCE = 1e-6  # a Param within this of a body's start (each number) is that start


@dataclass(frozen=True)
class Jitter:
    """How far each randomised quantity may move (half-widths of uniform draws; ``<Randomise>``'s attributes)."""

    object_xy: float = 0.03
    object_yaw: float = 0.3
    start_xy: float = 0.15
    start_yaw: float = 0.2
    noise_low: float = 0.5  # the per-seed noise factor is drawn in [low, high] × scale
    noise_high: float = 1.5
    noise_scale: float = 1.0

    @classmethod
    def of(cls, randomise: Randomise | None, noise_scale: float = 1.0) -> Jitter:
        """The jitter a configuration's ``<Randomise>`` asks for (the defaults without one)."""
        if randomise is None:
            return cls(noise_scale=noise_scale)
        return cls(randomise.object_xy, randomise.object_yaw, randomise.start_xy, randomise.start_yaw,
                   noise_scale=noise_scale)  # fmt: skip


@dataclass
class Randomised:
    """A randomised copy: where it is and what moved (for the run's record, its summary line and the tests)."""

    config: Path
    seed: int
    objects: dict[str, Pose2D] = field(default_factory=dict)  # name → x, y, yaw
    starts: dict[str, Pose2D] = field(default_factory=dict)  # body → x, y, yaw
    start_params: list[str] = field(default_factory=list)  # "Resource/plugin/Param" that moved with a start
    kept: dict[str, str] = field(default_factory=dict)  # body → why its start stays
    noise_factor: float = 1.0
    noise: dict[str, float] = field(default_factory=dict)  # node/channel → noise s.d.

    def to_json(self) -> dict[str, object]:
        """What this seed changed, as JSON-ready values."""
        return {
            "seed": self.seed,
            "objects": {k: [round(v, 4) for v in p] for k, p in self.objects.items()},
            "starts": {k: [round(v, 4) for v in p] for k, p in self.starts.items()},
            "start_params": self.start_params,
            "kept": self.kept,
            "noise_factor": round(self.noise_factor, 4),
            "noise": {k: round(v, 6) for k, v in self.noise.items()},
        }

    def describe(self) -> str:
        """One line saying what this seed randomised, naming what it could not (never a silent claim)."""
        objects = ", ".join(self.objects) or "none"
        starts = ", ".join(self.starts) or "none"
        if self.start_params:
            starts += f" (with {', '.join(self.start_params)})"
        kept = "; starts kept: " + ", ".join(f"{b} ({why})" for b, why in self.kept.items()) if self.kept else ""
        noise = f"×{self.noise_factor:.3f} on {len(self.noise)} channels" if self.noise else "none (no noisy sensor)"
        return f"seed {self.seed}: objects moved: {objects}; starts moved: {starts}{kept}; noise {noise}"


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


def params_named(root: ET.Element, owner: str, name: str) -> list[tuple[ET.Element, ET.Element]]:
    """(owner element, Param element) pairs for ``<owner>`` elements with a ``<Param name=name>`` below them."""
    return [
        (element, param)
        for element in root.iter(Q + owner)
        for param in element.iter(Q + "Param")
        if param.get("name") == name
    ]


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


def system_files(config: Path) -> list[Path]:
    """The files of ``config``'s system, sorted: it, the Parts its ``<Include>``s pull in, and the XML files its
    Params name (a ``world`` or an ``environment``), each relative to the file that names it; recursively.
    Other files of the directory (another example beside it) are copied but never edited."""
    found: set[Path] = set()
    todo = [config.resolve()]
    while todo:
        path = todo.pop()
        if path in found or not path.is_file():
            continue
        found.add(path)
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError:
            continue
        named = [e.get("href", "") for e in root.iter(Q + "Include")]
        named += [p.get("value", "") for p in root.iter(Q + "Param") if p.get("value", "").endswith(".xml")]
        todo += [path.parent / name for name in named if name and not Path(name).is_absolute()]
    return sorted(found)


def _same_pose(text: str, pose: Pose2D) -> bool:
    found = parse_pose(text) if len(text.split()) == 3 else None
    return found is not None and all(abs(a - b) <= START_TOLERANCE for a, b in zip(found, pose, strict=True))


def _typical_noise(channel: ET.Element, values: dict[str, str]) -> float:
    device = find(channel.get("kind", ""), channel.get("direction", ""), values)
    return 0.0 if device is None or device.typical_noise is None else device.typical_noise


def _starts(
    robots: list[Body], env: Environment | None, rng: np.random.Generator, jitter: Jitter, result: Randomised
) -> None:
    """Draw the mobile robots' starts into ``result.starts``; say in ``result.kept`` why the others stay."""
    where = {b.name: (b.start[0], b.start[1], b.radius or 0.0) for b in robots if b.start is not None}
    for body in robots:
        if body.start is None:
            result.kept[body.name] = "no 'pose' Param"
        elif not body.mobile:
            result.kept[body.name] = body.why
        elif env is None:
            result.kept[body.name] = "no <Environment> to keep it clear of"
        elif jitter.start_xy == 0 and jitter.start_yaw == 0:
            result.kept[body.name] = "startXY and startYaw are 0"
        elif body.radius is None:
            result.kept[body.name] = "its URDF's root link has no collision to keep clear with"
        else:
            others = {n: w for n, w in where.items() if n != body.name}
            start = place_start(body.name, body.start, env, rng, jitter.start_xy, jitter.start_yaw,
                                body.radius + START_MARGIN, others)  # fmt: skip
            result.starts[body.name] = start
            where[body.name] = (start[0], start[1], body.radius)


def randomise(
    config: Path, seed: int, out_dir: Path, jitter: Jitter | None = None, *, noise_scale: float = 1.0
) -> Randomised:
    """Copy ``config``'s directory to ``out_dir`` and randomise it for ``seed``; what moved, and the copy's file.

    ``jitter`` defaults to what the configuration's ``<Randomise>`` says, with ``noise_scale``.

    Without an ``<Environment>`` no object or start moves (nothing says where they may go); the noise does.

    Raises:
        ValueError: a body's channels disagree on its pose, a named object holds another up, or no draw
            satisfies the constraints; ckmconf.ConfigError: the copy is invalid.
    """
    config = Path(config)
    system = ckmconf.load(config)
    env = system.environment
    declared = None if system.validation is None else system.validation.randomise
    jitter = jitter or Jitter.of(declared, noise_scale)
    robots = bodies(system)
    if out_dir.exists():
        shutil.rmtree(out_dir)
    shutil.copytree(config.parent, out_dir)
    copy = out_dir / config.name
    rng = np.random.default_rng(seed)
    result = Randomised(copy, seed)
    if env is None:
        names: list[str] = []
    elif declared is not None and declared.objects is not None:
        names = list(declared.objects)
    else:
        names = movable(env)
    if env is not None and (jitter.object_xy > 0 or jitter.object_yaw > 0):
        result.objects = place_objects(env, names, rng, jitter.object_xy, jitter.object_yaw)
    result.noise_factor = jitter.noise_scale * float(rng.uniform(jitter.noise_low, jitter.noise_high))
    _starts(robots, env, rng, jitter, result)
    nominal = {b.name: b.start for b in robots if b.name in result.starts and b.start is not None}
    texts = {name: " ".join(_fmt(v) for v in pose) for name, pose in result.starts.items()}
    ET.register_namespace("", NS)
    trees = {path: ET.parse(path) for path in system_files(copy)}
    changed: set[Path] = set()
    index = 0
    for path, tree in trees.items():
        root = tree.getroot()
        for obj in root.iter(Q + "Object"):
            if obj.get("name") in result.objects and (pose := obj.find(Q + "Pose")) is not None:
                for key, value in zip(("x", "y", "yaw"), result.objects[obj.get("name", "")], strict=True):
                    pose.set(key, _fmt(value))
                changed.add(path)
        for node, channel in sim_channels(root):
            values = param_values(channel)
            if values.get("body") in texts and values.get("pose"):
                set_param(channel, "pose", texts[values["body"]])
            set_param(channel, "seed", str(seed if values.get("world") else 1000 * seed + index))
            index += 1
            base = float(values["noise"]) if values.get("noise") else _typical_noise(channel, values)
            if channel.get("direction") == "in" and base > 0:
                result.noise[f"{node.get('name')}/{channel.get('name')}"] = base * result.noise_factor
                set_param(channel, "noise", repr(base * result.noise_factor))
            changed.add(path)
        for resource in root.iter(Q + "SmartResource"):
            for owner in resource.iter():
                for param in owner.findall(Q + "Param"):
                    body = next((b for b, pose in nominal.items() if _same_pose(param.get("value", ""), pose)), None)
                    if body is not None:
                        param.set("value", texts[body])
                        where = [resource.get("name"), owner.get("name") if owner is not resource else None]
                        result.start_params.append("/".join(filter(None, [*where, param.get("name")])))
                        changed.add(path)
    for path in changed:
        trees[path].write(path, encoding="UTF-8", xml_declaration=True)
    ckmconf.load(copy)  # the copy must be a valid configuration before anything runs it
    return result
