"""Lock-step simulated time: a run's clock that moves only when every participant waits
(issue J point 5 "Simulated time", ``ckm-run --lockstep STEP``, decision D190).

Every process of the run (ckm-run, its partitions, the world server, its render workers) maps one
shared clock file: the simulated time in integer nanoseconds and, per process, a block of slots,
one per *participating* thread, each holding the simulated time at which that thread next needs
the clock (``RUNNING``: now — it is working; ``IDLE``: never by itself — an untimed wait). A
thread becomes a participant at its first timed wait (``time.sleep``, ``Condition.wait`` with a
timeout, hence ``Event.wait``, ``Queue.get``, the kernel scheduler's wait for its next release);
ckm-run's main thread participates from the start, so building the nodes holds the clock. The
world server serves as an observer (:func:`observe`): its waits follow the clock, never hold it.

The run's master (a thread of the ckm-run process, the ``CKM_LOCKSTEP`` variable names its pid)
advances the clock only when no slot is due (every participant waits for a later time), to the
earliest wake-up or by at most STEP, and sends a datagram to every process, whose ticker thread
releases the waits now due — marking their slots ``RUNNING`` *before* they wake, so the master
cannot move on meanwhile. A notify marks the woken participant ``RUNNING`` the same way. So a job
of a periodic task, a world server request it waits for, and what it notifies all happen at one
simulated instant, however long they take on the wall clock: the run is as fast as the machine
allows and its simulated result does not depend on the load.

Messages between the processes (D220, :mod:`runtime.lockstep_frames`): the master also waits until
every TOPICDATA and TOPICLINKS frame one process sent another has arrived, and an arrived frame is
handed to its subscribers at the next instant (1 ns later), so whether a task of another process
sees it never depends on the wall clock; a thread a participant starts holds the clock until its
first wait, and a process's transport until it heard every other transport of the run.

A process whose master is gone (ckm-run killed) falls back to the wall clock from the last
simulated time, so its own watchdogs still end it.
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing.connection
import os
import queue
import shutil
import socket
import subprocess
import threading
import time
import types
from collections.abc import Callable, Iterator, MutableMapping
from pathlib import Path
from typing import Any

import numpy as np

from .lockstep_clock import (
    _REAL,
    IDLE,
    IDLE_PACE,
    LOG,
    PENDING,
    RUNNING,
    STALL,
    VARIABLE,
    WORDS,
    SharedClock,
    next_instant,
    to_ns,
)
from .lockstep_frames import Settling
from .lockstep_os import alive, drain, sender, unheld

HOLD = "CKM_LOCKSTEP_HOLD"  # set for a ckm-run process the run starts: it holds the clock from its start
START_WAIT = 60.0  # wall seconds the clock waits for a started ckm-run process to join it

__all__ = ["VARIABLE", "SharedClock", "active", "create", "install", "observe", "real", "unclocked", "unheld_children",
           "wall_monotonic"]


def real(name: str) -> Callable[..., Any]:
    """The wall clock's ``time.NAME`` (``monotonic``, ``sleep``…) as it was before any patch."""
    function: Callable[..., Any] = _REAL.get(name) or getattr(time, name)
    return function


def wall_monotonic() -> float:
    """The machine's monotonic clock, in lock-step too: the network judges a peer's liveness by it, as
    its heartbeats are sent by it (D256); on the simulated clock a quick run outran the heartbeats."""
    return float(real("monotonic")())


# ---------------------------------------------------------------------- the master


class Master:
    """Advances the shared clock (a thread of the run's lead process)."""

    def __init__(self, clock: SharedClock) -> None:
        self.clock = clock
        self.moves = 0
        self.settling = Settling(clock)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        path = clock.directory / "m"
        path.unlink(missing_ok=True)
        self.sock.bind(str(path))
        self._addresses: dict[int, str] = {}
        self.waker = sender(0.02)  # a process whose queue stays full misses this move's wake-up (its POLL)
        unheld(threading.Thread(target=self._run, name="ckm-lockstep-master", daemon=True)).start()

    def _address(self, pid: int) -> str:
        """Where process ``pid``'s ticker listens (made once per process: a move wakes about ten)."""
        address = self._addresses.get(pid)
        if address is None:
            address = self._addresses[pid] = str(self.clock.directory / f"p{pid}")
        return address

    def _run(self) -> None:
        clock, blocks, words = self.clock, self.clock.blocks, self.clock.words
        clock.local.unclocked = True  # the frames it hands over in this process may sleep: on the wall clock
        checked = moved = _REAL["monotonic"]()
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
                # read once more: a DELIVERY slot an arriving frame set meanwhile (now + 1) is honoured, and
                # next_instant ignores a slot that turned RUNNING (D244: one copy for both made the loaded
                # partitioned rover's trajectory differ 2 runs in 7)
                words[0] = next_instant(blocks[live, 1:], now, clock.step_ns)  # due, and those just after it
                self.moves += 1
                moved = _REAL["monotonic"]()
                here = os.getpid()
                for pid in blocks[live, 0]:
                    if int(pid) == here:  # this process's waits: ended here, one hand-off fewer
                        clock.fire_due()
                        continue
                    with contextlib.suppress(OSError):
                        self.waker.sendto(b".", self._address(int(pid)))
                continue
            try:
                self.sock.recv(16)
                drain(self.sock, 0.02)
            except OSError:  # a timeout: look again (a poke may have been lost)
                pass
            wall = _REAL["monotonic"]()
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


# ---------------------------------------------------------------------- installing

_clock: SharedClock | None = None
_master: Master | None = None


def create(step: float, directory: Path) -> dict[str, str]:
    """Make a run's clock in ``directory`` (mastered by this process): the variables that put a
    process (and its children, which inherit them) on it."""
    if not step > 0.0:
        raise ValueError(f"lock-step: the step {step!r} must be a positive number of seconds")
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "clock").write_bytes(bytes(8 * WORDS))
    real = _REAL.get("monotonic", time.monotonic), _REAL.get("time", time.time)
    value = f"{directory} {to_ns(step)} {os.getpid()} {real[0]()!r} {real[1]()!r}"
    return {VARIABLE: value}


def install(env: MutableMapping[str, str]) -> SharedClock | None:
    """Put this process on the run's lock-step clock if ``env`` names one (idempotent)."""
    global _clock, _master
    text = env.get(VARIABLE)
    if not text or _clock is not None:
        return _clock
    try:
        directory, step, master, mono0, wall0 = text.rsplit(" ", 4)
        clock = SharedClock(Path(directory), int(step), int(master), float(mono0), float(wall0))
    except (ValueError, OSError) as error:
        raise ValueError(f"{VARIABLE}={text!r}: not a lock-step clock ({error})") from None
    for name in ("monotonic", "time", "perf_counter", "sleep"):
        _REAL[name] = getattr(time, name)
    # socket timeouts keep the wall clock (simtime's rule): multiprocessing.connection's waits recompute
    # theirs from time.monotonic, so on a clock held by the very thread polling, poll(0) never ended
    wall_time = types.ModuleType("time")
    wall_time.__dict__.update(time.__dict__)
    multiprocessing.connection.time = wall_time  # type: ignore[attr-defined]
    _patch(clock)
    _clock = clock
    os.register_at_fork(after_in_child=clock.after_fork)
    if env.get(HOLD) == "1":  # a ckm-run process started by the run (a partition): on the clock from now
        os.environ.pop(HOLD, None)
        clock.participant(threading.main_thread())
        clock.expect(-1)
    if clock.master == os.getpid():
        clock.participant(threading.main_thread())  # building the run holds the clock (before the master runs)
        _master = Master(clock)
        atexit.register(shutil.rmtree, clock.directory, ignore_errors=True)
    return clock


def _patch(clock: SharedClock) -> None:
    real_sleep, mono0, wall0 = _REAL["sleep"], clock.mono0, clock.wall0
    allocate = threading.Lock

    def born() -> None:  # a newborn's first wait: from here its own slot (or none) says what it needs
        if clock.newborns:
            clock.born(threading.current_thread())

    def sleep(seconds: float) -> None:
        if seconds <= 0 or clock.orphaned is not None or getattr(clock.local, "unclocked", False):
            born()
            real_sleep(max(0.0, seconds))
            return
        waiter = allocate()
        waiter.acquire()
        entry = clock.enter(waiter, seconds)
        born()  # after its wait is registered: the clock cannot move in between
        waiter.acquire()
        clock.leave(entry)

    time.monotonic = lambda: mono0 + clock.now() * 1e-9
    time.perf_counter = time.monotonic
    time.time = lambda: wall0 + clock.now() * 1e-9
    time.sleep = sleep  # type: ignore[assignment]
    wall_wait = threading.Condition.wait

    def wait(self: Any, timeout: float | None = None) -> bool:
        participant = getattr(clock.local, "slot", None) is not None
        # a participant starting a thread keeps the clock while it waits for it to boot (wall time)
        untimed = timeout is None and (not participant or getattr(clock.local, "starting", False))
        unclocked = getattr(clock.local, "unclocked", False)
        if clock.orphaned is not None or untimed or unclocked or (timeout is not None and timeout <= 0):
            if timeout is None or timeout > 0:
                born()
            return bool(wall_wait(self, timeout))
        if not self._is_owned():
            raise RuntimeError("cannot wait on un-acquired lock")
        waiter = allocate()
        waiter.acquire()
        self._waiters.append(waiter)
        saved = self._release_save()
        entry = clock.enter(waiter, timeout)
        born()
        try:
            waiter.acquire()
        finally:
            self._acquire_restore(saved)
            got = clock.leave(entry)
            if not got:
                with contextlib.suppress(ValueError):
                    self._waiters.remove(waiter)
        return got

    def notify(self: Any, n: int = 1) -> None:
        if not self._is_owned():
            raise RuntimeError("cannot notify on un-acquired lock")
        waiters = self._waiters
        while waiters and n > 0:
            waiter = waiters[0]
            if clock.notified(waiter):  # not a wait that ended at its time already
                try:
                    waiter.release()
                    n -= 1
                except RuntimeError:  # released already (gh-92530)
                    pass
            with contextlib.suppress(ValueError):
                waiters.remove(waiter)

    threading.Condition.wait = wait  # type: ignore[method-assign]
    threading.Condition.notify = notify  # type: ignore[method-assign]
    wall_join = threading.Thread.join

    def join(self: threading.Thread, timeout: float | None = None) -> None:
        # a joining participant waits for another thread, which may need the clock to move: it does not
        # hold the clock; the timeout (a stop step's bound, ckm-run's host.bounded) is on the wall clock,
        # which a clock moving freely would otherwise exhaust at once
        slot = getattr(clock.local, "slot", None)
        if slot is None or clock.orphaned is not None:
            born()
            wall_join(self, timeout)
            return
        with clock.lock:  # the thread's end marks it RUNNING again (D220): the clock cannot move before it returns
            if self.is_alive() and self in joiners:
                joiners[self].append(slot)
            clock._mark(slot, IDLE)
        clock.poke()
        try:
            wall_join(self, timeout)
        finally:
            with clock.lock, contextlib.suppress(KeyError, ValueError):
                joiners[self].remove(slot)
            clock.hold(slot, RUNNING)

    threading.Thread.join = join  # type: ignore[method-assign]
    joiners: dict[threading.Thread, list[int]] = {}  # a thread started here → the slots of the participants joining it
    wall_start = threading.Thread.start

    def start(self: threading.Thread) -> None:
        # a participant's new thread holds the clock until its first wait (D220): until then it may be a
        # supervisor about to start a partition, or a task about to wait for its first release
        local = clock.local
        held = (getattr(local, "slot", None) is not None and not getattr(local, "unclocked", False)
                and not getattr(local, "unheld", False) and not getattr(self, "ckm_unheld", False))  # fmt: skip
        run = self.run

        def run_then_end() -> None:
            try:
                run()
            finally:
                clock.born(self)
                with clock.lock:
                    for slot in joiners.pop(self, []):
                        clock._mark(slot, RUNNING)

        self.run = run_then_end  # type: ignore[method-assign]
        with clock.lock:
            joiners[self] = []
        if held:
            clock.newborn(self)
        local.starting = True
        try:
            wall_start(self)
        except BaseException:
            clock.born(self)
            with clock.lock:
                joiners.pop(self, None)
            raise
        finally:
            local.starting = False

    threading.Thread.start = start  # type: ignore[method-assign]
    wall_popen = subprocess.Popen.__init__

    def popen(self: subprocess.Popen[Any], args: Any, *more: Any, **options: Any) -> None:
        # a ckm-run process of this run (a partition) holds the clock from its start: it is counted
        # until it is on the clock, so the run does not go on while its interpreter starts
        words = [str(a) for a in args] if isinstance(args, list | tuple) else [str(args)]
        ours = "runtime.cli" in words and clock.orphaned is None
        if ours:
            options["env"] = {**(options.get("env") or os.environ), HOLD: "1"}
            clock.expect(+1)
        try:
            wall_popen(self, args, *more, **options)
        except BaseException:
            if ours:
                clock.expect(-1)
            raise

    subprocess.Popen.__init__ = popen  # type: ignore[method-assign]
    # the C SimpleQueue's timed get waits in C, unseen by the clock (a partition supervisor's poll): the
    # standard library's Python one waits on a Condition like Queue (D220)
    queue.SimpleQueue = queue._PySimpleQueue  # type: ignore[misc, attr-defined]
    # the standard library's own aliases of the monotonic clock, taken at its import
    for module, name in ((threading, "_time"), (queue, "time")):  # (subprocess's waits keep the wall clock)
        if getattr(module, name, None) is _REAL["monotonic"]:
            setattr(module, name, time.monotonic)


def unclocked() -> None:
    """The calling thread's waits are on the wall clock and it never holds the run's clock (D220): a
    network thread polling for links, which must form while the clock is held for them."""
    if _clock is not None:
        _clock.local.unclocked = True


@contextlib.contextmanager
def unheld_children() -> Iterator[None]:
    """Threads the calling thread starts in this block do not hold the clock until their first wait
    (D220): the network's threads, which wait in socket calls, not on the clock."""
    if _clock is None:
        yield
        return
    before = getattr(_clock.local, "unheld", False)
    _clock.local.unheld = True
    try:
        yield
    finally:
        _clock.local.unheld = before


def active() -> SharedClock | None:
    """This process's lock-step clock, or None (the wall clock or a scaled one)."""
    return _clock


def observe() -> None:
    """This process's threads follow the clock but never hold it (the world server: it serves the
    participants' requests while they hold it)."""
    if _clock is not None:
        _clock.observer = True
