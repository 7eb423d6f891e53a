"""A camera read in two requests (D246): ``render`` takes the world's state and answers a ticket, the
frame is made while the world runs on, ``frame`` answers it. The frame is of the step it was
ordered at, even when it waited for a busy render worker while the rover drove; bad tickets and
orders are refused naming the channel."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterator
from multiprocessing import Pipe
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import ckmconf
from ckmconf.model import Param
from plugins.hardware.sim import SimBackend
from plugins.sim.devices import SimWorld
from plugins.sim.plan import WorldPlan
from plugins.sim.render import RenderWorker
from plugins.sim.server import WorldServer
from plugins.sim.server_renders import MAX_ORDERS
from plugins.sim.serving import Client as ServedClient
from runtime.kernel.interfaces import ParamError
from tests.plugins.sim.test_server import STARTUP, channel_of
from tests.plugins.sim.test_server import config as config  # the fixture: the shared-world test system

Served = tuple[WorldServer, ServedClient, Connection, list[float]]


@pytest.fixture
def served(config: Path) -> Iterator[Served]:
    """A world server in this process on a clock the test sets, with one render worker and one client."""
    plan = WorldPlan.of(list(ckmconf.load(config).nodes))
    assert plan is not None
    clock = [0.0]
    environment = ckmconf.load(plan.world).environment if plan.world else None  # as the worker's mirror has it
    sim = SimWorld(lambda: clock[0], environment, plan.seed, plan.textures, plan.world)
    for name, (model, pose) in plan.bodies.items():
        sim.robot(name, model, pose)
    worker = RenderWorker(plan)
    server = WorldServer(sim, b"test key", renderers=[worker])
    near, far = Pipe()
    client = ServedClient(1, far)
    server.clients.append(client)
    try:
        assert worker.await_ready(STARTUP)
        yield server, client, near, clock
    finally:
        server.close()
        sim.world.close()


def ask(server: WorldServer, client: ServedClient, **message: Any) -> dict[str, Any] | None:
    return server.handle(client, json.dumps(message).encode())


def test_an_ordered_frame_is_of_the_step_it_was_ordered_at(config: Path, served: Served) -> None:
    server, client, near, clock = served
    wrist = channel_of(config, "wrist")
    small = dataclasses.replace(wrist, name="wrist_small", size=1200, params=tuple(
        Param(name=p.name, value={"width": "40", "height": "30"}.get(p.name, p.value)) for p in wrist.params
    ))  # fmt: skip
    handles = [server._open(client, SimBackend(c).spec()) for c in (wrist, small)]
    motors = [server._open(client, SimBackend(channel_of(config, n)).spec()) for n in ("left_motor", "right_motor")]
    reply = ask(server, client, op="read", handle=handles[1])  # what the small camera sees now, at t = 0
    assert reply is None
    server._dispatch()
    server._landed(server.renderers[0])
    before = near.recv()["value"]
    clock[0] = 0.1  # a later step, the rover still standing: no frame kept for it

    first = ask(server, client, op="render", handle=handles[0])
    second = ask(server, client, op="render", handle=handles[1])  # the worker is busy: it waits, with its state
    assert first is not None and second is not None and first["time"] == second["time"] == pytest.approx(0.1)
    server._dispatch()
    assert len(server._ordered) == 1
    for motor in motors:  # the rover drives towards the camera for a second meanwhile
        assert ask(server, client, op="write", handle=motor, value=1.0) is not None
    clock[0] = 1.5
    state = ask(server, client, op="state")  # the world runs on to 1.5 s
    assert state is not None and state["time"] == pytest.approx(1.5, abs=0.01)
    server._landed(server.renderers[0])
    server._dispatch()  # the second order goes to the worker now, from the state of t = 0
    assert not server._ordered
    assert ask(server, client, op="frame", handle=handles[1], ticket=second["ticket"]) is None  # not made: awaited
    server._landed(server.renderers[0])
    ordered = near.recv()
    assert ordered["time"] == pytest.approx(0.1)
    assert ask(server, client, op="frame", handle=handles[0], ticket=first["ticket"]) is None  # made: sent now
    assert near.recv()["value"].shape == (60, 80)
    assert ask(server, client, op="read", handle=handles[1]) is None  # what it sees at 1.5 s
    server._dispatch()
    server._landed(server.renderers[0])
    now = near.recv()["value"]
    moved = np.abs(now.astype(float) - before).mean()
    assert moved > 5.0  # mm on average: the rover came nearer
    # the ordered frame is of 0.1 s: only the robots settling on the floor (about 1 mm) since 0 s
    assert np.abs(ordered["value"].astype(float) - before).mean() < moved / 4
    assert not client.orders  # every ticket collected is forgotten



def test_bad_orders_and_tickets_are_refused_naming_the_channel(config: Path, served: Served) -> None:
    server, client, _, _ = served
    laser = server._open(client, SimBackend(channel_of(config, "laser")).spec())
    wrist = server._open(client, SimBackend(channel_of(config, "wrist")).spec())
    refused = ask(server, client, op="render", handle=laser)
    assert refused is not None and "sim channel 'laser': 'render' is for a camera channel" in refused["error"]
    for ticket in (99, "1", True, None):
        refused = ask(server, client, op="frame", handle=wrist, ticket=ticket)
        assert refused is not None and f"no render ordered with ticket {ticket!r}" in refused["error"]
    made = ask(server, client, op="render", handle=wrist)
    assert made is not None
    refused = ask(server, client, op="frame", handle=laser, ticket=made["ticket"])  # another channel's ticket
    assert refused is not None and "no render ordered" in refused["error"]
    for _ in range(MAX_ORDERS - 1):
        assert "ticket" in (ask(server, client, op="render", handle=wrist) or {})
    refused = ask(server, client, op="render", handle=wrist)
    assert refused is not None and f"{MAX_ORDERS} renders ordered and not collected" in refused["error"]
    assert ask(server, client, op="close", handle=wrist) == {}
    assert not client.orders  # closing the channel drops its orders
    assert ask(server, client, op="ping") is not None  # and the server serves on


def test_only_a_camera_has_a_latency(config: Path) -> None:
    laser = channel_of(config, "laser")
    slow = dataclasses.replace(laser, params=(*laser.params, Param(name="latency", value="0.1")))
    with pytest.raises(ParamError, match="Param 'latency' is a camera's"):
        SimBackend(slow)
    wrist = channel_of(config, "wrist")
    camera = SimBackend(dataclasses.replace(wrist, params=(*wrist.params, Param(name="latency", value="0.1"))))
    assert camera.latency == 0.1 and SimBackend(wrist).latency == 0.0

def test_renders_of_a_closed_channel_or_a_client_gone_are_not_made(config: Path, served: Served) -> None:
    server, client, _, clock = served
    wrist = channel_of(config, "wrist")
    handle = server._open(client, SimBackend(wrist).spec())
    other = ServedClient(2, Pipe()[1])
    server.clients.append(other)
    theirs = server._open(other, SimBackend(wrist).spec())
    assert ask(server, client, op="render", handle=handle) is not None
    server._dispatch()  # the worker is busy with it
    clock[0] = 0.1
    assert ask(server, client, op="render", handle=handle) is not None
    clock[0] = 0.2
    assert ask(server, other, op="render", handle=theirs) is not None
    assert ask(server, other, op="read", handle=theirs) is None
    assert len(server._ordered) == 2 and len(server._cameras) == 1
    assert ask(server, client, op="close", handle=handle) == {}
    assert [o.device for _, o, _, _ in server._ordered] == [other.devices[theirs]]  # the closed channel's is gone
    server._drop(other, "test")
    assert not server._ordered and not server._cameras
    server._landed(server.renderers[0])  # the render begun before still lands, unread
    server._dispatch()
    assert not server.renderers[0].busy and not client.orders
