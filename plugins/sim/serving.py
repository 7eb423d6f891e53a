"""The world server's connections (issue J point 5, decisions D100, D103): a client and the camera
reads waiting for one render of the render worker."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

from .devices import ChannelDevice
from .sensors import Frame

Reply = dict[str, Any]
LARGE = 1 << 16  # bytes: a reply carrying a larger array is sent by the client's sender thread


@dataclass
class Client:
    """One connection; large replies (frames) leave through a sender thread of its own, so a slow
    reader (a best-effort partition at niceness 10 on a busy machine) never stalls the physics."""

    number: int
    conn: Connection
    devices: dict[int, ChannelDevice] = field(default_factory=dict)
    outbox: queue.SimpleQueue[Callable[[], Reply] | None] | None = None
    orders: dict[int, Order] = field(default_factory=dict)  # renders ordered, by ticket, not yet collected

    def later(self, make: Callable[[], Reply]) -> None:
        """Send ``make()`` from the sender thread (made, and pickled, there)."""
        if self.outbox is None:
            self.outbox = queue.SimpleQueue()
            threading.Thread(target=self._send, name=f"ckm-sim-send-{self.number}", daemon=True).start()
        self.outbox.put(make)

    def _send(self) -> None:
        assert self.outbox is not None
        while (make := self.outbox.get()) is not None:
            try:
                self.conn.send(make())
            except (OSError, ValueError):  # gone: the physics thread drops it at its EOF
                return

    def close(self) -> None:
        """Stop the client's sender thread and close its connection."""
        if self.outbox is not None:
            self.outbox.put(None)
        self.conn.close()


def frame_reply(device: ChannelDevice, frame: Frame, time: float) -> Reply:
    """The reply to a camera read from a rendered ``frame`` at simulated ``time``."""
    try:
        return {"value": device.from_frame(frame), "time": time}
    except Exception as exc:  # never the server's end
        return {"error": f"sim channel {device.spec.name!r}: {exc}", "type": type(exc).__name__}


@dataclass
class Order:
    """A render ordered (``op: render``) at one world step and collected later (``op: frame``, D246)."""

    ticket: int
    device: ChannelDevice
    step: int
    time: float
    frame: Frame | None = None
    error: Reply | None = None  # why there is no frame
    awaited: bool = False  # the client asked for the frame before it was made


@dataclass
class Flight:
    """A frame the render worker is making, the camera reads waiting for it and the renders ordered."""

    key: tuple[int, int, float, int, int]
    step: int
    time: float
    waiters: list[tuple[Client, ChannelDevice]]
    orders: list[tuple[Client, Order]] = field(default_factory=list)
