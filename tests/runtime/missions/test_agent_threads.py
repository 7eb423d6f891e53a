"""AgentRunner's threading model (issue O point 2): the transport's threads only hand heartbeats and
signals over; the agent's own thread takes them in, so concurrent callbacks neither race its state
nor record an event twice."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from ckmconf.loader import load
from runtime.missions.agent import AgentRunner
from runtime.missions.recording import read_run
from runtime.network import open_transport
from runtime.network.api import Sample
from runtime.resources import codec
from tests.runtime.network.conftest import private_network

PLANS = Path(__file__).resolve().parents[2] / "data" / "plans" / "lost_spotter.xml"
CALLERS = 8
CALLS = 400
STRANGERS = 5000  # heartbeats of no agent of the plan (another plan's, a stale process)


pytestmark = pytest.mark.usefixtures("switching_often")


def sample(value: object, seq: int) -> Sample:
    return Sample(topic="/plan/together/agents", value=value, stamp=time.time(), source=7, seq=seq,
                  received=time.time())  # fmt: skip


def test_concurrent_heartbeats_and_signals_are_taken_in_once_on_the_agents_thread(tmp_path: Path) -> None:
    system = load(PLANS)
    transport = open_transport(private_network(), name="fetcher-pc")
    transport.setup()
    transport.start()
    runner = AgentRunner(system, "together", "fetcher", transport, tmp_path / "run", heartbeat=0.05, period=0.01)
    on_signal = runner._received("spotted")
    envelope = codec.encode({"agent": "spotter", "state": "FIX", "time": 0.0, "data": None})
    start, finals = threading.Barrier(CALLERS + 1), threading.Barrier(CALLERS)
    failures: list[BaseException] = []

    def caller(index: int) -> None:
        start.wait(10)
        try:
            for n in range(STRANGERS):  # while the agent waits to meet the others (D208)
                runner._on_beat(sample({"agent": f"stranger{index}-{n}", "state": "", "t": 0.0}, n))
            for n in range(CALLS):
                seq = index * CALLS + n
                runner._on_beat(sample({"agent": "spotter", "state": "Spot/TRACK", "t": 0.0}, seq))
                if n == CALLS // 2:
                    on_signal(sample(envelope, seq))
            finals.wait(30)  # every caller's final heartbeat at once
            for n in range(CALLS):
                runner._on_beat(sample({"agent": "spotter", "state": None, "outcome": "spotted"}, -index - n))
        except BaseException as error:  # reported by the assertion below
            failures.append(error)

    callers = [threading.Thread(target=caller, args=(i,), daemon=True) for i in range(CALLERS)]
    outcome: list[str | None] = []
    agent = threading.Thread(target=lambda: outcome.append(runner.run(60)), daemon=True)
    try:
        for thread in callers:
            thread.start()
        agent.start()
        start.wait(10)
        for thread in callers:
            thread.join(60)
        agent.join(60)
        assert not agent.is_alive() and all(not t.is_alive() for t in callers)
    finally:
        runner.stop()
        agent.join(10)
        transport.stop()
    assert not failures and runner.error is None
    assert outcome == ["done"]  # the signal reached NAV, the mission went on to its success
    assert set(runner.seen) == {"spotter"} and runner.finished == {"spotter": "spotted"} and not runner.lost
    events = read_run(tmp_path / "run").events
    assert [e.fields["finished"] for e in events if e.kind == "agent-finished"] == ["spotter"]  # once, of 8 finals
    received = [e for e in events if e.kind == "signal" and e.fields.get("direction") == "received"]
    assert [e.fields["name"] for e in received] == ["spotted"]  # latched once, of 8 arrivals
    assert not [e for e in events if e.kind in ("agent-lost", "error")]
