"""ckm-run: every example runs and stops cleanly; signals stop a run with actuators safe."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import ckmconf
from runtime.verification.verify import verify_safely
from tests.conftest import REPO

EXAMPLES = sorted(
    p for p in (REPO / "configs" / "examples").glob("*.xml") if "<Node " in p.read_text() or "split" in p.name
)


def ckm_run(*args: str) -> list[str]:
    return [sys.executable, "-m", "runtime.cli", *args]


@pytest.mark.parametrize("config", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_every_example_runs_for_its_duration_or_is_refused_before_start(config: Path, tmp_path: Path) -> None:
    done = subprocess.run(
        ckm_run(str(config), "--duration", "0.5", "--log-dir", str(tmp_path)),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    problems = verify_safely(ckmconf.load(config))
    if problems:  # what verify refuses, ckm-run refuses too, each problem located, nothing started
        assert done.returncode == 1, done.stderr
        assert all(str(problem) in done.stderr for problem in problems)
        assert not (tmp_path / "stats.json").exists()
        return
    assert done.returncode == 0, done.stderr
    stats = json.loads((tmp_path / "stats.json").read_text())
    assert stats["nodes"], "no node ran"
    for node in stats["nodes"].values():
        for actuator in node["actuators"].values():
            assert actuator["mode"] == "safe"  # stopped with its safe value driven
    assert (tmp_path / "ckm.log").exists()


def test_sigterm_stops_cleanly_with_actuators_safe(tmp_path: Path) -> None:
    process = subprocess.Popen(
        ckm_run(str(REPO / "configs/examples/closed_loop.xml"), "--log-dir", str(tmp_path)),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # signal only once ckm-run is up (its handler installed before it logs "running"), bounded
        log, deadline = tmp_path / "ckm.log", time.monotonic() + 90.0
        while not (log.exists() and " running " in log.read_text()):
            assert process.poll() is None, process.communicate()[1]
            assert time.monotonic() < deadline, "ckm-run did not log 'running' within 90 s"
            time.sleep(0.1)
        time.sleep(1.0)  # some control periods released before the stop
        process.send_signal(signal.SIGTERM)
        _, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, err
    stats = json.loads((tmp_path / "stats.json").read_text())
    motor = stats["nodes"]["motor-node"]["actuators"]["motor"]
    assert motor["mode"] == "safe" and motor["value"] == 0.0
    assert stats["nodes"]["motor-node"]["tasks"]["motor-node.pid"]["releases"] > 10


def test_errors_are_one_line(tmp_path: Path) -> None:
    unknown = subprocess.run(
        ckm_run(str(REPO / "configs/examples/closed_loop.xml"), "--node", "nope", "--log-dir", str(tmp_path)),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert unknown.returncode == 1
    assert unknown.stderr.strip().endswith("no node 'nope' (nodes: motor-node)")
    invalid = subprocess.run(
        ckm_run(str(REPO / "configs/invalid/sensor_unknown_channel.xml")),
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert invalid.returncode == 1 and "Traceback" not in invalid.stderr
    assert "HWChannel 'encodr' does not exist" in invalid.stderr
