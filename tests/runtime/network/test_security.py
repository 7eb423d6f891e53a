"""The group key (issue 3, item 8): key holders link and talk; anyone else can neither join nor
publish, and captured traffic — discovery datagrams or link frames — is useless when replayed.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import struct
import threading
import time
from collections.abc import Iterator

import msgpack
import pytest

from ckmconf.model import Network
from runtime.network.api import TopicQoS
from runtime.network.frames import AUTH, FLAG_AUTH, MAC_SIZE, PROLOGUE, FrameType
from runtime.network.guid import make_guid
from runtime.network.pubsub import MultiPeerTransport
from tests.runtime.network.conftest import private_network
from tests.runtime.network.peers import (
    KEY,
    OTHER_KEY,
    Events,
    LocalPeers,
    RawClient,
    exchange,
    hello,
    link_table,
    linked_pair,
    peer_processes,
    wait_until,
)


def rejected(transport: MultiPeerTransport) -> int:
    discovery = transport.peer._discovery
    assert discovery is not None
    return discovery.rejected


def known(transport: MultiPeerTransport) -> set[int]:
    discovery = transport.peer._discovery
    assert discovery is not None
    return set(discovery.known)


def test_key_holders_in_two_processes_link_and_exchange() -> None:
    network = private_network()
    with peer_processes() as spawn, LocalPeers() as local:
        remote = spawn(network, name="remote", key=KEY)
        remote.ready()
        peer = local.add(network, "local", key=KEY)
        assert wait_until(lambda: remote.guid in peer.peer.links, 10)
        remote.request("subscribe", topic="/keyed")
        assert peer.wait_for_subscribers("/keyed", 1, 10)
        peer.publisher(TopicQoS("/keyed")).publish({"secret": 42})
        reply = remote.request("received", topic="/keyed", count=1, wait=10.0)
        assert reply["ok"] and reply["values"] == [{"secret": 42}]
        assert rejected(peer) == 0


def test_peers_without_the_key_or_with_another_never_join_nor_publish() -> None:
    network = private_network()
    with LocalPeers() as peers:
        insiders = [peers.add(network, f"insider{i}", key=KEY) for i in range(2)]
        keyless = peers.add(network, "keyless")
        stranger = peers.add(network, "stranger", key=OTHER_KEY)
        outsiders = [keyless, stranger]
        got: list[object] = []
        for insider in insiders:
            insider.subscribe(TopicQoS("/orders"), lambda sample: got.append(sample.value))
        outsider_got: list[object] = []
        for outsider in outsiders:
            outsider.subscribe(TopicQoS("/news"), lambda sample: outsider_got.append(sample.value))
        assert wait_until(lambda: insiders[1].guid in insiders[0].peer.links, 10)
        assert exchange(insiders[0], insiders[1], "/among-insiders")

        deadline = time.monotonic() + 1.0  # 20 heartbeats of everyone
        while time.monotonic() < deadline:
            for outsider in outsiders:
                outsider.publisher(TopicQoS("/orders")).publish("forged order")
            insiders[0].publisher(TopicQoS("/news")).publish("for key holders only")
            time.sleep(0.05)
        insider_guids = {t.guid for t in insiders}
        for insider in insiders:
            assert set(link_table(insider)) == insider_guids - {insider.guid}
            assert not known(insider) & {o.guid for o in outsiders}
            assert rejected(insider) >= 10, "the outsiders' datagrams were not counted as rejected"
        for outsider in outsiders:
            assert not outsider.peer.links and not known(outsider) & insider_guids
            assert rejected(outsider) >= 10
        assert got == [] and outsider_got == []
        assert not insiders[0].wait_for_subscribers("/news", 1, 0.1)


@pytest.mark.parametrize("key", [None, OTHER_KEY], ids=["keyless", "other-key"])
def test_a_raw_hello_without_the_key_is_refused(key: bytes | None, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="ckm.link")
    with linked_pair(private_network(), key=KEY) as (low, high):
        fake = make_guid("127.0.0.1", 1)  # below everyone
        client = RawClient(high.guid & 0xFFFF)
        try:
            client.send(hello(fake, key=key))
            client.send(b"".join(hello(fake, key=key) for _ in range(3)))
            assert client.read_until_closed(5)[0]
        finally:
            client.close()
        reason = "unauthenticated" if key is None else "bad MAC"
        assert wait_until(lambda: reason in caplog.text, 5), caplog.text
        assert fake not in high.peer.links
        assert link_table(high) == {low.guid: False}
        assert exchange(low, high, "/still-keyed")


# ---------------------------------------------------------------------- replayed discovery datagrams


class Capture:
    """A socket in the discovery group that records every datagram and can send any back."""

    def __init__(self, network: Network) -> None:
        self.network = network
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        sock.bind(("", network.discovery_port))
        membership = socket.inet_aton(network.group) + socket.inet_aton("127.0.0.1")
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        sock.settimeout(0.05)
        self.sock = sock
        self.datagrams: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.datagrams.append(self.sock.recv(2048))
            except TimeoutError:
                continue
            except OSError:
                return

    def from_peer(self, guid: int, kind: str | None = None) -> list[bytes]:
        """The captured datagrams a keyed peer sent (the MAC is the last 32 bytes)."""
        found = []
        for datagram in list(self.datagrams):
            with contextlib.suppress(ValueError, msgpack.UnpackException):
                fields = msgpack.unpackb(datagram[:-MAC_SIZE], raw=False)
                if fields[3] == guid and (kind is None or fields[2] == kind):
                    found.append(datagram)
        return found

    def replay(self, datagrams: list[bytes]) -> None:
        for datagram in datagrams:
            self.sock.sendto(datagram, (self.network.group, self.network.discovery_port))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.sock.close()


@pytest.fixture
def capture_network() -> Iterator[tuple[Network, Capture]]:
    network = private_network()
    capture = Capture(network)
    try:
        yield network, capture
    finally:
        capture.close()


def test_replayed_discovery_datagrams_are_ignored_and_counted(capture_network: tuple[Network, Capture]) -> None:
    network, capture = capture_network
    with linked_pair(network, key=KEY) as (low, high):
        events = Events(low)
        assert wait_until(lambda: len(capture.from_peer(high.guid)) >= 6, 10)
        replays = capture.from_peer(high.guid)
        tampered = bytearray(replays[-1])
        tampered[-40] ^= 0x01  # inside the signed body
        before, since = rejected(low), time.monotonic()
        capture.replay([*replays, bytes(tampered)])
        assert wait_until(lambda: rejected(low) >= before + len(replays) + 1, 5)
        time.sleep(0.2)
        assert rejected(low) == before + len(replays) + 1
        assert not [e for t, e in events.items if t >= since and e.peer == high.guid], "a replay caused events"
        assert link_table(low) == {high.guid: True}


def test_replayed_datagrams_do_not_resurrect_a_peer_that_left(capture_network: tuple[Network, Capture]) -> None:
    network, capture = capture_network
    with LocalPeers() as peers:
        stays = peers.add(network, "stays", key=KEY)
        leaves = peers.add(network, "leaves", key=KEY)
        events = Events(stays)
        assert wait_until(lambda: leaves.guid in stays.peer.links, 10)
        assert wait_until(lambda: len(capture.from_peer(leaves.guid)) >= 4, 10)
        leaves.stop()
        assert events.wait("lost", leaves.guid, 5) is not None
        since = time.monotonic()
        capture.replay(capture.from_peer(leaves.guid))
        time.sleep(0.5)
        assert events.matching("found", leaves.guid, since) == [], "a replayed datagram brought back a ghost"
        assert leaves.guid not in known(stays)


# ---------------------------------------------------------------------- replayed link frames


def sniffer() -> socket.socket:
    try:
        sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(0x0003))
    except PermissionError as exc:
        pytest.skip(f"capturing loopback traffic needs CAP_NET_RAW: {exc}")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 24)
    sock.bind(("lo", 0))
    return sock


def tcp_stream(sock: socket.socket, destination_port: int) -> bytes:
    """Reassemble, from captured loopback packets, the bytes sent to ``destination_port``."""
    segments: dict[int, bytes] = {}
    sock.setblocking(False)
    while True:
        try:
            packet = sock.recv(1 << 17)
        except BlockingIOError:
            break
        ip = packet[14:]
        if len(ip) < 20 or ip[0] >> 4 != 4 or ip[9] != socket.IPPROTO_TCP:
            continue
        tcp = ip[(ip[0] & 0x0F) * 4 :]
        _source, destination, sequence = struct.unpack("!HHI", tcp[:8])
        payload = tcp[(tcp[12] >> 4) * 4 : struct.unpack("!H", ip[2:4])[0] - (ip[0] & 0x0F) * 4]
        if destination == destination_port and payload:
            segments[sequence] = payload  # loopback shows each packet twice: keep one
    return b"".join(segments[s] for s in sorted(segments))


def frames_of(stream: bytes) -> list[bytes]:
    frames = []
    while len(stream) >= PROLOGUE.size:
        _magic, _version, _kind, flags, length = PROLOGUE.unpack_from(stream)
        size = PROLOGUE.size + length + (AUTH.size + MAC_SIZE if flags & FLAG_AUTH else 0)
        frames.append(stream[:size])
        stream = stream[size:]
    return frames


@pytest.fixture
def sniffed_pair() -> Iterator[tuple[MultiPeerTransport, MultiPeerTransport, list[bytes]]]:
    """A keyed pair whose lower peer's frames to the higher one were captured off the wire."""
    sock = sniffer()
    try:
        with LocalPeers() as peers:
            first = peers.add(private_network(), "first", key=KEY, start=False)
            second = peers.add(first.peer.network, "second", key=KEY, start=False)
            low, high = sorted((first, second), key=lambda t: t.guid)
            high.subscribe(TopicQoS("/wire"))
            high.start()
            low.start()
            assert wait_until(lambda: low.guid in high.peer.links and high.guid in low.peer.links, 10)
            assert low.wait_for_subscribers("/wire", 1, 10)
            for i in range(5):
                low.publisher(TopicQoS("/wire")).publish(i)
            time.sleep(0.3)
            frames = frames_of(tcp_stream(sock, high.guid & 0xFFFF))
            assert frames and frames[0][3] == FrameType.HELLO, "no HELLO captured"
            assert any(f[3] == FrameType.TOPICDATA for f in frames)
            yield low, high, frames
    finally:
        sock.close()


def test_captured_link_frames_replayed_on_a_new_connection_are_rejected(
    sniffed_pair: tuple[MultiPeerTransport, MultiPeerTransport, list[bytes]], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="ckm.link")
    low, high, frames = sniffed_pair
    real = high.peer.links[low.guid]
    data = [f for f in frames if f[3] == FrameType.TOPICDATA]
    for replay in (data[0], b"".join(data), b"".join(frames[1:])):
        client = RawClient(high.guid & 0xFFFF)
        try:
            client.send(replay)
            assert client.read_until_closed(5)[0]
        finally:
            client.close()
    assert wait_until(lambda: "bad MAC" in caplog.text, 5)
    assert high.peer.links.get(low.guid) is real and real.state == "open"
    assert exchange(low, high, "/after-replay")


def test_a_captured_hello_replayed_does_not_open_a_link(
    sniffed_pair: tuple[MultiPeerTransport, MultiPeerTransport, list[bytes]],
) -> None:
    low, high, frames = sniffed_pair
    real = high.peer.links[low.guid]
    client = RawClient(high.guid & 0xFFFF)
    try:
        client.send(frames[0])
        wait_until(lambda: high.peer.links.get(low.guid) is not real, 2.0)
        assert high.peer.links.get(low.guid) is real and real.state == "open", "the replayed HELLO took the link"
    finally:
        client.close()
