"""Where ``ckm-bench mission`` may put an object or a robot's start in a seed's copy (thesis §6.1, D162, D301).

Footprints are the plan view of an ``<Object>``'s geometry (environment.xsd): its circles and
rectangles, a polygon bounded by the circle through its vertices. An object *stands on* the objects
whose footprint holds its pose (a cylinder on the workbench's top); one that stands on none stands
on the floor. Markings (``<Geometry2D height="0">``: a landing pad) are nobody's obstacle. Draws are
rejection-sampled: up to :data:`TRIES` uniform draws, the first that satisfies every constraint wins.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ckmconf.model.environment import Circle, Environment, EnvObject, Geometry2D, Geometry3D, Rectangle

TRIES = 500
Pose2D = tuple[float, float, float]


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
            reach = max(math.hypot(v.x - cx, v.y - cy) for v in base.vertices)
            atoms.append(Circle(x=cx, y=cy, radius=reach))
    return atoms


def is_marking(obj: EnvObject) -> bool:
    """Whether ``obj`` is flat on the floor (``<Geometry2D height="0">``): seen, never hit."""
    return isinstance(obj.geometry, Geometry2D) and obj.geometry.marking


def footprint_distance(obj: EnvObject, x: float, y: float, pose: Pose2D | None = None) -> float:
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


def _within(points: list[tuple[float, float]], x: float, y: float, margin: float) -> bool:
    """(x, y) inside the polygon, at least ``margin`` from its edges."""
    return _inside(points, x, y) and _edge_distance(points, x, y) >= margin


def _clear_of_avoided(env: Environment, x: float, y: float, margin: float) -> bool:
    return all(not _inside(a.points(), x, y) and _edge_distance(a.points(), x, y) >= margin for a in env.avoided)


def _in_map(env: Environment, x: float, y: float, margin: float) -> bool:
    bounds = env.map
    return bounds.xmin + margin <= x <= bounds.xmax - margin and bounds.ymin + margin <= y <= bounds.ymax - margin


def movable(env: Environment) -> list[str]:
    """The objects that move when ``<Randomise objects>`` is not given: every object that is not a
    marking and whose tag's ``<Semantic>`` says ``landmark="free"`` or ``"restricted-area"`` (a landmark,
    or an object whose tag has no Semantic, is furniture the map is built around: it stays)."""
    loose = {s.tag for s in env.semantics if s.landmark in ("free", "restricted-area")}
    return [o.name for o in env.objects if o.tag in loose and not is_marking(o)]


def supports_of(obj: EnvObject, env: Environment) -> list[EnvObject]:
    """The objects ``obj`` stands on: those whose footprint holds its pose and that stand lower (or are markings)."""
    return [
        o
        for o in env.objects
        if o.name != obj.name
        and (o.pose.z < obj.pose.z or is_marking(o))
        and footprint_distance(o, obj.pose.x, obj.pose.y) < 0
    ]


def place_objects(
    env: Environment, names: list[str], rng: np.random.Generator, xy: float, yaw: float
) -> dict[str, Pose2D]:
    """New poses of the objects ``names``, in that order: each within ±``xy`` m and ±``yaw`` rad of its own,
    its footprint (inset by its radius) on what it stands on, or on the floor inside the map, clear of the
    avoided areas and inside its ``area``; 5 mm clear of every other object as already placed.

    Raises:
        ValueError: an unknown name, an object holding another one up, or no draw satisfies the constraints.
    """
    objects = {o.name: o for o in env.objects}
    placed: dict[str, Pose2D] = {}
    for name in names:
        obj = objects.get(name)
        if obj is None:
            raise ValueError(f"the environment has no <Object name={name!r}> to move")
        held = [o.name for o in env.objects if obj in supports_of(o, env)]
        if held:
            raise ValueError(f"object {name!r} holds {', '.join(held)} up: moving it would leave them in the air")
        supports = supports_of(obj, env)
        own = radius(obj)
        area = next((a.points() for a in env.areas if a.name == obj.area), None)
        others = [o for o in env.objects if o.name != name and o not in supports and not is_marking(o)]
        for _ in range(TRIES):
            x = obj.pose.x + rng.uniform(-xy, xy)
            y = obj.pose.y + rng.uniform(-xy, xy)
            turned = obj.pose.yaw + rng.uniform(-yaw, yaw)
            on_support = all(footprint_distance(s, x, y) <= -own for s in supports)
            on_floor = bool(supports) or (_in_map(env, x, y, own) and _clear_of_avoided(env, x, y, own))
            in_area = area is None or _within(area, x, y, own)
            clear = all(footprint_distance(o, x, y, placed.get(o.name)) > own + 0.005 for o in others)
            if on_support and on_floor and in_area and clear:
                placed[name] = (x, y, turned)
                break
        else:
            under = "on " + ", ".join(s.name for s in supports) if supports else "on the floor"
            raise ValueError(f"no pose of {name} within ±{xy} m stays {under} and clear of the others")
    return placed


def place_start(
    body: str,
    nominal: Pose2D,
    env: Environment,
    rng: np.random.Generator,
    xy: float,
    yaw: float,
    clearance: float,
    others: Mapping[str, tuple[float, float, float]],
) -> Pose2D:
    """A start within ±``xy`` m and ±``yaw`` rad of ``nominal``: inside the ``<Area>`` holding ``nominal`` (if
    one does) and the map, ``clearance`` m from their edges, every object that is not a marking and the
    avoided areas; on the marking (a pad) it starts on, if any; and clear of the ``others`` robots
    (name → x, y, radius) by ``clearance`` plus their radius.

    Raises:
        ValueError: no draw satisfies the constraints.
    """
    x0, y0, yaw0 = nominal
    area = next((a.points() for a in env.areas if _inside(a.points(), x0, y0)), None)
    pads = [o for o in env.objects if is_marking(o) and footprint_distance(o, x0, y0) < 0]
    solid = [o for o in env.objects if not is_marking(o)]
    for _ in range(TRIES):
        x = x0 + rng.uniform(-xy, xy)
        y = y0 + rng.uniform(-xy, xy)
        heading = yaw0 + rng.uniform(-yaw, yaw)
        in_area = area is None or _within(area, x, y, clearance)
        on_pad = all(footprint_distance(p, x, y) < 0 for p in pads)
        clear = all(footprint_distance(o, x, y) >= clearance for o in solid)
        apart = all(math.hypot(x - ox, y - oy) >= clearance + r for ox, oy, r in others.values())
        free = _in_map(env, x, y, clearance) and _clear_of_avoided(env, x, y, clearance)
        if in_area and on_pad and clear and apart and free:
            return x, y, heading
    raise ValueError(f"no start of {body} within ±{xy} m of {x0:g} {y0:g} is clear of the objects and robots")
