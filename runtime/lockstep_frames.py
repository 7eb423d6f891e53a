"""Frames between the processes of a lock-step run (issue J point 5, ``ckm-run --lockstep``, D190, D220).

D190's clock waits for every participating thread but not for the messages between processes: a
TOPICDATA sample in flight when the clock moved reached its subscribers an instant later, so a
partitioned run differed between two runs. Here every process of the run counts, in its own row of
the clock file, the TOPICDATA and TOPICLINKS frames it *sent* to each other process of the run and
those that *arrived* from each (keyed by the peer's pid: a fan-out to N subscribers in M processes is
one frame per link, counted once at each end; a restarted process is a new row). The master advances
only when every pair of live processes agrees (sent to == arrived from), so no frame is in flight
when the clock moves; a frame missing after ``FRAME_WAIT`` wall seconds (a link that broke with
frames in its buffer) is forgiven, logged once, and the run goes on. A best-effort sample dropped
by its sender (a busy link) is never counted; one a subscriber's lifespan or history drops has
arrived and counts.

An arrived frame is not handed to the transport at once but at the clock's next instant, 1 ns
later (its process's ``DELIVERY`` slot asks for it), before any wait due then ends: whether a task
of another process released at the instant the frame was sent sees it would otherwise depend on the
wall clock; this way it never does, and sees it from the next instant on. Network identities (the
transports' GUIDs) are registered in the file, so frames to or from peers outside the run (not on
its clock) are not counted, and a process's transport holds the clock until it heard TOPICLINKS
from every other transport of the run: a partition's samples then flow from its first one.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Collection
from typing import Any

import numpy as np
import numpy.typing as npt

from .lockstep_clock import _REAL, DELIVERY, GUIDS, IDLE, LINKS, LOG, RUNNING, SharedClock
from .lockstep_os import unheld

FRAME_WAIT = 2.0  # wall seconds the master waits for a frame sent but not arrived before forgiving it
LINK_WAIT = 20.0  # wall seconds a new transport holds the clock for the run's other transports at most
LINK_POLL = 0.005  # wall seconds between its looks at what it heard


def _wall(name: str) -> Callable[..., Any]:
    """The wall clock's ``time.NAME`` (the patched one is the run's clock once installed)."""
    function: Callable[..., Any] = _REAL.get(name) or getattr(time, name)
    return function


class Settling:
    """The master's side: whether every frame sent between two live processes has arrived."""

    def __init__(self, clock: SharedClock) -> None:
        self.clock = clock
        self.forgiven: dict[tuple[int, int], int] = {}  # (sender pid, receiver pid) → frames given up
        self.since: float | None = None  # wall time the clock first waited for frames, this instant
        self.logged = False
        self.lost = 0

    def settled(self, live: npt.NDArray[np.bool_]) -> bool:
        """True when no frame is in flight between the processes of ``live`` blocks (or only forgiven ones)."""
        pids = self.clock.blocks[live, 0]
        rows = self.clock.counts[live]
        # a pair counts while its receiver has a transport: one that stopped takes no more frames (a run's end)
        receiving = np.count_nonzero(self.clock.guids[live], axis=1) > 0
        known = (rows[:, :, 0] != 0) & np.isin(rows[:, :, 0], pids[receiving])  # sent, to a receiving process
        known_in = (rows[:, :, 0] != 0) & np.isin(rows[:, :, 0], pids) & receiving[:, None]  # arrived at one
        in_flight = int(rows[:, :, 1][known].sum()) - int(rows[:, :, 2][known_in].sum())
        if in_flight <= 0:  # (never below: a frame is counted sent before it can arrive)
            self.since = None
            self.forgiven.clear()  # a forgiven frame that arrived after all is not forgiven twice
            return True
        if self.forgiven and self._forgiven(pids, rows, (known, known_in)) >= in_flight:
            self.since = None
            return True
        wall = _wall("monotonic")()
        if self.since is None:
            self.since = wall
        elif wall - self.since > FRAME_WAIT:
            self._forgive(pids, rows, (known, known_in))
            self.since = None
            return True
        return False

    def _pairs(self, pids: npt.NDArray[np.int64], rows: npt.NDArray[np.int64],
               masks: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]) -> dict[tuple[int, int], int]:  # fmt: skip
        """Frames in flight per (sender pid, receiver pid)."""
        sent: dict[tuple[int, int], int] = {}
        arrived: dict[tuple[int, int], int] = {}
        for row, pid in enumerate(pids.tolist()):
            for peer, out, _ in rows[row][masks[0][row]].tolist():
                sent[(pid, peer)] = out
            for peer, _, into in rows[row][masks[1][row]].tolist():
                arrived[(peer, pid)] = into
        return {pair: out - arrived.get(pair, 0) for pair, out in sent.items() if out > arrived.get(pair, 0)}

    def _forgiven(self, pids: npt.NDArray[np.int64], rows: npt.NDArray[np.int64],
                  masks: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]) -> int:  # fmt: skip
        """Frames forgiven still in flight (a late one that arrived after all is no longer forgiven)."""
        flying = self._pairs(pids, rows, masks)
        self.forgiven = {pair: min(count, flying[pair]) for pair, count in self.forgiven.items() if pair in flying}
        return sum(self.forgiven.values())

    def _forgive(self, pids: npt.NDArray[np.int64], rows: npt.NDArray[np.int64],
                 masks: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]) -> None:  # fmt: skip
        flying = self._pairs(pids, rows, masks)
        lost = sum(flying.values()) - sum(self.forgiven.get(pair, 0) for pair in flying)
        self.lost += lost
        self.forgiven = flying
        if not self.logged:
            self.logged = True
            LOG.warning("lock-step clock at %.3f s: %d frame(s) between processes %s not arrived after %g s: "
                        "forgiven, the clock goes on (logged once)", self.clock.now() * 1e-9, lost,
                        sorted(flying), FRAME_WAIT)  # fmt: skip


class Ledger:
    """One process's side: its transports' GUIDs, its counts and the frames waiting for the next instant."""

    def __init__(self, clock: SharedClock) -> None:
        self.clock = clock
        self.lock = threading.Lock()
        self.rows: dict[int, int] = {}  # peer pid → its entry in this process's row of counts
        self.known: dict[int, int] = {}  # guid → pid, as last found registered
        self.deferred: list[tuple[int, Callable[[], None]]] = []  # (instant it arrived at, hand it over)
        self.holding = 0  # transports waiting for the run's other transports
        clock.before_fire = self.flush

    # ------------------------------------------------------------------ identities

    def register(self, guid: int) -> None:
        """A transport of this process, on the run's clock: frames to and from it count."""
        block = self.clock._claim()
        with self.lock:
            row = self.clock.guids[block]
            free = np.flatnonzero(row == 0)
            if guid in row.tolist():
                return
            if not len(free):
                LOG.warning("lock-step clock: more than %d transports in process %d: %d is not counted",
                            GUIDS, os.getpid(), guid)  # fmt: skip
                return
            row[int(free[0])] = guid

    def unregister(self, guid: int) -> None:
        """A transport stopped: frames to it no longer count."""
        block = self.clock.block
        if block is not None:
            with self.lock:
                row = self.clock.guids[block]
                row[row == guid] = 0

    def pid(self, guid: int, stopped: bool = False) -> int | None:
        """The pid of the live process of this run whose transport ``guid`` is, or None (not on the clock);
        ``stopped``: also of a transport that stopped since (its last frames still arrive and count)."""
        blocks = np.flatnonzero((self.clock.guids == guid).any(axis=1))
        for block in blocks.tolist():
            pid = int(self.clock.blocks[block, 0])
            if pid:
                self.known[guid] = pid
                return pid
        last = self.known.get(guid)
        if stopped and last is not None and last in self.clock.blocks[:, 0]:
            return last
        return None

    def peers(self, own: int) -> set[int]:
        """The GUIDs of the run's other live transports."""
        live = self.clock.blocks[:, 0] != 0
        return {int(g) for g in self.clock.guids[live].ravel().tolist() if g and g != own}

    def _entry(self, pid: int) -> int:
        """This process's entry for ``pid`` (made on first use; with ``lock`` held)."""
        entry = self.rows.get(pid)
        if entry is None:
            block = self.clock._claim()
            counts = self.clock.counts[block]
            used = set(self.rows.values())
            live = {int(p) for p in self.clock.blocks[:, 0].tolist() if p}
            entry = next(i for i in range(len(counts)) if i not in used or int(counts[i, 0]) not in live)
            for old in [p for p, i in self.rows.items() if i == entry]:
                del self.rows[old]
            counts[entry, 1:] = 0
            counts[entry, 0] = pid  # last: the master reads an entry by its pid
            self.rows[pid] = entry
        return entry

    # ------------------------------------------------------------------ counting

    def sending(self, guid: int) -> bool:
        """Count a frame about to be sent to ``guid`` (before it is written: it can arrive at once);
        False if ``guid`` is not on the clock (nothing counted)."""
        pid = self.pid(guid)
        if pid is None or self.clock.block is None:
            return False
        with self.lock:
            self.clock.counts[self.clock.block, self._entry(pid), 1] += 1
        return True

    def unsent(self, guid: int) -> None:
        """A frame counted by :meth:`sending` could not be written (the link closed, a busy best-effort link)."""
        pid = self.pid(guid)
        if pid is not None and self.clock.block is not None:
            with self.lock:
                self.clock.counts[self.clock.block, self._entry(pid), 1] -= 1

    def arrived(self, guid: int, hand_over: Callable[[], None]) -> bool:
        """A frame from ``guid`` arrived: if it is on the clock, counted and ``hand_over`` kept for the
        next instant (True); else False (the caller hands it over now)."""
        pid = self.pid(guid, stopped=True)
        if pid is None or self.clock.block is None or self.clock.orphaned is not None:
            return False
        with self.lock:
            now = self.clock.now()
            self.deferred.append((now, hand_over))
            if self.clock.reserved[DELIVERY] > now + 1:  # first: the master moves only to the next instant
                self.clock.reserved[DELIVERY] = now + 1
                self.clock._mark(DELIVERY, now + 1)
            self.clock.counts[self.clock.block, self._entry(pid), 2] += 1
        self.clock.poke()
        return True

    def flush(self, now: int) -> None:
        """At a move (the ticker, before the waits due end): hand over the frames that arrived before
        ``now``; the ``DELIVERY`` slot holds the clock until they are."""
        with self.lock:
            due = [item for item in self.deferred if item[0] < now]
            if not due:
                return
            self.deferred = [item for item in self.deferred if item[0] >= now]
        for _, hand_over in due:
            try:
                hand_over()
            except Exception:
                LOG.exception("lock-step clock: handing over a frame failed")
        with self.lock:
            soonest = min((at + 1 for at, _ in self.deferred), default=IDLE)
            self.clock.reserved[DELIVERY] = soonest
            self.clock._mark(DELIVERY, soonest)
        self.clock.poke()

    # ------------------------------------------------------------------ linking

    def hold_links(self, guid: int, heard: Callable[[], Collection[int]]) -> None:
        """Hold the clock until transport ``guid`` heard (TOPICLINKS) every other transport of the run, at
        most ``LINK_WAIT`` wall seconds: the run does not go on while its links form on the wall clock."""
        with self.lock:
            self.holding += 1
            first = self.holding == 1
        if first:
            self.clock.reserve(LINKS, RUNNING)
        unheld(threading.Thread(target=self._await_links, args=(guid, heard), name="ckm-lockstep-links",
                                daemon=True)).start()  # fmt: skip

    def _await_links(self, guid: int, heard: Callable[[], Collection[int]]) -> None:
        self.clock.local.unclocked = True
        end = _wall("monotonic")() + LINK_WAIT
        try:
            while not self.peers(guid) <= set(heard()):
                if _wall("monotonic")() > end:
                    missing = sorted(self.peers(guid) - set(heard()))
                    LOG.warning("lock-step clock: transport %d did not hear the run's transports %s in %g s: "
                                "the clock goes on", guid, missing, LINK_WAIT)  # fmt: skip
                    return
                _wall("sleep")(LINK_POLL)
        finally:
            with self.lock:
                self.holding -= 1
                last = self.holding == 0
            if last:
                self.clock.reserve(LINKS, IDLE)


_ledger: Ledger | None = None
_ledger_lock = threading.Lock()


def ledger(clock: SharedClock | None) -> Ledger | None:
    """This process's ledger on ``clock`` (made on first use), or None off lock-step."""
    global _ledger
    if clock is None or clock.observer:
        return None
    with _ledger_lock:
        if _ledger is None or _ledger.clock is not clock:
            _ledger = Ledger(clock)
        return _ledger


def _forget() -> None:
    """In a forked child: the parent's transports, counts and frames are not its own."""
    global _ledger, _ledger_lock
    if _ledger is not None:
        _ledger.clock.before_fire = None
    _ledger, _ledger_lock = None, threading.Lock()


os.register_at_fork(after_in_child=_forget)
