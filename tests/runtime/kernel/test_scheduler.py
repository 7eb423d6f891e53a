"""The periodic scheduler: order, absolute releases, flexible periods, optional parts, misses."""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator

import pytest

from runtime.kernel.scheduler import Scheduler, Task


@pytest.fixture
def scheduler() -> Iterator[Scheduler]:
    running = Scheduler("test")
    running.start()
    yield running
    running.stop()


def wait_for(condition: object, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if callable(condition) and condition():
            return True
        time.sleep(0.002)
    return False


def test_same_release_runs_higher_priority_first(scheduler: Scheduler) -> None:
    order: list[str] = []
    release = scheduler.clock() + 0.05
    scheduler.add(Task("low", 10.0, lambda: order.append("low"), priority=10), first_release=release)
    scheduler.add(Task("high", 10.0, lambda: order.append("high"), priority=90), first_release=release)
    assert wait_for(lambda: len(order) == 2)
    assert order == ["high", "low"]


def test_releases_are_absolute(scheduler: Scheduler) -> None:
    task = scheduler.add(Task("tick", 0.01, lambda: None))
    first = task.release
    assert wait_for(lambda: task.stats.releases >= 20)
    # Every release lands on the grid first + k·period, whatever the lateness of earlier runs.
    offset = (task.release - first) / 0.01
    assert abs(offset - round(offset)) < 1e-6


def test_flexible_period(scheduler: Scheduler) -> None:
    task = scheduler.add(Task("flex", 0.05, lambda: None))
    assert wait_for(lambda: task.stats.releases >= 1)
    task.set_period(0.005)
    before = task.stats.releases
    assert wait_for(lambda: task.stats.releases >= before + 20, timeout=5)


def test_overrun_counts_misses_without_a_burst(scheduler: Scheduler) -> None:
    runs: list[float] = []

    def slow() -> None:
        runs.append(time.perf_counter())
        if len(runs) == 3:
            time.sleep(0.1)  # ten periods lost

    task = scheduler.add(Task("slow", 0.01, slow))
    assert wait_for(lambda: len(runs) >= 6)
    assert task.stats.misses >= 8
    gaps = [b - a for a, b in itertools.pairwise(runs[3:])]
    assert all(gap > 0.005 for gap in gaps)  # no catch-up burst after the overrun


def test_optional_part_only_when_idle(scheduler: Scheduler) -> None:
    ran = threading.Event()
    light = scheduler.add(Task("light", 0.01, lambda: None, optional=ran.set, min_idle=0.5))
    assert ran.wait(5)
    scheduler.remove("light")
    # A task busy 80% of the time leaves too little idle time for a part needing 50%.
    hog = scheduler.add(Task("hog", 0.01, lambda: time.sleep(0.008), optional=lambda: None, min_idle=0.5))
    assert wait_for(lambda: hog.stats.optional_skipped >= 20, timeout=10)
    assert light.stats.optional_runs >= 1


def test_a_failing_part_is_counted_and_the_task_goes_on(scheduler: Scheduler) -> None:
    def broken() -> None:
        raise RuntimeError("boom")

    task = scheduler.add(Task("broken", 0.01, broken))
    assert wait_for(lambda: task.stats.failures >= 3)


def test_removed_tasks_stop(scheduler: Scheduler) -> None:
    task = scheduler.add(Task("gone", 0.005, lambda: None))
    assert wait_for(lambda: task.stats.releases >= 2)
    scheduler.remove("gone")
    time.sleep(0.05)
    count = task.stats.releases
    time.sleep(0.05)
    assert task.stats.releases == count
    assert "gone" not in scheduler.statistics()


def test_duplicate_names_and_bad_periods_are_refused(scheduler: Scheduler) -> None:
    scheduler.add(Task("one", 1.0, lambda: None))
    with pytest.raises(ValueError, match="already runs"):
        scheduler.add(Task("one", 1.0, lambda: None))
    with pytest.raises(ValueError, match="period must be positive"):
        Task("zero", 0.0, lambda: None)
