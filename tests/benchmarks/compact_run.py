"""The compact cooperative mission run that tests/benchmarks/test_compact_mission.py checks, as a
process of its own.

The run takes minutes of a lock-step clock that waits for the machine, so it does not depend on how
loaded the machine is; the rest of the suite keeps about one of the two cores busy. The suite's
conftest therefore starts this process as soon as the tests are collected, at a lower priority (the
other tests' timings are not disturbed), moves the compact mission's tests to the end, and their
fixture waits for the result: the run goes on beside the rest of the suite instead of after it.

``python -m tests.benchmarks.compact_run ROOT`` writes ``ROOT/result.json`` (the config, the exit code
or null on a timeout, the wall seconds); SIGTERM stops the run cleanly (the ckm-run process group too).
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any

from benchmarks.mission import run_once
from benchmarks.mission_compact import compact
from tests.conftest import CONFIGS, REPO

LAB = CONFIGS / "usecase" / "lab.xml"
PORTS = (7650, 7660)  # a private network: never the lab's 7400/7410
LOCKSTEP = 0.01  # simulated s: the clock's largest step (the kernel's fastest loops run at 0.01-0.02 s)
DURATION = 120.0  # simulated s: the compact fetch takes about a minute
WALL_LIMIT = 900.0  # wall s: 227 s alone on a loaded 2-core machine, more beside the suite at a low priority
NICENESS = 10  # beside the suite: the tests that measure timing keep their share of the cores


def run(root: Path) -> dict[str, Any]:
    """Build the compact copy of the lab under ``root``, run its cooperative plan; the result written."""
    config = compact(LAB, root / "usecase", ports=PORTS)
    code, wall = run_once(config, "cooperative", root / "run", duration=DURATION, time_scale=None,
                          log=root / "run.log", lockstep=LOCKSTEP, timeout=WALL_LIMIT)  # fmt: skip
    result = {"config": str(config), "code": code, "wall": wall}
    (root / "result.json").write_text(json.dumps(result))
    return result


class Background:
    """The run in a process of its own, started at ``niceness``; :meth:`result` waits for it."""

    def __init__(self, root: Path, niceness: int = NICENESS) -> None:
        self.root = root
        root.mkdir(parents=True, exist_ok=True)
        nice = ["nice", "-n", str(niceness)] if niceness and shutil.which("nice") else []
        with (root / "background.log").open("w") as log:
            self.process = subprocess.Popen(
                [*nice, sys.executable, "-m", "tests.benchmarks.compact_run", str(root)],
                cwd=REPO,
                stdout=log,
                stderr=subprocess.STDOUT,
            )

    def result(self, timeout: float = WALL_LIMIT + 120) -> dict[str, Any]:
        """The run's result once it has ended; AssertionError (with its log) if it did not write one."""
        try:
            self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.stop()
        written = self.root / "result.json"
        log = (self.root / "background.log").read_text(errors="replace")
        code = self.process.returncode
        assert written.exists(), f"the compact mission run wrote no result (exit {code}):\n{log[-3000:]}"
        result: dict[str, Any] = json.loads(written.read_text())
        return result

    def stop(self) -> None:
        """SIGTERM (the run stops its ckm-run cleanly), then SIGKILL after a bound."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(60)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(10)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt  # run_once stops the ckm-run process group on it


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _interrupt)
    started = time.monotonic()
    print(json.dumps(run(Path(sys.argv[1]))), f"{time.monotonic() - started:.1f} s", flush=True)
