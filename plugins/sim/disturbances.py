"""World disturbances applied to the pybullet laboratory (issue K point 3, D178): a parsed
:mod:`plugins.sim.scenario` bound to a :class:`~plugins.sim.world.World` and fired as its physics runs.

:meth:`Disturbances.install` checks every name against the world (a :class:`ScenarioError` at
FILE:LINE:COL), adds the scenario's boxes *parked* far outside the laboratory (so a render worker's
mirror, built from the same plan, holds the same bodies with the same ids, and sees them move:
boxes are dynamic, 30 kg, like the movable objects a snapshot carries) and hooks the world: after
each advance every event not fired yet is tried, in file order, and fires once when all its
conditions hold. A fired event is appended to :attr:`Disturbances.fired` (simulated time, line,
text, where the body ended) and passed to ``on_fire`` (the world server writes the run's
``sim-disturbances.json`` from it and logs it).

Distances are planar: from the first body's base position to a point, or to the axis-aligned
bounding box of the second body's base (the workbench: its top; 0 inside it).

:class:`DisturbedPlan` is a :class:`~plugins.sim.plan.WorldPlan` whose world carries the
scenario: the world server and its render workers build it alike.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pybullet as p

from .devices import SimWorld
from .plan import WorldPlan
from .scenario import Action, Condition, Event, Scenario, ScenarioError, Token, parse, read
from .world import World

BOX_MASS = 30.0
"""kg: an added box stays where it is dropped when a robot brushes it."""
PARK = (-40.0, -40.0)
"""Where added boxes wait and removed bodies go: on the floor, far outside any laboratory map."""
CLEARANCE = 0.002
"""m above the floor a body is set down at (it settles under gravity)."""


@dataclass
class Fired:
    """An event that fired: when (simulated s), its line and text, and where its body ended."""

    time: float
    line: int
    text: str
    body: str
    position: list[float]

    def to_dict(self) -> dict[str, Any]:
        """The record a run keeps (``sim-disturbances.json``)."""
        return {"time": round(self.time, 3), "line": self.line, "event": self.text, "body": self.body,
                "position": [round(v, 4) for v in self.position]}  # fmt: skip


class Disturbances:
    """A scenario bound to one world (see the module docstring)."""

    def __init__(self, scenario: Scenario, on_fire: Callable[[Fired], None] | None = None) -> None:
        self.scenario = scenario
        self.on_fire = on_fire
        self.fired: list[Fired] = []
        self.pending: list[Event] = list(scenario.events)
        self.world: World | None = None
        self.bodies: dict[str, int] = {}
        self.starts: dict[str, tuple[float, ...]] = {}
        self._parked = 0

    # ------------------------------------------------------------------ binding

    def install(self, world: World) -> None:
        """Check the scenario's names against ``world``, park its boxes there and hook its advances."""
        self.world = world
        self.bodies = {**world.objects, **world.robots}
        for event in self.scenario.events:
            action = event.action
            if action.verb == "add":
                if action.body.text in self.bodies:
                    raise self._error(action.body, f"box {action.body.text!r}: the world has a body of that name")
                assert action.size is not None
                self.bodies[action.body.text] = self._box(*action.size)
        # where every body stands as the world is built (a box: parked): ``of start`` measures from there (D209)
        self.starts = {name: tuple(world.pose(body)[0][:2]) for name, body in self.bodies.items()}
        for event in self.scenario.events:  # boxes first: a later line may name an earlier one's box
            for condition in event.conditions:
                for token in (condition.body, condition.place):
                    if token is not None:
                        self._body(token)
            action = event.action
            if action.beside is not None:
                self._body(action.beside)
            if action.verb != "add":
                body = self._body(action.body)
                if p.getDynamicsInfo(body, -1, physicsClientId=world.client)[0] <= 0.0:
                    raise self._error(action.body, f"{action.body.text!r} cannot move (no mass): only objects a "
                                      "robot may pick and added boxes can be moved, dropped or removed")  # fmt: skip
        world.hooks.append(self.check)

    def _error(self, token: Token, message: str) -> ScenarioError:
        return ScenarioError(f"{self.scenario.where(token)}: {message}")

    def _body(self, token: Token) -> int:
        body = self.bodies.get(token.text)
        if body is None:
            known = ", ".join(sorted(self.bodies)) or "none"
            raise self._error(token, f"no body {token.text!r} in the world (bodies: {known})")
        return body

    def _box(self, width: float, depth: float, height: float) -> int:
        assert self.world is not None
        cid = self.world.client
        half = [width / 2, depth / 2, height / 2]
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[0.55, 0.4, 0.25, 1.0], physicsClientId=cid)
        x, y = self._park_spot()
        body = int(p.createMultiBody(BOX_MASS, col, vis, [x, y, height / 2 + CLEARANCE], physicsClientId=cid))
        p.changeDynamics(body, -1, lateralFriction=1.0, physicsClientId=cid)
        return body

    def _park_spot(self) -> tuple[float, float]:
        self._parked += 1
        return PARK[0] - 2.0 * self._parked, PARK[1]

    # ------------------------------------------------------------------ firing

    def check(self, world: World) -> None:
        """Fire every pending event whose conditions all hold now (the world's hook, after each advance)."""
        for event in list(self.pending):
            if all(self._holds(c, world) for c in event.conditions):
                self.pending.remove(event)
                position = self._apply(event.action, world)
                fired = Fired(world.time, event.line, event.text, event.action.body.text, position)
                self.fired.append(fired)
                if self.on_fire is not None:
                    self.on_fire(fired)

    def _holds(self, condition: Condition, world: World) -> bool:
        if condition.body is None:
            return world.time >= condition.value
        x, y = world.pose(self.bodies[condition.body.text])[0][:2]
        point = self.starts[condition.body.text] if condition.from_start else condition.point
        if point is not None:
            distance = math.hypot(x - point[0], y - point[1])
        else:
            assert condition.place is not None
            low, high = p.getAABB(self.bodies[condition.place.text], -1, physicsClientId=world.client)
            distance = math.hypot(max(low[0] - x, 0.0, x - high[0]), max(low[1] - y, 0.0, y - high[1]))
        return distance <= condition.value if condition.relation == "within" else distance > condition.value

    def _apply(self, action: Action, world: World) -> list[float]:
        body = self.bodies[action.body.text]
        cid = world.client
        self._let_go(body, world)
        (x, y, z), orientation = world.pose(body)
        if action.verb in ("move-to", "move-by"):
            dx, dy, *dz = action.numbers
            if action.verb == "move-to":
                target = [dx, dy, dz[0] if dz else z]
            else:
                target = [x + dx, y + dy, z + (dz[0] if dz else 0.0)]
            p.resetBasePositionAndOrientation(body, target, orientation, physicsClientId=cid)
        elif action.verb == "remove":
            self._set_down(body, *self._park_spot(), 0.0, world)
        else:  # drop, add: upright on the floor, at a point of the map or of a body's frame
            tx, ty = action.numbers
            yaw = p.getEulerFromQuaternion(orientation)[2]
            if action.beside is not None:
                (fx, fy, _), frame = world.pose(self.bodies[action.beside.text])
                heading = p.getEulerFromQuaternion(frame)[2]
                tx, ty = fx + math.cos(heading) * tx - math.sin(heading) * ty, fy + math.sin(heading) * tx + \
                    math.cos(heading) * ty  # fmt: skip
                yaw = heading
            self._set_down(body, tx, ty, yaw, world)
        p.resetBaseVelocity(body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=cid)
        return list(world.pose(body)[0])

    @staticmethod
    def _let_go(body: int, world: World) -> None:
        """Remove every constraint holding ``body``: a gripper's grasp (D187) lets go of what a
        disturbance moves. The grasp keeps its stale constraint id until the gripper opens; removing
        it again then only makes pybullet warn."""
        cid = world.client
        count = p.getNumConstraints(physicsClientId=cid)
        for uid in [p.getConstraintUniqueId(i, physicsClientId=cid) for i in range(count)]:
            if p.getConstraintInfo(uid, physicsClientId=cid)[2] == body:  # the held (child) body
                p.removeConstraint(uid, physicsClientId=cid)

    @staticmethod
    def _set_down(body: int, x: float, y: float, yaw: float, world: World) -> None:
        """Stand ``body`` upright on the floor at (x, y), turned ``yaw``."""
        cid = world.client
        upright = p.getQuaternionFromEuler([0.0, 0.0, yaw])
        p.resetBasePositionAndOrientation(body, [x, y, 10.0], upright, physicsClientId=cid)
        low, _ = p.getAABB(body, -1, physicsClientId=cid)
        p.resetBasePositionAndOrientation(body, [x, y, 10.0 - low[2] + CLEARANCE], upright, physicsClientId=cid)


@dataclass
class DisturbedPlan(WorldPlan):
    """A world plan whose world carries a scenario (the world server's and its render workers')."""

    scenario_source: str = ""
    scenario_text: str = ""
    installed: Disturbances | None = field(default=None, compare=False, repr=False)

    @classmethod
    def around(cls, plan: WorldPlan, scenario: Scenario, text: str) -> DisturbedPlan:
        """``plan`` with the scenario parsed from ``text`` (read from ``scenario.source``)."""
        return cls(plan.world, plan.seed, plan.textures, dict(plan.bodies), set(plan.cameras),
                   scenario_source=scenario.source, scenario_text=text)

    def build(self) -> SimWorld:
        """The plan's world, every robot loaded, then the scenario installed (its boxes parked)."""
        sim = super().build()
        self.installed = Disturbances(parse(self.scenario_text, self.scenario_source))
        self.installed.install(sim.world)
        return sim

    def __getstate__(self) -> dict[str, Any]:
        """What a render worker receives: the plan without the server's bound disturbances."""
        return {**self.__dict__, "installed": None}


ENV_SCENARIO = "CKM_SIM_SCENARIO"
"""The scenario file a run's world server applies (``ckm-bench mission --scenario`` sets it)."""


def disturbed(plan: WorldPlan, path: str | Path) -> DisturbedPlan:
    """``plan`` carrying the scenario file ``path``; a :class:`ScenarioError` if it is unreadable or malformed."""
    scenario = read(path)
    return DisturbedPlan.around(plan, scenario, Path(path).read_text())


def fired(plan: WorldPlan) -> list[dict[str, Any]]:
    """The events a plan's world has fired so far (none without a scenario)."""
    if isinstance(plan, DisturbedPlan) and plan.installed is not None:
        return [event.to_dict() for event in plan.installed.fired]
    return []


def record_into(ready: Path | None, log: logging.Logger) -> Callable[[Fired], None]:
    """What a world server does when an event fires: log it and rewrite the run's
    ``sim-disturbances.json`` beside its ``ready`` file (every event fired so far: a killed run keeps them)."""
    path = None if ready is None else ready.with_name(ready.name.replace("sim-server", "sim-disturbances"))
    done: list[dict[str, Any]] = []

    def on_fire(event: Fired) -> None:
        done.append(event.to_dict())
        log.warning("disturbance at %.2f s (scenario line %d): %s; %s now at %s", event.time, event.line, event.text,
                    event.body, [round(v, 3) for v in event.position])  # fmt: skip
        if path is not None:
            temporary = path.with_suffix(".tmp")
            temporary.write_text(json.dumps(done, indent=1))
            temporary.replace(path)

    return on_fire
