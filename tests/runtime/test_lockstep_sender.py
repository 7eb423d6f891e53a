"""runtime.lockstep_os.sender (D233): a wake-up to a full datagram queue sleeps, it does not spin."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

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
