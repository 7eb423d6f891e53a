"""Two runs of one system on one network (D257): the second is refused before its nodes start, naming
the first's address and what to do; the first runs on, warned, and ends as it would have."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from runtime.runrecord import EXIT_NETWORK
from tests.conftest import REPO
from tests.runtime.lockstep_runs import private_copy


def test_a_second_run_of_the_same_system_on_its_network_is_refused_and_the_first_goes_on(tmp_path: Path) -> None:
    config = private_copy(REPO / "configs/examples/closed_loop.xml", tmp_path / "closed_loop.xml")
    first_dir, second_dir = tmp_path / "first", tmp_path / "second"
    first = subprocess.Popen(
        [sys.executable, "-m", "runtime.cli", str(config), "--duration", "8", "--log-dir", str(first_dir)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        log = first_dir / "ckm.log"
        while not (log.exists() and "running " in log.read_text()):  # its nodes are running
            assert time.monotonic() < deadline and first.poll() is None, first.stderr.read() if first.stderr else ""
            time.sleep(0.1)
        second = subprocess.run(
            [sys.executable, "-m", "runtime.cli", str(config), "--duration", "3", "--log-dir", str(second_dir)],
            cwd=REPO, capture_output=True, text=True, timeout=60,
        )  # fmt: skip
        assert second.returncode == EXIT_NETWORK, second.stderr
        assert f"{config}: cannot join the network: another peer named" in second.stderr
        assert "127.0.0.1:" in second.stderr and "another run of this system" in second.stderr
        assert "running " not in (second_dir / "ckm.log").read_text()  # refused before any node ran
        _, errors = first.communicate(timeout=60)
        assert first.returncode == 0, errors
        assert "another peer named" in log.read_text()  # the first was warned
    finally:
        if first.poll() is None:
            first.kill()
            first.wait(10)
