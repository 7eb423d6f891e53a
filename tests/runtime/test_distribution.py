"""Configuration distribution (issue F, point 5): agents started with ``ckm-run --await-config``
are discovered, run the node pushed to them, refuse bad or hostile pushes keeping the old node,
obey the group key and stop cleanly on SIGTERM. Loopback only, a private group per network."""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from ckmconf import dumps
from ckmconf.model import Network, System
from editor.distribution import Ack, AgentDirectory, bundle, config_hash, distribute, push
from runtime.cli import EXIT_NETWORK
from runtime.cli import main as ckm_run_main
from runtime.distribution import ConfigAgent, ack_topic, bundle_hash, config_topic, parse_push
from runtime.network import Sample, Subscription, TopicQoS, Transport, open_transport, read_group_key
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network

DATA = REPO / "tests" / "data" / "distribution"
TWO_NODES = DATA / "two_nodes.xml"
INVALID = DATA / "invalid.xml"
KEY = b"distribution-test-group-key-0123456789"


def write_network(folder: Path, network: Network) -> Path:
    path = folder / "net.xml"
    path.write_bytes(dumps(System(name="bootstrap", version="1.0", network=network)))
    return path


@contextlib.contextmanager
def agent_processes(net: Path, folder: Path) -> Iterator[Callable[[str], subprocess.Popen[bytes]]]:
    """Start ``ckm-run --await-config`` agents; every one is stopped (or killed) at the end."""
    started: list[subprocess.Popen[bytes]] = []

    def spawn(name: str) -> subprocess.Popen[bytes]:
        run_dir = folder / name
        run_dir.mkdir()
        command = [sys.executable, "-m", "runtime.cli", "--await-config", str(net), "--name", name]
        with (folder / f"{name}.err").open("wb") as err:
            process = subprocess.Popen(
                [*command, "--log-dir", str(run_dir)], cwd=REPO, stdout=subprocess.DEVNULL, stderr=err
            )
        started.append(process)
        return process

    try:
        yield spawn
    finally:
        for process in started:
            if process.poll() is None:
                process.terminate()
        for process in started:
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5)


@contextlib.contextmanager
def editor_transport(network: Network, key: bytes | None = None) -> Iterator[Transport]:
    transport = open_transport(network, name="editor", key=key)
    transport.setup()
    transport.start()
    try:
        yield transport
    finally:
        transport.stop()


@dataclass
class Lab:
    network: Network
    folder: Path
    transport: Transport
    directory: AgentDirectory
    processes: dict[str, subprocess.Popen[bytes]]
    spawn: Callable[[str], subprocess.Popen[bytes]]


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Lab]:
    """Two agents, a1 and a2, and an editor on one private network."""
    network = private_network()
    folder = tmp_path_factory.mktemp("lab")
    net = write_network(folder, network)
    with agent_processes(net, folder) as spawn, editor_transport(network) as transport:
        processes = {name: spawn(name) for name in ("a1", "a2")}
        directory = AgentDirectory(transport)
        assert directory.wait_for(["a1", "a2"], 20), (folder / "a1.err").read_text()
        yield Lab(network, folder, transport, directory, processes, spawn)
        directory.close()


def running(directory: AgentDirectory, agent: str, hashed: str) -> Callable[[dict[str, Any]], bool]:
    def check(agents: dict[str, Any]) -> bool:
        found = agents.get(agent)
        return found is not None and found.status == "running" and found.config_hash == hashed

    return check


def from_agent(subscription: Subscription, directory: AgentDirectory, agent: str) -> list[Sample]:
    found = directory.get(agent)
    assert found is not None
    return [s for s in subscription.history() if s.source == found.announcement["guid"]]


def ensure_distributed(lab: Lab) -> str:
    """The two-node system running on a1 (left) and a2 (right); returns its hash."""
    hashed = bundle(TWO_NODES).hash
    if not lab.directory.wait_until(
        lambda agents: all(running(lab.directory, a, hashed)(agents) for a in ("a1", "a2")), 0
    ):
        acks = distribute(lab.transport, TWO_NODES, {"left": "a1", "right": "a2"}, timeout=15)
        assert all(ack.confirmed for ack in acks.values()), acks
    for agent in ("a1", "a2"):
        assert lab.directory.wait_until(running(lab.directory, agent, hashed), 5)
    return hashed


# ---------------------------------------------------------------------- in-process pieces


def test_a_bundle_holds_the_main_file_and_its_includes() -> None:
    sent = bundle(TWO_NODES)
    assert sent.main == "two_nodes.xml"
    assert set(sent.files) == {"two_nodes.xml", "parts/topics.xml"}
    assert sent.files["parts/topics.xml"] == (DATA / "parts" / "topics.xml").read_text()
    assert sent.hash == config_hash(sent.files) == bundle_hash(dict(reversed(sent.files.items())))
    assert config_hash({"a.xml": "x", "b.xml": ""}) != config_hash({"a.xml": "", "b.xml": "x"})


def test_await_config_arguments_are_checked(capsys: pytest.CaptureFixture[str]) -> None:
    for argv in (
        ["--await-config", "--node", "left"],
        ["--await-config", "--name", "../x"],
        [],
        ["x.xml", "--name", "a"],
    ):
        with pytest.raises(SystemExit) as exited:
            ckm_run_main(argv)
        assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "--node cannot go with --await-config" in err and "agent name '../x'" in err
    assert "required: config" in err and "--name goes with --await-config" in err


def test_an_include_leading_out_of_the_bundle_is_refused(tmp_path: Path) -> None:
    (tmp_path / "secret.xml").write_text('<Part xmlns="urn:ckm:1" version="1.0"/>')
    main = '<System xmlns="urn:ckm:1" version="1.0" name="s"><Include href="../../../secret.xml"/></System>'
    agent = ConfigAgent("u1", open_transport(private_network(), name="u1"), tmp_path / "run")
    ack = agent.handle({"id": "x", "node": "n", "files": {"main.xml": main}, "main": "main.xml"})
    assert not ack["accepted"] and "leads out of the bundle" in ack["errors"][0]
    assert agent.status == "refused" and agent.current is None
    assert not list((tmp_path / "run" / "configs").iterdir())  # a refused bundle is not kept
    again = parse_push({"id": 1, "node": "n", "files": {"a.xml": ""}, "main": "a.xml"})
    (tmp_path / "run" / "configs" / f"002-{again.hash[:12]}").mkdir()  # a run directory used before
    agent._pushes = 1
    assert agent._write(again).name == f"003-{again.hash[:12]}"


# ---------------------------------------------------------------------- agents in processes


def test_agents_are_discovered_waiting(lab: Lab) -> None:
    for name, process in lab.processes.items():
        agent = lab.directory.get(name)
        assert agent is not None and not agent.stale()
        assert agent.announcement["pid"] == process.pid and agent.announcement["host"]
        assert agent.status == "waiting" or agent.config_hash is not None  # unless a test pushed already


def test_a_two_node_config_is_distributed_and_runs(lab: Lab) -> None:
    expected = bundle(TWO_NODES).hash
    acks = distribute(lab.transport, TWO_NODES, {"left": "a1", "right": "a2"}, timeout=15)
    for node, agent in (("left", "a1"), ("right", "a2")):
        ack = acks[node]
        assert ack.accepted and ack.answered and ack.hash == expected and ack.confirmed, ack
        assert lab.directory.wait_until(running(lab.directory, agent, expected), 5)
        announced = lab.directory.get(agent)
        assert announced is not None and announced.node == node and announced.announcement["system"] == "two-nodes"
        speed = lab.transport.subscribe(TopicQoS(f"/dist/{node}/speed", "float64", history=50))
        assert speed.wait(10, 10), f"{node} does not publish"
        assert from_agent(speed, lab.directory, agent), f"{node} does not run in {agent}"
        speed.close()


def test_an_invalid_config_is_refused_and_the_old_one_keeps_running(lab: Lab) -> None:
    good = ensure_distributed(lab)
    sent = bundle(INVALID)
    ack = push(lab.transport, "a1", "left", sent.files, sent.main, timeout=10)
    assert ack.answered and not ack.accepted and ack.hash == sent.hash
    assert any(e.startswith("invalid.xml:17:26: ") and "HWChannel 'encodr' does not exist" in e for e in ack.errors), (
        ack.errors
    )
    files, main = _files_main(TWO_NODES)  # valid XML, but the plant cannot be built: refused at setup
    files[main] = files[main].replace('<Param name="gain" value="2000"/>', '<Param name="noise" value="-1"/>', 1)
    at_setup = push(lab.transport, "a1", "left", files, main, timeout=10)
    assert not at_setup.accepted and "parameter 'noise' = -1.0 must not be negative" in at_setup.errors[0]
    missing = push(lab.transport, "a1", "nowhere", *_files_main(TWO_NODES), timeout=10)
    assert not missing.accepted and "no node 'nowhere' (nodes: left, right)" in missing.errors[0]
    assert lab.directory.wait_until(lambda agents: agents["a1"].announcement["last_id"] == missing.id, 5)
    agent = lab.directory.get("a1")
    assert agent is not None and agent.status == "running" and agent.config_hash == good
    assert agent.announcement["errors"] == list(missing.errors)
    speed = lab.transport.subscribe(TopicQoS("/dist/left/speed", "float64", history=50))
    assert speed.wait(10, 10) and from_agent(speed, lab.directory, "a1"), "the old node stopped"
    speed.close()


def _files_main(path: Path) -> tuple[dict[str, str], str]:
    sent = bundle(path)
    return sent.files, sent.main


def test_hostile_pushes_are_refused_and_the_agent_survives(lab: Lab) -> None:
    good = ensure_distributed(lab)
    acks: list[dict[str, Any]] = []
    answers = lab.transport.subscribe(TopicQoS(ack_topic("a2"), "ack", history=16), lambda s: acks.append(s.value))
    publisher = lab.transport.publisher(TopicQoS(config_topic("a2"), "config"))
    system = '<System xmlns="urn:ckm:1" version="1.0" name="s"/>'
    hostile: list[tuple[Any, str]] = [
        ({"id": "up", "node": "right", "files": {"../../etc/x.xml": system}, "main": "../../etc/x.xml"}, "bad path"),
        ({"id": "abs", "node": "right", "files": {"/etc/x.xml": system}, "main": "/etc/x.xml"}, "bad path"),
        ({"id": "huge", "node": "right", "files": {"a.xml": "x" * (9 << 20)}, "main": "a.xml"}, "at most 8388608"),
        ({"id": "main", "node": "right", "files": {"a.xml": system}, "main": "b.xml"}, "not in the bundle"),
        ({"id": "types", "node": "right", "files": {"a.xml": 5}, "main": "a.xml"}, "must all be text"),
        ({"id": "xml", "node": "right", "files": {"a.xml": "<System"}, "main": "a.xml"}, "a.xml:"),
        ([1, 2, 3], "a push is a map"),
    ]
    assert lab.transport.wait_for_subscribers(config_topic("a2"), 1, 5)
    try:
        for count, (message, _) in enumerate(hostile, 1):  # one at a time, as the editor does
            publisher.publish(message)
            assert answers.wait(count, 10), acks
    finally:
        answers.close()
    by_id = {a["id"]: a for a in acks}
    for message, reason in hostile:
        ack = by_id[message["id"] if isinstance(message, dict) else None]
        assert not ack["accepted"] and reason in ack["errors"][0], (reason, ack)
    assert lab.processes["a2"].poll() is None
    assert lab.directory.wait_until(lambda agents: agents["a2"].announcement["last_id"] is None, 5)
    assert lab.directory.wait_until(running(lab.directory, "a2", good), 5)
    again = push(lab.transport, "a2", "right", *_files_main(TWO_NODES), timeout=10)
    assert again.confirmed  # still takes pushes (the same config, restarted)


def test_sigterm_stops_an_agent_cleanly_with_actuators_safe(lab: Lab) -> None:
    process = lab.spawn("s1")
    assert lab.directory.wait_for(["s1"], 20)
    sent = bundle(TWO_NODES)
    assert push(lab.transport, "s1", "left", sent.files, sent.main, timeout=15).confirmed
    process.send_signal(signal.SIGTERM)
    assert process.wait(20) == 0, (lab.folder / "s1.err").read_text()
    assert lab.directory.wait_until(lambda agents: agents["s1"].status == "stopped", 5)
    (stats_file,) = (lab.folder / "s1" / "configs").glob("*/stats.json")
    stats = json.loads(stats_file.read_text())
    assert stats["hash"] == sent.hash and stats["agent"] == "s1"
    motor = stats["nodes"]["left"]["actuators"]["motor"]
    assert motor["mode"] == "safe" and motor["value"] == 0.0
    assert (lab.folder / "s1" / "ckm.log").exists()


# ---------------------------------------------------------------------- group key


def test_only_holders_of_the_group_key_can_push(tmp_path: Path) -> None:
    (tmp_path / "group.key").write_bytes(KEY)
    network = private_network(group_key_file="group.key")
    net = write_network(tmp_path, network)
    key = read_group_key(network, tmp_path)
    sent = bundle(TWO_NODES)
    with (
        agent_processes(net, tmp_path) as spawn,
        editor_transport(network, key) as keyed,
        editor_transport(network) as keyless,
    ):
        spawn("k1")
        insider, outsider = AgentDirectory(keyed), AgentDirectory(keyless)
        assert insider.wait_for(["k1"], 20), (tmp_path / "k1.err").read_text()
        refused: Ack = push(keyless, "k1", "left", sent.files, sent.main, timeout=2.5)
        assert not refused.answered and "no answer" in refused.errors[0]
        assert outsider.get("k1") is None  # never even heard of it
        agent = insider.get("k1")
        assert agent is not None and agent.status == "waiting" and agent.announcement["last_id"] is None
        accepted = push(keyed, "k1", "left", sent.files, sent.main, timeout=15)
        assert accepted.confirmed, accepted
        assert insider.wait_until(running(insider, "k1", sent.hash), 5)
        assert outsider.get("k1") is None
        insider.close()
        outsider.close()


def test_an_agent_without_its_key_file_cannot_start(tmp_path: Path) -> None:
    net = write_network(tmp_path, private_network(group_key_file="missing.key"))
    done = subprocess.run(
        [sys.executable, "-m", "runtime.cli", "--await-config", str(net), "--name", "k2", "--log-dir", str(tmp_path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == EXIT_NETWORK, done.stderr
    assert "cannot join the network" in done.stderr and "Traceback" not in done.stderr
