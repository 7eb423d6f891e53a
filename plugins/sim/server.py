"""The world server: ONE simulated laboratory for every process of a run (issue J point 5, D100–D103).

``python -m plugins.sim.server CONFIG [--node NAME …] [--ready FILE] [--parent PID]`` builds the
pybullet world the way an in-process ``hardware.sim`` channel does (:class:`WorldPlan`: the
``<Environment>`` of the world file, the seed and textures, every robot at the pose its first
channel gives) and serves device requests on ``127.0.0.1`` (an ephemeral port) to clients that
know the key in ``CKM_SIM_AUTHKEY`` (:mod:`plugins.sim.client`). When listening it writes FILE
(JSON: ``address``, ``pid``, ``world``, ``robots``; never the key).

One thread, the one that built the world, owns the pybullet client and answers every request in
turn (it waits on all connections at once and serves one request of each ready one per round), so
the physics state is never touched concurrently; a thread of its own only accepts connections
(the HMAC handshake). Camera reads are rendered by a render worker process on a mirror of the
world (:mod:`plugins.sim.render`, D103) while this thread goes on serving; ``--render-workers N``
sets how many (default: one per robot with a camera, at most one per core), 0 renders them here.
Before each read or write the world advances, in its fixed steps, to the
server's clock (real time, ``time.monotonic``; started by the first request), as D88 does in
process. A request is a JSON object with ``op``: ``open`` (``spec``: a :class:`Spec`) → ``handle``;
``read``/``write``/``close`` (``handle``; ``value`` to write, a number or a multirotor's list of four,
``"reply": false`` for a silent write,
answered only if it fails); ``render`` → ``ticket`` then ``frame`` (``handle``, ``ticket``) → the
camera's frame of the step it was ordered at (D246); ``state`` (time, steps, robots' true
planar poses); ``ping``. A bad request (malformed, unknown op, handle, body, joint, link) is
answered ``{"error": …, "type": …}`` naming the channel; it never stops the server.
``--scenario FILE`` (default ``$CKM_SIM_SCENARIO``) disturbs the world as the run goes
(:mod:`plugins.sim.disturbances`, D178): each fired event is logged and kept in the run's
``sim-disturbances.json`` and ``sim-final.json``; a bad scenario stops the server at start (exit 1).
"""

from __future__ import annotations

import argparse
import itertools
import json
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection, Listener, Pipe, answer_challenge, deliver_challenge, wait
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from ckmconf import ConfigError, load
from ckmconf.model import System
from runtime import lockstep
from runtime.kernel.interfaces import ParamError

from .client import ENV_KEY, no_delay
from .devices import ChannelDevice, SimWorld, Spec
from .disturbances import ENV_SCENARIO, DisturbedPlan, disturbed, fired, record_into
from .evidence import Trace, body_pose, watch_parent, write_final, write_ready
from .plan import WorldPlan
from .render import RenderWorker
from .scenario import ScenarioError
from .server_renders import RenderDispatch
from .serving import LARGE, Client, Flight

LOG = logging.getLogger("ckm.sim.server")
HOST = "127.0.0.1"
MAX_REQUEST = 1 << 20  # bytes: a request is a small JSON object; anything larger is malformed


class WorldServer(RenderDispatch):
    """Serves ``sim``'s devices to authenticated clients (see the module docstring)."""

    def __init__(
        self, sim: SimWorld, authkey: bytes, host: str = HOST, port: int = 0, renderers: Sequence[RenderWorker] = ()
    ) -> None:
        self.sim = sim
        self.renderers = list(renderers)
        self._cameras: list[tuple[Client, ChannelDevice]] = []  # camera reads waiting for a worker
        self._ordered = []  # renders ordered, waiting for a worker (D246)
        self._tickets = itertools.count(1)
        self._flights: dict[RenderWorker, Flight] = {}
        self._unmirrored: set[tuple[int, int, float, int, int]] = set()  # renders the worker could not make
        self.authkey = authkey
        self.listener = Listener((host, port))  # authenticated per connection, in a thread of its own
        host, port = self.listener.address
        self.address = f"{host}:{port}"
        self.clients: list[Client] = []
        self._pending: list[Connection] = []
        self._lock = threading.Lock()
        self._wake_r, self._wake_w = Pipe(duplex=False)
        self._handles = itertools.count(1)
        self._numbers = itertools.count(1)
        self.requests = 0
        self.errors = 0

    # ------------------------------------------------------------------ connections

    def _accept(self) -> None:
        while True:
            try:
                conn = self.listener.accept()
            except OSError:  # the listener was closed: the server stops
                return
            # the HMAC handshake off the physics thread, and apart: a silent peer blocks no one else
            threading.Thread(target=self._authenticate, args=(conn,), name="ckm-sim-auth", daemon=True).start()

    def _authenticate(self, conn: Connection) -> None:
        no_delay(conn)
        try:
            deliver_challenge(conn, self.authkey)
            answer_challenge(conn, self.authkey)
        except Exception as exc:  # a client without the key, or one that hung up mid-handshake
            LOG.warning("refused a connection: %s: %s", type(exc).__name__, exc)
            conn.close()
            return
        with self._lock:  # several handshakes may end at once: one writer of the wake-up pipe at a time
            self._pending.append(conn)
            self._wake_w.send_bytes(b".")

    def serve(self, stop: threading.Event) -> None:
        """Answer requests until ``stop`` is set (call from the thread that built the world)."""
        threading.Thread(target=self._accept, name="ckm-sim-accept", daemon=True).start()
        while not stop.is_set():
            rendering = {worker.conn: worker for worker in self.renderers if worker.busy}
            ready = wait([self._wake_r, *rendering, *(c.conn for c in self.clients)], timeout=0.2)
            batch: list[tuple[Client, bytes]] = []
            for conn in ready:
                if conn is self._wake_r:
                    self._admit()
                    continue
                if conn in rendering:
                    self._landed(rendering[conn])
                    continue
                client = next(c for c in self.clients if c.conn is conn)
                data = self._receive(client)
                if data is not None:
                    batch.append((client, data))
            # renders last (stable sort): a wheel read waits for at most the render under way (D103)
            batch.sort(key=lambda item: self._renders(*item))
            for client, data in batch:
                reply = self.handle(client, data)
                if reply is not None:  # None: a camera read, answered when its frame is made
                    self._reply(client, reply)
            self._dispatch()

    def _admit(self) -> None:
        while self._wake_r.poll():
            self._wake_r.recv_bytes()
        with self._lock:
            pending, self._pending = self._pending, []
        for conn in pending:
            client = Client(next(self._numbers), conn)
            self.clients.append(client)
            LOG.info("client %d connected", client.number)

    def _drop(self, client: Client, why: str) -> None:
        LOG.info("client %d left (%s), %d channel(s) released", client.number, why, len(client.devices))
        self.clients.remove(client)
        self._withdraw(client)
        client.close()

    def _receive(self, client: Client) -> bytes | None:
        try:
            return client.conn.recv_bytes(MAX_REQUEST)
        except EOFError:  # the client closed its end: the normal way a process of the run leaves
            self._drop(client, "hung up")
            return None
        except OSError as exc:  # a broken connection, or a request over MAX_REQUEST (unreadable after it)
            self._drop(client, f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)
            return None

    def _reply(self, client: Client, reply: dict[str, Any]) -> None:
        if client not in self.clients:
            return
        value = reply.get("value")
        if isinstance(value, np.ndarray) and value.nbytes > LARGE:
            client.later(lambda: reply)
            return
        try:
            client.conn.send(reply)
        except (OSError, ValueError) as exc:
            self._drop(client, f"reply not sent: {exc}")

    def _renders(self, client: Client, data: bytes) -> bool:
        """Whether the request reads a camera (the one costly kind of request)."""
        try:
            message = json.loads(data)
            device = client.devices.get(message.get("handle")) if message.get("op") in ("read", "render") else None
        except (ValueError, AttributeError, TypeError):
            return False
        return device is not None and device.spec.values.get("sensor") in ("rgb", "depth")

    # ------------------------------------------------------------------ requests

    def handle(self, client: Client, data: bytes) -> dict[str, Any] | None:
        """The reply to one request (None: a camera read handed to a render worker, or a silent write
        that succeeded); an error reply for anything wrong, never an exception."""
        self.requests += 1
        name, silent = "", False
        try:
            message = json.loads(data)
            if not isinstance(message, dict):
                raise ValueError("a request is a JSON object with 'op'")
            op = message.get("op")
            silent = op == "write" and message.get("reply") is False  # answered only if it fails
            if op == "open":
                spec = Spec.from_dict(message.get("spec"))
                name = spec.name
                return {"handle": self._open(client, spec)}
            if op == "ping":
                return {"time": self.sim.world.time}
            if op == "state":
                return self._state()
            if op not in ("read", "write", "close", "render", "frame"):
                raise ValueError(f"unknown op {op!r} (open, read, render, frame, write, close, state, ping)")
            handle = message.get("handle")
            device = client.devices.get(handle) if isinstance(handle, int) else None
            if device is None or not isinstance(handle, int):
                raise ValueError(f"no channel open with handle {handle!r} on this connection")
            name = device.spec.name
            if op == "close":
                del client.devices[handle]
                self._withdraw(client, device)
                for ticket in [t for t, o in client.orders.items() if o.device is device]:
                    del client.orders[ticket]  # its renders are not collected: dropped (a made one lands unread)
                return {}
            if op == "render":
                return self._order(client, device)
            if op == "frame":
                return self._collect(client, device, message.get("ticket"))
            if op == "read" and self.renderers and device.camera not in (None, *self._unmirrored):
                self._cameras.append((client, device))
                return None
            with self.sim.lock:
                self.sim.sync()
                if op == "read":
                    return {"value": device.read(), "time": self.sim.world.time}
                value = message.get("value")
                if isinstance(value, list) and value and all(_number(x) for x in value):  # a multirotor's set-point
                    device.write([float(x) for x in value])
                elif isinstance(value, int | float) and _number(value):
                    device.write(float(value))
                else:
                    raise ValueError(f"write needs a number 'value' (or a list of numbers), not {value!r}")
                return None if silent else {"time": self.sim.world.time}
        except Exception as exc:  # every failure is the client's answer, never the server's end
            self.errors += 1
            text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
            if not text.startswith("sim channel"):
                text = f"sim channel {name!r}: {text}" if name else f"world server: bad request: {text}"
            LOG.warning("client %d: %s", client.number, text)
            return {"error": text, "type": type(exc).__name__, **({"silent": True} if silent else {})}

    def _open(self, client: Client, spec: Spec) -> int:
        world = spec.values.get("world")
        if world and world != self.sim.source:
            raise ParamError(f"sim channel {spec.name!r}: Param 'world' names {world}, but the run's simulated "
                             f"world was built from {self.sim.source}")
        with self.sim.lock:
            device = ChannelDevice(self.sim, spec)
        handle = next(self._handles)
        client.devices[handle] = device
        return handle

    def _state(self) -> dict[str, Any]:
        with self.sim.lock:
            self.sim.sync()
            robots = {name: robot.planar_pose() for name, robot in self.sim.robots.items()}
        world = self.sim.world
        return {"time": world.time, "steps": world.steps, "robots": robots, "requests": self.requests}

    def close(self) -> None:
        """Stop listening, end the render workers and drop every client."""
        self.listener.close()
        for worker in self.renderers:
            worker.hang_up()  # all end together
        for worker in self.renderers:
            worker.close()
        for client in list(self.clients):
            self._drop(client, "server stopping")


# ---------------------------------------------------------------------- the process


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def render_workers(plan: WorldPlan) -> int:
    """The default number of render workers: the robots whose cameras may ask for frames at once
    (each robot's colour and depth share one render), bounded by the cores that can render them."""
    return min(len(plan.cameras), os.cpu_count() or 1)


def main(argv: list[str] | None = None) -> int:
    """``python -m plugins.sim.server``: build the world of a configuration and serve its channels (D100)."""
    parser = argparse.ArgumentParser(prog="python -m plugins.sim.server", description=__doc__.split("\n")[0])
    parser.add_argument("config", type=Path, help="the System file whose sim channels shape the world")
    parser.add_argument("--node", action="append", help="only these nodes' channels (default: every node)")
    parser.add_argument("--ready", type=Path, help="write the address here (JSON) once listening")
    parser.add_argument("--parent", type=int, help="stop when this process is no longer the parent")
    parser.add_argument("--port", type=int, default=0, help="TCP port on 127.0.0.1 (default: any free one)")
    parser.add_argument("--render-workers", type=int, default=None,
                        help="render worker processes (default: one per robot with a camera, at most one per core; "
                        "0: render in the physics thread)")
    parser.add_argument("--scenario", default=os.environ.get(ENV_SCENARIO) or None,
                        help=f"disturb the world as this scenario file says (default: ${ENV_SCENARIO})")
    args = parser.parse_args(argv)
    lockstep.observe()  # in lock-step it serves while the run's tasks hold the clock, never holds it (D190)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        key = bytes.fromhex(os.environ.get(ENV_KEY, ""))
    except ValueError:
        key = b""
    if not key:
        print(f"world server: {ENV_KEY} must hold the clients' key in hex", file=sys.stderr)
        return 2
    try:
        system: System = load(args.config)
        nodes = [n for n in system.nodes if args.node is None or n.name in args.node]
        plan = WorldPlan.of(nodes)
        if plan is not None and args.scenario:
            plan = disturbed(plan, args.scenario)
    except (ConfigError, ScenarioError) as error:
        print(error, file=sys.stderr)
        return 1
    if plan is None:
        print(f"{args.config}: no hardware.sim channel: no world to serve", file=sys.stderr)
        return 1
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    started = time.perf_counter()
    count = render_workers(plan) if args.render_workers is None else max(0, args.render_workers)
    workers = [RenderWorker(plan) for _ in range(count)]  # build their mirrors meanwhile
    try:
        sim = plan.build()
    except ScenarioError as error:  # a name the world does not have: said before anyone connects
        print(error, file=sys.stderr)
        for worker in workers:
            worker.close()
        return 1
    if isinstance(plan, DisturbedPlan) and plan.installed is not None:
        plan.installed.on_fire = record_into(args.ready, LOG)
    renderers = [worker for worker in workers if worker.await_ready()]
    if len(renderers) < len(workers):
        LOG.error("%d of %d render workers did not start", len(workers) - len(renderers), len(workers))
    server = WorldServer(sim, key, port=args.port, renderers=renderers)
    trace = Trace(sim)
    LOG.info("world %s with %s built in %.2f s; listening on %s", plan.world, ", ".join(plan.bodies),
             time.perf_counter() - started, server.address)
    if args.parent is not None:
        threading.Thread(target=watch_parent, args=(args.parent, stop, LOG), daemon=True).start()
    if args.ready is not None:
        ready = {"address": server.address, "pid": os.getpid(), "world": plan.world, "robots": list(plan.bodies),
                 "scenario": args.scenario}  # fmt: skip
        write_ready(args.ready, ready)
    try:
        server.serve(stop)
    finally:
        server.close()
        final = {"time": sim.world.time, "positions": sim.world.movable_positions(), "scenario": args.scenario,
                 "bodies": {name: body_pose(sim.world, robot.body) for name, robot in sim.robots.items()},
                 "disturbances": fired(plan), "trace": trace.samples}  # fmt: skip
        if args.ready is not None:
            write_final(args.ready, final)
        LOG.info("stopped after %d requests (%d refused); at %.1f s: %s", server.requests, server.errors,
                 final["time"], final["positions"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
