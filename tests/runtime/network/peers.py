"""Helpers for the CKMultiPeer tests: peers in this process, peers in other processes, raw clients.

A peer process is ``python -m tests.runtime.network.peers CONFIG_JSON``: one MultiPeerTransport
driven by JSON lines, commands on stdin, replies and events on stdout. The parent side is
:class:`PeerProcess`; :func:`peer_processes` kills every process it made, whatever happens.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import queue
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ckmconf.model import Network
from runtime.network.api import NetworkEvent, Sample, Subscription, TopicQoS
from runtime.network.frames import Authenticator, FrameType, encode
from runtime.network.link import _HELLO_SESSION, PROTOCOL
from runtime.network.pubsub import MultiPeerTransport

REPO = Path(__file__).resolve().parents[3]
KEY = b"ckm-test-group-key-0123456789abcdef"
OTHER_KEY = b"ckm-test-other-key-fedcba9876543210"


def wait_until(predicate: Callable[[], bool], timeout: float, interval: float = 0.005) -> bool:
    """Poll ``predicate`` until it holds or ``timeout`` seconds pass; its last value."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return predicate()
        time.sleep(interval)
    return True


def link_table(transport: MultiPeerTransport) -> dict[int, bool]:
    """The open links of a peer: remote GUID → whether this side initiated it."""
    with transport.peer._lock:
        return {guid: link.outgoing for guid, link in transport.peer.links.items()}


def assert_one_link_per_pair(tables: dict[int, dict[int, bool]]) -> None:
    """Every pair of peers linked, and exactly one side — the lower GUID — initiated the link."""
    guids = set(tables)
    for guid, links in tables.items():
        assert set(links) == guids - {guid}, f"{guid} is linked to {sorted(links)}, not to all of {sorted(guids)}"
        for remote, outgoing in links.items():
            assert outgoing == (guid < remote), f"link {guid}→{remote}: outgoing={outgoing} breaks the mandala"
            assert tables[remote][guid] != outgoing, f"both ends of {guid}↔{remote} claim the same role"


def hello(guid: int, *, key: bytes | None = None, direction: bytes = b"O", name: str = "raw") -> bytes:
    """A HELLO frame as a connecting peer (direction O) or an accepting one (A) sends it."""
    auth = Authenticator(key, _HELLO_SESSION) if key is not None else None
    return encode(FrameType.HELLO, [guid, name, os.urandom(16), PROTOCOL], auth=auth, direction=direction)


def ports_free(first: int, count: int, address: str = "127.0.0.1") -> bool:
    """Whether a peer could bind each of ``count`` ports from ``first`` (as it binds: no SO_REUSEADDR)."""
    for port in range(first, first + count):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            try:
                sock.bind((address, port))
            except OSError:
                return False
    return True


def network_with_free_ports(count: int, **overrides: Any) -> Network:
    """A private network whose first ``count`` ports are free now, for tests that expect exact ports.

    Earlier tests leave TIME_WAIT connections on their ports for a minute, and those block a bind
    without SO_REUSEADDR (see test_a_port_left_in_time_wait_is_reused).
    """
    from tests.runtime.network.conftest import private_network

    for _ in range(100):
        network = private_network(**overrides)
        if ports_free(network.base_port, count):
            return network
    raise AssertionError(f"no range of {count} free ports found")


class RawClient:
    """A plain TCP connection to a peer's port, to speak (or break) the protocol by hand."""

    def __init__(self, port: int, *, host: str = "127.0.0.1", source: str = "127.0.0.1") -> None:
        self.sock = socket.create_connection((host, port), timeout=5.0, source_address=(source, 0))

    def send(self, data: bytes) -> bool:
        """False when the peer has already closed (that is allowed: it may hang up early)."""
        try:
            self.sock.sendall(data)
        except OSError:
            return False
        return True

    def read_until_closed(self, timeout: float) -> tuple[bool, bytes]:
        """(whether the peer closed the connection within ``timeout``, what it sent before)."""
        received = bytearray()
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return False, bytes(received)
            self.sock.settimeout(min(left, 0.2))
            try:
                data = self.sock.recv(65536)
            except TimeoutError:
                continue
            except OSError:  # reset: closed too
                return True, bytes(received)
            if not data:
                return True, bytes(received)
            received += data

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


class Events:
    """Records a transport's events with their arrival time (monotonic clock)."""

    def __init__(self, transport: MultiPeerTransport) -> None:
        self.items: list[tuple[float, NetworkEvent]] = []
        self._changed = threading.Condition()
        transport.on_event(self._record)

    def _record(self, event: NetworkEvent) -> None:
        with self._changed:
            self.items.append((time.monotonic(), event))
            self._changed.notify_all()

    def matching(self, kind: str, peer: int | None = None, since: float = 0.0) -> list[float]:
        with self._changed:
            return [t for t, e in self.items if e.kind == kind and (peer is None or e.peer == peer) and t >= since]

    def wait(self, kind: str, peer: int | None, timeout: float, since: float = 0.0) -> float | None:
        """Monotonic time of the first ``kind`` event about ``peer`` at or after ``since``."""
        with self._changed:
            self._changed.wait_for(lambda: bool(self.matching(kind, peer, since)), timeout)
        found = self.matching(kind, peer, since)
        return found[0] if found else None


class LocalPeers:
    """MultiPeerTransports in this process; every one made is stopped on exit."""

    def __init__(self) -> None:
        self.made: list[MultiPeerTransport] = []

    def add(
        self, network: Network, name: str = "peer", *, key: bytes | None = None, start: bool = True
    ) -> MultiPeerTransport:
        transport = MultiPeerTransport(network, name=name, key=key)
        self.made.append(transport)
        transport.setup()
        if start:
            transport.start()
        return transport

    def __enter__(self) -> LocalPeers:
        return self

    def __exit__(self, *_: object) -> None:
        for transport in reversed(self.made):
            transport.stop()


@contextlib.contextmanager
def linked_pair(
    network: Network, *, key: bytes | None = None, timeout: float = 10.0
) -> Iterator[tuple[MultiPeerTransport, MultiPeerTransport]]:
    """Two started peers in this process, linked to each other: (lower GUID, higher GUID)."""
    with LocalPeers() as peers:
        first, second = peers.add(network, "first", key=key), peers.add(network, "second", key=key)
        low, high = sorted((first, second), key=lambda t: t.guid)
        assert wait_until(lambda: low.guid in high.peer.links and high.guid in low.peer.links, timeout), "no link"
        yield low, high


def exchange(publisher: MultiPeerTransport, subscriber: MultiPeerTransport, topic: str, timeout: float = 10.0) -> bool:
    """Whether a fresh value published on one peer reaches a new subscription on the other."""
    qos = TopicQoS(topic)
    got: list[Any] = []
    token = os.urandom(8).hex()
    subscription = subscriber.subscribe(qos, lambda sample: got.append(sample.value))
    try:
        pub = publisher.publisher(qos)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if token in got:
                return True
            if publisher.wait_for_subscribers(topic, 1, 0.05):
                pub.publish(token)
            wait_until(lambda: token in got, 0.05)
        return token in got
    finally:
        subscription.close()


# ---------------------------------------------------------------------- peers in other processes


def network_settings(network: Network) -> dict[str, Any]:
    return {f.name: getattr(network, f.name) for f in dataclasses.fields(network) if f.name != "zenoh"}


class PeerProcess:
    """A peer in its own OS process (optionally inside a network namespace)."""

    def __init__(
        self,
        network: Network,
        *,
        name: str,
        key: bytes | None = None,
        hold: bool = False,
        netns: str | None = None,
    ) -> None:
        config = {"network": network_settings(network), "name": name, "key": key.hex() if key else None, "hold": hold}
        command = [sys.executable, "-m", "tests.runtime.network.peers", json.dumps(config)]
        if netns is not None:
            command = ["ip", "netns", "exec", netns, *command]
        self.name = name
        self.events: list[dict[str, Any]] = []
        self.stderr: list[str] = []
        self.guid = 0
        self._replies: queue.Queue[dict[str, Any]] = queue.Queue()
        self._next_id = 0
        self.process = subprocess.Popen(
            command,
            cwd=REPO,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        threading.Thread(target=self._read_stdout, daemon=True).start()
        threading.Thread(target=self._read_stderr, daemon=True).start()

    def _read_stdout(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            message = json.loads(line)
            if message["type"] == "event":
                self.events.append(message)
            else:
                self._replies.put(message)

    def _read_stderr(self) -> None:
        assert self.process.stderr is not None
        for line in self.process.stderr:
            self.stderr.append(line)

    def _reply(self, timeout: float) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while True:
            try:
                return self._replies.get(timeout=0.1)
            except queue.Empty:
                if time.monotonic() < deadline and self.process.poll() is None:
                    continue
            time.sleep(0.1)  # let the reader threads drain what the process wrote last
            if not self._replies.empty():
                return self._replies.get()
            raise AssertionError(
                f"peer process {self.name} did not answer within {timeout} s "
                f"(exit code {self.process.poll()}); stderr:\n{''.join(self.stderr[-30:])}"
            ) from None

    def ready(self, timeout: float = 30.0) -> int:
        """Wait for the process to be set up (and started unless held); its GUID."""
        message = self._reply(timeout)
        assert message["type"] == "ready", message
        self.guid = int(message["guid"])
        return self.guid

    def request(self, command: str, timeout: float = 20.0, **arguments: Any) -> dict[str, Any]:
        self._next_id += 1
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps({"cmd": command, "id": self._next_id, **arguments}) + "\n")
        self.process.stdin.flush()
        reply = self._reply(timeout)
        assert reply.get("id") == self._next_id, reply
        return reply

    def post(self, command: str, **arguments: Any) -> None:
        """Send a command without waiting for its reply (collect it with :meth:`collect`)."""
        self._next_id += 1
        assert self.process.stdin is not None
        self.process.stdin.write(json.dumps({"cmd": command, "id": self._next_id, **arguments}) + "\n")
        self.process.stdin.flush()

    def collect(self, timeout: float = 20.0) -> dict[str, Any]:
        reply = self._reply(timeout)
        assert reply.get("id") == self._next_id, reply
        return reply

    def links(self) -> dict[int, bool]:
        return {int(guid): bool(outgoing) for guid, outgoing in self.request("status")["links"]}

    def stop(self, timeout: float = 10.0) -> None:
        """A clean stop (goodbye on discovery), then wait for the process to end."""
        self.request("stop", timeout)
        self.process.wait(timeout)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait(timeout=10)

    def close(self) -> None:
        self.kill()
        for stream in (self.process.stdin, self.process.stdout, self.process.stderr):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()


def settled(processes: list[PeerProcess], count: int, timeout: float = 30.0) -> dict[int, dict[int, bool]]:
    """Wait until every process has ``count`` links and as many TCP connections; their link tables."""
    for process in processes:
        assert process.request("wait_linked", timeout + 10, count=count, wait=timeout)["ok"], (
            f"{process.name} not fully linked"
        )
    tables: dict[int, dict[int, bool]] = {}
    for process in processes:

        def exact(process: PeerProcess = process) -> bool:
            status = process.request("status")
            tables[process.guid] = {int(g): bool(o) for g, o in status["links"]}
            return len(tables[process.guid]) == count and int(status["tcp"]) == count

        assert wait_until(exact, 10, interval=0.05), f"{process.name}: not exactly one TCP connection per link"
    return tables


@contextlib.contextmanager
def peer_processes() -> Iterator[Callable[..., PeerProcess]]:
    """``spawn(network, name=…, key=…, hold=…, netns=…)`` makes peer processes; all are killed at the end."""
    made: list[PeerProcess] = []

    def spawn(network: Network, **options: Any) -> PeerProcess:
        process = PeerProcess(network, **options)
        made.append(process)
        return process

    try:
        yield spawn
    finally:
        for process in made:
            process.close()


# ---------------------------------------------------------------------- the child's side


def established_tcp() -> int:
    """How many TCP connections this process has open (psutil reads this process's namespace)."""
    import psutil

    return sum(1 for c in psutil.Process().net_connections(kind="tcp") if c.status == psutil.CONN_ESTABLISHED)


class _Child:
    def __init__(self, config: dict[str, Any]) -> None:
        network = Network(**config["network"])
        key = bytes.fromhex(config["key"]) if config["key"] else None
        self.transport = MultiPeerTransport(network, name=config["name"], key=key)
        self.subscriptions: dict[str, Subscription] = {}
        self.samples: dict[str, list[Sample]] = {}
        self._out = threading.Lock()
        self.transport.on_event(self._event)

    def emit(self, message: dict[str, Any]) -> None:
        with self._out:
            sys.stdout.write(json.dumps(message) + "\n")
            sys.stdout.flush()

    def _event(self, event: NetworkEvent) -> None:
        self.emit({"type": "event", "kind": event.kind, "peer": event.peer, "detail": event.detail})

    def handle(self, request: dict[str, Any]) -> dict[str, Any]:
        command = request["cmd"]
        peer = self.transport.peer
        if command == "start":
            self.transport.start()
            return {}
        if command == "status":
            discovery = peer._discovery
            assert discovery is not None
            with peer._lock:
                links = [[guid, link.outgoing] for guid, link in peer.links.items()]
            return {
                "guid": peer.guid,
                "links": links,
                "known": sorted(discovery.known),
                "rejected": discovery.rejected,
                "tcp": established_tcp(),
                "offsets": [[guid, peer.clock.offset(guid)] for guid in peer.linked()],
            }
        if command == "wait_linked":
            count = int(request["count"])
            ok = wait_until(lambda: len(peer.linked()) >= count, float(request["wait"]))
            return {"ok": ok, "linked": peer.linked()}
        if command == "subscribe":
            topic = request["topic"]
            self.samples[topic] = []
            self.subscriptions[topic] = self.transport.subscribe(TopicQoS(topic), self.samples[topic].append)
            return {}
        if command == "received":
            topic, count = request["topic"], int(request["count"])
            ok = self.subscriptions[topic].wait(count, float(request["wait"]))
            samples = list(self.samples[topic])
            return {
                "ok": ok,
                "count": len(samples),
                "values": [s.value for s in samples[-10:]],
                "sources": sorted({s.source for s in samples}),
            }
        if command == "publish":
            topic, count = request["topic"], int(request["count"])
            subscribed = self.transport.wait_for_subscribers(topic, int(request["subscribers"]), request["wait"])
            publisher = self.transport.publisher(TopicQoS(topic, reliability=request.get("reliability", "reliable")))
            value = request.get("value")
            sent = sum(publisher.publish(i if value is None else value) for i in range(count))
            return {"subscribed": subscribed, "sent": sent}
        raise ValueError(f"unknown command {command!r}")

    def run(self, hold: bool) -> None:
        self.transport.setup()
        if not hold:
            self.transport.start()
        self.emit({"type": "ready", "guid": self.transport.guid})
        try:
            for line in sys.stdin:
                request = json.loads(line)
                if request["cmd"] == "stop":
                    self.transport.stop()
                    self.emit({"type": "reply", "id": request["id"]})
                    return
                self.emit({"type": "reply", "id": request["id"], **self.handle(request)})
        finally:
            self.transport.stop()


def main() -> None:
    config = json.loads(sys.argv[1])
    _Child(config).run(bool(config["hold"]))


if __name__ == "__main__":
    main()
