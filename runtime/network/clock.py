"""SYNCTIME (§3.1.4.3): NTP-style clock offsets between peers, from four timestamps.

The requester stamps t1 when it sends, the responder t2 when it receives and t3 when it
answers, the requester t4 when the answer arrives:

    offset = ((t2 - t1) + (t3 - t4)) / 2      the remote clock minus ours
    delay  = (t4 - t1) - (t3 - t2)            the round trip spent on the network

Among recent exchanges the one with the smallest delay gives the best offset (least queueing).
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass


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
