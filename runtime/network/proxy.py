"""PROXYWRAPPER (§3.1.4.3): reaching a peer through another when no direct link is possible.

Linked peers tell each other whom they are linked to (``["route", [[guid, name], …]]``). A peer
learned this way that cannot be linked directly — it is out of multicast reach, or connecting
to it fails — becomes reachable *via* a neighbour after ``proxy_after`` seconds: frames for it
are wrapped as ``["fwd", src, dst, type, body]`` and the neighbour forwards them. Only one relay
is used (a relay never forwards a forwarded frame), so routes cannot loop. Each hop is an
authenticated link; the relay, a key holder itself, is trusted like any group member.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from .frames import Frame, FrameType


class Router:
    """PROXYWRAPPER routes (§3.1.4.3) through neighbours for one MultiPeer (which owns it and calls its hooks)."""

    def __init__(
        self,
        *,
        local: Callable[[], int],
        linked: Callable[[], list[int]],
        send_direct: Callable[[int, FrameType, list[Any]], bool],
        deliver: Callable[[int, Frame], None],
        on_route: Callable[[int, str, int | None], None],
        proxy_after: float,
    ) -> None:
        self._local = local
        self._linked = linked
        self._send_direct = send_direct
        self._deliver = deliver
        self._on_route = on_route
        self.proxy_after = proxy_after
        self.neighbours: dict[int, dict[int, str]] = {}  # via → {guid: name} it is linked to
        self.routes: dict[int, int] = {}  # destination → via
        self._heard_at: dict[int, float] = {}
        self._lock = threading.Lock()
        self.forwarded = 0

    # ------------------------------------------------------------------ gossip

    def announce(self, names: dict[int, str]) -> None:
        """Tell every neighbour whom we are linked to (called when our links change)."""
        table = [[guid, names.get(guid, "")] for guid in self._linked()]
        for guid in self._linked():
            self._send_direct(guid, FrameType.PROXYWRAPPER, ["route", table])

    def link_down(self, via: int) -> None:
        """A direct link closed: routes through it are gone."""
        with self._lock:
            self.neighbours.pop(via, None)
            lost = [dst for dst, hop in self.routes.items() if hop == via]
            for dst in lost:
                del self.routes[dst]
        for dst in lost:
            self._on_route(dst, "", None)

    def link_up(self, guid: int) -> None:
        """A direct link opened: it replaces any route to the same peer."""
        with self._lock:
            self.routes.pop(guid, None)
            self._heard_at.pop(guid, None)

    # ------------------------------------------------------------------ sending

    def send(self, guid: int, kind: FrameType, body: list[Any]) -> bool:
        """Wrap a frame for ``guid`` in PROXYWRAPPER to its relay; False if no route is known."""
        via = self.routes.get(guid)
        if via is None:
            return False
        return self._send_direct(via, FrameType.PROXYWRAPPER, ["fwd", self._local(), guid, int(kind), body])

    # ------------------------------------------------------------------ receiving

    def handle(self, sender: int, frame: Frame) -> None:
        """Take a PROXYWRAPPER frame from ``sender``: a route list, or a frame to forward or deliver."""
        body = frame.body
        if len(body) == 2 and body[0] == "route" and isinstance(body[1], list):
            entries = {
                e[0]: str(e[1]) for e in body[1] if isinstance(e, list) and len(e) == 2 and isinstance(e[0], int)
            }
            with self._lock:
                self.neighbours[sender] = entries
                now = time.monotonic()
                for guid in entries:
                    self._heard_at.setdefault(guid, now)
                gone = [dst for dst, via in self.routes.items() if via == sender and dst not in entries]
                for dst in gone:
                    del self.routes[dst]
            for dst in gone:
                self._on_route(dst, "", None)
        elif len(body) == 5 and body[0] == "fwd" and all(isinstance(v, int) for v in body[1:4]):
            self._forward_or_deliver(sender, body[1], body[2], body[3], body[4])

    def _forward_or_deliver(self, sender: int, src: int, dst: int, kind: int, inner: Any) -> None:
        if kind == FrameType.PROXYWRAPPER or not isinstance(inner, list):
            return  # one relay only, and only real frames
        try:
            frame_type = FrameType(kind)
        except ValueError:
            return
        if dst == self._local():
            if src not in self.neighbours.get(sender, {}):
                return  # the relay does not say it is linked to that origin: not believed
            if src not in self._linked() and self.routes.get(src) != sender:
                with self._lock:
                    self.routes[src] = sender
                self._on_route(src, "", sender)  # the other side found us first: answer the same way
            self._deliver(src, Frame(frame_type, inner))
        elif sender == src and dst in self._linked():
            self.forwarded += 1
            self._send_direct(dst, FrameType.PROXYWRAPPER, ["fwd", src, dst, kind, inner])

    # ------------------------------------------------------------------ timer

    def tick(self) -> None:
        """Give unreachable peers a route once they have been unlinked for ``proxy_after`` seconds."""
        now = time.monotonic()
        local = self._local()
        direct = set(self._linked())
        new: list[tuple[int, str, int]] = []
        with self._lock:
            for via, entries in self.neighbours.items():
                for guid, name in entries.items():
                    waited = now - self._heard_at.get(guid, now)
                    if guid == local or guid in direct or guid in self.routes or waited < self.proxy_after:
                        continue
                    self.routes[guid] = via
                    new.append((guid, name, via))
        for guid, name, via in new:
            self._on_route(guid, name, via)
