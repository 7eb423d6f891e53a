"""A plan across two OS processes (§5.3, Fig. 5.6): each agent runs on its node's ``ckm-run``;
the spotter's signal crosses the network and releases the fetcher; a vanished agent is reported."""

from __future__ import annotations

import json
import random
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from runtime.cli import EXIT_AGENTS
from runtime.missions.recording import Event, Run, RunError, read_run
from runtime.network.ports import private_base
from tests.waiting import until

DATA = Path(__file__).resolve().parents[2] / "data" / "plans" / "two_agents.xml"
LOST = DATA.parent / "lost_spotter.xml"  # the fetcher gives up on lost('spotter') (issue K point 3a)


def _config(tmp_path: Path) -> Path:
    """The test plan with a private loopback network (its own multicast group and ports)."""
    return _config_from(DATA.read_text(), tmp_path)


def _config_from(text: str, tmp_path: Path) -> Path:
    """``text`` with a private loopback network inserted before its first Node."""
    rng = random.Random()
    base = private_base(rng)  # below the ephemeral port range: no EADDRINUSE from other sockets
    network = (
        f'<Network transport="multipeer" group="239.255.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}" '
        f'discoveryPort="{base + 63}" interface="127.0.0.1" basePort="{base}" portTries="40" heartbeat="0.05"/>'
    )
    start = text.index(">", text.index("<System")) + 1  # Network comes first in a System
    text = text[:start] + "\n  " + network + text[start:]
    path = tmp_path / "plan.xml"
    path.write_text(text)
    return path


def _ckm_run(config: Path, node: str, run_dir: Path, duration: float, plan: str = "together") -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "runtime.cli", str(config), "--node", node, "--plan", plan]
    command += ["--duration", str(duration), "--log-dir", str(run_dir)]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _kill(*processes: subprocess.Popen[str]) -> None:
    """Kill (and reap) those of ``processes`` still running: a failed test leaves none behind."""
    for process in processes:
        if process.poll() is None:
            process.kill()
            process.wait(10)


def _run_both(config: Path, run_dir: Path, duration: float, timeout: float) -> Run:
    """Fetcher and spotter each on its own ``ckm-run`` until both exit 0; the run they recorded."""
    fetcher = _ckm_run(config, "fetcher-pc", run_dir, duration)
    spotter = _ckm_run(config, "spotter-pc", run_dir, duration)
    try:
        for process in (fetcher, spotter):
            _, err = process.communicate(timeout=timeout)
            assert process.returncode == 0, err
    finally:
        _kill(fetcher, spotter)
    return read_run(run_dir)


def _signal(run: Run) -> Event:
    """The signal event the fetcher received (asserting the spotter sent it)."""
    sent = next(e for e in run.events if e.kind == "signal" and e.fields["direction"] == "sent")
    received = next(e for e in run.events if e.kind == "signal" and e.fields["direction"] == "received")
    assert sent.agent == "spotter" and received.agent == "fetcher"
    return received


def test_two_agents_in_two_processes_complete_the_plan_with_a_signal(tmp_path: Path) -> None:
    config = _config(tmp_path)
    run = _run_both(config, tmp_path / "run", 30, timeout=60)
    ends = {e.agent: e.fields["outcome"] for e in run.events if e.kind == "end"}
    assert ends == {"spotter": "spotted", "fetcher": "done"}
    received = _signal(run)
    assert not [e for e in run.events if e.kind == "agent-lost"]  # the spotter finished: never "lost"
    left_nav = next(e for e in run.events if e.kind == "exit" and e.agent == "fetcher" and e.fields["state"] == "NAV")
    assert left_nav.fields["to"] == "GO" and left_nav.t >= received.t
    stats = json.loads((tmp_path / "run" / "stats.json").read_text())
    assert stats["system"] == "two-agents"


def test_an_agent_that_disappears_is_reported_lost(tmp_path: Path) -> None:
    config = _config(tmp_path)
    # The spotter never runs: the fetcher waits for its signal and reports it lost after lostAfter (2 s).
    fetcher = _ckm_run(config, "fetcher-pc", tmp_path / "run", 4)
    try:
        _, err = fetcher.communicate(timeout=60)
        # --duration cut the mission short: it did not reach its success final, so the run says so.
        assert fetcher.returncode == EXIT_AGENTS, err
        assert "agent fetcher: mission ended stopped" in err
    finally:
        _kill(fetcher)
    run = read_run(tmp_path / "run")
    lost = [e for e in run.events if e.kind == "agent-lost"]
    assert [e.fields["lost"] for e in lost] == ["spotter"]
    assert any(e.kind == "end" and e.fields["outcome"] == "stopped" for e in run.events)


@pytest.mark.parametrize("args", [["--plan", "nope"]])
def test_an_unknown_plan_is_refused(tmp_path: Path, args: list[str]) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "runtime.cli", str(DATA), *args, "--log-dir", str(tmp_path)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 1 and "no plan 'nope' (plans: together)" in result.stderr


def test_both_agents_in_one_embedded_run_still_signal_each_other(tmp_path: Path) -> None:
    example = Path(__file__).resolve().parents[3] / "configs" / "examples" / "plan_two_agents.xml"
    text = example.read_text()
    config = _config_from(text, tmp_path)
    result = subprocess.run(
        [sys.executable, "-m", "runtime.cli", str(config), "--plan", "fetch-together", "--duration", "30",
         "--log-dir", str(tmp_path / "run")],
        capture_output=True, text=True, timeout=90,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    ends = {e.agent: e.fields["outcome"] for e in read_run(tmp_path / "run").events if e.kind == "end"}
    assert ends == {"walker": "over", "carrier": "done"}
    report = subprocess.run(
        [sys.executable, "-m", "runtime.missions.cli", "report", str(tmp_path / "run"), "--json"],
        capture_output=True, text=True, timeout=90,
    )  # fmt: skip
    assert report.returncode == 0, report.stderr
    table = json.loads(report.stdout.strip().splitlines()[-1])
    assert table
    assert (tmp_path / "run" / "report" / "plan.png").read_bytes()[:4] == b"\x89PNG"


def test_a_signal_payload_crosses_two_processes_and_sets_the_receivers_goal(tmp_path: Path) -> None:
    """Fig. 7.13: the spotter's SPOT writes the object's position as the payload of `spotted`
    (checked against ObjectPosition when sent); in another process the fetcher's NAV_COOP reads
    it and sets its goal approachDistance (1 m) short of the object."""
    import threading

    from ckmconf.loader import load
    from runtime.network import open_transport
    from runtime.network.api import TopicQoS
    from runtime.resources import codec

    config = _config_from((DATA.parent / "payload.xml").read_text(), tmp_path)
    network = load(config).network
    assert network is not None
    feed = open_transport(network, name="recognition")  # what a recognition service would publish
    feed.setup()
    feed.start()
    seen = {"name": "cylinder_red_stripes", "shape": "cylinder", "texture": "red_stripes", "x": 3.0, "y": 4.0,
            "z": 0.1, "reliability": 0.9}  # fmt: skip
    publisher = feed.publisher(TopicQoS("/recog/objects", "ckm/behavior-input"))
    stop = threading.Event()

    def publish() -> None:
        while not stop.wait(0.1):
            publisher.publish(codec.encode({"objects": [seen], "reliability": 0.9}))

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        run = _run_both(config, tmp_path / "run", 40, timeout=90)
    finally:
        stop.set()
        thread.join(5)
        feed.stop()
    ends = {e.agent: e.fields["outcome"] for e in run.events if e.kind == "end"}
    assert ends == {"spotter": "spotted", "fetcher": "underway"}
    received = _signal(run)
    payload = received.fields["value"]["data"]
    assert (payload["label"], payload["x"], payload["y"], payload["z"]) == ("cylinder_red_stripes", 3.0, 4.0, 0.1)
    goal = next(e for e in run.events if e.kind == "log" and e.agent == "fetcher")
    assert goal.fields["message"] == "goal set" and goal.fields["source"] == "spotted"
    assert goal.fields["goal"] == "2.400 3.200 0.927"  # 1 m short of (3, 4), facing it


def _events(run_dir: Path, agent: str, kind: str) -> list[Any]:
    """The recorded events of one agent and kind so far (none while nothing is recorded)."""
    try:
        return [e for e in read_run(run_dir).events if e.agent == agent and e.kind == kind]
    except RunError:
        return []


def _gave_up(run_dir: Path, fetcher: subprocess.Popen[str]) -> tuple[str, Any]:
    """The fetcher's stderr once it has ended, and its run (asserting the failure branch was taken)."""
    _, err = fetcher.communicate(timeout=60)
    assert fetcher.returncode == EXIT_AGENTS, err  # the plan's agent did not end in its success final
    assert "agent fetcher: mission ended failed" in err
    run = read_run(run_dir)
    left = next(e for e in run.events if e.kind == "exit" and e.agent == "fetcher" and e.fields["state"] == "NAV")
    assert left.fields["to"] == "gave_up" and "lost('spotter')" in left.fields["condition"]
    ends = {e.agent: e.fields["outcome"] for e in run.events if e.kind == "end"}
    assert ends["fetcher"] == "failed"
    return err, run


def test_a_spotter_killed_after_start_sends_the_fetcher_down_its_failure_branch(tmp_path: Path) -> None:
    """Fig. 7.13's failure: the Nao's process dies; the Turtlebot's mission takes its failure branch
    (lost('spotter') once it is silent for lostAfter) instead of waiting out NAV's timeout."""
    config = _config_from(LOST.read_text(), tmp_path)
    run_dir = tmp_path / "run"
    spotter = _ckm_run(config, "spotter-pc", run_dir, 60)
    fetcher = _ckm_run(config, "fetcher-pc", run_dir, 60)
    try:
        assert until(lambda: bool(_events(run_dir, "spotter", "enter")) and bool(_events(run_dir, "fetcher", "enter")),
                     timeout=60), "the two agents did not start"  # fmt: skip
        time.sleep(1.0)  # heartbeats (every 0.5 s) cross: the fetcher has seen the spotter alive
        assert not _events(run_dir, "fetcher", "agent-lost")
        spotter.kill()
        spotter.wait(10)
        _, run = _gave_up(run_dir, fetcher)
    finally:
        _kill(fetcher, spotter)
    lost = [e for e in run.events if e.kind == "agent-lost"]
    assert [(e.agent, e.fields["lost"]) for e in lost] == [("fetcher", "spotter")]
    assert not [e for e in run.events if e.kind == "end" and e.agent == "spotter"]  # killed: it wrote no end


def test_a_spotter_ending_in_its_failure_final_sends_the_fetcher_down_its_failure_branch(tmp_path: Path) -> None:
    """The spotter gives up (its final `lost`, not its success final): lost('spotter') holds at once,
    though the plan's lostAfter (30 s) is far off; the recording says it finished, not that it was lost."""
    config = _config_from(LOST.read_text(), tmp_path)
    run_dir = tmp_path / "run"
    fetcher = _ckm_run(config, "fetcher-pc", run_dir, 60, plan="fails")
    spotter = _ckm_run(config, "spotter-pc", run_dir, 60, plan="fails")
    try:
        _, err = spotter.communicate(timeout=60)
        assert spotter.returncode == EXIT_AGENTS and "agent spotter: mission ended lost" in err, err
        _, run = _gave_up(run_dir, fetcher)
    finally:
        _kill(fetcher, spotter)
    finished = [e.fields for e in run.events if e.kind == "agent-finished" and e.agent == "fetcher"]
    assert finished == [{"finished": "spotter", "outcome": "lost"}]
    assert not [e for e in run.events if e.kind == "agent-lost"]
    ended = next(e for e in run.events if e.kind == "end" and e.agent == "fetcher")
    assert ended.t < 25.0  # long before lostAfter (30 s) or NAV's timeout (60 s)
