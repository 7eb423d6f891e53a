"""SYNCTIME (§3.1.4.3): NTP-style clock offsets between peers, from four timestamps.

The requester stamps t1 when it sends, the responder t2 when it receives and t3 when it
answers, the requester t4 when the answer arrives:

    offset = ((t2 - t1) + (t3 - t4)) / 2      the remote clock minus ours
    delay  = (t4 - t1) - (t3 - t2)            the round trip spent on the network

Among recent exchanges the one with the smallest delay gives the best offset (least queueing).
:class:`ClockSync` keeps the offsets; :class:`SyncTimeExchange` asks and answers the SYNCTIME
frames of one peer (an opening burst on each new link, then one exchange per period).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .frames import Frame, FrameType

BURST = 8
"""Exchanges of the opening burst on a new link: the least-delay one gives a good first offset."""


@dataclass(frozen=True)
class Offset:
    """One SYNCTIME result: the remote clock minus ours, and the round-trip delay, in seconds."""

    offset: float
    delay: float


class ClockSync:
    """Offsets to remote peers, updated from SYNCTIME exchanges."""

    def __init__(self, window: int = 8) -> None:
        self._window = window
        self._samples: dict[int, deque[Offset]] = {}
        self._lock = threading.Lock()

    def add(self, guid: int, t1: float, t2: float, t3: float, t4: float) -> Offset:
        """Record one exchange with peer ``guid``; returns its offset and delay.

        Args:
            guid: The responding peer.
            t1: Our clock when the request left.
            t2: The peer's clock when the request arrived.
            t3: The peer's clock when the answer left.
            t4: Our clock when the answer arrived.
        """
        sample = Offset(((t2 - t1) + (t3 - t4)) / 2, (t4 - t1) - (t3 - t2))
        with self._lock:
            self._samples.setdefault(guid, deque(maxlen=self._window)).append(sample)
        return sample

    def best(self, guid: int) -> Offset | None:
        """The lowest-delay offset of the recent window (the most trustworthy, NTP's rule), None if none."""
        with self._lock:
            samples = self._samples.get(guid)
            return min(samples, key=lambda s: s.delay) if samples else None

    def offset(self, guid: int) -> float:
        """Remote clock minus local clock (0 until the first exchange)."""
        best = self.best(guid)
        return best.offset if best is not None else 0.0

    def to_local(self, guid: int, remote_time: float) -> float:
        """A remote timestamp expressed on the local clock."""
        return remote_time - self.offset(guid)

    def forget(self, guid: int) -> None:
        """Drop a lost peer's samples."""
        with self._lock:
            self._samples.pop(guid, None)


class SyncTimeExchange:
    """The SYNCTIME requests and replies of one peer (§3.1.4.3), feeding its :class:`ClockSync`."""

    def __init__(self, clock: ClockSync, send: Callable[[int, FrameType, list[Any]], bool]) -> None:
        self.clock = clock
        self._send = send
        self._lock = threading.Lock()
        self._burst: dict[int, int] = {}  # guid → exchanges left in the opening burst
        self._asked: dict[int, deque[float]] = {}  # requests awaiting their reply

    def linked(self, guid: int) -> None:
        """A new link to ``guid``: open with a burst of :data:`BURST` exchanges (:meth:`tick`)."""
        self._burst[guid] = BURST

    def bursting(self) -> bool:
        """Whether a new link's opening burst still has exchanges to make (one per :meth:`tick`)."""
        return bool(self._burst)

    def tick(self) -> None:
        """One exchange with each peer still in its opening burst."""
        for guid, left in list(self._burst.items()):
            self.ask(guid)
            if left <= 1:
                self._burst.pop(guid, None)
            else:
                self._burst[guid] = left - 1

    def ask(self, guid: int) -> None:
        """Send a request stamped t1 to ``guid``."""
        sent = time.time()
        with self._lock:
            asked = self._asked.setdefault(guid, deque(maxlen=16))
            asked.append(sent)
        self._send(guid, FrameType.SYNCTIME, ["req", sent])

    def handle(self, guid: int, frame: Frame) -> None:
        """A SYNCTIME frame from ``guid``: answer a request (t2, t3), or record the reply to one of ours (t4)."""
        received = time.time()
        body = frame.body
        if len(body) == 2 and body[0] == "req" and isinstance(body[1], float):
            self._send(guid, FrameType.SYNCTIME, ["rep", body[1], received, time.time()])
        elif len(body) == 4 and body[0] == "rep" and all(type(v) is float and math.isfinite(v) for v in body[1:]):
            t1, t2, t3 = body[1], body[2], body[3]
            with self._lock:
                asked = self._asked.get(guid)
                if asked is None or t1 not in asked:
                    return  # an answer to nothing we asked: ignored
                asked.remove(t1)
            if t3 >= t2 and received >= t1:
                self.clock.add(guid, t1, t2, t3, received)
