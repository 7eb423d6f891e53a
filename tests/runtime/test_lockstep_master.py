"""The lock-step master's wake-ups (runtime.lockstep_master, runtime.lockstep_os, D229): a move wakes only
the processes with a wait due and the observers, a wake-up to a full queue never blocks its sender, and
a wake-up that found its process busy is sent again, so none is ever needed twice to move the run."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from runtime import lockstep
from runtime.lockstep_clock import IDLE, RUNNING, SharedClock
from runtime.lockstep_master import Master
from runtime.lockstep_os import nonblocking_sender

STEP = 10_000_000


@pytest.fixture(autouse=True)
def _no_run_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("CKM_LOCKSTEP", raising=False)


def _inbox(directory: Path, pid: int) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(directory / f"p{pid}"))
    sock.setblocking(False)
    return sock


def _count(sock: socket.socket) -> int:
    got = 0
    while True:
        try:
            sock.recv(16)
        except BlockingIOError:
            return got
        got += 1


def test_a_move_wakes_the_processes_with_a_wait_due_and_the_observers_only(tmp_path: Path) -> None:
    lockstep.create(0.01, tmp_path)
    clock = SharedClock(tmp_path, STEP, os.getpid(), 0.0, 0.0)
    due, later, observer, untimed = 4_000_001, 4_000_002, 4_000_003, 4_000_004  # pids no process has
    inboxes = {pid: _inbox(tmp_path, pid) for pid in (due, later, observer, untimed)}
    clock.blocks[:4, 0] = [due, later, observer, untimed]
    clock.blocks[:4, 1:] = IDLE
    clock.blocks[0, 1:3] = [STEP, 3 * STEP]  # one wait due at the move's time, one later
    clock.blocks[1, 1] = 2 * STEP  # only later
    clock.blocks[3, 1] = RUNNING  # a thread still working (the master never moves then; woken again)
    master = Master.__new__(Master)
    master.clock, master.tx = clock, nonblocking_sender()
    master._tick_due(STEP, clock.blocks[:, 0] != 0)
    got = {pid: _count(sock) for pid, sock in inboxes.items()}
    assert got == {due: 1, later: 0, observer: 1, untimed: 1}


def test_a_wake_up_to_a_full_queue_fails_at_once_and_the_pending_ones_stay(tmp_path: Path) -> None:
    """The master's queue holds net.unix.max_dgram_qlen datagrams; a poke beyond it must not wait (a
    socket with a timeout spins until the timeout) and the queued wake-ups are still there to read."""
    lockstep.create(0.01, tmp_path)
    master = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    master.bind(str(tmp_path / "m"))
    clock = SharedClock(tmp_path, STEP, os.getpid(), 0.0, 0.0)
    clock.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)  # as when the process is on the clock
    assert clock.tx.gettimeout() == 0.0
    for _ in range(200):
        clock.poke()  # never raises, never waits
    with pytest.raises(BlockingIOError):
        clock.tx.sendto(b".", str(tmp_path / "m"))
    master.setblocking(False)
    assert 1 <= _count(master) <= 200


def test_a_holder_whose_wake_up_was_lost_is_woken_again(tmp_path: Path) -> None:
    """A master in a process of its own; a process holds the clock (a wait due now) and its first
    wake-up is read away unseen: the master, seeing no move for RETICK wall seconds, sends another."""
    script = textwrap.dedent(
        f"""
        import sys, time
        from pathlib import Path
        from runtime import lockstep, lockstep_master
        from runtime.lockstep_clock import _REAL, IDLE, SharedClock
        _REAL.update(monotonic=time.monotonic, sleep=time.sleep)  # the wall clocks, as install() keeps them
        lockstep_master.RETICK = 0.05
        directory = Path({str(tmp_path)!r})
        clock = SharedClock(directory, {STEP}, 0, 0.0, 0.0)
        clock.blocks[0, 1:] = IDLE
        clock.blocks[0, 1] = 0  # due at the clock's time 0: it holds the clock
        clock.blocks[0, 0] = int(sys.argv[1])
        lockstep_master.Master(clock)
        time.sleep(30)
        """
    )
    lockstep.create(0.01, tmp_path)
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    inbox = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    inbox.bind(str(tmp_path / f"p{holder.pid}"))
    inbox.settimeout(10.0)
    master = subprocess.Popen([sys.executable, "-c", script, str(holder.pid)], cwd=Path(__file__).parents[2])
    try:
        inbox.recv(16)  # lost: nobody looks at the clock after it
        inbox.recv(16)  # sent again, with no poke from anyone
        words = np.memmap(tmp_path / "clock", dtype=np.int64, mode="r")
        assert int(words[0]) == 0  # and the clock waited for the holder all along
    finally:
        for process in (master, holder):
            process.kill()
            process.wait(10)
