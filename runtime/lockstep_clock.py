"""The shared clock of a lock-step run, as one process sees it (issue J point 5, D190, D220;
:mod:`runtime.lockstep` installs it and documents the protocol, :mod:`runtime.lockstep_frames` counts
the frames between its processes in the file's last two regions)."""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import heapq
import itertools
import logging
import math
import mmap
import os
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .lockstep_os import alive, drain, sender, unheld

LOG = logging.getLogger("ckm.lockstep")
VARIABLE = "CKM_LOCKSTEP"  # "DIRECTORY STEP_NS MASTER_PID MONO0 WALL0"
BLOCKS = 64  # processes of a run
SLOTS = 255  # participating threads per process
ROW = SLOTS + 1  # a block: pid, then the slots' wake-up times
HEADER = 2  # words before the blocks: the time (ns), the run processes started but not yet on the clock
PENDING = 1  # the header word counting them
RUNNING = -1  # a slot's value: the thread works now (holds the clock)
IDLE = 1 << 62  # an untimed wait, or a free slot
POLL = 0.5  # wall seconds a ticker or the master waits for a datagram before looking around
STALL = 10.0  # wall seconds without a move of the clock before the holders are logged
IDLE_PACE = 0.001  # wall seconds per STEP while no participant waits for a time
WAITING, FIRED, NOTIFIED = 0, 1, 2
GUIDS = 4  # network identities (transports) a process registers in the file (D220)
FIELDS = 3  # a process's count of frames with one peer process: its pid, frames sent to it, arrived from it
WORDS = HEADER + BLOCKS * ROW + BLOCKS * GUIDS + BLOCKS * BLOCKS * FIELDS  # the clock file, in int64 words
# slots of no thread (D220): frames arrived, handed to their subscribers at the next instant; threads started
# by a participant, until their first wait; transports waiting for the run's other transports
DELIVERY, NEWBORN, LINKS = SLOTS - 1, SLOTS - 2, SLOTS - 3
NEWBORN_WAIT = 0.5  # wall seconds a thread started by a participant holds the clock before its first wait at most
MERGE_NS = 5_000  # waits due within 5 µs of the earliest end at one move of the clock (D241)


def next_instant(deadlines: npt.NDArray[np.int64], now: int, step: int) -> int:
    """Where the master moves the clock from ``now`` (ns): to the latest wake-up within MERGE_NS of
    the earliest (D241); ``step`` ahead if nobody is due before. Processes compute the same period's
    releases a few hundred ns apart (each from its own start); one move ends them all, where one
    per release cost a round of wake-ups each: 273 moves per simulated second, not 111."""
    ahead = deadlines[deadlines > now]  # never back: a slot at RUNNING (-1) or a wait already due is no target
    due, limit = (int(ahead.min()) if ahead.size else IDLE), now + step
    if due > limit:  # nobody due within a step (IDLE: nobody waits for a time)
        return limit
    return int(ahead[ahead <= due + MERGE_NS].max())  # a cluster may end up to MERGE_NS past the step


_REAL: dict[str, Callable[..., Any]] = {}  # the wall clocks, kept before any patch


def to_ns(seconds: float) -> int:
    """Whole nanoseconds, rounded up: a wait never ends before its time."""
    return math.ceil(seconds * 1e9)


class Entry:
    """One wait: the lock its thread sleeps on, when it ends, and the slot it holds."""

    __slots__ = ("deadline", "slot", "state", "waiter")

    def __init__(self, waiter: Any, deadline: int, slot: int | None) -> None:
        self.waiter, self.deadline, self.slot, self.state = waiter, deadline, slot, WAITING


class _Farewell:
    """Kept in a participant's thread-local storage: frees its slot when the thread ends."""

    def __init__(self, clock: SharedClock, slot: int) -> None:
        self.clock, self.slot = clock, slot

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.clock.release_slot(self.slot)


class SharedClock:
    """This process's view of the run's lock-step clock (see the module docstring)."""

    def __init__(self, directory: Path, step_ns: int, master: int, mono0: float, wall0: float) -> None:
        self.directory, self.step_ns, self.master = directory, step_ns, master
        self.mono0, self.wall0 = mono0, wall0
        self._file = os.open(directory / "clock", os.O_RDWR)
        self._map = mmap.mmap(self._file, 8 * WORDS)
        self.words: npt.NDArray[np.int64] = np.frombuffer(self._map, dtype=np.int64)
        self.blocks = self.words[HEADER : HEADER + BLOCKS * ROW].reshape(BLOCKS, ROW)
        start = HEADER + BLOCKS * ROW
        self.guids = self.words[start : start + BLOCKS * GUIDS].reshape(BLOCKS, GUIDS)
        self.counts = self.words[start + BLOCKS * GUIDS :].reshape(BLOCKS, BLOCKS, FIELDS)
        self.observer = False
        self.orphaned: tuple[int, float] | None = None  # (clock ns, wall monotonic) when the master went
        self._reset()

    def _reset(self) -> None:
        """Per-process state (again in a forked child: the parent's block and ticker are not its own)."""
        self.lock = threading.Lock()
        self.block: int | None = None
        self.heap: list[tuple[int, int, Entry]] = []
        self.entries: dict[Any, Entry] = {}
        self.order = itertools.count()
        self.free = list(range(LINKS - 1, -1, -1))
        self.newborns: dict[threading.Thread, float] = {}  # started by a participant: wall time their hold lapses
        self.reserved = {DELIVERY: IDLE, NEWBORN: IDLE, LINKS: IDLE}
        self.threads: dict[int, threading.Thread] = {}
        self.local = threading.local()
        self.sock: socket.socket | None = None
        self.poker: socket.socket | None = None  # its own, blocking: the ticker's socket changes modes
        self._master_address = str(self.directory / "m")
        self.before_fire: Callable[[int], None] | None = None  # frames handed over at a move (lockstep_frames)

    # ------------------------------------------------------------------ time

    def now(self) -> int:
        """The run's simulated time, ns since its origin."""
        if self.orphaned is not None:
            ns, wall = self.orphaned
            return ns + to_ns(_REAL["monotonic"]() - wall)
        return int(self.words[0])

    def seconds(self) -> float:
        """The simulated time in seconds since the run's origin."""
        return self.now() * 1e-9

    # ------------------------------------------------------------------ this process's block

    def _claim(self) -> int:
        """This process's block (claimed on first need, under the file's lock)."""
        if self.block is not None:
            return self.block
        fcntl.flock(self._file, fcntl.LOCK_EX)
        try:
            for index in range(BLOCKS):
                pid = int(self.blocks[index, 0])
                if pid == 0 or not alive(pid):
                    self.blocks[index, 1:] = IDLE
                    self.guids[index] = 0  # a dead process's transports and counts are not ours
                    self.counts[index] = 0
                    self.blocks[index, 0] = os.getpid()
                    break
            else:
                raise RuntimeError(f"lock-step clock: more than {BLOCKS} processes in one run")
        finally:
            fcntl.flock(self._file, fcntl.LOCK_UN)
        self.block = index
        atexit.register(self.leave_clock)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        path = self.directory / f"p{os.getpid()}"
        path.unlink(missing_ok=True)
        self.sock.bind(str(path))
        self.sock.settimeout(POLL)
        self.poker = sender(POLL)
        unheld(threading.Thread(target=self._tick, name="ckm-lockstep-ticker", daemon=True)).start()
        return index

    def expect(self, change: int) -> None:
        """Count a ckm-run process started (+1) or on the clock (-1): the master waits for it."""
        fcntl.flock(self._file, fcntl.LOCK_EX)
        try:
            self.words[PENDING] = max(0, int(self.words[PENDING]) + change)
        finally:
            fcntl.flock(self._file, fcntl.LOCK_UN)
        if change < 0:
            self._claim()
            self.poke()

    def participant(self, thread: threading.Thread | None = None) -> int | None:
        """The calling thread's slot, made on its first call (None: an observer process, or full)."""
        slot: int | None = getattr(self.local, "slot", None)
        if slot is not None or self.observer or self.orphaned is not None or getattr(self.local, "unclocked", False):
            return slot
        block = self._claim()
        with self.lock:
            if not self.free:
                return None
            slot = self.free.pop()
            self.threads[slot] = thread or threading.current_thread()
            self.blocks[block, 1 + slot] = RUNNING
        self.local.slot = slot
        self.local.farewell = _Farewell(self, slot)
        return slot

    def leave_clock(self) -> None:
        """At this process's end: none of its threads holds the clock any more."""
        block, self.block = self.block, None
        if block is not None and int(self.blocks[block, 0]) == os.getpid():
            self.blocks[block, 1:] = IDLE
            self.blocks[block, 0] = 0
            self.poke()

    def release_slot(self, slot: int) -> None:
        """Free a participant's slot (its thread ended)."""
        with self.lock:
            if self.threads.pop(slot, None) is not None and self.block is not None:
                self.blocks[self.block, 1 + slot] = IDLE
                self.free.append(slot)
        self.poke()

    def hold(self, slot: int, value: int) -> None:
        """Set a participant's slot (``RUNNING``, or the time it waits for) and tell the master."""
        with self.lock:
            self._mark(slot, value)
        self.poke()

    def _mark(self, slot: int | None, value: int) -> None:
        if slot is not None and self.block is not None:
            self.blocks[self.block, 1 + slot] = value

    def reserve(self, slot: int, value: int) -> None:
        """Set one of the slots of no thread (``DELIVERY``, ``NEWBORN``, ``LINKS``: D220) and tell the master."""
        self._claim()
        with self.lock:
            self.reserved[slot] = value
            self._mark(slot, value)
        self.poke()

    # ------------------------------------------------------------------ threads started by a participant

    def newborn(self, thread: threading.Thread) -> None:
        """``thread``, started by a participant, holds the clock until its first wait or its end (D220):
        a thread's first steps take wall time the clock must not move in (a supervisor before its first
        poll), but one blocked in a socket call never waits on the clock, so the hold lapses after
        ``NEWBORN_WAIT`` wall seconds."""
        with self.lock:
            first = not self.newborns
            self.newborns[thread] = _REAL["monotonic"]() + NEWBORN_WAIT
        if first:
            self.reserve(NEWBORN, RUNNING)

    def born(self, thread: threading.Thread, lapsed: bool = False) -> None:
        """``thread`` waits (or ended, or its hold lapsed): it no longer holds the clock as a newborn."""
        with self.lock:
            if self.newborns.pop(thread, None) is None:
                return
            last = not self.newborns
        if lapsed:
            LOG.info(
                "lock-step clock: thread %s did not wait in %g s (a socket call?): the clock goes on",
                thread.name,
                NEWBORN_WAIT,
            )
        if last:
            self.reserve(NEWBORN, IDLE)

    def _lapse(self) -> float:
        """End the newborns' holds that lapsed; the wall seconds until the next one lapses (or ``POLL``)."""
        wall: float = _REAL["monotonic"]()
        with self.lock:
            items = list(self.newborns.items())
        for thread, until in items:
            if until <= wall or not thread.is_alive():
                self.born(thread, lapsed=thread.is_alive())
        with self.lock:
            soonest = min(self.newborns.values(), default=wall + POLL)
        return min(POLL, max(0.01, soonest - wall))

    def poke(self) -> None:
        """Tell the master a slot changed (it may now advance)."""
        if self.poker is not None:
            with contextlib.suppress(OSError):
                self.poker.sendto(b".", self._master_address)

    # ------------------------------------------------------------------ waits

    def enter(self, waiter: Any, timeout: float | None) -> Entry:
        """Register a wait on ``waiter`` (a locked lock) for ``timeout`` simulated seconds (None: untimed)."""
        slot = self.participant() if timeout is not None else getattr(self.local, "slot", None)
        self._claim()
        deadline = IDLE if timeout is None else self.now() + to_ns(max(0.0, timeout)) + 1
        entry = Entry(waiter, deadline, slot)
        with self.lock:
            self.entries[waiter] = entry
            if deadline != IDLE:
                heapq.heappush(self.heap, (deadline, next(self.order), entry))
            self._mark(slot, deadline)
            if self.now() >= deadline:  # the clock passed it already (an observer's wait)
                self._fire(entry)
        if slot is not None:
            self.poke()
        return entry

    def leave(self, entry: Entry) -> bool:
        """After the wait: True if a notify ended it (not its time)."""
        with self.lock:
            self.entries.pop(entry.waiter, None)
            if entry.state == WAITING:  # woken some other way (never here): treat as a timeout
                entry.state = FIRED
            self._mark(entry.slot, RUNNING)
        return entry.state == NOTIFIED

    def _fire(self, entry: Entry) -> None:
        """End a wait at its time (with ``lock`` held)."""
        if entry.state != WAITING:
            return
        entry.state = FIRED
        self._mark(entry.slot, RUNNING)  # before it wakes: the master must wait for it
        with contextlib.suppress(RuntimeError):
            entry.waiter.release()

    def notified(self, waiter: Any) -> bool:
        """A notify releases ``waiter``: False if its wait already ended at its time (skip it)."""
        with self.lock:
            entry = self.entries.get(waiter)
            if entry is None:
                return True
            if entry.state != WAITING:
                return False
            entry.state = NOTIFIED
            self._mark(entry.slot, RUNNING)
            return True

    # ------------------------------------------------------------------ the ticker

    def _tick(self) -> None:
        sock = self.sock
        assert sock is not None
        self.local.unclocked = True  # what it hands over (frames: D220) may sleep: on the wall clock here
        last, moved = -1, _REAL["monotonic"]()
        while True:
            try:
                sock.recv(16)
                drain(sock, self._lapse() if self.newborns else POLL)
            except TimeoutError:
                if self.newborns:
                    sock.settimeout(self._lapse())
                if not alive(self.master):
                    self._orphan()
                    return
            except OSError:
                return
            now = self.fire_due()
            with self.lock:
                for slot, thread in list(self.threads.items()):
                    if not thread.is_alive():
                        self.threads.pop(slot)
                        self._mark(slot, IDLE)
                        self.free.append(slot)
            wall = _REAL["monotonic"]()
            if now != last:
                last, moved = now, wall
            elif wall - moved > STALL:
                moved = wall
                self._log_holders(now)

    def fire_due(self) -> int:
        """End every wait of this process whose time has come (after handing over the frames that
        arrived before the move: D220); the time now."""
        now = self.now()
        if self.before_fire is not None:
            self.before_fire(now)
        with self.lock:
            while self.heap and self.heap[0][0] <= now:
                self._fire(heapq.heappop(self.heap)[2])
        return now

    def _log_holders(self, now: int) -> None:
        if self.block is None:
            return
        held = [t.name for s, t in self.threads.items() if int(self.blocks[self.block, 1 + s]) <= now]
        names = {DELIVERY: "frames to hand over", NEWBORN: "threads not yet waiting", LINKS: "transports linking"}
        held += [names[s] for s, value in self.reserved.items() if value <= now]
        if held:
            LOG.warning(
                "lock-step clock at %.3f s held for %g s by this process's %s", now * 1e-9, STALL, ", ".join(held)
            )

    def _orphan(self) -> None:
        """The master is gone: the wall clock from here on; every wait ends."""
        LOG.error("lock-step clock: the run's master %d is gone; this process runs on the wall clock", self.master)
        with self.lock:
            self.orphaned = (int(self.words[0]), _REAL["monotonic"]())
            self.newborns.clear()
            for _, _, entry in self.heap:
                self._fire(entry)
            self.heap.clear()
        if self.before_fire is not None:  # the frames kept for the next instant: now (D220)
            self.before_fire(IDLE)

    def after_fork(self) -> None:
        """In a forked child: nothing of the parent's block is ours."""
        self._reset()
