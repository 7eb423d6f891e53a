"""A point-mass airframe for the flight service's own tests: its velocity follows the set-point with
a first-order lag (an airframe's velocity loop), the floor stops it, a fix reads its position with
noise. The closed loop on the simulator's multirotors is in tests/plugins/sim."""

from __future__ import annotations

import math
import random
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ckmconf.model import Param
from ckmconf.model.resources import Plugin
from plugins.flight.service import FlightControl
from runtime.resources.spt import Context


@dataclass
class PointMass:
    """x, y, z (m), yaw (rad) and the velocity (heading frame) it has; ``lag`` s, ``top`` m/s."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    lag: float = 0.3
    top: float = math.inf
    velocity: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])

    def step(self, command: Mapping[str, Any], dt: float) -> None:
        """Follow the set-point (ahead, left, up, turn) for ``dt`` s."""
        wanted = [command["linear"]["x"], command["linear"]["y"], command["linear"]["z"], command["angular"]["z"]]
        share = 1.0 - math.exp(-dt / self.lag)
        self.velocity = [v + share * (w - v) for v, w in zip(self.velocity, wanted, strict=True)]
        ahead, left, up, turn = (max(-self.top, min(self.top, v)) for v in self.velocity)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        self.x += (c * ahead - s * left) * dt
        self.y += (s * ahead + c * left) * dt
        self.z = max(0.0, self.z + up * dt)
        self.yaw = math.atan2(math.sin(self.yaw + turn * dt), math.cos(self.yaw + turn * dt))


def flight_control(**params: object) -> FlightControl:
    """plugin.flight-control with ``params``."""
    return FlightControl(Plugin(name="flight", kind="flight-control",
                                params=tuple(Param(name=k, value=str(v)) for k, v in params.items())))


class Loop:
    """The service flying the point mass: ``run`` steps both at ``period`` s, a fix every ``fix_every``."""

    def __init__(self, service: FlightControl, body: PointMass, *, noise: float = 0.0, period: float = 0.05,
                 seed: int = 1) -> None:
        self.service, self.body, self.noise, self.period = service, body, noise, period
        self.rng = random.Random(seed)
        self.now, self.frame = 0.0, 0
        self.goal: dict[str, Any] | None = None
        self.fixes = True
        self.out: dict[str, Any] = {}
        self.next_id = 1

    def send(self, action: str, **fields: float | str) -> int:
        """Send a goal with a fresh id; returns it."""
        goal_id, self.next_id = self.next_id, self.next_id + 1
        self.goal = {"id": goal_id, "action": action, **fields}
        return goal_id

    def fix(self) -> dict[str, float]:
        b, n = self.body, self.noise
        return {"x": b.x + self.rng.gauss(0, n), "y": b.y + self.rng.gauss(0, n), "z": b.z + self.rng.gauss(0, n)}

    def run(self, seconds: float, until: str | None = None) -> dict[str, Any]:
        """Step for ``seconds`` (or until the status reads ``until``); the last outputs."""
        end = self.now + seconds
        while self.now < end - 1e-9:
            data: dict[str, Any] = {"goal": self.goal, "heading": self.body.yaw}
            data["position"] = self.fix() if self.fixes else self.out.get("last_fix")
            if self.fixes:
                self.out["last_fix"] = data["position"]
            last_fix = self.out.get("last_fix")
            self.out = {**self.service.process(data, Context(self.frame, self.now)), "last_fix": last_fix}
            if "cmd_vel" in self.out:
                self.body.step(self.out["cmd_vel"], self.period)
            self.now += self.period
            self.frame += 1
            if until is not None and (self.out.get("status") or {}).get("state") == until:
                break
        return self.out
