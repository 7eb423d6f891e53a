"""One behavioural suite for every transport (CKMultiPeer and Zenoh), plus Zenoh's own mapping.

Every wait is bounded; the bounds are generous because these machines are shared and loaded.
Tests assert what arrived, never how fast.
"""

from __future__ import annotations

import dataclasses
import json
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from ckmconf.model import Connect, Listen, Network, Zenoh
from runtime.network import EVENTS_TOPIC, NetworkEvent, Sample, TopicQoS, Transport, open_transport
from runtime.network.api import NetworkError

from .conftest import TRANSPORTS, private_network

TIMEOUT = 30.0
ROOT = Path(__file__).resolve().parents[3]
Make = Callable[..., Transport]


def wait_until(predicate: Callable[[], bool], timeout: float = TIMEOUT) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.005)
    return predicate()


class Events:
    """Collects a transport's events (registered before the peers it should hear exist)."""

    def __init__(self, transport: Transport) -> None:
        self.items: list[NetworkEvent] = []
        self._lock = threading.Lock()
        transport.on_event(self._add)

    def _add(self, event: NetworkEvent) -> None:
        with self._lock:
            self.items.append(event)

    def of(self, kind: str, *, topic: str | None = None, peer: int | None = None) -> list[NetworkEvent]:
        with self._lock:
            return [
                e
                for e in self.items
                if e.kind == kind and (topic is None or e.topic == topic) and (peer is None or e.peer == peer)
            ]


@pytest.fixture(params=TRANSPORTS)
def network(request: pytest.FixtureRequest) -> Network:
    return private_network(request.param)


def pair(transports: Make, network: Network) -> tuple[Transport, Transport]:
    return transports(network, "a"), transports(network, "b")


def test_samples_flow_both_ways(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    to_b, to_a = TopicQoS("/t/to_b"), TopicQoS("/t/to_a")
    at_b, at_a = b.subscribe(to_b), a.subscribe(to_a)
    assert a.wait_for_subscribers(to_b.name, 1, TIMEOUT)
    assert b.wait_for_subscribers(to_a.name, 1, TIMEOUT)
    assert a.publisher(to_b).publish({"x": [1, 2.5, "three"]}) == 1
    assert b.publisher(to_a).publish(b"\x00bytes") == 1
    assert at_b.wait(1, TIMEOUT) and at_a.wait(1, TIMEOUT)
    got_b, got_a = at_b.latest(), at_a.latest()
    assert got_b is not None and got_a is not None
    assert (got_b.topic, got_b.value, got_b.source, got_b.seq) == (to_b.name, {"x": [1, 2.5, "three"]}, a.guid, 1)
    assert (got_a.topic, got_a.value, got_a.source, got_a.seq) == (to_a.name, b"\x00bytes", b.guid, 1)
    assert a.guid != b.guid and 0 < a.guid < 1 << 48


def test_local_subscribers_get_the_object_itself_once(transports: Make, network: Network) -> None:
    a = transports(network, "a")
    qos = TopicQoS("/t/local")
    seen: list[Sample] = []
    a.subscribe(qos, seen.append)
    assert not a.wait_for_subscribers(qos.name, 1, 0.3), "a local subscriber is not a remote one"
    b = transports(network, "b")
    remote = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    value = {"pose": [1.0, 2.0]}
    publisher = a.publisher(qos)
    assert publisher.publish(value) == 1
    assert seen[0].value is value and seen[0].source == a.guid  # delivered before publish() returns
    for i in range(20):
        publisher.publish(i)
    assert remote.wait(21, TIMEOUT)
    latest = remote.latest()
    assert latest is not None and latest.value == 19 and latest.value is not value
    # The remote has everything, so an echo would have come back by now.
    assert [s.value for s in seen] == [value, *range(20)], "local samples must not come back from the network"


def test_late_subscriber_gets_only_later_samples(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    qos = TopicQoS("/t/late", history=10)
    publisher = a.publisher(qos)
    for i in range(5):
        assert publisher.publish(i) == 0
    late = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    for i in range(5, 10):
        publisher.publish(i)
    # Wait for the last sample, not for five: under Zenoh early samples may arrive first (below).
    deadline = time.monotonic() + TIMEOUT
    while (latest := late.latest()) is None or latest.value != 9:
        assert time.monotonic() < deadline, [s.value for s in late.history()]
        time.sleep(0.01)
    values = [s.value for s in late.history()]
    if network.transport == "multipeer":
        # CKMultiPeer sends a sample only to peers known to subscribe when it is published.
        assert values == [5, 6, 7, 8, 9]
        assert [s.seq for s in late.history()] == [6, 7, 8, 9, 10]
    else:
        # Zenoh's put is asynchronous: samples still queued in its batches when the subscriber's
        # declaration arrives may reach it. Every later sample arrives, in order, once.
        assert values[-5:] == [5, 6, 7, 8, 9]
        assert values == sorted(set(values))


def test_history_depth_is_kept(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    qos = TopicQoS("/t/history", history=3)
    subscription = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    for i in range(10):
        publisher.publish(i)
    assert subscription.wait(10, TIMEOUT)
    assert [s.value for s in subscription.history()] == [7, 8, 9]
    latest = subscription.latest()
    assert latest is not None and latest.value == 9


def test_deadline_missed_only_when_the_publisher_is_silent(transports: Make, network: Network) -> None:
    # a stall of 0.2 s on a loaded machine would otherwise declare the peer lost mid-stream (liveliness, not deadline)
    a, b = pair(transports, dataclasses.replace(network, lost_after=100))
    events = Events(b)
    qos = TopicQoS("/t/deadline", deadline=1.0)
    subscription = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    publisher.publish(0)
    assert subscription.wait(1, TIMEOUT)
    before = len(events.of("deadline-missed", topic=qos.name))  # discovery may outlast one deadline
    for i in range(1, 60):  # 1.2 s of samples every 20 ms: never a second without one
        publisher.publish(i)
        time.sleep(0.02)
    assert subscription.wait(60, TIMEOUT), [(e.kind, e.detail) for e in events.items]
    assert len(events.of("deadline-missed", topic=qos.name)) == before
    assert wait_until(lambda: len(events.of("deadline-missed", topic=qos.name)) > before)


def test_lifespan_drops_stale_samples(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    events: list[Sample] = []
    b.subscribe(TopicQoS(EVENTS_TOPIC, history=100), events.append)
    qos = TopicQoS("/t/lifespan", history=10, lifespan=5.0)
    subscription = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    publisher.publish("stale", stamp=time.time() - 60.0)
    publisher.publish("fresh")
    assert subscription.wait(1, TIMEOUT)
    assert [s.value for s in subscription.history()] == ["fresh"]
    stale = [s.value for s in events if s.value.kind == "stale-dropped"]
    assert len(stale) == 1 and stale[0].topic == qos.name and stale[0].peer == a.guid


def test_unsubscribe_stops_delivery(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    qos, marker = TopicQoS("/t/unsub"), TopicQoS("/t/marker")
    subscription, markers = b.subscribe(qos), b.subscribe(marker)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT) and a.wait_for_subscribers(marker.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    publisher.publish(1)
    assert subscription.wait(1, TIMEOUT)
    subscription.close()
    assert wait_until(lambda: not a.wait_for_subscribers(qos.name, 1, 0))
    assert publisher.publish(2) == 0
    a.publisher(marker).publish("after")  # sent after 2 on the same path: once it is here, 2 would be too
    assert markers.wait(1, TIMEOUT)
    assert subscription.received == 1
    again = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher.publish(3)
    assert again.wait(1, TIMEOUT)


def test_peers_found_and_lost(transports: Make, network: Network) -> None:
    a = transports(network, "a")
    events = Events(a)
    b = transports(network, "b")
    assert wait_until(lambda: b.guid in a.peers() and a.guid in b.peers())
    assert wait_until(lambda: bool(events.of("found", peer=b.guid)))
    b.stop()
    b.stop()  # idempotent
    assert wait_until(lambda: bool(events.of("lost", peer=b.guid)))
    assert wait_until(lambda: b.guid not in a.peers())


def test_reliable_samples_arrive_complete_and_in_order(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    qos = TopicQoS("/t/bulk", history=10)
    values: list[int] = []
    subscription = b.subscribe(qos, lambda s: values.append(s.value))
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    for i in range(5000):
        publisher.publish(i)
    assert subscription.wait(5000, 60.0)
    assert values == list(range(5000))


def test_best_effort_samples_flow_in_order(transports: Make, network: Network) -> None:
    a, b = pair(transports, network)
    qos = TopicQoS("/t/best", reliability="best-effort")
    values: list[int] = []
    subscription = b.subscribe(qos, lambda s: values.append(s.value))
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    publisher = a.publisher(qos)
    sent = 0
    deadline = time.monotonic() + TIMEOUT
    while subscription.received < 20 and time.monotonic() < deadline:  # any may be dropped: keep going
        publisher.publish(sent)
        sent += 1
        time.sleep(0.001)
    assert subscription.received >= 20, f"{sent} sent, dropped busy: {getattr(a, 'dropped_busy', '?')}"
    assert values == sorted(values) and len(set(values)) == len(values)  # dropped, never reordered


def spawn(script: str, network: Network) -> subprocess.Popen[bytes]:
    """Run ``script`` under ``python -c`` with the network's settings as its argument."""
    settings = {f.name: getattr(network, f.name) for f in dataclasses.fields(network) if f.name not in ("loc", "zenoh")}
    command = [sys.executable, "-c", script, json.dumps(settings)]
    return subprocess.Popen(command, cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)


CHILD = """
import json, os, sys
from ckmconf.model import Network
from runtime.network import TopicQoS, open_transport

with open_transport(Network(**json.loads(sys.argv[1])), name="child") as transport:
    publisher = transport.publisher(TopicQoS("/proc/data"))
    if not transport.wait_for_subscribers("/proc/data", 1, 60):
        sys.exit(3)
    for i in range(20):
        publisher.publish({"i": i, "pid": os.getpid()})
    print(transport.guid, flush=True)
    sys.stdin.read()  # stay up until the test closes our stdin
"""


@pytest.mark.parametrize("ending", ["clean", "killed"])
def test_a_transport_in_another_process(transports: Make, network: Network, ending: str) -> None:
    a = transports(network, "a")
    events = Events(a)
    qos = TopicQoS("/proc/data", history=20)
    subscription = a.subscribe(qos)
    child = spawn(CHILD, network)
    try:
        arrived = subscription.wait(20, 60.0)
        if ending == "killed":
            child.kill()  # no goodbye: the peer is lost when its heartbeat / lease runs out
        out, err = child.communicate(b"", timeout=60.0)
        assert arrived, err.decode(errors="replace")
        assert child.returncode == (0 if ending == "clean" else -9), err.decode(errors="replace")
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(timeout=10)
    samples = subscription.history()
    assert [s.value["i"] for s in samples] == list(range(20))
    assert {s.value["pid"] for s in samples} == {child.pid}
    source = samples[0].source
    assert {s.source for s in samples} == {source}
    if ending == "clean":
        assert source == int(out.split()[0])
    assert wait_until(lambda: bool(events.of("lost", peer=source)) and source not in a.peers())


FORGETFUL = """
import json, sys
from ckmconf.model import Network
from runtime.network import TopicQoS, open_transport

transport = open_transport(Network(**json.loads(sys.argv[1])))
transport.setup()
transport.start()
transport.subscribe(TopicQoS("/forgotten"), lambda sample: None)
transport.publisher(TopicQoS("/forgotten")).publish(1)
print("leaving without stop()", flush=True)
"""


def test_a_process_that_forgets_stop_still_exits(network: Network) -> None:
    child = spawn(FORGETFUL, network)
    try:
        out, err = child.communicate(timeout=60.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(timeout=10)
    assert child.returncode == 0, err.decode(errors="replace")
    assert out == b"leaving without stop()\n"


# ---------------------------------------------------------------------- Zenoh only


def test_zenoh_key_expressions() -> None:
    from runtime.network.zenoh_session import key_expr

    assert key_expr("/a/b") == "ckm/a/b"
    assert key_expr("a/b") == "ckm/a/b"
    assert key_expr("/ckm/events") == "ckm/ckm/events"
    for bad in ("/", "/a//b", "/a/*", "/a/**", "/@peer/1", "/a/$x", "/a?b"):
        with pytest.raises(ValueError, match="cannot be a Zenoh key expression"):
            key_expr(bad)


def test_zenoh_refuses_a_group_key() -> None:
    with pytest.raises(ValueError, match="configure TLS or user-password authentication in Zenoh instead"):
        open_transport(private_network("zenoh"), key=b"0123456789abcdef")


def test_zenoh_config_follows_the_network() -> None:
    from runtime.network.zenoh_session import zenoh_config

    network = private_network("zenoh")
    config = zenoh_config(network)
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("scouting/multicast/enabled")) is True
    assert json.loads(config.get_json("scouting/multicast/address")) == f"{network.group}:{network.discovery_port}"
    assert json.loads(config.get_json("scouting/multicast/interface")) == "127.0.0.1"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    assert json.loads(config.get_json("transport/link/tx/lease")) == 1000  # 0.05 s × 4, raised to the floor
    client = private_network(
        "zenoh",
        heartbeat=0.5,
        lost_after=5,
        zenoh=Zenoh(mode="client", multicast_scouting=False, connect=(Connect(endpoint="tcp/127.0.0.1:7447"),)),
    )
    config = zenoh_config(client)
    assert json.loads(config.get_json("mode")) == "client"
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(config.get_json("listen/endpoints")) == []
    assert json.loads(config.get_json("transport/link/tx/lease")) == 2500
    assert json.loads(config.get_json("transport/link/tx/keep_alive")) == 5


def test_zenoh_reports_what_keeps_it_from_starting() -> None:
    bad = private_network("zenoh", zenoh=Zenoh(listen=(Listen(endpoint="no-protocol"),)))
    expected = "invalid Zenoh setting listen/endpoints = ['no-protocol']: Endpoints must be of the form <protocol>/"
    with pytest.raises(NetworkError, match=re.escape(expected)):
        open_transport(bad).setup()
    lonely = private_network(
        "zenoh", zenoh=Zenoh(mode="client", multicast_scouting=False, connect=(Connect(endpoint="tcp/127.0.0.1:9"),))
    )
    transport = open_transport(lonely)
    try:
        with pytest.raises(NetworkError, match=r"cannot open the Zenoh session: Unable to connect to any of"):
            transport.setup()
    finally:
        transport.stop()


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def test_zenoh_clients_through_a_router(transports: Make) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = private_network(
        "zenoh", zenoh=Zenoh(mode="router", multicast_scouting=False, listen=(Listen(endpoint=endpoint),))
    )
    client = dataclasses.replace(
        router, zenoh=Zenoh(mode="client", multicast_scouting=False, connect=(Connect(endpoint=endpoint),))
    )
    transports(router, "router")
    a, b = transports(client, "a"), transports(client, "b")
    qos = TopicQoS("/t/routed")
    subscription = b.subscribe(qos)
    assert a.wait_for_subscribers(qos.name, 1, TIMEOUT)
    assert wait_until(lambda: b.guid in a.peers())
    a.publisher(qos).publish("via the router")
    assert subscription.wait(1, TIMEOUT)
    latest = subscription.latest()
    assert latest is not None and (latest.value, latest.source) == ("via the router", a.guid)
