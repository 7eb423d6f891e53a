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
(the HMAC handshake). Before each read or write the world advances, in its fixed steps, to the
server's clock (real time, ``time.monotonic``; started by the first request), as D88 does in
process. A request is a JSON object with ``op``: ``open`` (``spec``: a :class:`Spec`) → ``handle``;
``read``/``write``/``close`` (``handle``; ``value`` to write); ``state`` (time, steps, robots' true
planar poses); ``ping``. A bad request (malformed, unknown op, handle, body, joint, link) is
answered ``{"error": …, "type": …}`` naming the channel; it never stops the server.
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
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, Listener, Pipe, wait
from pathlib import Path
from types import FrameType
from typing import Any

from ckmconf import ConfigError, load
from ckmconf.model import HWChannel, Node, System
from runtime.kernel.interfaces import ParamError

from .client import ENV_KEY
from .devices import ChannelDevice, SimWorld, Spec

LOG = logging.getLogger("ckm.sim.server")
HOST = "127.0.0.1"
MAX_REQUEST = 1 << 20  # bytes: a request is a small JSON object; anything larger is malformed


@dataclass
class WorldPlan:
    """What the server builds, read from the run's sim channels in document order (D101): the first
    channel naming ``world`` (else the first sim channel) decides the world file, seed and textures;
    each robot is loaded, in the order first named, at the ``pose`` (and ``model``) of the first of
    its channels giving one."""

    world: str
    seed: int
    textures: str
    bodies: dict[str, tuple[str, str]] = field(default_factory=dict)  # name → (model, pose)

    @classmethod
    def of(cls, nodes: list[Node]) -> WorldPlan | None:
        """The plan of ``nodes``' sim channels (None without any); ConfigError located at a channel
        whose Params are wrong or that names another world than the one already chosen."""
        from plugins.hardware.sim import SimBackend  # the backend reads the Params (one code path)

        backends: list[tuple[HWChannel, SimBackend]] = []
        for channel in (ch for node in nodes for ch in node.channels if ch.backend == "sim"):
            try:
                backends.append((channel, SimBackend(channel)))
            except ParamError as exc:
                raise _located(channel, str(exc)) from None
        if not backends:
            return None
        named = [(ch, b) for ch, b in backends if b.values["world"]]
        first_channel, first = named[0] if named else backends[0]
        for channel, backend in named[1:]:
            if backend.world_file != first.world_file:
                raise _located(channel, f"sim channel {channel.name!r}: Param 'world' names {backend.world_file}, "
                                        f"but channel {first_channel.name!r} already chose {first.world_file}: "
                                        "a run has one simulated world")
        plan = cls(first.world_file, int(first.values["seed"]), first._path(first.values["textures"]))
        for _, backend in backends:
            spec = backend.spec().values
            model, pose = plan.bodies.get(spec["body"], ("", ""))
            plan.bodies[spec["body"]] = (model or spec["model"], pose or spec["pose"])
        return plan

    def build(self) -> SimWorld:
        """The world, on real time, with every robot of the plan loaded."""
        environment = load(self.world).environment if self.world else None
        sim = SimWorld(time.monotonic, environment, self.seed, self.textures, self.world)
        for name, (model, pose) in self.bodies.items():
            sim.robot(name, model, pose)
        return sim


def _located(channel: HWChannel, message: str) -> ConfigError:
    loc = channel.loc
    if loc is None:
        return ConfigError("<memory>", 1, 1, "/", message)
    return ConfigError(loc.file, loc.line, loc.column, loc.xpath, message)


@dataclass
class _Client:
    number: int
    conn: Connection
    devices: dict[int, ChannelDevice] = field(default_factory=dict)


class WorldServer:
    """Serves ``sim``'s devices to authenticated clients (see the module docstring)."""

    def __init__(self, sim: SimWorld, authkey: bytes, host: str = HOST, port: int = 0) -> None:
        self.sim = sim
        self.listener = Listener((host, port), authkey=authkey)
        host, port = self.listener.address
        self.address = f"{host}:{port}"
        self.clients: list[_Client] = []
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
                conn = self.listener.accept()  # the HMAC challenge happens here, off the physics thread
            except OSError:  # the listener was closed: the server stops
                return
            except Exception as exc:  # a client without the key, or one that hung up mid-handshake
                LOG.warning("refused a connection: %s: %s", type(exc).__name__, exc)
                continue
            with self._lock:
                self._pending.append(conn)
            self._wake_w.send_bytes(b".")

    def serve(self, stop: threading.Event) -> None:
        """Answer requests until ``stop`` is set (call from the thread that built the world)."""
        threading.Thread(target=self._accept, name="ckm-sim-accept", daemon=True).start()
        while not stop.is_set():
            ready = wait([self._wake_r, *(c.conn for c in self.clients)], timeout=0.2)
            batch: list[tuple[_Client, bytes]] = []
            for conn in ready:
                if conn is self._wake_r:
                    self._admit()
                    continue
                client = next(c for c in self.clients if c.conn is conn)
                data = self._receive(client)
                if data is not None:
                    batch.append((client, data))
            # renders last (stable sort): a wheel read waits for at most the render under way (D103)
            batch.sort(key=lambda item: self._renders(*item))
            for client, data in batch:
                self._reply(client, self.handle(client, data))

    def _admit(self) -> None:
        while self._wake_r.poll():
            self._wake_r.recv_bytes()
        with self._lock:
            pending, self._pending = self._pending, []
        for conn in pending:
            client = _Client(next(self._numbers), conn)
            self.clients.append(client)
            LOG.info("client %d connected", client.number)

    def _drop(self, client: _Client, why: str) -> None:
        LOG.info("client %d left (%s), %d channel(s) released", client.number, why, len(client.devices))
        self.clients.remove(client)
        client.conn.close()

    def _receive(self, client: _Client) -> bytes | None:
        try:
            return client.conn.recv_bytes(MAX_REQUEST)
        except (EOFError, OSError) as exc:  # gone, or a request over MAX_REQUEST (unreadable after it)
            self._drop(client, f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)
            return None

    def _reply(self, client: _Client, reply: dict[str, Any]) -> None:
        if client not in self.clients:
            return
        try:
            client.conn.send(reply)
        except (OSError, ValueError) as exc:
            self._drop(client, f"reply not sent: {exc}")

    def _renders(self, client: _Client, data: bytes) -> bool:
        """Whether the request reads a camera (the one costly kind of request)."""
        try:
            message = json.loads(data)
            device = client.devices.get(message.get("handle")) if message.get("op") == "read" else None
        except (ValueError, AttributeError, TypeError):
            return False
        return device is not None and device.spec.values.get("sensor") in ("rgb", "depth")

    # ------------------------------------------------------------------ requests

    def handle(self, client: _Client, data: bytes) -> dict[str, Any]:
        """The reply to one request; an error reply for anything wrong, never an exception."""
        self.requests += 1
        name = ""
        try:
            message = json.loads(data)
            if not isinstance(message, dict):
                raise ValueError("a request is a JSON object with 'op'")
            op = message.get("op")
            if op == "open":
                spec = Spec.from_dict(message.get("spec"))
                name = spec.name
                return {"handle": self._open(client, spec)}
            if op == "ping":
                return {"time": self.sim.world.time}
            if op == "state":
                return self._state()
            if op not in ("read", "write", "close"):
                raise ValueError(f"unknown op {op!r} (open, read, write, close, state, ping)")
            handle = message.get("handle")
            device = client.devices.get(handle) if isinstance(handle, int) else None
            if device is None or not isinstance(handle, int):
                raise ValueError(f"no channel open with handle {handle!r} on this connection")
            name = device.spec.name
            if op == "close":
                del client.devices[handle]
                return {}
            with self.sim.lock:
                self.sim.sync()
                if op == "read":
                    return {"value": device.read(), "time": self.sim.world.time}
                value = message.get("value")
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ValueError(f"write needs a number 'value', not {value!r}")
                device.write(float(value))
                return {"time": self.sim.world.time}
        except Exception as exc:  # every failure is the client's answer, never the server's end
            self.errors += 1
            text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
            if not text.startswith("sim channel"):
                text = f"sim channel {name!r}: {text}" if name else f"world server: bad request: {text}"
            LOG.warning("client %d: %s", client.number, text)
            return {"error": text, "type": type(exc).__name__}

    def _open(self, client: _Client, spec: Spec) -> int:
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
        self.listener.close()
        for client in list(self.clients):
            self._drop(client, "server stopping")


# ---------------------------------------------------------------------- the process


def _watch_parent(parent: int, stop: threading.Event) -> None:
    while not stop.is_set():
        if os.getppid() != parent:
            LOG.error("parent %d is gone: stopping", parent)
            stop.set()
        stop.wait(0.5)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plugins.sim.server", description=__doc__.split("\n")[0])
    parser.add_argument("config", type=Path, help="the System file whose sim channels shape the world")
    parser.add_argument("--node", action="append", help="only these nodes' channels (default: every node)")
    parser.add_argument("--ready", type=Path, help="write the address here (JSON) once listening")
    parser.add_argument("--parent", type=int, help="stop when this process is no longer the parent")
    parser.add_argument("--port", type=int, default=0, help="TCP port on 127.0.0.1 (default: any free one)")
    args = parser.parse_args(argv)
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
    except ConfigError as error:
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
    sim = plan.build()
    server = WorldServer(sim, key, port=args.port)
    LOG.info("world %s with %s built in %.2f s; listening on %s", plan.world, ", ".join(plan.bodies),
             time.perf_counter() - started, server.address)
    if args.parent is not None:
        threading.Thread(target=_watch_parent, args=(args.parent, stop), daemon=True).start()
    if args.ready is not None:
        record = {"address": server.address, "pid": os.getpid(), "world": plan.world, "robots": list(plan.bodies)}
        temporary = args.ready.with_suffix(".tmp")
        temporary.write_text(json.dumps(record))
        temporary.replace(args.ready)  # atomic: a reader never sees half of it
    try:
        server.serve(stop)
    finally:
        server.close()
        LOG.info("stopped after %d requests (%d refused)", server.requests, server.errors)
    return 0


if __name__ == "__main__":
    sys.exit(main())
