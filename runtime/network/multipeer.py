"""CKMultiPeer (§3.1.4): discovery, the full mesh of TCP links, listeners and clock sync.

Lifecycle: ``MultiPeer(network, name=…)`` does no I/O; ``setup()`` binds the listening port
(trying the next ones when busy, :func:`runtime.network.ports.bind_listener`) and the discovery
socket; ``start()`` starts the threads; ``stop()`` says goodbye and closes everything. The clock
sync exchange is :class:`runtime.network.clock.SyncTimeExchange`, the reconnect back-off
:class:`runtime.network.reconnect.ReconnectSchedule`.
"""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ckmconf.model import Network

from .. import lockstep
from .api import NetworkError
from .clock import ClockSync, SyncTimeExchange
from .discovery import Discovery
from .frames import Frame, FrameType, encode
from .guid import guid_address, guid_text, make_guid
from .link import Link
from .ports import bind_listener
from .proxy import Router
from .reconnect import ReconnectSchedule

LOG = logging.getLogger("ckm.multipeer")

Listener = Callable[[int, Frame], None]
MAX_PENDING_LINKS = 64
BUSY_POLL = 0.005  # s of wall time between the timer's looks while links form
IDLE_POLL = 0.05  # … and once every link is up (route expiry, the periodic clock sync)


@dataclass(frozen=True)
class PeerEvent:
    """found / lost (discovery), linked / unlinked (TCP link up or down)."""

    kind: str
    guid: int
    name: str
    reason: str = ""


class MultiPeer:
    """One member of a CKMultiPeer group (§3.1.4), configured by ``<Network>``."""

    def __init__(self, network: Network, *, name: str = "peer", key: bytes | None = None) -> None:
        self.network = network
        self.name = name
        self.key = key
        self.guid = 0
        self.links: dict[int, Link] = {}
        self.names: dict[int, str] = {}
        self.rejected_links = 0
        self.evicted_links = 0  # pending handshakes closed to make room for a new connection
        self.clock = ClockSync()
        self.sync = SyncTimeExchange(self.clock, self.send)
        self._listeners: dict[FrameType, list[Listener]] = {}
        self._event_callbacks: list[Callable[[PeerEvent], None]] = []
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._nudge = threading.Event()  # wakes the timer at once: an attempt is due, a link opened
        self._server: socket.socket | None = None
        self._discovery: Discovery | None = None
        self._threads: list[threading.Thread] = []
        self._reconnects = ReconnectSchedule(network.reconnect_min, network.reconnect_max)
        self._all_links: list[Link] = []
        self.router = Router(
            local=lambda: self.guid,
            linked=self.linked,
            send_direct=self._send_direct,
            deliver=self._dispatch,
            on_route=self._route_changed,
            proxy_after=max(1.0, 2 * network.reconnect_max),
        )
        self.add_listener(FrameType.SYNCTIME, self.sync.handle)
        self.add_listener(FrameType.PROXYWRAPPER, self.router.handle)

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Bind the listening port (next ones if busy), derive the GUID and open discovery."""
        net = self.network
        self._server = bind_listener(net.interface, net.base_port, net.port_tries)
        self.guid = make_guid(net.interface, self._server.getsockname()[1])
        self._discovery = Discovery(
            guid=self.guid,
            name=self.name,
            group=net.group,
            port=net.discovery_port,
            interface=net.interface,
            heartbeat=net.heartbeat,
            lost_after=net.lost_after,
            key=self.key,
            on_found=self._found,
            on_lost=self._lost,
            alive=self.alive,
        )
        try:
            self._discovery.setup()
        except OSError as exc:
            self._server.close()
            raise NetworkError(f"cannot join multicast group {net.group}:{net.discovery_port}: {exc}") from exc

    def start(self) -> None:
        """Start the accept and timer threads, then discovery; links follow the announcements."""
        assert self._server is not None and self._discovery is not None, "call setup() first"
        for target, label in ((self._accept_loop, "accept"), (self._timer_loop, "timer")):
            thread = threading.Thread(target=target, name=f"ckm-{label}", daemon=True)
            thread.start()
            self._threads.append(thread)
        self._discovery.start()

    def stop(self) -> None:
        """Stop discovery, close the server and every link, join the threads; idempotent."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._nudge.set()
        if self._discovery is not None:
            self._discovery.stop()
        if self._server is not None:
            self._server.close()
        with self._lock:
            links = list(self._all_links)
        for link in links:
            link.close("peer stopping")
        for link in links:
            link.join()
        for thread in self._threads:
            thread.join(timeout=2)

    def __enter__(self) -> MultiPeer:
        self.setup()
        self.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ API

    def add_listener(self, kind: FrameType, callback: Listener) -> None:
        """Call ``callback(sender_guid, frame)`` for every frame of ``kind`` (§3.1.4.4).

        The frame is only valid during the call: copy what you keep.
        """
        self._listeners.setdefault(kind, []).append(callback)

    def on_event(self, callback: Callable[[PeerEvent], None]) -> None:
        """Call ``callback`` on every peer event (found, linked, unlinked, lost)."""
        self._event_callbacks.append(callback)

    def linked(self) -> list[int]:
        """GUIDs of the peers with a direct link, sorted."""
        with self._lock:
            return sorted(self.links)

    def reachable(self) -> list[int]:
        """Peers linked directly or through a neighbour (PROXYWRAPPER)."""
        with self._lock:
            return sorted(set(self.links) | set(self.router.routes))

    def send(self, guid: int, kind: FrameType, body: list[Any]) -> bool:
        """Send one frame to a peer, directly or through the neighbour that reaches it."""
        return self._send_direct(guid, kind, body) or (guid not in self.links and self.router.send(guid, kind, body))

    def _send_direct(self, guid: int, kind: FrameType, body: list[Any]) -> bool:
        link = self.links.get(guid)
        return link is not None and link.send(kind, body)

    def broadcast(self, kind: FrameType, body: list[Any], guids: list[int] | None = None) -> int:
        """Send to every reachable peer (or those listed); encodes once for direct links without a key."""
        wanted = guids if guids is not None else self.reachable()
        with self._lock:
            targets = [self.links[g] for g in wanted if g in self.links]
            routed = [g for g in wanted if g not in self.links and g in self.router.routes]
        sent = sum(self.router.send(g, kind, body) for g in routed)
        if self.key is None and targets:
            data = encode(kind, body)
            return sent + sum(link.send_encoded(data) for link in targets)
        return sent + sum(link.send(kind, body) for link in targets)

    def wait_linked(self, count: int, timeout: float) -> bool:
        """Wait until at least ``count`` links are open (tests and benchmarks)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if len(self.links) >= count:
                return True
            time.sleep(0.005)
        return len(self.links) >= count

    # ------------------------------------------------------------------ discovery callbacks

    def _found(self, guid: int, name: str) -> None:
        self.names[guid] = name
        self._emit(PeerEvent("found", guid, name))
        if guid > self.guid:  # the mandala: the lower GUID connects to the higher one
            with self._lock:
                self._reconnects.found(guid)
            self._nudge.set()

    def _lost(self, guid: int, name: str, reason: str) -> None:
        with self._lock:
            self._reconnects.forget(guid)
            link = self.links.get(guid)
        self._emit(PeerEvent("lost", guid, name, reason))
        if link is not None:
            link.close("peer lost (no heartbeat)")

    # ------------------------------------------------------------------ links

    def _accept_loop(self) -> None:
        assert self._server is not None
        while not self._stop.is_set():
            try:
                sock, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            self._start_link(sock, outgoing=False, expected=None)

    def _start_link(self, sock: socket.socket, *, outgoing: bool, expected: int | None) -> None:
        link = Link(
            sock,
            local_guid=self.guid,
            local_name=self.name,
            max_frame=self.network.max_frame,
            key=self.key,
            outgoing=outgoing,
            expected=expected,
            on_open=self._opened,
            on_frame=self._frame,
            on_close=self._closed,
        )
        evicted: Link | None = None
        with self._lock:
            if self._stop.is_set():
                sock.close()
                return
            # Accept always: past the cap the oldest incoming handshake makes room, so idle or
            # unauthenticated connections can delay a real peer by one eviction, never block it.
            pending = [old for old in self._all_links if old.state != "open" and not old.outgoing]
            if not outgoing and len(pending) >= MAX_PENDING_LINKS:
                evicted = pending[0]
                self.evicted_links += 1
            self._all_links.append(link)
        if evicted is not None:
            evicted.close(f"evicted: {MAX_PENDING_LINKS} connections were still in their handshake")
        try:
            link.start()
        except OSError as exc:
            link.close(f"cannot start: {exc}")

    def _connect(self, guid: int) -> None:
        address, port = guid_address(guid)
        try:
            # From the interface address: the GUID we claim must match where the link comes from.
            sock = socket.create_connection((address, port), timeout=1.0, source_address=(self.network.interface, 0))
        except OSError as exc:
            LOG.debug("connect to %s failed: %s", guid_text(guid), exc)
            self._schedule_retry(guid)
            return
        finally:
            with self._lock:
                self._reconnects.attempted(guid)
        self._start_link(sock, outgoing=True, expected=guid)

    def _opened(self, link: Link) -> bool:
        guid = link.remote_guid
        assert guid is not None
        with self._lock:
            if self._stop.is_set():
                return False
            if not link.outgoing and guid > self.guid:
                self.rejected_links += 1
                return False  # a higher GUID must wait for us to connect
            old = self.links.get(guid)
            if old is not None and old is not link \
                    and lockstep.wall_monotonic() - old.last_received < self._healthy_window():
                self.rejected_links += 1
                return False  # the current link is alive: a second HELLO for it is an intruder or a ghost
            self.links[guid] = link
            self._reconnects.linked(guid)
        if old is not None and old is not link:
            old.close("replaced by a new connection")
        self.names.setdefault(guid, link.remote_name)
        self.router.link_up(guid)
        self._emit(PeerEvent("linked", guid, link.remote_name))
        self.sync.linked(guid)
        self._nudge.set()
        threading.Thread(target=self.router.announce, args=(self.names,), daemon=True).start()
        return True

    def _closed(self, link: Link, reason: str) -> None:
        guid = link.remote_guid if link.remote_guid is not None else link.expected
        who = guid_text(guid) if guid is not None else "an unidentified connection"
        LOG.info("link to %s closed: %s", who, reason)  # every closed link, handshake time-outs included
        with self._lock:
            if link in self._all_links:
                self._all_links.remove(link)
            current = self.links.get(guid) if guid is not None else None
            if current is link:
                del self.links[guid]  # type: ignore[arg-type]
        if current is link and guid is not None:
            self._emit(PeerEvent("unlinked", guid, link.remote_name, reason))
            self.router.link_down(guid)
            if not self._stop.is_set():
                self.router.announce(self.names)
            self._schedule_retry(guid)
        elif link.outgoing and guid is not None and guid not in self.links:
            self._schedule_retry(guid)  # the handshake failed: try again later

    def _healthy_window(self) -> float:
        """A link that carried something this recently is alive (SYNCTIME runs on every link)."""
        return max(3 * self.network.clock_sync, self.network.heartbeat * self.network.lost_after)

    def alive(self, guid: int) -> bool:
        """Whether the link to ``guid`` carried traffic recently: discovery spares busy peers."""
        link = self.links.get(guid)
        return (
            link is not None
            and lockstep.wall_monotonic() - link.last_received < self.network.heartbeat * self.network.lost_after
        )

    def _schedule_retry(self, guid: int) -> None:
        if self._stop.is_set() or guid < self.guid or self._discovery is None or guid not in self._discovery.known:
            return
        with self._lock:
            self._reconnects.retry(guid, time.monotonic())
        self._nudge.set()

    def _frame(self, link: Link, frame: Frame) -> None:
        assert link.remote_guid is not None
        self._dispatch(link.remote_guid, frame)

    def _dispatch(self, guid: int, frame: Frame) -> None:
        for callback in self._listeners.get(frame.type, ()):
            callback(guid, frame)

    def _route_changed(self, guid: int, name: str, via: int | None) -> None:
        if via is not None:
            self.names.setdefault(guid, name)
            self._emit(PeerEvent("linked", guid, self.names.get(guid, name), f"via {guid_text(via)}"))
        else:
            self._emit(PeerEvent("unlinked", guid, self.names.get(guid, ""), "route lost"))

    def _emit(self, event: PeerEvent) -> None:
        for callback in list(self._event_callbacks):
            try:
                callback(event)
            except Exception:
                LOG.exception("event callback failed on %s", event)

    # ------------------------------------------------------------------ timer: reconnects, clock sync

    def poll_interval(self) -> float:
        """How long the timer waits before its next look: BUSY_POLL while links form, else IDLE_POLL."""
        with self._lock:
            busy = self._reconnects.pending()
        return BUSY_POLL if busy or self.sync.bursting() else IDLE_POLL

    def _timer_loop(self) -> None:
        # on the wall clock: links form while a lock-step clock waits for them (D220). It looks every
        # BUSY_POLL while links are forming (an attempt due, a clock-sync burst), else every IDLE_POLL:
        # a run's eight processes polling at 200 Hz cost 9 CPU seconds of a one-minute mission (D239)
        lockstep.unclocked()
        next_sync = time.monotonic() + self.network.clock_sync
        while not self._stop.is_set():
            self._nudge.wait(self.poll_interval())
            self._nudge.clear()
            if self._stop.is_set():
                return
            now = time.monotonic()
            with self._lock:
                due = self._reconnects.due(now, self.links)
            for guid in due:
                threading.Thread(target=self._connect, args=(guid,), name="ckm-connect", daemon=True).start()
            self.router.tick()
            self.sync.tick()
            if now >= next_sync:
                next_sync = now + self.network.clock_sync
                for guid in self.linked():
                    self.sync.ask(guid)
