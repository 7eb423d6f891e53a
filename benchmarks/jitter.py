"""ckm-bench jitter: a CKM periodic task at 1 kHz for 10 s, against a bare loop in the same process.

The reference is a plain hybrid sleep-and-spin loop on absolute deadlines, run for half the
time right before and half right after the kernel's task, so both see the same machine noise.
"""

from __future__ import annotations

import time
from typing import Any

from runtime.kernel.scheduler import SPIN, Scheduler, Task

PERIOD = 0.001


def _summary(lateness: list[float], missed: int) -> dict[str, Any]:
    values = sorted(abs(x) for x in lateness)

    def pick(q: float) -> float:
        return values[min(len(values) - 1, int(q * len(values)))] * 1e6 if values else 0.0

    return {"p50": round(pick(0.5), 1), "p99": round(pick(0.99), 1), "max": round(pick(1.0), 1), "missed": missed}


def reference_loop(duration: float) -> dict[str, Any]:
    """A bare hybrid loop: sleep to just before each absolute release, spin the rest."""
    lateness: list[float] = []
    missed = 0
    start = time.perf_counter() + PERIOD
    index = 0
    end = start + duration
    while True:
        release = start + index * PERIOD
        if release >= end:
            break
        remaining = release - time.perf_counter()
        if remaining > SPIN:
            time.sleep(remaining - SPIN)
        while time.perf_counter() < release:
            pass
        now = time.perf_counter()
        lateness.append(now - release)
        skipped = int((now - release) // PERIOD)
        missed += skipped
        index += 1 + skipped
    return _summary(lateness, missed)


def kernel_task(duration: float) -> dict[str, Any]:
    """Run one kernel task (§3.1.2.8) at ``PERIOD`` for ``duration`` s; its |lateness| percentiles (µs) and misses."""
    scheduler = Scheduler("bench-jitter")
    counter = [0]

    def work() -> None:
        counter[0] += 1

    task = scheduler.add(Task("tick", PERIOD, work, priority=90))
    scheduler.start()
    time.sleep(duration)
    scheduler.stop()
    lateness = list(task.stats.jitter)
    return _summary(lateness, task.stats.misses) | {"releases": task.stats.releases}


def run(duration: float = 10.0) -> dict[str, Any]:
    """Measure the kernel task's release jitter for ``duration`` s, and the bare loop's before and after it."""
    before = reference_loop(duration / 4)
    kernel = kernel_task(duration)
    after = reference_loop(duration / 4)
    return {
        "period_us": round(PERIOD * 1e6),
        "duration_s": duration,
        "releases": kernel["releases"],
        "p50_abs_jitter_us": kernel["p50"],
        "p99_abs_jitter_us": kernel["p99"],
        "max_abs_jitter_us": kernel["max"],
        "missed": kernel["missed"],
        "ref_p50_abs_jitter_us": round((before["p50"] + after["p50"]) / 2, 1),
        "ref_p99_abs_jitter_us": round((before["p99"] + after["p99"]) / 2, 1),
        "ref_max_abs_jitter_us": max(before["max"], after["max"]),
        "ref_missed": before["missed"] + after["missed"],
    }


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench jitter``'s table."""
    return [
        ("period", f"{result['period_us']} µs for {result['duration_s']} s ({result['releases']} releases)"),
        (
            "kernel |jitter| p50 / p99 / max",
            f"{result['p50_abs_jitter_us']} / {result['p99_abs_jitter_us']} / {result['max_abs_jitter_us']} µs",
        ),
        ("kernel missed releases", str(result["missed"])),
        (
            "bare loop |jitter| p50 / p99 / max",
            f"{result['ref_p50_abs_jitter_us']} / {result['ref_p99_abs_jitter_us']}"
            f" / {result['ref_max_abs_jitter_us']} µs",
        ),
        ("bare loop missed releases", str(result["ref_missed"])),
    ]
