"""Peer discovery (§3.1.4.2) over a UDP multicast group: announce, re-announce, heartbeat, lose.

Every peer announces its GUID on the group; a peer that hears a GUID it did not know answers
with its own announcement so the newcomer learns it too; afterwards the channel carries only
the periodic heartbeat. A GUID silent for ``lost_after`` heartbeat periods is declared lost.
With a group key every datagram is authenticated, and per-sender counters (with a boot id, so a
restarted peer is heard again) make replays useless.
"""

from __future__ import annotations

import hashlib
import hmac
import logging
import os
import socket
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import msgpack

from .. import lockstep

LOG = logging.getLogger("ckm.discovery")
MAGIC = "CKD"
MAX_DATAGRAM = 1024
MAC_SIZE = 32

HELLO = "hello"
HEARTBEAT = "beat"
BYE = "bye"


@dataclass
class Known:
    """What discovery knows of another peer."""

    guid: int
    name: str
    boot: bytes
    counter: int
    last_heard: float = field(default_factory=lockstep.wall_monotonic)


class Discovery:
    """The multicast side of a peer (peer discovery, §3.1.4.2). Callbacks run on the discovery thread."""

    def __init__(
        self,
        *,
        guid: int,
        name: str,
        group: str,
        port: int,
        interface: str,
        heartbeat: float,
        lost_after: int,
        key: bytes | None,
        on_found: Callable[[int, str], None],
        on_lost: Callable[[int, str, str], None],
        alive: Callable[[int], bool] = lambda guid: False,
    ) -> None:
        self.guid = guid
        self.name = name
        self.group = group
        self.port = port
        self.interface = interface
        self.heartbeat = heartbeat
        self.lost_after = lost_after
        self.key = key
        self.on_found = on_found
        self.on_lost = on_lost
        self.alive = alive
        self._retired: dict[int, tuple[bytes, int]] = {}  # guid → last (boot, counter) of a peer gone
        self._answer_due = False
        self.known: dict[int, Known] = {}
        self.rejected = 0
        self._boot = os.urandom(8)
        self._counter = 0
        self._sock: socket.socket | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._lock = threading.Lock()
        self._table = threading.Lock()
        self._last_answer = 0.0

    def setup(self) -> None:
        """Open the multicast socket bound to the group (§3.1.4.2); no threads yet."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if hasattr(socket, "SO_REUSEPORT"):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        # Bound to the group address and with IP_MULTICAST_ALL off, the socket hears only its
        # own group even when another group on this host uses the same port.
        sock.bind((self.group, self.port))
        sock.setsockopt(socket.IPPROTO_IP, getattr(socket, "IP_MULTICAST_ALL", 49), 0)
        membership = socket.inet_aton(self.group) + socket.inet_aton(self.interface)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(self.interface))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 1)
        sock.settimeout(0.005)
        self._sock = sock

    def start(self) -> None:
        """Start the receive and heartbeat threads and announce this peer (HELLO)."""
        for target, label in ((self._receive_loop, "rx"), (self._beat_loop, "beat")):
            thread = threading.Thread(target=target, name=f"ckm-discovery-{label}", daemon=True)
            thread.start()
            self._threads.append(thread)
        self.announce(HELLO)

    def stop(self) -> None:
        """Announce BYE, stop the threads and close the socket."""
        if self._sock is not None and not self._stop.is_set():
            self.announce(BYE)
        self._stop.set()
        for thread in self._threads:
            thread.join(timeout=2)
        if self._sock is not None:
            self._sock.close()

    def announce(self, kind: str) -> None:
        """Send one announcement of ``kind`` (hello, beat, bye) to the group, HMAC-signed with a group key."""
        if self._sock is None:
            return
        with self._lock:
            self._counter += 1
            body = msgpack.packb([MAGIC, 1, kind, self.guid, self.name, self._boot, self._counter], use_bin_type=True)
        packet = body + (hmac.new(self.key, body, hashlib.sha256).digest() if self.key else b"")
        try:
            self._sock.sendto(packet, (self.group, self.port))
        except OSError as exc:
            LOG.warning("discovery: cannot send on %s:%s: %s", self.group, self.port, exc)

    def _receive_loop(self) -> None:
        assert self._sock is not None
        while not self._stop.is_set():
            self._flush_answer()
            try:
                packet, _ = self._sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                continue
            except OSError:
                return
            message = self._parse(packet)
            if message is not None:
                self._handle(*message)

    def _parse(self, packet: bytes) -> tuple[str, int, str, bytes, int] | None:
        if self.key is not None:
            body, mac = packet[:-MAC_SIZE], packet[-MAC_SIZE:]
            expected = hmac.new(self.key, body, hashlib.sha256).digest()
            if len(packet) <= MAC_SIZE or not hmac.compare_digest(mac, expected):
                self.rejected += 1
                return None
        else:
            body = packet
        try:
            fields: Any = msgpack.unpackb(body, raw=False, max_bin_len=64, max_str_len=256, max_array_len=16)
        except (ValueError, msgpack.UnpackException, TypeError):
            self.rejected += 1
            return None
        valid = (
            isinstance(fields, list)
            and len(fields) == 7
            and fields[0] == MAGIC
            and fields[1] == 1
            and fields[2] in (HELLO, HEARTBEAT, BYE)
            and type(fields[3]) is int
            and 0 < fields[3] < 1 << 48
            and isinstance(fields[4], str)
            and isinstance(fields[5], bytes)
            and type(fields[6]) is int
        )
        if not valid:
            self.rejected += 1
            return None
        return fields[2], fields[3], fields[4], fields[5], fields[6]

    def _handle(self, kind: str, guid: int, name: str, boot: bytes, counter: int) -> None:
        if guid == self.guid:
            return
        with self._table:
            self._update(kind, guid, name, boot, counter)

    def _update(self, kind: str, guid: int, name: str, boot: bytes, counter: int) -> None:
        known = self.known.get(guid)
        retired = self._retired.get(guid)
        last = (known.boot, known.counter) if known is not None else retired
        if last is not None and last[0] == boot and counter <= last[1]:
            self.rejected += 1  # a replayed or duplicated datagram, even of a peer that has left
            return
        if kind == BYE:
            if known is not None:
                self._retire(guid, boot, counter)
                self.on_lost(guid, known.name, "said goodbye")
            return
        fresh = known is None or known.boot != boot
        if known is not None and fresh:
            self.on_lost(guid, known.name, "restarted")  # the old incarnation is gone
        self.known[guid] = Known(guid, name, boot, counter)
        if fresh:
            self.on_found(guid, name)
            self._answer()

    def _retire(self, guid: int, boot: bytes, counter: int) -> None:
        del self.known[guid]
        self._retired[guid] = (boot, counter)

    def _answer(self) -> None:
        # A newcomer must learn us: re-announce. In a burst of joins, answers within 5 ms are
        # merged into one sent when the burst's first window ends (never dropped).
        now = lockstep.wall_monotonic()
        if now - self._last_answer > 0.005:
            self._last_answer = now
            self.announce(HELLO)
        else:
            self._answer_due = True

    def _flush_answer(self) -> None:
        if self._answer_due and lockstep.wall_monotonic() - self._last_answer > 0.005:
            self._answer_due = False
            self._last_answer = lockstep.wall_monotonic()
            self.announce(HELLO)

    def _beat_loop(self) -> None:
        # heartbeats and their deadlines on the wall clock, in lock-step too (D256): a receiver stamping a
        # beat with the simulated time saw a peer "stop" whenever the run's clock outran its threads
        lockstep.unclocked()
        while not self._stop.wait(self.heartbeat):
            self.announce(HEARTBEAT)
            deadline = lockstep.wall_monotonic() - self.heartbeat * self.lost_after
            with self._table:
                for guid, known in list(self.known.items()):
                    if known.last_heard >= deadline:
                        continue
                    if self.alive(guid):
                        known.last_heard = lockstep.wall_monotonic()  # busy but talking on its link: not lost
                        continue
                    self._retire(guid, known.boot, known.counter)
                    self.on_lost(guid, known.name, "heartbeat stopped")
