"""The triple buffer: never torn under stress, acquisition and supply keep their rates while the
processing is five times slower, failures are counted, and stop is clean and bounded."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from runtime.resources.buffers import Supplied, TripleBuffer

Frame = npt.NDArray[np.int64]
CHUNKS = 8
SIZE = 4096


class Producer:
    """Writes frame ``n`` in place into the buffer it is handed, in chunks, yielding between them."""

    def __init__(self) -> None:
        self.count = 0
        self.buffers: set[int] = set()

    def __call__(self, reuse: Frame | None) -> Frame:
        frame = reuse if reuse is not None else np.empty(SIZE, dtype=np.int64)
        self.buffers.add(id(frame))
        step = SIZE // CHUNKS
        for start in range(0, SIZE, step):
            frame[start : start + step] = self.count
            time.sleep(0)  # let another thread run mid-write: a shared slot would show it
        self.count += 1
        return frame


def _consistent(frame: Frame) -> bool:
    """Read in chunks, yielding between them: a slot written meanwhile would mix two frames."""
    first = int(frame[0])
    step = SIZE // CHUNKS
    for start in range(0, SIZE, step):
        if not np.all(frame[start : start + step] == first):
            return False
        time.sleep(0)
    return True


class Checker:
    """The consumer: every result whole, of the frame it claims, never older than the previous one."""

    def __init__(self) -> None:
        self.frames: list[int] = []
        self.problems: list[str] = []
        self.lock = threading.Lock()

    def __call__(self, item: Supplied[Frame]) -> None:
        if not _consistent(item.value):
            self.problems.append(f"torn result in frame {item.frame}")
        elif int(item.value[0]) != item.frame:
            self.problems.append(f"frame {item.frame} carries the data of frame {int(item.value[0])}")
        if self.frames and item.frame < self.frames[-1]:
            self.problems.append(f"frame {item.frame} after frame {self.frames[-1]}")
        if item.repeated != bool(self.frames and item.frame == self.frames[-1]):
            self.problems.append(f"frame {item.frame}: repeated flag {item.repeated} is wrong")
        with self.lock:
            self.frames.append(item.frame)


class PassThrough:
    """The processor: checks its input whole, takes ``delay`` seconds, returns the input itself."""

    def __init__(self, delay: float) -> None:
        self.delay = delay
        self.problems: list[str] = []

    def __call__(self, frame: Frame) -> Frame:
        if not _consistent(frame):
            self.problems.append(f"torn input {int(frame[0])}")
        time.sleep(self.delay)
        return frame


def test_never_torn_under_stress() -> None:
    """A few thousand frames; the processor returns its input itself, so the consumer reads the very
    buffer the producer writes in place: only the slot rotation keeps them apart."""
    producer, checker, process = Producer(), Checker(), PassThrough(0.003)
    problems = process.problems

    buffer = TripleBuffer(producer, process, checker, acquire_period=0.0005, supply_period=0.0007)
    buffer.start()
    deadline = time.monotonic() + 20.0
    while buffer.stats().acquired < 3000 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert buffer.stop(timeout=5.0)
    stats = buffer.stats()
    assert stats.acquired >= 3000
    assert problems == [] and checker.problems == []
    assert len(producer.buffers) <= 3  # the same three buffers go round
    assert stats.processed >= 100 and stats.dropped > stats.processed  # the slow processor drops frames
    assert 0 <= stats.acquired - stats.processed - stats.dropped <= 2  # at most one in acquire, one in process
    assert len(checker.frames) == stats.supplied >= 1000
    assert len(set(checker.frames)) >= stats.processed - stats.skipped - 2  # one may be left in process, one in supply
    assert stats.errors == {"acquire": 0, "process": 0, "supply": 0}


def test_acquisition_and_supply_keep_their_rates_while_processing_is_five_times_slower() -> None:
    period, work, duration = 0.004, 0.020, 1.6
    expected = duration / period  # 400 ticks at each end; processing can do at most 80 frames
    supplied: list[int] = []

    def process(frame: int) -> int:
        time.sleep(work)
        return frame * 10

    buffer: TripleBuffer[int, int] = TripleBuffer(
        lambda _: 1,
        process,
        lambda item: supplied.append(item.value),
        acquire_period=period,
        supply_period=period,
    )
    with buffer:
        time.sleep(duration)
    stats = buffer.stats()
    assert not buffer.running
    assert 0.6 * expected <= stats.acquired <= 1.1 * expected + 2
    assert 0.6 * expected <= stats.supplied + stats.idle <= 1.1 * expected + 2
    assert stats.supplied >= 0.5 * expected
    assert 0.3 * duration / work <= stats.processed <= 1.1 * duration / work + 1
    assert stats.dropped >= stats.acquired * 0.6
    assert stats.repeated >= stats.supplied * 0.6  # most ticks re-supply the newest result
    assert set(supplied) == {10}


def test_without_repeat_each_result_is_supplied_once() -> None:
    seen: list[int] = []

    def slow(frame: int) -> int:
        time.sleep(0.01)
        return frame

    buffer: TripleBuffer[int, int] = TripleBuffer(
        lambda reuse: 0 if reuse is None else reuse + 1,
        slow,
        lambda item: seen.append(item.frame),
        acquire_period=0.002,
        supply_period=0.001,
        repeat=False,
    )
    with buffer:
        time.sleep(0.5)
    stats = buffer.stats()
    assert seen == sorted(set(seen)) and stats.repeated == 0
    # Every result is supplied once or skipped, but for one left in process and one in supply at stop.
    assert len(seen) + stats.skipped >= stats.processed - 2 and stats.idle > 0


def test_failures_are_counted_and_the_loops_go_on() -> None:
    calls = {"acquire": 0, "supply": 0}

    def acquire(reuse: int | None) -> int:
        calls["acquire"] += 1
        if calls["acquire"] % 5 == 0:
            raise OSError("camera hiccup")
        return calls["acquire"]

    def process(frame: int) -> int:
        if frame % 3 == 0:
            raise ValueError("bad frame")
        return frame

    def supply(item: Supplied[int]) -> None:
        calls["supply"] += 1
        if calls["supply"] % 7 == 0:
            raise ConnectionError("publisher down")

    buffer = TripleBuffer(acquire, process, supply, acquire_period=0.002, supply_period=0.002)
    with buffer:
        time.sleep(0.4)
    stats = buffer.stats()
    assert stats.errors["acquire"] > 0 and stats.errors["process"] > 0 and stats.errors["supply"] > 0
    assert stats.processed > 10 and stats.supplied > 10
    assert isinstance(buffer.last_error, (OSError, ValueError, ConnectionError))


def test_stop_is_bounded_even_while_processing_blocks() -> None:
    release = threading.Event()
    entered = threading.Event()
    supplied: list[Any] = []

    def process(frame: int) -> int:
        entered.set()
        release.wait(10.0)
        return frame

    buffer = TripleBuffer(lambda _: 1, process, supplied.append, acquire_period=0.001, supply_period=0.001)
    buffer.start()
    with pytest.raises(RuntimeError, match="already started"):
        buffer.start()
    assert entered.wait(5.0)
    started = time.monotonic()
    assert not buffer.stop(timeout=0.3)  # the processor is stuck in its callback
    assert time.monotonic() - started < 1.0
    release.set()
    assert buffer.stop(timeout=5.0) and not buffer.running
    count = buffer.stats().acquired
    time.sleep(0.05)
    assert buffer.stats().acquired == count  # nothing runs after stop
    assert supplied == []  # the one result completed after stop was never supplied


def test_a_buffer_can_restart_and_stop_before_start_is_harmless() -> None:
    buffer: TripleBuffer[int, int] = TripleBuffer(
        lambda _: 1, lambda x: x, lambda _: None, acquire_period=0.001, supply_period=0.001
    )
    assert buffer.stop(timeout=0.1)
    for _ in range(2):
        buffer.start()
        time.sleep(0.05)
        assert buffer.stop(timeout=2.0)
    assert buffer.stats().processed > 0
    with pytest.raises(ValueError, match="greater than 0"):
        TripleBuffer(lambda _: 1, lambda x: x, lambda _: None, acquire_period=0.0, supply_period=0.001)


def test_a_supply_on_arrival_hands_over_every_result_once_never_torn_and_only_when_there_is_one() -> None:
    """supply_period=None (a Smart Resource's stream, D234): each processed frame reaches the consumer
    once, soon after it is computed, in order and whole; with nothing new the supply never runs."""
    producer, checker, process = Producer(), Checker(), PassThrough(0.002)
    problems = process.problems
    buffer = TripleBuffer(producer, process, checker, acquire_period=0.0005, supply_period=None, repeat=False)
    buffer.start()
    deadline = time.monotonic() + 20.0
    while buffer.stats().processed < 300 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert buffer.stop(timeout=5.0)
    stats = buffer.stats()
    assert problems == [] and checker.problems == []
    assert stats.processed >= 300
    assert len(checker.frames) == len(set(checker.frames)) == stats.supplied  # each once, none repeated
    assert stats.repeated == 0 and stats.idle == 0 and stats.overruns["supply"] == 0
    # every result reached the consumer unless a newer one replaced it first (one may be left in process)
    assert stats.supplied + stats.skipped >= stats.processed - 1


def test_a_supply_on_arrival_waits_for_a_result_and_wakes_when_one_comes() -> None:
    gate = threading.Event()
    supplied: list[Supplied[int]] = []
    arrived = threading.Event()

    def process(frame: int) -> int:
        gate.wait(10.0)
        return frame

    def supply(item: Supplied[int]) -> None:
        supplied.append(item)
        arrived.set()

    buffer = TripleBuffer(lambda _: 7, process, supply, acquire_period=0.001, supply_period=None, repeat=False)
    buffer.start()
    try:
        time.sleep(0.2)
        assert supplied == [] and buffer.stats().idle == 0  # nothing computed: nothing supplied, no empty ticks
        gate.set()
        assert arrived.wait(5.0)
        assert supplied[0].value == 7 and not supplied[0].repeated
    finally:
        assert buffer.stop(timeout=5.0)


def test_a_supply_on_arrival_cannot_repeat() -> None:
    with pytest.raises(ValueError, match="cannot repeat"):
        TripleBuffer(lambda _: 1, lambda x: x, lambda _: None, acquire_period=0.001, supply_period=None)
