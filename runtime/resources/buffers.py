"""The triple buffer of a Smart Device (thesis §3.2.3, Fig. 3.12): acquire, process and supply slots.

Acquisition (a producer callback at a fixed period), processing (the SPT, usually slower) and
supply (a consumer or publisher at a fixed period) each work on a slot of their own; the slots
rotate acquire → process → supply → acquire, so the same three buffers are reused and the producer
can write its next frame in place. Five threads:

- ``acquire``: calls ``acquire(reuse)`` every ``acquire_period`` into the acquire slot. A frame
  still unprocessed there is overwritten and counted as *dropped*: a slow processor costs frames,
  never the acquisition rate.
- ``switch-ap`` (the acquire↔process switching thread): as soon as the acquire slot holds a fresh
  frame, the acquisition is between writes and the processor is idle with an empty slot, it
  swaps the two slots and wakes the processor.
- ``process``: runs ``process(data)`` on the process slot and stores the result in that slot.
- ``switch-ps`` (the process↔supply switching thread): as soon as the process slot holds a
  complete result and the supply is between reads, it swaps the two slots; a result replaced
  before any supply tick read it is counted as *skipped*. The processor gets the old supply slot,
  empty, which the next acquire↔process switch hands on to the acquisition for reuse.
- ``supply``: every ``supply_period`` calls ``supply(Supplied)`` with the supply slot's result,
  the newest complete one; with no newer result it supplies the same one again (``repeated``)
  unless ``repeat=False``, so a publisher keeps its fixed rate. ``supply_period=None`` supplies
  each result as soon as the process↔supply switch hands it over (``repeat=False`` then): a Smart
  Resource's stream publishes what it computed at once, where a short fixed poll woke its supply
  thread 8 times per frame for nothing (D234).

The switching threads swap as soon as a switch is due; before the acquisition (or the supply)
takes its slot again it lets a due switch happen first, a wait bounded by the switching thread's
wake-up (at most ``wait``). Otherwise an acquisition running back to back could overwrite every
fresh frame before the switching thread got the lock, and the processor would starve.

Why no read is ever torn. The slot indices of the three roles are a permutation of 0, 1, 2, only
changed under the lock. A role marks itself busy under the lock, then reads or writes its own
slot's buffers outside the lock, then clears the mark under the lock; the switching threads only
swap two roles when neither is busy. So a slot changes hands only between complete writes and
complete reads, and no slot is ever written by one thread while another reads it. A result is
marked complete (under the lock) only after ``process`` returned, so the supply only ever sees
whole results, and since the lock orders every hand-over, it also sees every write made before it.
Frames go through the processor in acquisition order and results reach the supply slot in
processing order, so the consumer sees frame numbers that never decrease.

Values handed to ``supply`` are valid during the call: their slot is recycled afterwards (copy to
keep). Every wait is bounded; ``stop()`` joins each thread with a time budget and says whether all
ended (a ``process`` call longer than the budget keeps its daemon thread until it returns).
"""

from __future__ import annotations

import enum
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Generic, TypeVar, cast

T = TypeVar("T")
R = TypeVar("R")

_LOG = logging.getLogger(__name__)


class SlotState(enum.Enum):
    """What a slot of the triple buffer holds (§3.2.3): nothing, a fresh frame, a result, a supplied result."""

    EMPTY = "empty"  # nothing useful (its buffers may be reused)
    FRESH = "fresh"  # an acquired frame not processed yet
    DONE = "done"  # a complete result not supplied yet
    SUPPLIED = "supplied"  # a complete result already supplied at least once


@dataclass
class Slot(Generic[T, R]):
    """One of the three buffers: a frame, its result, and where it stands."""

    data: T | None = None
    result: R | None = None
    frame: int = -1
    stamp: float = 0.0
    state: SlotState = SlotState.EMPTY


@dataclass(frozen=True)
class Supplied(Generic[R]):
    """What the supply callback gets: a complete result, the frame it came from and its acquisition time."""

    frame: int
    stamp: float
    value: R
    repeated: bool


@dataclass
class BufferStats:
    """Counters of a triple buffer (see the module docstring for dropped and skipped)."""

    acquired: int = 0
    processed: int = 0
    supplied: int = 0
    repeated: int = 0
    dropped: int = 0
    skipped: int = 0
    idle: int = 0  # supply ticks before any result existed (or repeats suppressed)
    switches_ap: int = 0
    switches_ps: int = 0
    overruns: dict[str, int] = field(default_factory=lambda: {"acquire": 0, "supply": 0})
    errors: dict[str, int] = field(default_factory=lambda: {"acquire": 0, "process": 0, "supply": 0})


class TripleBuffer(Generic[T, R]):
    """Acquisition and supply at fixed rates around a slower processing step (§3.2.3, Fig. 3.12).

    ``acquire(reuse)`` returns the next frame; ``reuse`` is the frame this slot held before (None
    at first), which the producer may overwrite in place and return. ``process(frame)`` returns
    the result. ``supply(Supplied)`` consumes it. Exceptions in any of them are counted in
    ``stats().errors`` (``last_error`` keeps the latest) and the loops go on; a failed frame is lost.
    """

    def __init__(
        self,
        acquire: Callable[[T | None], T],
        process: Callable[[T], R],
        supply: Callable[[Supplied[R]], None],
        *,
        acquire_period: float,
        supply_period: float | None,
        repeat: bool = True,
        name: str = "triple-buffer",
        wait: float = 0.1,
    ) -> None:
        if not (acquire_period > 0 and (supply_period is None or supply_period > 0) and wait > 0):
            raise ValueError("triple buffer: periods and wait must be greater than 0")
        if supply_period is None and repeat:
            raise ValueError("triple buffer: a supply on arrival (no supply period) cannot repeat a result")
        self._acquire = acquire
        self._process = process
        self._supply = supply
        self.acquire_period = acquire_period
        self.supply_period = supply_period
        self.repeat = repeat
        self.name = name
        self._wait = wait
        self._slots: list[Slot[T, R]] = [Slot(), Slot(), Slot()]
        self._acq, self._proc, self._sup = 0, 1, 2
        self._acq_busy = self._proc_busy = self._sup_busy = False
        self._lock = threading.Lock()
        self._to_switch_ap = threading.Condition(self._lock)
        self._to_process = threading.Condition(self._lock)
        self._to_switch_ps = threading.Condition(self._lock)
        self._to_supply = threading.Condition(self._lock)  # a result switched in (supply on arrival)
        self._switched = threading.Condition(self._lock)
        self._stopping = threading.Event()
        self._threads: list[threading.Thread] = []
        self._stats = BufferStats()
        self.last_error: BaseException | None = None

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start the acquire, process and supply threads and the two switch threads (Fig. 3.12)."""
        if self._threads:
            raise RuntimeError(f"{self.name} is already started")
        self._stopping.clear()
        loops = {
            "acquire": self._acquire_loop,
            "switch-ap": self._switch_ap_loop,
            "process": self._process_loop,
            "switch-ps": self._switch_ps_loop,
            "supply": self._supply_loop,
        }
        for role, loop in loops.items():
            thread = threading.Thread(target=loop, name=f"{self.name}.{role}", daemon=True)
            self._threads.append(thread)
            thread.start()

    def stop(self, timeout: float = 2.0) -> bool:
        """Stop every thread, waiting at most ``timeout`` seconds in all; True if all of them ended."""
        self._stopping.set()
        with self._lock:
            conditions = (self._to_switch_ap, self._to_process, self._to_switch_ps, self._switched, self._to_supply)
            for condition in conditions:
                condition.notify_all()
        end = time.monotonic() + timeout
        for thread in self._threads:
            thread.join(max(0.0, end - time.monotonic()))
        alive = [t for t in self._threads if t.is_alive()]
        if not alive:
            self._threads = []
        return not alive

    @property
    def running(self) -> bool:
        """True while any of the buffer's threads is alive."""
        return any(t.is_alive() for t in self._threads)

    def __enter__(self) -> TripleBuffer[T, R]:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stats(self) -> BufferStats:
        """A copy of the counters."""
        with self._lock:
            return replace(self._stats, overruns=dict(self._stats.overruns), errors=dict(self._stats.errors))

    # ------------------------------------------------------------------ the two fixed-rate ends

    def _pace(self, deadline: float, period: float, role: str) -> float:
        """Sleep until ``deadline``; more than a period late, skip the missed ticks (not bunch them)."""
        now = time.monotonic()
        if deadline > now:
            self._stopping.wait(deadline - now)
            return deadline
        if now - deadline > period:
            with self._lock:
                self._stats.overruns[role] += 1
            return now
        return deadline

    def _failed(self, role: str, exc: BaseException) -> None:
        """Count a callback failure (called with the lock held)."""
        self._stats.errors[role] += 1
        self.last_error = exc
        _LOG.warning("%s: %s callback failed: %r", self.name, role, exc)

    def _ap_pending(self) -> bool:
        """The acquire↔process switch can happen now (lock held)."""
        return (
            self._slots[self._acq].state is SlotState.FRESH
            and not self._acq_busy
            and self._slots[self._proc].state is SlotState.EMPTY
            and not self._proc_busy
        )

    def _ps_pending(self) -> bool:
        """The process↔supply switch can happen now (lock held)."""
        return self._slots[self._proc].state is SlotState.DONE and not self._proc_busy and not self._sup_busy

    def _let_switch(self, pending: Callable[[], bool]) -> None:
        """Before taking its slot again, a fixed-rate end lets a due switch happen (lock held).

        Without this an acquisition running back to back would overwrite its fresh frame before the
        switching thread got the lock, and the processor would starve; the wait is the switching
        thread's wake-up time, bounded by ``wait``.
        """
        end = time.monotonic() + self._wait
        while pending() and not self._stopping.is_set():
            remaining = end - time.monotonic()
            if remaining <= 0:
                return
            self._switched.wait(remaining)

    def _acquire_loop(self) -> None:
        deadline = time.monotonic()
        while not self._stopping.is_set():
            with self._lock:
                self._let_switch(self._ap_pending)
                slot = self._slots[self._acq]
                self._acq_busy = True
                if slot.state is SlotState.FRESH:  # the processor never took it: overwritten
                    self._stats.dropped += 1
                slot.state = SlotState.EMPTY
                reuse = slot.data
            stamp = time.monotonic()
            try:
                data = self._acquire(reuse)
            except Exception as exc:
                with self._lock:
                    self._acq_busy = False
                    self._failed("acquire", exc)
            else:
                with self._lock:
                    slot.data, slot.stamp, slot.state = data, stamp, SlotState.FRESH
                    slot.frame = self._stats.acquired
                    self._stats.acquired += 1
                    self._acq_busy = False
                    self._to_switch_ap.notify()
            deadline = self._pace(deadline + self.acquire_period, self.acquire_period, "acquire")

    def _supply_loop(self) -> None:
        deadline = time.monotonic()
        while not self._stopping.is_set():
            item: Supplied[R] | None = None
            with self._lock:
                if self.supply_period is None:  # on arrival: until a result is switched in
                    while not self._stopping.is_set() and self._slots[self._sup].state is not SlotState.DONE:
                        self._to_supply.wait(self._wait)
                    if self._stopping.is_set():
                        return
                else:
                    self._let_switch(self._ps_pending)  # so that the newest complete result is the one supplied
                slot = self._slots[self._sup]
                fresh = slot.state is SlotState.DONE
                if fresh or (self.repeat and slot.state is SlotState.SUPPLIED):
                    self._sup_busy = True
                    item = Supplied(slot.frame, slot.stamp, cast(R, slot.result), repeated=not fresh)
                    slot.state = SlotState.SUPPLIED
                else:
                    self._stats.idle += 1
            if item is not None:
                error: Exception | None = None
                try:
                    self._supply(item)
                except Exception as exc:
                    error = exc
                with self._lock:
                    self._sup_busy = False
                    if error is not None:
                        self._failed("supply", error)
                    else:
                        self._stats.supplied += 1
                        self._stats.repeated += 1 if item.repeated else 0
                    self._to_switch_ps.notify()
            if self.supply_period is not None:
                deadline = self._pace(deadline + self.supply_period, self.supply_period, "supply")

    # ------------------------------------------------------------------ processing and the two switches

    def _switch_ap_loop(self) -> None:
        with self._lock:
            while not self._stopping.is_set():
                if self._ap_pending():
                    self._acq, self._proc = self._proc, self._acq
                    self._stats.switches_ap += 1
                    self._to_process.notify()
                    self._switched.notify_all()
                else:
                    self._to_switch_ap.wait(self._wait)

    def _process_loop(self) -> None:
        while True:
            with self._lock:
                while not self._stopping.is_set() and self._slots[self._proc].state is not SlotState.FRESH:
                    self._to_process.wait(self._wait)
                if self._stopping.is_set():
                    return
                slot = self._slots[self._proc]
                self._proc_busy = True
                data = cast(T, slot.data)
            try:
                result = self._process(data)
            except Exception as exc:
                with self._lock:
                    slot.state = SlotState.EMPTY
                    self._proc_busy = False
                    self._failed("process", exc)
                    self._to_switch_ap.notify()
            else:
                with self._lock:
                    slot.result, slot.state = result, SlotState.DONE
                    self._stats.processed += 1
                    self._proc_busy = False
                    self._to_switch_ps.notify()

    def _switch_ps_loop(self) -> None:
        with self._lock:
            while not self._stopping.is_set():
                if self._ps_pending():
                    old = self._slots[self._sup]
                    if old.state is SlotState.DONE:  # a newer result arrived before any supply tick read it
                        self._stats.skipped += 1
                    old.state = SlotState.EMPTY
                    self._proc, self._sup = self._sup, self._proc
                    self._stats.switches_ps += 1
                    self._to_switch_ap.notify()
                    self._to_supply.notify()
                    self._switched.notify_all()
                else:
                    self._to_switch_ps.wait(self._wait)
