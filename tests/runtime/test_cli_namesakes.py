"""Two runs of one system on one network (D257): the second is refused before its nodes start, naming
the first's address and what to do; the first runs on, warned, and ends as it would have. On ports of its
own (``ckm-run --ports``, D258) the second runs beside the first."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import ckmconf
from runtime.network.guid import guid_address
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


def test_a_second_run_on_ports_of_its_own_runs_beside_the_first_and_bad_ports_are_refused(tmp_path: Path) -> None:
    """D258: ``ckm-run --ports DISCOVERY BASE`` moves a run (and its partitions) off its <Network>'s ports,
    so a second run of one system runs beside the first, neither hearing the other."""
    source = REPO / "configs/examples/partitions.xml"  # a run with partition processes, which inherit the ports
    config = private_copy(source, tmp_path / "partitions.xml")
    network = ckmconf.load(config).network
    assert network is not None
    other = (network.discovery_port + 1, network.base_port + 200)
    runs = [
        subprocess.Popen(
            [sys.executable, "-m", "runtime.cli", str(config), "--duration", "4", "--log-dir", str(tmp_path / name),
             *extra],
            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        for name, extra in (("first", []), ("second", ["--ports", str(other[0]), str(other[1])]))
    ]
    try:
        for run in runs:
            _, errors = run.communicate(timeout=120)
            assert run.returncode == 0, errors
    finally:
        for run in runs:
            if run.poll() is None:
                run.kill()
                run.wait(10)
    for name in ("first", "second"):
        logs = "".join(log.read_text() for log in (tmp_path / name).rglob("ckm.log"))
        assert "another peer named" not in logs and "running " in logs
    linked = [int(g) for g in re.findall(r"network: linked (\d+)", (tmp_path / "second" / "ckm.log").read_text())]
    assert linked and all(0 <= guid_address(g)[1] - other[1] < 48 for g in linked)  # its partitions: on its ports
    for bad, message in ((["1", "2"], "two different ports in 1024-65535"), (["x", "9000"], "two port numbers")):
        done = subprocess.run([sys.executable, "-m", "runtime.cli", str(config), "--ports", *bad],
                              cwd=REPO, capture_output=True, text=True, timeout=60)  # fmt: skip
        assert done.returncode == 2 and f"--ports = {' '.join(bad)!r}: expected {message}" in done.stderr
