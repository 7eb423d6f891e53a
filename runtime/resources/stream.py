"""The streams of a Smart Resource (thesis §3.2.2–3.2.3): one per acquisition plugin.

Every profile tree starts at an acquisition plugin (its root). The profiles that share a root
form a *stream*: one Topology (the plugins of those trees), one triple buffer (§3.2.3) whose
acquisition takes the newest value of the stream's input — the first Input topic of its
services (:func:`newest_of`), or a ``source`` callable given by the caller (a camera driver, a
benchmark) — and whose processing runs the profiles every instance of the stream has selected,
so frames are grabbed once for all clients (§3.2.2). The supply step hands each instance the
output of the profile it selected (:meth:`runtime.resources.instance.Instance.deliver`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..network.api import Subscription
from . import codec
from .buffers import Supplied, TripleBuffer
from .instance import Instance
from .spt import Frame, Topology

Source = Callable[[], Any]


@dataclass
class _Input:
    seq: int
    stamp: float  # acquisition time, wall clock
    data: Any


class Stream:
    """The profiles rooted at one acquisition plugin (§3.2.2): a Topology, a triple buffer and its instances."""

    def __init__(
        self,
        root: str,
        topology: Topology,
        period: float,
        supply: float | None,
        source: Source,
        *,
        asked: Callable[[], bool] | None = None,
        inputs: Sequence[Subscription] = (),
    ) -> None:
        self.root, self.topology, self.period, self.source = root, topology, period, source
        self.asked = asked  # a lazy stream's question: does a subscriber ask for an output (D245)
        self.inputs = list(inputs)  # asked for only while the stream works (passive while it rests)
        self.asking = asked is None
        self.rested = 0  # periods a lazy stream took nothing
        self.instances: dict[str, Instance] = {}
        self.lock = threading.Lock()
        self._seq = 0
        self._last_processed = -1
        self.busy_cpu = 0.0
        self.errors = 0
        self.buffer: TripleBuffer[_Input, tuple[_Input, Frame, float] | None] = TripleBuffer(
            self._acquire,
            self._process,
            self._supply,
            acquire_period=period,
            supply_period=supply,
            repeat=False,
            name=f"stream-{root}",
        )

    def statistics(self) -> dict[str, Any]:
        """Frames processed, frames whose processing raised, frames the triple buffer dropped, periods rested."""
        return {
            "frames": self.topology.frames,
            "errors": self.errors,
            "dropped": self.buffer.stats().dropped,
            "rested": self.rested,
        }

    def _acquire(self, reuse: _Input | None) -> _Input:
        if self.asked is not None and not self._rouse():
            self.rested += 1
            self.source()  # what arrives meanwhile is taken and dropped: waking, the stream starts afresh
            return _Input(-1, time.time(), None)
        data = self.source()
        if data is not None:
            self._seq += 1
        return _Input(self._seq if data is not None else -1, time.time(), data)

    def _rouse(self) -> bool:
        """Whether a subscriber asks for an output now; ask for the inputs, or stop asking, to match (D245)."""
        wanted = self.asked is not None and self.asked()
        if wanted != self.asking:
            self.asking = wanted
            for subscription in self.inputs:
                subscription.demand(wanted)
            if wanted:
                with self.lock:
                    instances = list(self.instances.values())
                for instance in instances:
                    instance.resume()
        return wanted

    def _process(self, item: _Input) -> tuple[_Input, Frame, float] | None:
        if item.data is None or item.seq == self._last_processed:
            return None
        self._last_processed = item.seq
        start, began = time.thread_time(), time.perf_counter()
        try:
            frame = self.topology.run(item.data, item.stamp)
            return item, frame, time.perf_counter() - began
        except Exception:
            self.errors += 1
            raise
        finally:
            self.busy_cpu += time.thread_time() - start

    def _supply(self, supplied: Supplied[tuple[_Input, Frame, float] | None]) -> None:
        if supplied.value is None:
            return
        item, frame, latency = supplied.value
        with self.lock:
            instances = dict(self.instances)
        now = time.time()
        for key, value in frame.outputs.items():
            instance = instances.get(key)
            if instance is not None:
                instance.deliver(value, item.stamp, now, latency)


def newest_of(subscriptions: Mapping[str, Subscription]) -> Source:
    """A stream's acquisition from its input topics (codec-decoded), each sample taken once.

    One input: its newest value. Several (a fusion service): ``{input name: newest value or
    None}``. Either way None — nothing to process — until a sample arrives that the stream has
    not taken yet, so a frame is never processed twice. A sample that arrived before the
    stream last asked for its input (a lazy stream waking, D245) is not taken: it may be
    from before the rest (D249).
    """
    taken: dict[str, tuple[int, int]] = {}

    def latest() -> Any:
        samples = {name: sub.latest(since_ask=True) for name, sub in subscriptions.items()}
        fresh = {n: (s.source, s.seq) for n, s in samples.items() if s is not None}
        if not fresh or fresh == taken:
            return None
        taken.clear()
        taken.update(fresh)
        values = {n: None if s is None else codec.decode(s.value) for n, s in samples.items()}
        return next(iter(values.values())) if len(values) == 1 else values

    return latest
