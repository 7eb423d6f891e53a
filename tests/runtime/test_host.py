"""runtime.host: one process's nodes built, started, stopped within a bound, discarded, stopped by a
signal, their failures turned into the exit code and their run recorded (issue H point 2)."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.model import System
from ckmconf.model.kernel import Controller as ControllerRecord
from runtime.host import Host, stop_on_signals
from runtime.host_network import JoinError, joined
from runtime.kernel.interfaces import Controller
from runtime.kernel.runlog import RunLog
from runtime.network import TopicQoS
from runtime.registry import Registry
from runtime.runrecord import EXIT_FAILED
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network
from tests.waiting import until

CLOSED_LOOP = REPO / "configs" / "examples" / "closed_loop.xml"
SERIOUS_ALARM = REPO / "tests" / "data" / "run" / "serious_alarm.xml"


def private(config: Path) -> System:
    """The configuration on a loopback network of its own (tests never hear each other)."""
    return dataclasses.replace(ckmconf.load(config), network=private_network())




@pytest.fixture
def hosts() -> Iterator[Callable[..., Host]]:
    """Hosts joined to their system's network; every one is stopped at the end of the test."""
    made: list[Host] = []

    def make(config: Path, run_dir: Path, **options: Any) -> Host:
        host = Host(private(config), config, run_dir, **options)
        made.append(host)
        host.join("host-test").start()
        return host

    yield make
    for host in made:
        host.stop()


def test_a_node_is_built_started_and_stopped_with_its_actuators_safe(
    hosts: Callable[..., Host], tmp_path: Path
) -> None:
    host = hosts(CLOSED_LOOP, tmp_path)
    assert host.transport is not None
    runtime = host.build(host.system.nodes[0], host.transport)
    assert host.runtimes == [runtime] and set(runtime.backends) == {"encoder", "pwm"}
    host.start()
    motor = runtime.actuators["motor"]
    speeds = host.transport.subscribe(TopicQoS("/motor-node/~speed", "float64"))
    assert until(lambda: speeds.latest() is not None, 10), "the sensor never published"
    host.stop()
    assert motor.mode == "safe" and motor.value == 0.0  # the safe value driven at the stop
    assert all(b.plant is None for b in runtime.backends.values()), "a channel is still open"  # type: ignore[attr-defined]
    assert host.failures() == [] and host.stuck == []


def test_a_discarded_node_closes_its_hardware_without_driving_an_actuator(
    hosts: Callable[..., Host], tmp_path: Path
) -> None:
    host = hosts(CLOSED_LOOP, tmp_path)
    assert host.transport is not None
    runtime = host.build(host.system.nodes[0], host.transport)
    host.discard(runtime)
    assert host.runtimes == []
    assert all(b.plant is None for b in runtime.backends.values())  # type: ignore[attr-defined]
    assert runtime.actuators["motor"].mode == "waiting"  # never commanded, never driven to its safe value


def test_an_alarm_the_configuration_calls_an_error_reaches_the_exit_code(
    hosts: Callable[..., Host], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    host = hosts(SERIOUS_ALARM, tmp_path)
    assert host.transport is not None
    runtime = host.build(host.system.nodes[0], host.transport)
    host.start()
    assert until(lambda: runtime.log.serious is not None, 15), "the monitor never raised heartbeat_lost"
    host.stop()
    assert host.failures() == [EXIT_FAILED]
    assert "base: alarm heartbeat_lost (error) raised" in capsys.readouterr().err


class Faulty(Controller):
    """A control law whose every step raises: a part that fails while the node runs."""

    def __init__(self, record: ControllerRecord) -> None:
        super().__init__(record)

    def step(self, inputs: Mapping[str, float], dt: float) -> float:
        raise ZeroDivisionError("the law divides by a zero gain")


def test_a_task_that_raises_reaches_the_exit_code_with_its_first_error(
    hosts: Callable[..., Host], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "faulty.xml"  # closed_loop.xml with the PID replaced by the faulty law
    config.write_text(CLOSED_LOOP.read_text().replace('kind="pid"', 'kind="faulty"'))
    registry = Registry()
    registry.register("controller", "faulty", Faulty)
    host = hosts(config, tmp_path, registry=registry)
    assert host.transport is not None
    runtime = host.build(host.system.nodes[0], host.transport)
    host.start()

    def failed() -> bool:
        return bool(runtime.statistics()["tasks"]["motor-node.pid"]["failures"])

    assert until(failed, 15), "the faulty controller never ran"
    host.stop()
    assert host.failures() == [EXIT_FAILED]
    err = capsys.readouterr().err
    assert "motor-node: task motor-node.pid failed" in err and "the law divides by a zero gain" in err


def test_a_failure_while_running_stops_the_run_with_its_code_and_message(
    hosts: Callable[..., Host], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    host = hosts(CLOSED_LOOP, tmp_path)
    threading.Timer(0.2, host.fail, (EXIT_FAILED, "the world server broke")).start()
    started = time.monotonic()
    host.wait(60)
    assert host.stopping.is_set() and time.monotonic() - started < 60
    host.stop()
    assert host.failures() == [EXIT_FAILED]
    assert f"{CLOSED_LOOP}: the world server broke" in capsys.readouterr().err


def test_a_stop_step_that_hangs_is_left_behind_after_its_bound_and_fails_the_run(
    hosts: Callable[..., Host], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    host = hosts(CLOSED_LOOP, tmp_path, stop_timeout=0.3)
    release = threading.Event()
    order: list[str] = []
    host.on_stop("flush the stuck device", lambda: release.wait(30))
    host.on_stop("finish the recording", lambda: order.append("recording"))
    try:
        host.stop()
    finally:
        release.set()
    assert order == ["recording"]  # the last registered runs first, and the stuck one did not block the rest
    assert host.stuck == ["flush the stuck device"]
    assert host.transport is not None and host.failures() == [EXIT_FAILED]
    assert "could not flush the stuck device within 0.3 s" in capsys.readouterr().err


def test_sigterm_stops_the_run_in_order_and_the_previous_handler_comes_back(
    hosts: Callable[..., Host], tmp_path: Path
) -> None:
    host = hosts(CLOSED_LOOP, tmp_path)
    assert host.transport is not None
    runtime = host.build(host.system.nodes[0], host.transport)
    before = signal.getsignal(signal.SIGTERM)
    with stop_on_signals(host.stopping):
        host.start()
        threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()
        started = time.monotonic()
        host.wait(60)  # a run without a duration: only the signal ends it (60 s bounds the test)
        assert host.stopping.is_set() and time.monotonic() - started < 60
        host.stop()
    assert signal.getsignal(signal.SIGTERM) is before
    assert runtime.actuators["motor"].mode == "safe"
    assert host.failures() == []


def test_the_run_record_is_written_while_running_and_at_the_stop(hosts: Callable[..., Host], tmp_path: Path) -> None:
    host = hosts(CLOSED_LOOP, tmp_path / "run")
    assert host.transport is not None
    run_log = RunLog(tmp_path / "run")
    try:
        host.build(host.system.nodes[0], host.transport, sinks=[run_log.event])
        host.start()
        host.wait(0.5, every=(0.1, lambda: host.keep_statistics(run_log, {"while": "running"})))
        running = json.loads(run_log.stats_path.read_text())
        assert running["while"] == "running" and running["system"] == "closed-loop"
        host.stop()
        host.keep_statistics(run_log, {})
    finally:
        run_log.close()
    stats = json.loads((tmp_path / "run" / "stats.json").read_text())
    assert stats["config"] == str(CLOSED_LOOP) and stats["stopped"] >= stats["started"]
    assert stats["nodes"]["motor-node"]["actuators"]["motor"]["mode"] == "safe"
    assert stats["nodes"]["motor-node"]["tasks"]["motor-node.speed"]["releases"] > 0
    host.write_run({"agent": "a1"})  # the agent's form: stats.json and events.jsonl in one go
    assert json.loads((tmp_path / "run" / "stats.json").read_text())["agent"] == "a1"
    assert (tmp_path / "run" / "events.jsonl").exists()


def test_a_missing_group_key_file_cannot_join_and_says_so(tmp_path: Path) -> None:
    system = dataclasses.replace(ckmconf.load(CLOSED_LOOP), network=private_network(group_key_file="missing.key"))
    host = Host(system, tmp_path / "system.xml", tmp_path)
    with pytest.raises(JoinError, match="cannot join the network: cannot read the group key file"):
        host.join("host-test")
    assert host.transport is None


def test_joined_stops_its_transport_however_the_block_ends() -> None:
    network = private_network()
    with joined(network, "watcher") as watcher:
        with pytest.raises(RuntimeError, match="inside"), joined(network, "bench") as transport:
            assert until(lambda: transport.guid in watcher.peers(), 20), "the peers never found each other"
            raise RuntimeError("inside")
        assert until(lambda: transport.guid not in watcher.peers(), 20), "the bench peer never left"


def test_a_host_joins_with_the_cdr_codec_when_a_topic_has_a_ros_type(tmp_path: Path) -> None:
    ros_typed = REPO / "tests" / "data" / "ros" / "ros_typed_loop.xml"
    for config, cdr in ((ros_typed, True), (CLOSED_LOOP, False)):
        host = Host(private(config), config, tmp_path / config.stem)
        transport = host.join("host-cdr-test")
        try:
            assert (getattr(transport, "codec", None) is not None) is cdr, config.name
        finally:
            transport.stop()
