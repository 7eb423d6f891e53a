"""What the lock-step run tests share: a config copied onto a private network, one ``ckm-run --lockstep``
run of it, and busy processes competing for the cores while a run goes on (the machine has none to spare)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import ckmconf
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network


def private_copy(source: Path, config: Path) -> Path:
    """``source`` (a System) written to ``config`` with a private loopback network: no other run hears it."""
    system = ckmconf.load(source)
    ckmconf.dump(dataclasses.replace(system, network=private_network()), config)
    return config


def run_lockstep(config: Path, run_dir: Path, duration: float) -> subprocess.CompletedProcess[str]:
    """``ckm-run CONFIG --lockstep 0.01`` for ``duration`` simulated s, logs in ``run_dir``; asserts it exited 0."""
    command = [sys.executable, "-m", "runtime.cli", str(config), "--lockstep", "0.01", "--duration", str(duration),
               "--log-dir", str(run_dir)]  # fmt: skip
    done = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return done


@contextmanager
def busy(count: int) -> Iterator[None]:
    """``count`` busy processes at the test's own priority while the block runs; killed at its end."""
    spin = "import time\nend = time.time() + 120\nwhile time.time() < end:\n    pass\n"
    load = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(count)]
    try:
        yield
    finally:
        for process in load:
            process.kill()
            process.wait(10)
