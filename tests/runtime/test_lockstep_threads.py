"""Lock-step threads (runtime.lockstep, D221): a thread a participant starts holds the clock until its
first wait (at most NEWBORN_WAIT wall seconds), a joined thread's end hands the clock back to its
joiner at once, and ``queue.SimpleQueue``'s timed get waits on the run's clock."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import REPO

PROBE = r"""
import json, os, queue, socket, sys, tempfile, threading, time
from pathlib import Path
if "CKM_LOCKSTEP" not in os.environ:  # become the run's master, as ckm-run does
    from runtime import lockstep
    os.environ.update(lockstep.create(0.01, Path(tempfile.mkdtemp(prefix="ckm-lockstep-test-"))))
    os.execv(sys.executable, [sys.executable, "-c", sys.argv[1], sys.argv[1]])
from runtime import lockstep, simtime
real_sleep, wall, m0 = lockstep.real("sleep"), lockstep.real("monotonic"), time.monotonic()
w0 = wall()
seen = {}
def slow_start():  # 0.3 s of wall-clock work before its first wait: the clock must not move meanwhile
    real_sleep(0.3)
    seen["slow"] = time.monotonic() - m0
    time.sleep(0.5)
    seen["slow_woke"] = time.monotonic() - m0
    time.sleep(1.0)  # ends at 1.5 s, after the main thread started to join it
def blocked():  # a socket call that never waits on the clock: its hold lapses, the clock goes on
    a, b = socket.socketpair()
    b.settimeout(3.0)
    try:
        b.recv(1)
    except TimeoutError:
        pass
    seen["blocked_wall"] = wall() - w0
threads = [threading.Thread(target=slow_start), threading.Thread(target=blocked)]
for t in threads:
    t.start()
time.sleep(0.25)
seen["main"] = time.monotonic() - m0  # after the slow thread's wall work and the socket thread's lapse
seen["main_wall"] = wall() - w0
simple = queue.SimpleQueue()
t0 = time.monotonic()
try:
    simple.get(timeout=0.75)
except queue.Empty:
    seen["simple"] = time.monotonic() - t0
threads[0].join()
seen["joined"] = time.monotonic() - m0
threads[1].join()
print(json.dumps(seen))
"""


def test_a_started_thread_holds_the_clock_until_it_waits_and_a_simple_queue_waits_on_it() -> None:
    done = subprocess.run([sys.executable, "-c", PROBE, PROBE], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["slow"] == pytest.approx(0.0, abs=1e-6)  # 0.3 s of wall time, no simulated time
    assert seen["slow_woke"] == pytest.approx(0.5, abs=1e-5)
    assert seen["main"] == pytest.approx(0.25, abs=1e-5)  # the clock went on once the socket thread lapsed
    assert seen["simple"] == pytest.approx(0.75, abs=1e-5)  # the C SimpleQueue waited 0.75 s of wall time
    assert seen["joined"] == pytest.approx(1.5, abs=1e-5)  # at the slow thread's end, not a moment later
    # the clock waited for the slow thread's wall work, but not for the socket call (its hold lapsed)
    assert 0.3 <= seen["main_wall"] < seen["blocked_wall"]
