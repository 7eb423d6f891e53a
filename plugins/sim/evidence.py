"""What the world server leaves in the run directory, and how it notices its run is gone (issue J
point 5, D171, D190).

``sim-server.json`` (written once listening, atomically), ``sim-final.json`` (at its end: the
simulated time, where every movable body stands, the fired disturbances and the :class:`Trace` of
the robots' true poses, planar and in 3D) and the watch on ckm-run, its parent.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from pathlib import Path
from typing import Any

import pybullet as p

from .devices import SimWorld
from .world import World

TRACE_EVERY = 1.0  # simulated seconds between the samples of the robots' trace


class Trace:
    """The robots' true planar poses (``robots``) and 3D poses (``bodies``: x, y, z, roll, pitch, yaw), and
    the objects' positions and tilts, at the first world step
    at or after every TRACE_EVERY seconds (a world hook). In lock-step the world steps at the same
    simulated instants under any load, so two runs of one configuration leave the same trace (D190)."""

    def __init__(self, sim: SimWorld, every: float = TRACE_EVERY) -> None:
        self.sim, self.every = sim, every
        self.samples: list[dict[str, Any]] = []
        self._next = 0.0
        sim.world.hooks.append(self)

    def __call__(self, world: World) -> None:
        """After the world stepped: a sample if a TRACE_EVERY boundary was passed."""
        if world.time + 1e-9 < self._next:
            return
        while self._next <= world.time + 1e-9:
            self._next += self.every
        robots = {name: [round(v, 6) for v in robot.planar_pose()] for name, robot in self.sim.robots.items()}
        sample = {"steps": world.steps, "time": round(world.time, 6), "robots": robots,
                  "bodies": {name: body_pose(world, robot.body) for name, robot in self.sim.robots.items()}}
        self.samples.append({**sample, "objects": world.object_poses()})  # a carried or knocked object's way


def body_pose(world: World, body: int) -> list[float]:
    """A robot's base in 3D: x, y, z (m) and roll, pitch, yaw (rad) — where a flying or tipped body is,
    which the planar ``robots`` pose does not say (issue N)."""
    position, orientation = world.pose(body)
    return [round(v, 6) for v in (*position, *p.getEulerFromQuaternion(orientation))]


def write_ready(path: Path, ready: dict[str, Any]) -> None:
    """Write the server's address file atomically: a reader never sees half of it."""
    temporary = path.with_suffix(".tmp")
    temporary.write_text(json.dumps(ready))
    temporary.replace(path)


def write_final(ready: Path, final: dict[str, Any]) -> None:
    """The run's evidence of what the robots did to the world (the report reads it): beside ``ready``."""
    ready.with_name(ready.name.replace("sim-server", "sim-final")).write_text(json.dumps(final))


def watch_parent(parent: int, stop: threading.Event, log: logging.Logger) -> None:
    """Set ``stop`` once ``parent`` is no longer this process's parent (ckm-run died)."""
    while not stop.is_set():
        if os.getppid() != parent:
            log.error("parent %d is gone: stopping", parent)
            stop.set()
        stop.wait(0.5)
