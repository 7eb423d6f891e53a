"""lost('agent') and the clock silence is measured on (issue K point 3a, D177): ``lostAfter`` is
seconds of the run's clock — simulated seconds under ``ckm-run --time-scale`` — not wall seconds."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from ckmconf import ConfigError
from ckmconf.loader import load, load_bytes
from plugins.hardware.simulation import ManualClock
from runtime import simtime
from runtime.missions.agent import AgentRunner
from runtime.missions.recording import read_run
from runtime.network import open_transport
from runtime.network.api import TopicQoS
from tests.runtime.network.conftest import private_network
from tests.waiting import until

PLANS = Path(__file__).resolve().parents[2] / "data" / "plans" / "lost_spotter.xml"


def test_silence_is_measured_on_the_runs_clock_and_lost_takes_the_failure_branch(tmp_path: Path) -> None:
    system = load(PLANS)
    clock = ManualClock()
    transport = open_transport(private_network(), name="fetcher-pc")
    transport.setup()
    transport.start()
    runner = AgentRunner(system, "together", "fetcher", transport, tmp_path / "run", heartbeat=0.1, period=0.02,
                         clock=clock)  # fmt: skip
    answer: list[str | None] = []
    thread = threading.Thread(target=lambda: answer.append(runner.run(120)), daemon=True)
    try:
        thread.start()
        time.sleep(0.5)  # wall time passes, the run's clock stands: the spotter is not lost
        clock.advance(1.0)  # 1 s of the run's clock, under lostAfter (1.5 s)
        time.sleep(0.3)
        # the fetcher still waits to hear the spotter before its mission starts (D208)
        assert not runner.lost and runner.engine.active_path() is None
        clock.advance(1.0)  # past lostAfter: the mission starts without it, lost, and NAV's lost('spotter') fires
        thread.join(10)
        assert not thread.is_alive()
    finally:
        runner.stop()
        thread.join(10)
        transport.stop()
    assert answer == ["failed"] and not runner.succeeded
    assert runner.lost == {"spotter"} and runner.agent_lost("spotter")
    events = read_run(tmp_path / "run").events
    assert [e.fields["lost"] for e in events if e.kind == "agent-lost"] == ["spotter"]
    left = next(e for e in events if e.kind == "exit" and e.fields["state"] == "NAV")
    assert left.fields["to"] == "gave_up"


def test_an_agent_waits_for_the_others_heartbeat_and_starts_as_soon_as_it_is_heard(tmp_path: Path) -> None:
    """D208: the fetcher's mission does not start while the spotter has not been heard (a signal sent
    before its process linked would be lost), and starts at once when the spotter's heartbeat comes,
    on a clock that never moved."""
    system = load(PLANS)
    clock = ManualClock()
    network = private_network()
    transport, spotter = open_transport(network, name="fetcher-pc"), open_transport(network, name="spotter-pc")
    for each in (transport, spotter):
        each.setup()
        each.start()
    runner = AgentRunner(system, "together", "fetcher", transport, tmp_path / "run", heartbeat=0.1, period=0.02,
                         clock=clock)  # fmt: skip
    thread = threading.Thread(target=runner.run, args=(120,), daemon=True)
    beat = spotter.publisher(TopicQoS("/plan/together/agents", "ckm/agent-heartbeat", history=8))
    try:
        thread.start()
        time.sleep(0.5)
        assert runner.engine.active_path() is None and not runner.lost
        assert until(lambda: (beat.publish({"agent": "spotter", "state": "", "t": 0.0}), "spotter" in runner.seen)[1],
                     timeout=10)  # fmt: skip
        assert until(lambda: runner.engine.active_path() == "Fetch/NAVIGATION/NAV", timeout=10)
        assert not runner.lost
    finally:
        runner.stop()
        thread.join(10)
        for each in (transport, spotter):
            each.stop()


def test_an_agent_that_finished_in_its_success_final_is_not_lost(tmp_path: Path) -> None:
    system = load(PLANS)
    transport = open_transport(private_network(), name="fetcher-pc")
    runner = AgentRunner(system, "together", "fetcher", transport, tmp_path / "run")
    try:
        runner.finished["spotter"] = "spotted"  # the success final: the first Spot declares
        assert not runner.agent_lost("spotter")
        for failure in ("lost", "crashed", "stopped", None):
            runner.finished["spotter"] = failure
            assert runner.agent_lost("spotter"), failure
        assert not runner.agent_lost("nobody")
    finally:
        runner.recorder.close()


def test_the_default_clock_is_the_scaled_one_under_a_time_scale() -> None:
    """In a process of a scaled run the agent's clock runs at the scale (lostAfter in simulated seconds)."""
    probe = (
        "import threading; from runtime import simtime; from runtime.missions.agent import _run_clock\n"
        "real = simtime._REAL['monotonic']; r0, c0 = real(), _run_clock()\n"
        "threading.Event().wait(0.1)\n"  # 0.1 s of the scaled clock: 0.4 s of wall time
        "r1, c1 = real(), _run_clock(); print((c1 - c0) / (r1 - r0))"
    )
    env = {**os.environ, **simtime.environment(0.25)}
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, env=env,
                            cwd=Path(__file__).resolve().parents[3])  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert abs(float(result.stdout) - 0.25) < 0.01


def test_lost_of_an_agent_no_plan_has_is_refused_where_it_is_written(tmp_path: Path) -> None:
    text = PLANS.read_text().replace("lost('spotter')", "lost('spoter')")
    line = next(n for n, row in enumerate(text.splitlines(), start=1) if "lost('spoter')" in row)
    with pytest.raises(ConfigError) as caught:
        load_bytes(text.encode(), str(tmp_path / "plans.xml"))
    message = str(caught.value)
    assert message.startswith(f"{tmp_path / 'plans.xml'}:{line}:") and "agent 'spoter' does not exist" in message
    assert "did you mean 'spotter'" in message
