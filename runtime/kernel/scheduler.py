"""Periodic tasks on absolute deadlines (§3.1.2.8).

One scheduler thread runs its tasks in release order (ties: higher priority first). It sleeps
until shortly before the next release and spins the rest of the way, which gives
sub-millisecond release accuracy without holding a core. Releases are absolute
(``start + k · period``), so lateness never accumulates as drift. A task may change its period
at run time (flexible tasks) and may have an optional part that runs only while the scheduler's
measured idle share is at least the part's ``min_idle`` (advanced control when resources allow).

Tasks are cooperative: a part that overruns delays the others; that shows in their statistics
as jitter and misses rather than being hidden.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import logging
import threading
import time
from array import array
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from runtime import simtime

LOG = logging.getLogger("ckm.scheduler")
SPIN = 0.0003  # seconds spun before a release instead of sleeping
IDLE_WINDOW = 1.0  # seconds over which the idle share is measured
BUSY_LIMIT = 100_000  # runs kept for the idle share at most (a bound even for a stalled clock)


SAMPLES_KEPT = 20000  # recent jitter and execution-time samples per task


class Ring:
    """The last ``maxlen`` floats, in one array allocated up front: a node's memory does not grow
    while it fills (a deque of floats would add ~32 bytes per sample for minutes at slow rates)."""

    def __init__(self, maxlen: int = SAMPLES_KEPT) -> None:
        self.maxlen = maxlen
        self._values = array("d", bytes(8 * maxlen))
        self._next = 0
        self._count = 0

    def append(self, value: float) -> None:
        """Store ``value``, overwriting the oldest sample once full."""
        self._values[self._next] = value
        self._next = (self._next + 1) % self.maxlen
        self._count = min(self._count + 1, self.maxlen)

    def recent(self, count: int) -> list[float]:
        """The last ``count`` samples, oldest first."""
        count = min(count, self._count)
        start = (self._next - count) % self.maxlen
        if start + count <= self.maxlen:
            return self._values[start : start + count].tolist()
        return self._values[start:].tolist() + self._values[: self._next].tolist()

    def values(self) -> npt.NDArray[np.float64]:
        """The kept samples, unordered, as a view of the buffer (copy it before the ring changes)."""
        return np.frombuffer(self._values, dtype=np.float64, count=self._count)

    def copy(self) -> Ring:
        """An independent copy (one memory copy: cheap to take under a lock)."""
        twin = Ring.__new__(Ring)
        twin.maxlen, twin._values, twin._next, twin._count = self.maxlen, self._values[:], self._next, self._count
        return twin

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[float]:
        return iter(self.recent(self._count))


@dataclass
class TaskStats:
    """What a task did: releases, runs, misses, and recent jitter and execution times (seconds)."""

    releases: int = 0
    misses: int = 0
    optional_runs: int = 0
    optional_skipped: int = 0
    failures: int = 0
    jitter: Ring = field(default_factory=Ring)
    exec_time: Ring = field(default_factory=Ring)
    max_jitter: float = 0.0
    first_failure: str | None = None  # the first exception a part raised (ckm-run reports it)

    def snapshot(self) -> TaskStats:
        """A copy to summarise later; the scheduler takes it under its lock, so sorting the samples
        never holds up its thread."""
        return dataclasses.replace(self, jitter=self.jitter.copy(), exec_time=self.exec_time.copy())

    def summary(self, period: float) -> dict[str, Any]:
        """The figures; call it on a snapshot, or where nothing appends meanwhile."""
        # numpy on the ring's own buffer: no Python float per sample (the statistics file is
        # rewritten every few seconds, and transient lists of 20 000 floats show in a node's RSS).
        jitters = np.sort(np.abs(self.jitter.values()))
        execs = np.sort(self.exec_time.values())

        def pct(values: npt.NDArray[np.float64], q: float) -> float:
            return float(values[min(len(values) - 1, int(q * len(values)))]) if len(values) else 0.0

        return {
            "period_s": period,
            "releases": self.releases,
            "misses": self.misses,
            "failures": self.failures,
            "first_failure": self.first_failure,
            "optional_runs": self.optional_runs,
            "optional_skipped": self.optional_skipped,
            "jitter_p50_us": round(pct(jitters, 0.5) * 1e6, 1),
            "jitter_p99_us": round(pct(jitters, 0.99) * 1e6, 1),
            "jitter_max_us": round(self.max_jitter * 1e6, 1),
            "exec_mean_us": round(float(np.mean(execs)) * 1e6, 1) if len(execs) else 0.0,
            "exec_p99_us": round(pct(execs, 0.99) * 1e6, 1),
        }


class Task:
    """A periodic task: a required part, an optional part, a period and a priority."""

    def __init__(
        self,
        name: str,
        period: float,
        required: Callable[[], None],
        *,
        priority: int = 50,
        optional: Callable[[], None] | None = None,
        min_idle: float = 0.2,
        finish: Callable[[], None] | None = None,
    ) -> None:
        if period <= 0:
            raise ValueError(f"task {name!r}: period must be positive, not {period}")
        self.name = name
        self.period = period
        self.required = required
        self.optional = optional
        self.min_idle = min_idle
        self.finish = finish  # runs after the required part and, when it ran, the optional one
        self.priority = priority
        self.stats = TaskStats()
        self.release = 0.0
        self.active = True

    def set_period(self, period: float) -> None:
        """Change the period from the next release on (flexible tasks)."""
        if period <= 0:
            raise ValueError(f"task {self.name!r}: period must be positive, not {period}")
        self.period = period


class Scheduler:
    """Runs periodic tasks on one thread."""

    def __init__(self, name: str = "ckm-scheduler", *, clock: Callable[[], float] = time.perf_counter) -> None:
        self.name = name
        self.clock = clock
        self.tasks: dict[str, Task] = {}
        self._queue: list[tuple[float, int, int, Task]] = []
        self._order = itertools.count()
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # (end, duration) of the runs of the last IDLE_WINDOW: trimmed on every run, so bounded.
        self._busy: deque[tuple[float, float]] = deque(maxlen=BUSY_LIMIT)
        self._busy_total = 0.0  # their durations summed, kept as runs come and go: idle_share is O(1)

    # ------------------------------------------------------------------ tasks

    def add(self, task: Task, *, first_release: float | None = None) -> Task:
        """Schedule ``task``, first released one period from now unless ``first_release`` is given (§3.1.2.8).

        Raises:
            ValueError: a task of that name already runs on this scheduler.
        """
        with self._lock:
            if task.name in self.tasks:
                raise ValueError(f"a task named {task.name!r} already runs on {self.name}")
            task.release = self.clock() + task.period if first_release is None else first_release
            self.tasks[task.name] = task
            self._push(task)
        self._wake.set()
        return task

    def remove(self, name: str) -> Task | None:
        """Unschedule task ``name``; returns it, or None when no such task runs."""
        with self._lock:
            task = self.tasks.pop(name, None)
            if task is not None:
                task.active = False
        self._wake.set()
        return task

    def _push(self, task: Task) -> None:
        heapq.heappush(self._queue, (task.release, -task.priority, next(self._order), task))

    def idle_share(self) -> float:
        """Share of the last second the scheduler spent waiting rather than running parts."""
        now = self.clock()
        with self._lock:
            self._trim_busy(now)
            busy = self._busy_total  # _trim_busy zeroes it with the last run: no float residue
        return max(0.0, 1.0 - busy / IDLE_WINDOW)

    def _trim_busy(self, now: float) -> None:
        while self._busy and self._busy[0][0] < now - IDLE_WINDOW:
            self._busy_total -= self._busy.popleft()[1]
        if not self._busy:
            self._busy_total = 0.0

    def statistics(self, tasks: list[Task] | None = None) -> dict[str, dict[str, Any]]:
        """The figures of ``tasks`` (default: every task it runs), read under the lock the scheduler
        thread records them under, so a reader never walks a deque being appended to."""
        with self._lock:
            chosen = list(self.tasks.values()) if tasks is None else tasks
        figures = {}
        for task in chosen:  # one task's copy at a time: a short lock, a small transient
            with self._lock:
                snapshot = task.stats.snapshot()
            figures[task.name] = snapshot.summary(task.period)
        return figures

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Start the scheduler's thread."""
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the loop and wait (at most 5 s) for its thread to end."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=5)

    # ------------------------------------------------------------------ the loop

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                entry = self._queue[0] if self._queue else None
            if entry is None:
                self._wake.wait(0.1)
                self._wake.clear()
                continue
            release, _, _, task = entry
            if not self._wait_until(release):
                continue  # woken early: a task was added or removed; look again
            with self._lock:
                if not self._queue or self._queue[0][3] is not task:
                    continue
                heapq.heappop(self._queue)
            if task.active:
                self._execute(task, release)

    def _wait_until(self, release: float) -> bool:
        remaining = release - self.clock()
        spin = SPIN * simtime.scale()  # SPIN wall seconds, on a scaled clock too (runtime.simtime)
        if remaining > spin:
            self._wake.clear()
            if self._wake.wait(remaining - spin):
                return False
        while self.clock() < release:
            pass
        return True

    def _execute(self, task: Task, release: float) -> None:
        start = self.clock()
        stats = task.stats
        lateness = start - release
        try:
            task.required()
            if task.optional is not None:
                if self.idle_share() >= task.min_idle:
                    task.optional()
                    stats.optional_runs += 1
                else:
                    stats.optional_skipped += 1
            if task.finish is not None:
                task.finish()
        except Exception as exc:
            stats.failures += 1
            if stats.first_failure is None:
                stats.first_failure = f"{type(exc).__name__}: {exc}"[:500]
            LOG.exception("task %s failed", task.name)
        end = self.clock()
        with self._lock:  # statistics() reads these from other threads
            stats.releases += 1
            stats.jitter.append(lateness)
            stats.max_jitter = max(stats.max_jitter, abs(lateness))
            stats.exec_time.append(end - start)
            if len(self._busy) == BUSY_LIMIT:  # the deque drops its oldest run as this one comes
                self._busy_total -= self._busy[0][1]
            self._busy.append((end, end - start))
            self._busy_total += end - start
            self._trim_busy(end)
            # The next release is absolute; releases already past are misses, not a burst of runs.
            task.release = release + task.period
            if task.release <= end:
                skipped = int((end - task.release) // task.period) + 1
                stats.misses += skipped
                task.release += skipped * task.period
            if task.active and task.name in self.tasks:
                self._push(task)
