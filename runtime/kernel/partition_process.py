"""Inside a partition process (§3.1.3.2): tied to its supervisor's life, held to its memory budget.

Isolation, as far as an unprivileged process can honestly get it:

- Parent death: a partition process must never outlive its supervisor. The child arms
  ``prctl(PR_SET_PDEATHSIG, SIGTERM)`` at start and then checks that its parent is still the
  supervisor (the pid in ``CKM_SUPERVISOR_PID``), which closes the window before the signal was
  armed; SIGTERM makes it stop cleanly, actuators safe. Linux sends that signal when the *thread*
  that forked the child ends, so every child is forked by the supervisor's watcher thread, which
  lives until the children are stopped. Elsewhere a thread polls the parent pid instead.
- Memory: ``memory`` MiB is the partition's own budget on top of the runtime it starts with.
  rlimits do not fit (tested): the interpreter with numpy, zenoh and the transport maps ~190 MiB
  of data and ~700 MiB of address space, so an absolute RLIMIT_AS or RLIMIT_DATA of tens of MiB
  stops it from starting (OpenBLAS fails to allocate); a relative RLIMIT_DATA counts the 8 MiB
  each new thread reserves for its stack, so a 32 MiB partition could not open links to eight
  more peers ("can't start new thread") and silently lost them. What is counted instead is
  private resident memory (anonymous pages really in RAM), checked every 0.2 s by a thread of
  the partition from the moment it runs; past the budget the partition stops cleanly (actuators
  safe) and exits with MEMORY_EXIT, a crash the supervisor restarts per policy. Not kernel
  enforced: a burst can overshoot for up to one check (plus the stop).
"""

from __future__ import annotations

import ctypes
import logging
import os
import re
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from ckmconf.model import Partition

LOG = logging.getLogger("ckm.partitions")
PARENT_ENV = "CKM_SUPERVISOR_PID"
PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>
BEST_EFFORT_NICE = 10
MEMORY_EXIT = 3  # exit code of a partition that went over its memory budget
STOP_GRACE = 10.0  # seconds a partition over its budget has to stop cleanly before it is ended


_LOCATED = re.compile(r"^\S+:\d+:\d+: ")


def first_error(console: Path, start: int) -> str | None:
    """The first error a partition process printed after byte ``start`` of its console log: the
    first located ``FILE:LINE:COL: …`` line, else the last line (a traceback's exception)."""
    try:
        with console.open("rb") as file:
            file.seek(start)
            lines = [line.strip() for line in file.read(1 << 20).decode("utf-8", "replace").splitlines()]
    except OSError:
        return None
    lines = [line for line in lines if line]
    located = next((line for line in lines if _LOCATED.match(line)), None)
    return located or (lines[-1] if lines else None)


def enter_partition(partition: Partition) -> None:
    """First thing a partition process does: tie its life to the supervisor's, and yield CPU if
    best-effort. Raises SystemExit when the supervisor is already gone."""
    expected = os.environ.get(PARENT_ENV)
    if expected is not None:  # started by a supervisor (not by hand)
        parent = int(expected)
        armed = _die_with_parent()
        if os.getppid() != parent:  # it died before the signal was armed
            raise SystemExit(f"partition {partition.name}: supervisor {parent} is gone")
        if not armed:
            threading.Thread(target=_watch_parent, args=(parent,), name="ckm-parent-watch", daemon=True).start()
    if partition.criticality == "best-effort":
        os.nice(BEST_EFFORT_NICE)  # before any thread starts: every thread inherits it


def _die_with_parent() -> bool:
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os.kill(os.getpid(), signal.SIGTERM)  # the same clean stop as a supervisor's SIGTERM


class MemoryWatch:
    """The partition's memory budget: private resident memory (anonymous pages actually in RAM)
    may grow by at most ``memory`` MiB over what the process uses once running. A thread checks it
    every ``period``; past the budget it calls ``exceeded(used, limit)`` once, which should stop the
    process, and ends it with MEMORY_EXIT if it is still there ``grace`` seconds later."""

    def __init__(
        self,
        partition: Partition,
        exceeded: Callable[[int, int], None],
        period: float = 0.2,
        grace: float | None = STOP_GRACE,
    ) -> None:
        self.baseline = _private_bytes()
        self.limit = None if partition.memory is None or not self.baseline else self.baseline + (partition.memory << 20)
        self.peak = self.baseline
        self._exceeded = exceeded
        self._period = period
        self._grace = grace
        if partition.memory is not None and self.limit is None:
            LOG.warning("partition %s: no memory accounting on this system; memory not limited", partition.name)
        if self.limit is not None:
            threading.Thread(target=self._run, name="ckm-memory-watch", daemon=True).start()

    def _run(self) -> None:
        assert self.limit is not None
        while True:
            time.sleep(self._period)
            used = _private_bytes() or 0
            self.peak = max(self.peak or 0, used)
            if used > self.limit:
                self._exceeded(used, self.limit)
                if self._grace is not None:
                    time.sleep(self._grace)
                    os._exit(MEMORY_EXIT)
                return

    def statistics(self) -> dict[str, int | None]:
        """Baseline, limit and peak of the partition's private memory, in bytes."""
        return {"baseline_bytes": self.baseline, "limit_bytes": self.limit, "peak_bytes": self.peak}


def _private_bytes() -> int | None:
    """Resident minus file-backed shared pages (Linux /proc/self/statm), in bytes."""
    try:
        with open("/proc/self/statm") as statm:
            fields = statm.read().split()
        return (int(fields[1]) - int(fields[2])) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, IndexError, ValueError):
        return None
