"""runtime.lockstep_os.sender (D233): a wake-up to a full datagram queue sleeps, it does not spin; and
the master's next instant (runtime.lockstep_clock.next_instant, D241)."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import numpy as np
import pytest

from runtime.lockstep_clock import IDLE, next_instant
from runtime.lockstep_os import sender


def test_a_send_to_a_full_queue_sleeps_in_the_kernel_until_its_timeout_then_fails(tmp_path: Path) -> None:
    receiver = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    receiver.bind(str(tmp_path / "m"))
    sock = sender(0.3)
    try:
        sent = 0
        cpu, wall = time.process_time(), time.monotonic()
        with pytest.raises(OSError):
            while sent < 10_000:  # the queue holds net.unix.max_dgram_qlen datagrams (10 by default)
                sock.sendto(b".", str(tmp_path / "m"))
                sent += 1
        cpu, wall = time.process_time() - cpu, time.monotonic() - wall
        assert 0 < sent < 10_000
        assert wall >= 0.25  # it waited for the reader ...
        assert cpu < 0.15  # ... asleep: a Python-level timeout polled an always-writable socket for all of it
        receiver.recv(16)  # room again: the next send goes through at once
        sock.sendto(b".", str(tmp_path / "m"))
    finally:
        sock.close()
        receiver.close()


def test_a_send_to_no_receiver_fails_at_once(tmp_path: Path) -> None:
    sock = sender(5.0)
    try:
        started = time.monotonic()
        with pytest.raises(OSError):
            sock.sendto(b".", str(tmp_path / "gone"))
        assert time.monotonic() - started < 2.0
    finally:
        sock.close()


def test_the_clock_moves_once_for_wake_ups_a_few_microseconds_apart() -> None:
    """D241: releases of one period computed in different processes (300 ns apart here) end at one
    move, at the latest of them (none early), even a few µs past a step; one over 5 µs later waits
    for a move of its own; with nobody due within a step the clock moves one step."""
    step = 10_000_000
    apart = np.array([[10_000_300, 9_999_700, IDLE], [10_004_000, 16_666_667, IDLE]], dtype=np.int64)
    assert next_instant(apart, 0, step) == 10_004_000
    assert next_instant(np.array([9_999_700, 10_004_701], dtype=np.int64), 0, step) == 9_999_700
    assert next_instant(np.array([25_000_000, 25_000_001], dtype=np.int64), 0, step) == step
    assert next_instant(np.array([19_999_700, 20_000_000], dtype=np.int64), 9_999_700, step) == 20_000_000
    assert next_instant(np.array([[IDLE, IDLE]], dtype=np.int64), 7, step) == 7 + step
    assert next_instant(np.empty((0, 3), dtype=np.int64), 7, step) == 7 + step
    # a slot set to RUNNING (-1) or a wait already due never takes the clock back
    assert next_instant(np.array([-1, 5, 300_000], dtype=np.int64), 5, step) == 300_000
