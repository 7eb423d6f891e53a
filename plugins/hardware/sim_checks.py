"""The checks of a ``hardware.sim`` channel: against the device table (decision D295: its kind,
direction, size, mode and Params as the row of :data:`plugins.sim.device_table.DEVICES` serving it
allows, so the documented table and the checks cannot disagree) and against the rest of its system
(decision D288): its robot's URDF (the model file, the links and joints its Params name; a
multirotor's rotor links and whether its rotors lift its mass, D293) and where the robot is spawned
(inside the map, clear of avoided areas, objects and the other robots). ``SimBackend.problems`` runs
the first always, the others when ``verify`` gives it the system; at run time the world loads the
model anyway.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from difflib import get_close_matches
from functools import lru_cache
from pathlib import Path
from typing import Any

from ckmconf.model import Environment, HWChannel, System
from plugins.environment.geometry import Footprint
from plugins.environment.map_model import BOUNDS, MapModel
from plugins.environment_file import environment_of
from plugins.sim.device_table import find, selector_of, unserved
from plugins.sim.flight import GRAVITY
from plugins.sim.urdf import MODELS, Kinematics

PWM_MODE = (
    "a pwm channel drives its joint by a duty cycle: mode 'velocity' (duty x maxVelocity) "
    "or 'effort' (duty x the joint's effort limit); a position target needs kind 'analog'"
)


def device_problems(channel: HWChannel, v: dict[str, Any], named: dict[str, Any]) -> list[tuple[str | None, Any, str]]:
    """What the device table refuses in the channel (its Params read as ``v``, given as ``named``), as
    ``(the Param it is about or None, the Param or the channel, message)``: no row for its kind,
    direction and device, a size the device cannot give, a ``mode`` it does not take, a Param it does
    not read, a Param it requires left out."""
    if not selector_of(v):
        return []  # SimBackend.problems asks for 'sensor' or 'joint'/'joints'
    device = find(channel.kind, channel.direction, v)
    if device is None:
        return [(None, channel, unserved(channel.kind, channel.direction, v))]
    found: list[tuple[str | None, Any, str]] = []
    expected = device.size.count(v)
    if expected is not None and channel.size != expected:
        gives = f"{expected} value{'' if expected == 1 else 's'}"
        found.append((None, channel, f"size is {channel.size}, its {device.name} device gives {gives}"))
    if "mode" in named and v["mode"] not in device.modes:
        if channel.kind == "pwm":
            message = PWM_MODE
        elif device.modes:
            takes = ", ".join(device.modes)
            message = f"Param 'mode' is {v['mode']!r}: the {device.name} device ({device.where}) takes {takes}"
        else:
            message = f"Param 'mode' chooses a joint quantity: the {device.name} device ({device.where}) takes none"
        found.append(("mode", named["mode"], message))
    for name, param in named.items():
        if name not in device.params:
            found.append(
                (
                    name,
                    param,
                    f"Param {name!r} is not read by the {device.name} device ({device.where}), "
                    f"which reads {', '.join(p for p in device.params if p != 'body')}",
                )
            )
    for name in device.required:
        if name not in named:
            found.append((name, channel, f"the {device.name} device ({device.where}) needs Param {name!r}"))
    return found


def system_problems(
    channel: HWChannel, v: dict[str, Any], named: dict[str, Any], system: System
) -> list[tuple[Any, str]]:
    """What is wrong with the channel (its Params read as ``v``, given as ``named``) in ``system``."""
    found: list[tuple[Any, str]] = []
    if v["body"]:  # a body's model may be named by another of its channels
        found.extend(_model_problems(channel, v, named, system))
    if v["pose"]:
        world = _world_of(channel, v, system)
        if world is not None:
            found.extend(_spawn_problems(v["pose"], named["pose"], world))
        if v["body"]:
            found.extend(_overlap_problems(channel, v, named["pose"], system))
    return found


def _model_file(channel: HWChannel, v: dict[str, Any], system: System) -> tuple[Path, HWChannel]:
    """The URDF a channel's robot is loaded from, and the channel that says so: Param ``model`` (relative
    to its channel's file) of this channel or of another channel of the same body, else the shipped
    ``plugins/sim/models/<body>.urdf``."""
    giver, model_text = channel, v["model"]
    if not model_text:
        for other in (c for n in system.nodes for c in n.channels if c.backend == "sim"):
            values = {p.name: p.value for p in other.params}
            if values.get("body") == v["body"] and values.get("model"):
                giver, model_text = other, values["model"]
                break
    if not model_text:
        return MODELS / f"{v['body']}.urdf", channel
    model = Path(model_text)
    if model.is_absolute() or giver.loc is None:
        return model, giver
    return Path(giver.loc.file).parent / model, giver


@lru_cache(maxsize=32)
def _model(path: str, mtime: float) -> Kinematics:
    return Kinematics(path)


def _model_problems(
    channel: HWChannel, v: dict[str, Any], named: dict[str, Any], system: System
) -> list[tuple[Any, str]]:
    """The robot model a channel names that does not exist, and the links and joints its Params name
    that the model does not have (each at its Param, offering the nearest names)."""
    path, giver = _model_file(channel, v, system)
    if giver is not channel and not path.is_file():  # the other channel reports its own model
        return []
    where = named.get("model") or named.get("body") or channel
    if not path.is_file():
        shipped = ", ".join(sorted(m.stem for m in MODELS.glob("*.urdf")))
        also = f"; the shipped models: {shipped}" if giver is channel and not v["model"] else ""
        return [
            (
                where,
                f"robot model {str(path)!r} does not exist (give Param 'model', a URDF relative to this file{also})",
            )
        ]
    try:
        model = _model(str(path), path.stat().st_mtime)
    except (ValueError, OSError) as error:
        return [(where, f"robot model {path.name} cannot be read: {error}")]
    found: list[tuple[Any, str]] = []

    def unknown(param: str, name: str, choices: Sequence[str], what: str) -> None:
        near = get_close_matches(name, choices, n=3)
        hint = f"; did you mean {', '.join(near)}?" if near else f" (its {what}s: {', '.join(choices)})"
        found.append(
            (named.get(param, channel), f"Param {param!r}: the model {path.name} has no {what} {name!r}{hint}")
        )

    links, joints = list(model.links), list(model.joints)
    if v["sensor"] and v["link"] not in links:
        unknown("link", v["link"], links, "link")
    if v["grasp"] and v["grasp"] not in links:
        unknown("grasp", v["grasp"], links, "link")
    for param in ("joint", "mirror"):
        if v[param] and v[param] not in joints:
            unknown(param, v[param], joints, "joint")
    for joint in v["joints"].split():
        if joint not in joints:
            unknown("joints", joint, joints, "joint")
    if v["actuator"] == "multirotor":
        rotors = v["rotors"].split()
        for rotor in rotors:
            if rotor not in links:
                unknown("rotors", rotor, links, "link")
        mass = _mass(str(path), path.stat().st_mtime)
        if rotors and v["maxThrust"] is not None and len(rotors) * v["maxThrust"] <= mass * GRAVITY:
            found.append((named.get("maxThrust", channel), f"thrust {len(rotors)} × {v['maxThrust']:g} N cannot lift "
                                                           f"{mass:.3g} kg ({mass * GRAVITY:.1f} N), the mass of "
                                                           f"{path.name}"))
    return found


@lru_cache(maxsize=32)  # keyed by the file's modification time: an edited URDF is read again
def _mass(path: str, mtime: float) -> float:
    """The robot's mass (kg): every link's ``<inertial><mass>`` summed, as the simulator loads it."""
    total = 0.0
    for mass in ET.parse(path).getroot().findall("link/inertial/mass"):
        try:
            total += float(mass.get("value", "0"))
        except ValueError:
            continue
    return total


def _world_of(channel: HWChannel, v: dict[str, Any], system: System) -> Environment | None:
    """The ``<Environment>`` the channel's world is built from: the file its ``world`` Param names
    (relative to the channel's file), else the system's own; None when it cannot be read (reported
    elsewhere) or there is none."""
    if not v["world"]:
        return system.environment
    if channel.loc is None:
        return None
    try:
        return environment_of(Path(channel.loc.file).parent / v["world"], f"sim channel {channel.name!r}")
    except ValueError:
        return None


def _spawn_problems(pose: str, param: Any, environment: Environment) -> list[tuple[Any, str]]:
    """A robot placed outside the map, inside an avoided area (a wall in the simulation) or inside an
    object standing on the floor: it would start stuck, or see nothing but the inside of it."""
    try:
        x, y = (float(v) for v in pose.split()[:2])
    except ValueError:
        return [(param, f"Param 'pose' = {pose!r} is not 'x y yaw' (m, m, rad)")]
    model = _map(environment)
    base = Footprint(radius=0.01, height=0.05)  # the robot's base point, at the floor
    hits = model.collisions(base, x, y)
    if not hits:
        return []
    inside = ", ".join("the map's bounds" if h == BOUNDS else repr(h) for h in hits)
    where = "outside the map" if hits == [BOUNDS] else f"inside {inside}"
    return [(param, f"Param 'pose' places the robot at ({x:g}, {y:g}), {where}: it would start stuck in it")]


@lru_cache(maxsize=4)
def _map(environment: Environment) -> MapModel:
    return MapModel.from_environment(environment)


def robot_model(channel: HWChannel, system: System) -> Path:
    """The URDF the robot of ``channel`` (a ``sim`` HWChannel) is loaded from (see :func:`_model_file`)."""
    values = {p.name: p.value for p in channel.params}
    return _model_file(channel, {"body": values.get("body", ""), "model": values.get("model", "")}, system)[0]


def base_radius(path: Path) -> float | None:
    """How far the robot's root link reaches from its origin in the plane (see :func:`_base_radius`)."""
    return _base_radius(path)


def _base_radius(path: Path) -> float | None:
    """How far the robot's root link reaches from its origin in the plane: the half diagonal of a box
    collision, a cylinder's or sphere's radius (the largest of its collisions); None when it has none."""
    try:
        return _reach(str(path), path.stat().st_mtime)
    except OSError:
        return None


@lru_cache(maxsize=32)  # keyed by the file's modification time: an edited URDF is read again
def _reach(path: str, mtime: float) -> float | None:
    try:
        model = _model(path, mtime)
        root = ET.parse(path).getroot()
    except (ValueError, OSError, ET.ParseError):
        return None
    link = next((e for e in root.findall("link") if e.get("name") == model.root), None)
    reach: list[float] = []
    for geometry in [] if link is None else link.findall("collision/geometry"):
        for shape in geometry:
            try:
                if shape.tag == "box":
                    sx, sy, _ = (float(v) for v in str(shape.get("size")).split())
                    reach.append(math.hypot(sx, sy) / 2)
                elif shape.tag in ("cylinder", "sphere"):
                    reach.append(float(str(shape.get("radius"))))
            except ValueError:
                continue
    return max(reach) if reach else None


def _overlap_problems(channel: HWChannel, v: dict[str, Any], param: Any, system: System) -> list[tuple[Any, str]]:
    """Two robots placed so that their bases overlap (each base as the circle its collision reaches):
    reported once, at the pose of the robot whose name sorts later."""
    try:
        x, y = (float(t) for t in v["pose"].split()[:2])
    except ValueError:
        return []  # the pose itself is reported by _spawn_problems
    mine = _base_radius(_model_file(channel, v, system)[0])
    found: list[tuple[Any, str]] = []
    seen: set[str] = set()
    for other in (c for n in system.nodes for c in n.channels if c.backend == "sim"):
        values = {p.name: p.value for p in other.params}
        body, pose = values.get("body", ""), values.get("pose", "")
        if not body or not pose or body >= v["body"] or body in seen:
            continue
        seen.add(body)
        try:
            ox, oy = (float(t) for t in pose.split()[:2])
        except ValueError:
            continue
        theirs = _base_radius(_model_file(other, {"body": body, "model": values.get("model", "")}, system)[0])
        if mine is None or theirs is None:
            continue
        apart = math.hypot(x - ox, y - oy)
        if apart < mine + theirs:
            found.append(
                (
                    param,
                    f"Param 'pose' places {v['body']!r} {apart:.2f} m from {body!r}: their bases "
                    f"({mine:.2f} m and {theirs:.2f} m from their centres) overlap at spawn",
                )
            )
    return found


def multirotor_problems(v: dict[str, Any], problem: Callable[[str | None, str], None]) -> None:
    """What keeps an ``actuator="multirotor"`` channel from flying beyond what its device row checks
    (kind, direction, size, required Params; D293): 3 rotors or more, one spin of ±1 per rotor."""
    rotors = v["rotors"].split()
    if v["rotors"] and len(rotors) < 3:
        problem("rotors", f"Param 'rotors': a multirotor needs 3 rotor links or more, not {len(rotors)}")
    spins = v["spin"].split()
    if v["spin"] and (not all(s in ("1", "+1", "-1", "1.0", "-1.0") for s in spins) or len(spins) != len(rotors)):
        problem("spin", f"Param 'spin' needs one +1 or -1 per rotor ({len(rotors)} rotors), not {v['spin']!r}")
