"""The master of a lock-step run's clock: the thread of the run's lead process that moves the time
(issue J point 5, D190, D220; the protocol is in :mod:`runtime.lockstep`'s docstring)."""

from __future__ import annotations

import contextlib
import os
import socket
import threading

import numpy as np
import numpy.typing as npt

from .lockstep_clock import (
    _REAL,
    IDLE,
    IDLE_PACE,
    LOG,
    PENDING,
    STALL,
    SharedClock,
    unheld,
)
from .lockstep_frames import Settling
from .lockstep_os import alive, nonblocking_sender

RETICK = 0.2  # wall seconds without a move before the holders are woken again
START_WAIT = 60.0  # wall seconds the clock waits for a started ckm-run process to join it


class Master:
    """Advances the shared clock (a thread of the run's lead process)."""

    def __init__(self, clock: SharedClock) -> None:
        self.clock = clock
        self.moves = 0
        self.settling = Settling(clock)
        self.tx = nonblocking_sender()
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        path = clock.directory / "m"
        path.unlink(missing_ok=True)
        self.sock.bind(str(path))
        unheld(threading.Thread(target=self._run, name="ckm-lockstep-master", daemon=True)).start()

    def _run(self) -> None:
        clock, blocks, words = self.clock, self.clock.blocks, self.clock.words
        clock.local.unclocked = True  # the frames it hands over in this process may sleep: on the wall clock
        checked = moved = reticked = _REAL["monotonic"]()
        self.sock.settimeout(0.02)
        while True:
            live = blocks[:, 0] != 0
            now = int(words[0])
            due = int(blocks[live, 1:].min()) if live.any() else IDLE
            pending = int(words[PENDING])
            if pending and _REAL["monotonic"]() - moved > START_WAIT:  # a process that never came: go on
                LOG.warning("lock-step clock: %d started process(es) not on the clock after %g s", pending, START_WAIT)
                words[PENDING] = pending = 0
            # frames between the processes still in flight hold it too (D220: forgiven after a wall timeout)
            if due > now and not pending and self.settling.settled(live):
                if due == IDLE:  # nobody waits for a time: move on, but at no more than STEP per IDLE_PACE
                    _REAL["sleep"](IDLE_PACE)
                # again, after the frames settled: an arrived frame sets its DELIVERY slot before its count
                due = int(blocks[live, 1:].min()) if live.any() else IDLE
                if due <= now or words[PENDING]:
                    continue
                words[0] = min(due, now + clock.step_ns)
                self.moves += 1
                moved = _REAL["monotonic"]()
                self._tick_due(int(words[0]), live)
                continue
            try:
                self.sock.recv(16)
                self.sock.setblocking(False)
                try:
                    while True:
                        self.sock.recv(16)
                except OSError:
                    pass
                finally:
                    self.sock.settimeout(0.02)
            except OSError:  # a timeout: look again (a poke may have been lost)
                pass
            wall = _REAL["monotonic"]()
            if wall - max(moved, reticked) > RETICK:  # a lost wake-up never holds the run: the holders again
                reticked = wall
                self._tick_due(now, live)
            if wall - checked > 1.0:
                checked = wall
                for index in np.flatnonzero(live):
                    pid = int(blocks[index, 0])
                    if not alive(pid):
                        LOG.warning("lock-step clock: process %d ended; its threads no longer hold the clock", pid)
                        blocks[index, 1:] = IDLE
                        blocks[index, 0] = 0
            if wall - moved > STALL:
                moved = wall
                holders = [int(blocks[i, 0]) for i in np.flatnonzero(live) if int(blocks[i, 1:].min()) <= now]
                LOG.warning("lock-step clock held at %.3f s for %g s by process(es) %s", now * 1e-9, STALL, holders)

    def _tick_due(self, now: int, live: npt.NDArray[np.bool_]) -> None:
        """Wake the processes with a wait due at ``now``, and those with no timed participant (the
        world server observes the clock: its waits are not in the file). A process with nothing due
        sleeps on: one hand-off per process that works at this instant, not per process of the run."""
        clock, blocks = self.clock, self.clock.blocks
        here = os.getpid()
        for index in np.flatnonzero(live):
            row_due = int(blocks[index, 1:].min())
            if now < row_due < IDLE:
                continue
            pid = int(blocks[index, 0])
            if pid == here:  # this process's waits: ended here, one hand-off fewer
                clock.fire_due()
                continue
            with contextlib.suppress(OSError):
                self.tx.sendto(b".", str(clock.directory / f"p{pid}"))
