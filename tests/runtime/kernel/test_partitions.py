"""Partitions (§3.1.3.2): separate processes, restarted on their own; a crash is an alarm, never a stop.

The ckm-run tests run a node whose loop spans two partitions and its main process: a sensor in
"io" feeds a PID in "control" that drives an actuator in "io", and a relay in the main process
echoes the measure on an external topic the test watches. Every process is killed in finally.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
import types
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest

import ckmconf
from ckmconf.model import Alarm, Node, Partition
from runtime.cli import EXIT_FAILED
from runtime.kernel.partitions import MEMORY_EXIT, PartitionSupervisor
from runtime.network import Sample, TopicQoS, Transport, open_transport
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network
from tests.waiting import until

CONFIG = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="partition-test">
  <Node name="arm">
    <Partition name="io" criticality="safety" memory="64" restart="on-failure" maxRestarts="3" restartDelay="0.2"/>
    <Partition name="control" cpu="0.3" restart="{restart}" maxRestarts="{max_restarts}" restartDelay="0.2"/>
    <HWChannel name="enc" direction="in"><Param name="plant" value="arm"/></HWChannel>
    <HWChannel name="drive" direction="out" min="-1" max="1">
      <Param name="plant" value="arm"/>
      <Param name="order" value="1"/>
      <Param name="gain" value="2000"/>
      <Param name="timeConstant" value="0.2"/>
    </HWChannel>
    <Topic name="pos" type="float64" scope="internal"/>
    <Topic name="cmd" type="float64" scope="internal"/>
    <Topic name="/test/target" type="float64" lifespan="1"/>
    <Topic name="/test/pos" type="float64"/>
    <Sensor name="pos" channel="enc" topic="pos" period="0.01" partition="io">
      <Adaptation>
        <Linear gain="0.001"/>
        <LowPass cutoff="20"/>
      </Adaptation>
    </Sensor>
    <Controller name="pid" kind="pid" period="0.01" partition="control">
      <Param name="kp" value="0.8"/>
      <Param name="ki" value="2"/>
      <Input topic="pos" role="measure"/>
      <Input topic="/test/target" role="setpoint"/>
      <Output topic="cmd"/>
    </Controller>
    <Controller name="echo" kind="relay" period="0.02">
      <Input topic="pos"/>
      <Output topic="/test/pos"/>
    </Controller>
    <Actuator name="drive" channel="drive" topic="cmd" min="-1" max="1" safeValue="0" partition="io"/>
    <Monitor period="0.2">
      <Alarm name="control-crash" measure="partition-crash" partition="control"/>
    </Monitor>
  </Node>
</System>
"""




def gone(process: psutil.Process) -> bool:
    try:
        return bool(process.status() == psutil.STATUS_ZOMBIE)
    except psutil.NoSuchProcess:
        return True


class Run:
    """One ckm-run of the test node, the test's own peer on its network, and cleanup."""

    def __init__(self, tmp_path: Path, restart: str = "on-failure", max_restarts: int = 3) -> None:
        self.network = private_network()
        text = CONFIG.format(restart=restart, max_restarts=max_restarts)
        system = ckmconf.load_bytes(text.encode(), str(tmp_path / "template.xml"))
        self.config = tmp_path / "partitions.xml"
        ckmconf.dump(dataclasses.replace(system, network=self.network), self.config)
        self.run_dir = tmp_path / "run"
        self.events: list[dict[str, Any]] = []
        self.positions: list[float] = []
        self.seen: list[psutil.Process] = []
        self.probe: Transport = open_transport(self.network, name="probe")
        self.probe.setup()
        self.probe.start()
        self.probe.subscribe(TopicQoS("/arm/alarms", "event", history=64), self._event)
        self.probe.subscribe(TopicQoS("/test/pos"), lambda s: self.positions.append(float(s.value)))
        self.target = self.probe.publisher(TopicQoS("/test/target"))
        with (tmp_path / "ckm-run.out").open("w") as out:
            self.parent = subprocess.Popen(
                [sys.executable, "-m", "runtime.cli", str(self.config), "--log-dir", str(self.run_dir)],
                cwd=REPO,
                stdout=out,
                stderr=subprocess.STDOUT,
            )

    def _event(self, sample: Sample) -> None:
        self.events.append(dict(sample.value))

    def kinds(self, partition: str) -> list[str]:
        return [e["kind"] for e in list(self.events) if e.get("partition") == partition]

    def children(self) -> dict[str, psutil.Process]:
        """The running partition processes, by partition."""
        found: dict[str, psutil.Process] = {}
        try:
            for child in psutil.Process(self.parent.pid).children():
                command = child.cmdline()
                if "--partition" in command and not gone(child):
                    found[command[command.index("--partition") + 1]] = child
                    self.seen.append(child)
        except psutil.Error:
            pass
        return found

    def running(self, partition: str) -> int:
        """How many times the partition's process got to run (its ckm.log is appended to)."""
        log = self.run_dir / partition / "ckm.log"
        return log.read_text().count("INFO ckm.run: running") if log.exists() else 0

    def wait_children(self, timeout: float = 30.0) -> dict[str, psutil.Process]:
        def ready() -> bool:
            return set(self.children()) == {"io", "control"} and all(self.running(p) for p in ("io", "control"))

        assert until(ready, timeout), "partitions did not start"
        return self.children()

    def follows(self, target: float, timeout: float = 30.0) -> bool:
        """Whether the loop brings /test/pos to ``target`` (the target is republished meanwhile)."""

        def close() -> bool:
            self.target.publish(target)
            return len(self.positions) > 5 and all(abs(p - target) < 0.05 for p in self.positions[-5:])

        return until(close, timeout)

    def stop(self) -> int:
        self.parent.send_signal(signal.SIGTERM)
        return self.parent.wait(timeout=60)

    def stats(self, where: str = "") -> dict[str, Any]:
        return dict(json.loads((self.run_dir / where / "stats.json").read_text()))

    def logged_events(self) -> list[dict[str, Any]]:
        lines = (self.run_dir / "events.jsonl").read_text().splitlines()
        return [json.loads(line) for line in lines]

    def close(self) -> None:
        self.parent.kill()
        for process in self.seen:  # partitions this test saw, by pid
            with contextlib.suppress(psutil.Error):
                process.kill()
        self.parent.wait(timeout=10)
        self.probe.stop()


@pytest.fixture
def runs(tmp_path: Path) -> Iterator[Callable[..., Run]]:
    made: list[Run] = []

    def make(**options: Any) -> Run:
        run = Run(tmp_path, **options)
        made.append(run)
        return run

    yield make
    for run in made:
        run.close()


def test_loop_spans_partitions_and_sigterm_stops_every_child(runs: Callable[..., Run]) -> None:
    run = runs()
    children = run.wait_children()
    assert run.follows(0.5), f"the loop did not settle: {run.positions[-5:]}"
    assert run.stop() == 0
    assert until(lambda: all(gone(c) for c in children.values()), 10)
    partitions = run.stats()["partitions"]["arm"]
    for name in ("io", "control"):
        assert partitions[name]["last_exit_code"] == 0 and partitions[name]["crashes"] == 0
        assert partitions[name]["pids"][0]["pid"] == children[name].pid
    assert partitions["control"]["cpu_share"] == 0.3 and partitions["control"]["cpu_share_enforced"] is False
    io = run.stats("io")
    assert io["nodes"]["arm"]["actuators"]["drive"]["mode"] == "safe"  # stopped cleanly, actuator safe
    assert io["memory"]["limit_bytes"] == io["memory"]["baseline_bytes"] + (64 << 20)
    assert (run.run_dir / "io" / "ckm.log").exists() and (run.run_dir / "control" / "ckm.log").exists()


def test_a_killed_partition_is_restarted_alone_and_raises_an_alarm(runs: Callable[..., Run]) -> None:
    run = runs()
    children = run.wait_children()
    assert run.follows(0.5)
    children["control"].kill()
    assert until(lambda: run.children().get("control", children["control"]).pid != children["control"].pid, 20)
    assert run.children()["io"].pid == children["io"].pid  # the other partition kept running
    assert run.follows(-0.3), "the restarted partition did not close the loop again"
    assert until(lambda: any(e["kind"] == "alarm" and e["alarm"] == "control-crash" for e in run.events), 10)
    assert run.stop() == EXIT_FAILED  # a crash, even one restarted, is a failed run (issue G)
    events = run.logged_events()
    crashed = next(e for e in events if e["kind"] == "partition-crashed")
    assert crashed["partition"] == "control" and crashed["exit_code"] == -9 and crashed["signal"] == "SIGKILL"
    assert any(e["kind"] == "partition-restarted" and e["partition"] == "control" for e in events)
    assert any(e["kind"] == "alarm" and e["alarm"] == "control-crash" for e in events)
    control = run.stats()["partitions"]["arm"]["control"]
    assert (control["crashes"], control["restarts"], len(control["pids"])) == (1, 1, 2)
    assert run.stats()["partitions"]["arm"]["io"]["restarts"] == 0


def test_restart_never_leaves_a_crashed_partition_down(runs: Callable[..., Run]) -> None:
    run = runs(restart="never")
    children = run.wait_children()
    children["control"].kill()
    assert until(lambda: "partition-given-up" in run.kinds("control"), 15)
    time.sleep(1.0)  # well past restartDelay
    assert set(run.children()) == {"io"} and run.children()["io"].pid == children["io"].pid
    assert run.stop() == EXIT_FAILED
    control = run.stats()["partitions"]["arm"]["control"]
    assert (control["crashes"], control["restarts"], control["given_up"]) == (1, 0, True)
    assert "partition-restarted" not in [e["kind"] for e in run.logged_events()]


def test_max_restarts_is_respected(runs: Callable[..., Run]) -> None:
    run = runs(max_restarts=1)
    first = run.wait_children()["control"]
    first.kill()
    assert until(lambda: run.children().get("control", first).pid != first.pid, 20)
    second = run.children()["control"]
    second.kill()
    assert until(lambda: "partition-given-up" in run.kinds("control"), 15)
    time.sleep(1.0)
    assert "control" not in run.children()
    assert run.stop() == EXIT_FAILED
    control = run.stats()["partitions"]["arm"]["control"]
    assert (control["crashes"], control["restarts"], control["given_up"]) == (2, 1, True)
    assert [p["pid"] for p in control["pids"]] == [first.pid, second.pid]


def test_children_exit_when_the_parent_is_killed(runs: Callable[..., Run]) -> None:
    run = runs()
    children = run.wait_children()
    os.kill(run.parent.pid, signal.SIGKILL)
    run.parent.wait(timeout=10)
    started = time.monotonic()
    assert until(lambda: all(gone(c) for c in children.values()), 5), "a partition outlived its supervisor"
    assert time.monotonic() - started < 3
    for partition in ("io", "control"):  # each took the clean way out, on the SIGTERM the kernel sent
        assert "signal SIGTERM: stopping" in (run.run_dir / partition / "ckm.log").read_text()


# ---------------------------------------------------------------------- the supervisor on its own


def sleeper(code: str = "import time; time.sleep(60)") -> Callable[[Partition], list[str]]:
    return lambda partition: [sys.executable, "-c", code]


class Events:
    def __init__(self) -> None:
        self.items: list[tuple[str, dict[str, Any]]] = []
        self.lock = threading.Lock()

    def __call__(self, kind: str, detail: dict[str, Any]) -> None:
        with self.lock:
            self.items.append((kind, detail))

    def kinds(self) -> list[str]:
        with self.lock:
            return [kind for kind, _ in self.items]


@pytest.fixture
def supervise(tmp_path: Path) -> Iterator[Callable[..., tuple[PartitionSupervisor, Events]]]:
    made: list[PartitionSupervisor] = []

    def make(partition: Partition, command: Callable[[Partition], list[str]]) -> tuple[PartitionSupervisor, Events]:
        events = Events()
        node = Node(name="n", partitions=(partition,))
        supervisor = PartitionSupervisor(node, tmp_path / "x.xml", tmp_path, events, command=command, stop_timeout=2)
        made.append(supervisor)
        supervisor.start()
        return supervisor, events

    yield make
    for supervisor in made:
        supervisor.stop()
        for state in supervisor.states.values():
            if state.process is not None:
                state.process.kill()


def test_always_restarts_clean_exits_too(supervise: Callable[..., tuple[PartitionSupervisor, Events]]) -> None:
    partition = Partition(name="p", restart="always", max_restarts=2, restart_delay=0.05)
    supervisor, events = supervise(partition, sleeper("pass"))
    assert until(lambda: "partition-given-up" in events.kinds(), 20)
    assert events.kinds().count("partition-exited") == 3 and events.kinds().count("partition-restarted") == 2
    assert supervisor.crashes("p") == 0


def test_restart_action_skips_the_delay_and_restarts_a_running_partition(
    supervise: Callable[..., tuple[PartitionSupervisor, Events]],
) -> None:
    partition = Partition(name="p", restart="on-failure", max_restarts=5, restart_delay=30)
    supervisor, events = supervise(partition, sleeper())
    assert until(lambda: supervisor.pid("p") is not None, 10)
    first = supervisor.pid("p")
    assert first is not None
    os.kill(first, signal.SIGKILL)
    assert until(lambda: supervisor.crashes("p") == 1, 10)
    supervisor.on_alarm(Alarm(name="a", measure="partition-crash", partition="p", action="restart"))
    assert until(lambda: supervisor.pid("p") not in (None, first), 5)  # not after the 30 s delay
    second = supervisor.pid("p")
    supervisor.on_alarm(Alarm(name="a", measure="partition-crash", partition="p", action="restart"))
    time.sleep(0.3)
    assert supervisor.pid("p") == second  # already back up: a crash alarm leaves it alone
    supervisor.restart("p")  # any other restart request stops it and starts it again
    assert until(lambda: supervisor.pid("p") not in (None, second), 10)
    assert supervisor.crashes("p") == 1  # an exit the supervisor asked for is no crash
    assert supervisor.statistics()["p"]["restarts"] == 2
    assert events.kinds().count("partition-restarted") == 2 and "partition-crashed" in events.kinds()


def test_a_partition_over_its_memory_budget_is_a_crash(
    supervise: Callable[..., tuple[PartitionSupervisor, Events]],
) -> None:
    partition = Partition(name="p", restart="never")
    _, events = supervise(partition, sleeper(f"raise SystemExit({MEMORY_EXIT})"))
    assert until(lambda: "partition-given-up" in events.kinds(), 10)
    crashed = next(detail for kind, detail in events.items if kind == "partition-crashed")
    assert crashed["exit_code"] == MEMORY_EXIT and crashed["reason"] == "memory budget exceeded"


def test_stop_kills_a_partition_that_ignores_sigterm(
    supervise: Callable[..., tuple[PartitionSupervisor, Events]],
) -> None:
    stubborn = "import signal, time; signal.signal(signal.SIGTERM, signal.SIG_IGN); print('ready', flush=True)"
    stubborn += "; time.sleep(60)"
    supervisor, events = supervise(Partition(name="p"), sleeper(stubborn))
    log = supervisor.run_dir / "p" / "console.log"
    assert until(lambda: log.exists() and "ready" in log.read_text(), 10)
    started = time.monotonic()
    supervisor.stop()
    assert time.monotonic() - started < 6
    assert supervisor.statistics()["p"]["last_exit_code"] == -signal.SIGKILL
    assert "partition-crashed" not in events.kinds()


MEMORY_PROBE = """
import sys, threading
from ckmconf.model import Partition
from runtime.kernel.partitions import MemoryWatch
exceeded = threading.Event()
watch = MemoryWatch(Partition(name="p", memory=16), lambda used, limit: exceeded.set(), period=0.05, grace=None)
assert watch.limit is not None and watch.baseline is not None
assert watch.limit == watch.baseline + (16 << 20)
ballast = bytearray(b"\\x01") * (48 << 20)  # written, so resident
print("exceeded" if exceeded.wait(20) else "not exceeded", flush=True)
"""


def test_memory_watch_reports_growth_past_the_budget() -> None:
    """In a process of its own: the suite's process may free garbage from earlier tests between the
    baseline and the ballast, which once hid the growth."""
    probe = subprocess.run([sys.executable, "-c", MEMORY_PROBE], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.strip() == "exceeded"


SLOW_TO_STOP = (
    "import signal, sys, time\n"
    "def stop(*_):\n"
    "    time.sleep(0.6)  # a clean stop that takes a while\n"
    "    sys.exit(0)\n"
    "signal.signal(signal.SIGTERM, stop)\n"
    "print('ready', flush=True)\n"
    "time.sleep(60)\n"
)


def test_a_stop_is_bounded_on_the_wall_clock_when_the_run_clock_races_ahead(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Under --lockstep the run's clock may move ten times faster than the wall while the supervisor
    waits for the first partition to stop; the second one once found its share of ``stop_timeout``
    used up on that clock and was killed (-9) while stopping cleanly. Both exit 0 now."""
    import runtime.kernel.partitions as partitions

    wall = time.monotonic
    racing = types.SimpleNamespace(monotonic=lambda: 20 * wall(), sleep=time.sleep, time=time.time)
    monkeypatch.setattr(partitions, "time", racing)
    node = Node(name="n", partitions=(Partition(name="a"), Partition(name="b")))
    supervisor = PartitionSupervisor(
        node, tmp_path / "x.xml", tmp_path, Events(), command=sleeper(SLOW_TO_STOP), stop_timeout=3
    )
    supervisor.start()
    try:
        logs = [supervisor.run_dir / name / "console.log" for name in ("a", "b")]
        assert until(lambda: all(log.exists() and "ready" in log.read_text() for log in logs), 20)
    finally:
        supervisor.stop()
    assert {name: supervisor.statistics()[name]["last_exit_code"] for name in ("a", "b")} == {"a": 0, "b": 0}


def test_a_partition_that_reports_failures_when_stopped_fails_the_run(
    supervise: Callable[..., tuple[PartitionSupervisor, Events]],
) -> None:
    """A partition asked to stop never crashed, but its own verdict (exit code > 0, the first error on
    its console) says a task failed while it ran: ckm-run must hear of it (issue G, fail loudly)."""
    code = (
        "import signal, sys, time\n"
        "def bye(*_):\n"
        "    print('x.xml:3:4: task t failed 7 time(s)', file=sys.stderr, flush=True)\n"
        "    sys.exit(5)\n"
        "signal.signal(signal.SIGTERM, bye)\n"
        "time.sleep(60)\n"
    )
    partition = Partition(name="p", restart="never")
    supervisor, events = supervise(partition, sleeper(code))
    assert until(lambda: supervisor.pid("p") is not None, 10)
    time.sleep(0.5)  # the child has installed its handler
    assert "partition-started" in events.kinds()
    supervisor.stop()
    assert supervisor.crashes("p") == 0
    assert supervisor.failures() == [("p", "x.xml:3:4: task t failed 7 time(s)")]
