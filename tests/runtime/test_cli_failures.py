"""ckm-run fails loudly (issue G): a run that breaks never exits 0, and says why on its stderr;
what a run writes survives a SIGKILL; processes sharing a run directory keep their own files."""

from __future__ import annotations

import functools
import json
import random
import signal
import subprocess
import sys
from pathlib import Path

from runtime.cli import EXIT_AGENTS, EXIT_CONFIG, EXIT_FAILED
from runtime.network.ports import private_base
from tests import waiting
from tests.conftest import REPO

DATA = REPO / "tests" / "data" / "run"


def private(name: str, tmp_path: Path) -> Path:
    """The test config with a private loopback network, inserted on the System's line (lines keep their numbers)."""
    text = (DATA / name).read_text()
    rng = random.Random()
    base = private_base(rng)
    network = (
        f'<Network transport="multipeer" group="239.255.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}" '
        f'discoveryPort="{base + 63}" interface="127.0.0.1" basePort="{base}" portTries="40" heartbeat="0.05"/>'
    )
    start = text.index(">", text.index("<System")) + 1
    path = tmp_path / name
    path.write_text(text[:start] + network + text[start:])
    return path


def ckm_run(*args: str | Path, timeout: float = 90) -> subprocess.CompletedProcess[str]:
    command = [sys.executable, "-m", "runtime.cli", *map(str, args)]
    return subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=timeout)


until = functools.partial(waiting.until, interval=0.1)  # this file's polling period


def test_an_unknown_controller_kind_in_a_partition_is_refused_before_anything_starts(tmp_path: Path) -> None:
    config = private("partition_unknown_controller.xml", tmp_path)
    done = ckm_run(config, "--duration", "3", "--log-dir", tmp_path / "run")
    assert done.returncode == EXIT_CONFIG, done.stderr
    assert f"{config}:11:" in done.stderr and "no-such-controller" in done.stderr
    assert not (tmp_path / "run").exists(), "something was started"


def test_a_partition_that_cannot_build_fails_the_run_with_its_located_error(tmp_path: Path) -> None:
    config = private("partition_build_fails.xml", tmp_path)
    done = ckm_run(config, "--duration", "3", "--log-dir", tmp_path / "run")
    assert done.returncode == EXIT_FAILED, done.stderr
    line = next(line for line in done.stderr.splitlines() if "[node arm, partition control]" in line)
    assert line.startswith(f"{config}:11:5: ") and "conflicts with" in line
    stats = json.loads((tmp_path / "run" / "stats.json").read_text())
    assert stats["partitions"]["arm"]["control"]["first_error"].startswith(f"{config}:11:5: ")


def test_a_plan_whose_agent_gives_up_exits_non_zero_and_logs_the_outcome(tmp_path: Path) -> None:
    config = private("plan_gives_up.xml", tmp_path)
    done = ckm_run(config, "--node", "fetcher-pc", "--plan", "together", "--duration", "30", "--log-dir", tmp_path)
    assert done.returncode == EXIT_AGENTS, done.stderr
    assert "agent fetcher: mission ended failed" in done.stderr
    assert "agent fetcher: outcome failed" in (tmp_path / "ckm.log").read_text()


def test_two_node_processes_share_a_run_directory_and_a_sigkill_keeps_what_happened(tmp_path: Path) -> None:
    config = private("two_nodes.xml", tmp_path)
    run_dir = tmp_path / "run"
    processes = {
        node: subprocess.Popen(
            [sys.executable, "-m", "runtime.cli", str(config), "--node", node, "--log-dir", str(run_dir)],
            cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )
        for node in ("left", "right")
    }
    try:

        def linked_and_counted() -> bool:
            events = [p for p in run_dir.glob("events*.jsonl") if "network-linked" in p.read_text()]
            stats = list(run_dir.glob("stats*.json"))
            return len(events) == 2 and len(stats) == 2 and all(p.stat().st_size > 0 for p in stats)

        assert until(linked_and_counted, 60), sorted(p.name for p in run_dir.iterdir())
        processes["left"].send_signal(signal.SIGKILL)  # no clean stop: what was written must stay
        processes["right"].send_signal(signal.SIGTERM)
        assert processes["left"].wait(30) == -signal.SIGKILL
        assert processes["right"].wait(30) == 0, processes["right"].stderr.read()  # type: ignore[union-attr]
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.wait(10)
    by_node = {}
    for path in run_dir.glob("stats*.json"):
        stats = json.loads(path.read_text())
        (node,) = stats["nodes"]
        by_node[node] = (path, stats)
    assert set(by_node) == {"left", "right"}, "one process overwrote the other's statistics"
    assert by_node["left"][1]["nodes"]["left"]["tasks"]["left.value"]["releases"] > 0  # written while running
    events = {p.name: p.read_text() for p in run_dir.glob("events*.jsonl")}
    assert len(events) == 2 and all("network-linked" in text for text in events.values())


def test_an_alarm_the_configuration_calls_an_error_fails_the_run(tmp_path: Path) -> None:
    """D147: a run whose monitor raised an error (or critical) alarm broke, even if nothing crashed;
    a warning alone does not fail a run (the same run without the error alarm exits 0)."""
    config = private("serious_alarm.xml", tmp_path)
    done = ckm_run(config, "--duration", "2", "--log-dir", tmp_path / "run")
    assert done.returncode == EXIT_FAILED, done.stderr
    assert "base: alarm heartbeat_lost (error) raised 1 time(s), first: staleness = " in done.stderr
    assert "staleness = inf" not in done.stderr  # never published: as old as the watch (D311)
    warning_only = tmp_path / "warning.xml"
    warning_only.write_text(config.read_text().replace('severity="error"', 'severity="warning"'))
    done = ckm_run(warning_only, "--duration", "2", "--log-dir", tmp_path / "run2")
    assert done.returncode == 0, done.stderr
