"""Lock-step across processes (runtime.lockstep_frames, ``ckm-run --lockstep``, D220): the run's clock
moves only when every TOPICDATA and TOPICLINKS frame between its processes has arrived, an arrived
frame is handed over at the next instant, and a frame that never arrives is forgiven after a bounded
wall time, so a partitioned run is as repeatable as a one-process one and a lost frame never hangs it."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from runtime import lockstep, lockstep_frames
from runtime.lockstep_clock import SharedClock
from tests.conftest import REPO
from tests.runtime.lockstep_runs import busy, private_copy, run_lockstep


@pytest.fixture(autouse=True)
def _offscreen(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("QT_QPA_PLATFORM", "offscreen")
    monkeypatch.delenv("CKM_LOCKSTEP", raising=False)
    monkeypatch.delenv("CKM_TIME_SCALE", raising=False)


def _run(config: Path, run_dir: Path) -> list[dict[str, object]]:
    done = run_lockstep(config, run_dir, 2.5)
    partitions = json.loads((run_dir / "stats.json").read_text())["partitions"]["rover"]
    exits = {name: state["pids"][0]["exit_code"] for name, state in partitions.items()}
    assert exits == {"lidar": 0, "left": 0}, done.stderr[-2000:]
    logs = "".join((run_dir / name / "ckm.log").read_text() for name in ("", "lidar", "left"))
    said = [line for line in logs.splitlines() if "ckm.lockstep" in line]
    assert not [line for line in said if "forgiven" in line or "did not hear" in line], said  # all arrived, linked
    trace: list[dict[str, object]] = json.loads((run_dir / "sim-final.json").read_text())["trace"]
    return [sample for sample in trace if float(str(sample["time"])) <= 2.0]


def test_a_partitioned_rover_gives_the_same_trajectory_in_two_runs_one_under_heavy_load(tmp_path: Path) -> None:
    """tests/data/lockstep/rover_partitioned.xml: the rover of tests/data/lockstep/rover.xml with its lidar
    in a partition of its own and its left relay in another, so every range fans out over CKMultiPeer to
    two other processes and the left duty crosses back to the wheels. Its true poses at 0.05, 1 and 2
    simulated seconds are the same, to the micrometre, in a
    quiet run and in one with two busy processes taking the two cores (before D220 two quiet
    runs already differed by millimetres: a frame in flight when the clock moved arrived a step late)."""
    config = private_copy(REPO / "tests/data/lockstep/rover_partitioned.xml", tmp_path / "rover.xml")
    quiet = _run(config, tmp_path / "quiet")
    with busy(2):  # both cores busy (the shared machine adds its own load)
        loaded = _run(config, tmp_path / "loaded")
    assert [sample["time"] for sample in quiet] == pytest.approx([0.05, 1.0, 2.0], abs=0.06)
    assert loaded == quiet
    rover = [sample["robots"]["rover"] for sample in quiet]  # type: ignore[index]
    assert rover[-1][0] - rover[0][0] > 0.3  # it drove on the partition's ranges: the equality is of a moving path


def test_the_master_waits_for_a_frame_in_flight_and_forgives_a_lost_one_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """The accounting on a real clock file: process A (this test) sent three frames to process B (a
    sleeping child), which counts two arrived: the clock may not move; the third arriving settles it;
    a fourth that never comes is forgiven after FRAME_WAIT wall seconds, logged once, and a late
    arrival of it afterwards is not counted twice (the next lost one is forgiven again, silently);
    frames to a process whose transport stopped, or that ended, are not waited for."""
    monkeypatch.setattr(lockstep_frames, "FRAME_WAIT", 0.2)
    lockstep.create(0.01, tmp_path)
    clock = SharedClock(tmp_path, 10_000_000, os.getpid(), 0.0, 0.0)
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        a, b = os.getpid(), child.pid
        clock.blocks[0, 0], clock.blocks[1, 0] = a, b
        clock.guids[0, 0], clock.guids[1, 0] = 1001, 1002  # each has a transport on the clock
        clock.counts[0, 0] = [b, 3, 0]  # A: sent 3 to B
        clock.counts[1, 0] = [a, 0, 2]  # B: 2 arrived from A
        clock.counts[0, 1] = [4242, 9, 0]  # frames to a process not in the run: not waited for
        settling = lockstep_frames.Settling(clock)
        live = clock.blocks[:, 0] != 0
        assert not settling.settled(live)
        clock.counts[1, 0, 2] = 3  # the third arrives
        assert settling.settled(live)
        clock.counts[0, 0, 1] = 4  # a fourth is sent and lost
        caplog.set_level(logging.WARNING, logger="ckm.lockstep")
        waited = time.monotonic()
        while not settling.settled(live):
            assert time.monotonic() - waited < 10.0
            time.sleep(0.01)
        assert 0.2 <= time.monotonic() - waited < 10.0 and settling.lost == 1
        clock.counts[1, 0, 2] = 4  # it arrives after all: settled, nothing forgiven any more
        assert settling.settled(live) and settling.forgiven == {}
        clock.counts[0, 0, 1] = 5  # the next one in flight is waited for again
        assert not settling.settled(live)
        waited = time.monotonic()
        while not settling.settled(live):
            assert time.monotonic() - waited < 10.0
            time.sleep(0.01)
        assert settling.lost == 2
        forgiven = [r.getMessage() for r in caplog.records if "forgiven" in r.getMessage()]
        assert len(forgiven) == 1 and "1 frame(s)" in forgiven[0] and str((a, b)) in forgiven[0]  # logged once
        clock.counts[0, 0, 1] = 6  # one more in flight, then B's transport stops (a run's end): not waited for
        assert not settling.settled(live)
        clock.guids[1, 0] = 0
        assert settling.settled(live)
        clock.guids[1, 0] = 1002
        assert not settling.settled(live)
        clock.blocks[1, 0] = 0  # B ended: its frames no longer count
        assert settling.settled(clock.blocks[:, 0] != 0)
        assert np.all(clock.counts[0, 0] == [b, 6, 0])
    finally:
        child.kill()
        child.wait(10)
