"""Camera renders off the physics thread of the world server (issue J point 5, decision D103).

A TinyRenderer frame takes 20–150 ms of a core (QVGA–VGA); served in the physics thread it would
hold every other request (a wheel encoder read at 100 Hz) for that long. The server therefore keeps
a render worker: a process (``spawn``) that builds the same world from the same
:class:`~plugins.sim.server.WorldPlan` (so body ids agree, and its objects wear the same texture
skins, D145) and never steps it. For each frame the
server sends a snapshot of every movable body — base pose and joint positions, read in a fraction of
a millisecond — and the camera; the worker sets its mirror to that state, renders, and returns the
:class:`Frame` while the server goes on answering. The frame shows the world at the step it was
asked at, as an in-thread render would. A snapshot the mirror cannot take (a robot the plan did not
load) or a worker that died makes the server render in its own thread again.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

import pybullet as p

from .sensors import Camera, Frame
from .world import World

if TYPE_CHECKING:
    from .plan import WorldPlan

LOG = logging.getLogger("ckm.sim.render")
START_TIMEOUT = 120.0
BodyState = tuple[int, tuple[float, ...], tuple[float, ...], list[float]]
Job = tuple[str, str, float, int, int]  # robot, link, fov, width, height


def snapshot(world: World) -> list[BodyState]:
    """Base pose and joint positions of every body that can move (robots, movable objects)."""
    cid = world.client
    state: list[BodyState] = []
    for index in range(p.getNumBodies(physicsClientId=cid)):
        body = p.getBodyUniqueId(index, physicsClientId=cid)
        joints = p.getNumJoints(body, physicsClientId=cid)
        if joints == 0 and p.getDynamicsInfo(body, -1, physicsClientId=cid)[0] == 0.0:
            continue  # static: the floor, walls, avoided areas, fixed objects never move
        position, orientation = p.getBasePositionAndOrientation(body, physicsClientId=cid)
        angles = [s[0] for s in p.getJointStates(body, range(joints), physicsClientId=cid)] if joints else []
        state.append((body, tuple(position), tuple(orientation), angles))
    return state


def restore(world: World, state: list[BodyState]) -> None:
    """Put the mirror's bodies where the snapshot says."""
    cid = world.client
    for body, position, orientation, angles in state:
        p.resetBasePositionAndOrientation(body, position, orientation, physicsClientId=cid)
        for joint, angle in enumerate(angles):
            p.resetJointState(body, joint, angle, physicsClientId=cid)


def _work(plan: WorldPlan, conn: Connection) -> None:
    """The worker process: build the mirror, then render what it is sent until the pipe closes."""
    sim = plan.build()
    cameras: dict[Job, Camera] = {}
    conn.send(("ready", p.getNumBodies(physicsClientId=sim.world.client)))
    while True:
        try:
            state, job = conn.recv()
        except (EOFError, OSError):  # the server closed the pipe: nothing to keep, end at once
            os._exit(0)  # (an orderly exit tears the mirror world down for seconds)
        try:
            restore(sim.world, state)
            robot, link, fov, width, height = job
            camera = cameras.get(job)
            if camera is None:
                camera = cameras[job] = Camera(sim.robots[robot], link, fov=fov)
            conn.send(("frame", camera.render(width, height)))
        except Exception as exc:  # the server renders this one itself
            conn.send(("error", f"{type(exc).__name__}: {exc}"))


class RenderWorker:
    """The server's handle on its render worker: one frame in flight at a time."""

    def __init__(self, plan: WorldPlan) -> None:
        context = multiprocessing.get_context("spawn")  # never fork a process holding a pybullet client
        self.conn, child = context.Pipe()
        self.process = context.Process(target=_work, args=(plan, child), name="ckm-sim-render", daemon=True)
        self.process.start()
        child.close()
        self.busy = False
        self.bodies = 0

    def await_ready(self, timeout: float = START_TIMEOUT) -> bool:
        """Wait for the mirror to be built; False (and the worker stopped) if it is not."""
        try:
            if self.conn.poll(timeout):
                kind, self.bodies = self.conn.recv()
                return bool(kind == "ready")
        except (EOFError, OSError):
            pass
        self.close()
        return False

    def submit(self, world: World, job: Job, state: list[BodyState] | None = None) -> None:
        """Send the worker ``world``'s movable state (or a ``state`` taken earlier: an ordered render,
        D246) and the render ``job`` (the answer comes with :meth:`result`)."""
        self.conn.send((snapshot(world) if state is None else state, job))
        self.busy = True

    def result(self) -> Frame | str:
        """The frame, or why there is none (then the server renders it itself)."""
        self.busy = False
        try:
            kind, value = self.conn.recv()
        except (EOFError, OSError) as exc:
            return f"the render worker is gone ({type(exc).__name__})"
        return value if kind == "frame" else str(value)

    def alive(self) -> bool:
        """Whether the worker process still runs."""
        return self.process.is_alive()

    def hang_up(self) -> None:
        """Close the pipe: the worker ends (close() then waits for it)."""
        self.conn.close()

    def close(self) -> None:
        """Stop the worker process and close its pipe (bounded wait)."""
        self.hang_up()
        self.process.join(2.0)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(2.0)


def job_of(device: Any) -> Job:
    """The worker's description of a camera channel's render."""
    camera: Camera = device.device
    values = device.spec.values
    return (device.robot.name, values["link"], camera.fov, values["width"], values["height"])
