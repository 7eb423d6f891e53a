"""Delegation of SPT processing plugins: every frame gets exactly one output, equal to a never-delegated
run, whether the plugin runs here, on a taker in this process or in another process, is refused,
or loses its taker mid-stream. Hostile messages are refused without hurting the host.

All traffic stays on loopback (a private multicast group and port range per test).
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ckmconf.model import Network, Param
from ckmconf.model.resources import Plugin, Profile, SmartResource, Use
from runtime.network import Sample, TopicQoS, Transport, open_transport
from runtime.resources.delegation import (
    PREFIX,
    DelegatedPlugin,
    DelegationRefused,
    PluginHost,
    channel,
    describe,
)
from runtime.resources.spt import Context, ProcessingPlugin, Topology
from tests.conftest import REPO
from tests.runtime.network.conftest import private_network, transports  # noqa: F401 (fixture)
from tests.runtime.resources.plugin_host_peer import Accumulate, registry, same

RNG = np.random.default_rng(7)
IMAGES = [RNG.integers(0, 256, size=(8, 12, 3), dtype=np.uint8) for _ in range(40)]
RESOURCE = SmartResource(
    name="camera",
    node="giver",
    plugins=(
        Plugin(name="half", kind="resize", params=(Param(name="scale", value="0.5"),)),
        Plugin(name="acc", kind="accumulate", params=(Param(name="weight", value="0.5"),)),
    ),
    profiles=(Profile(name="p", output="acc", root=Use(plugin="half", uses=(Use(plugin="acc"),))),),
)
FRAME_TIMEOUT = 10.0  # only ever reached when a test kills the taker: generous, so a slow machine never falls back


def _topology() -> Topology:
    topology = Topology(RESOURCE, registry())
    topology.setup()
    topology.select("svc", "p")
    return topology


@pytest.fixture(scope="module")
def reference() -> list[Any]:
    """The outputs of a run that is never delegated."""
    topology = _topology()
    return [topology.run(image, stamp=float(i)).outputs["svc"] for i, image in enumerate(IMAGES)]


class Run:
    """A topology fed frame by frame, its outputs kept in order."""

    def __init__(self) -> None:
        self.topology = _topology()
        self.outputs: list[Any] = []

    def frames(self, count: int) -> None:
        for _ in range(count):
            i = len(self.outputs)
            frame = self.topology.run(IMAGES[i], stamp=float(i))
            self.outputs.append(frame.outputs["svc"])  # exactly one output per frame, or run() raised

    def matches(self, reference: list[Any]) -> bool:
        return len(self.outputs) > 0 and all(same(a, b) for a, b in zip(self.outputs, reference, strict=False))

    def wrap(self, name: str, transport: Transport, **options: Any) -> DelegatedPlugin:
        options.setdefault("frame_timeout", FRAME_TIMEOUT)
        return DelegatedPlugin.wrap(self.topology, name, transport, "giver", **options)


@pytest.fixture
def network(transports: Callable[..., Transport]) -> Callable[[str], Transport]:  # noqa: F811 (the fixture)
    """Started transports on one private loopback network; all stopped at the end."""
    settings: Network = private_network()
    return lambda name: transports(settings, name)


def _linked(a: Transport, b: Transport, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and not (b.guid in a.peers() and a.guid in b.peers()):
        time.sleep(0.01)
    assert b.guid in a.peers() and a.guid in b.peers(), "the two transports never connected"


@pytest.fixture
def pair(network: Callable[[str], Transport]) -> tuple[Transport, Transport]:
    giver, taker = network("giver"), network("taker")
    _linked(giver, taker)
    return giver, taker


# ---------------------------------------------------------------------- in one process


def test_a_stateful_and_a_real_plugin_move_and_come_back_with_outputs_unchanged(
    pair: tuple[Transport, Transport], reference: list[Any]
) -> None:
    giver, taker = pair
    run = Run()
    local_acc = run.topology.plugins["acc"]
    assert isinstance(local_acc, Accumulate)
    run.frames(5)
    acc, half = run.wrap("acc", giver), run.wrap("half", giver)
    assert run.topology.plugins["acc"] is acc and run.topology.profiles["p"].tree.children[0].plugin is acc
    with PluginHost(taker, "taker", registry()) as host:
        run.frames(2)  # wrapped, still local
        acc.delegate("taker", timeout=10)
        half.delegate("taker", timeout=10)
        assert acc.taker == half.taker == "taker"
        run.frames(6)
        assert host.processed == {"acc": 6, "half": 6}
        assert sorted(host.hosted) == ["acc", "half"]
        acc.recall()
        half.recall()
        run.frames(5)
        assert host.hosted == [] and host.processed == {"acc": 6, "half": 6}
    assert run.matches(reference) and len(run.outputs) == 18
    assert (acc.local_calls, acc.remote_calls, local_acc.calls) == (7, 6, 12)
    assert [e.kind for e in acc.events] == ["delegated", "recalled"]
    assert acc.unwrap(run.topology) is local_acc and run.topology.plugins.get("acc") is local_acc


def test_a_refused_delegation_says_why_and_the_plugin_keeps_running_here(
    pair: tuple[Transport, Transport], reference: list[Any]
) -> None:
    giver, taker = pair
    run = Run()
    acc = run.wrap("acc", giver)
    with PluginHost(taker, "taker", registry(accumulate=False)) as host:
        run.frames(3)
        with pytest.raises(
            DelegationRefused, match=r"node 'taker' refused plugin 'acc': .*'accumulate' does not exist"
        ):
            acc.delegate("taker", timeout=10)
        run.frames(3)
        # A kind it knows but cannot set up is refused too, with the plugin's reason.
        camera = DelegatedPlugin(_Passthrough(Plugin(name="cam", kind="failing-setup")), giver, "giver")
        with pytest.raises(DelegationRefused, match="setup of plugin 'cam' failed: OSError: no camera on this node"):
            camera.delegate("taker", timeout=10)
        assert host.hosted == [] and not host.processed
    assert acc.taker is None and acc.local_calls == 6
    assert run.matches(reference)
    assert [e.kind for e in acc.events] == ["delegation-refused"]


def test_a_taker_that_stops_answering_costs_one_timeout_and_no_frame(
    pair: tuple[Transport, Transport], reference: list[Any]
) -> None:
    giver, taker = pair
    run = Run()
    alarms: list[str] = []
    acc = run.wrap("acc", giver, frame_timeout=0.5, on_event=lambda e: alarms.append(e.kind))
    host = PluginHost(taker, "taker", registry())
    host.start()
    try:
        run.frames(2)
        acc.delegate("taker", timeout=10)
        acc.frame_timeout = FRAME_TIMEOUT
        run.frames(4)
    finally:
        host.stop()  # the taker is gone: the next request goes unanswered
    acc.frame_timeout = 0.5
    run.frames(4)
    assert host.processed["acc"] == 4
    assert acc.taker is None and (acc.local_calls, acc.remote_calls) == (6, 4)
    assert run.matches(reference) and len(run.outputs) == 10
    assert alarms == ["delegated", "delegation-fallback"]
    assert "no answer within 0.5 s" in acc.events[-1].reason


def test_a_taker_answering_garbage_is_revoked_and_the_frame_computed_here(
    network: Callable[[str], Transport], reference: list[Any]
) -> None:
    giver, liar = network("giver"), network("liar")
    _linked(giver, liar)
    replies: dict[str, Any] = {}

    def answer(sample: Sample) -> None:  # READY to any offer, then a RESULT holding an object array
        message = sample.value
        if message["op"] == "offer":
            replies["to"] = liar.publisher(TopicQoS(message["reply"]))
            replies["to"].publish({"op": "ready", "id": message["id"]})
        elif message["op"] in ("go", "process"):
            bad = {"~nd": ["|O", [1], b"12345678"]}
            replies["to"].publish(
                {"op": "result", "id": message["id"], "seq": message["seq"], "result": bad, "state": {}}
            )

    liar.subscribe(channel("liar"), answer)
    run = Run()
    acc = run.wrap("acc", giver)
    run.frames(2)
    acc.delegate("liar", timeout=10)
    run.frames(3)
    assert acc.taker is None and acc.remote_calls == 0 and acc.local_calls == 5
    assert run.matches(reference)
    assert acc.events[-1].kind == "delegation-fallback"
    assert "bad answer: dtype '|O' is not allowed" in acc.events[-1].reason


class _Passthrough(ProcessingPlugin):
    def process(self, data: Any, context: Context) -> Any:
        return data


# ---------------------------------------------------------------------- hostile messages


def test_hostile_messages_are_refused_with_a_reason_and_the_host_keeps_serving(
    pair: tuple[Transport, Transport], reference: list[Any]
) -> None:
    giver, taker = pair
    reply = f"{PREFIX}evil/reply"
    answers: list[dict[str, Any]] = []
    arrived = threading.Condition()

    def collect(sample: Sample) -> None:
        with arrived:
            answers.append(sample.value)
            arrived.notify_all()

    giver.subscribe(TopicQoS(reply), collect)
    send = giver.publisher(channel("taker")).publish
    def text(kind: str = "resize", **params: str) -> str:  # a plugin as configuration text (D195)
        record = Plugin(name="h", kind=kind, params=tuple(Param(name=n, value=v) for n, v in params.items()))
        return describe(record, "evil")

    resize = text(scale="0.5")

    def offer(ident: str, **fields: Any) -> dict[str, Any]:
        return {"op": "offer", "id": ident, "from": "evil", "reply": reply, "plugin": resize, "state": {}} | fields

    def go(seq: int, **fields: Any) -> dict[str, Any]:
        base = {"op": "go", "id": "ok", "seq": seq, "frame": 0, "stamp": 0.0, "resource": "r", "state": {}}
        return base | {"data": {"~nd": ["|u1", [2, 2], b"abcd"]}} | fields

    # The queue holds the whole burst below (a real giver has one request in flight per plugin).
    with PluginHost(taker, "taker", registry(), max_bytes=1 << 20, queue_size=64) as host:
        assert giver.wait_for_subscribers(channel("taker").name, 1, 10)
        hostile: list[Any] = [
            42,
            {"no": "op"},
            {"op": "explode", "id": "x"},
            {"op": "offer"},
            offer("elsewhere", reply="/robot/cmd_vel"),
            offer("no-dict", plugin="resize"),
            offer("bad-params", plugin={"name": "h", "kind": "resize", "params": [["scale", "0.5"]]}),
            offer("bad-param", plugin=text(bogus="1")),
            offer("bad-value", plugin=text(scale="big")),
            offer("include", plugin=resize.replace("<Node", '<Include href="/etc/passwd"/><Node')),
            offer("bad-state", state=[1, 2]),
            offer("no-kind", plugin=text("rm-rf")),
            {"op": "process", "id": "unknown", "seq": 1},
            offer("ok"),
            {"op": "process", "id": "ok", "seq": 1, "frame": 0, "stamp": 0.0, "resource": "r", "data": 1},
            go(2, frame="zero"),
            go(3, data={"~nd": ["|u1", [2048, 1024], b"x" * (2 << 20)]}),
            go(4, data={"~nd": ["|O", [1], b"12345678"]}),
            go(5, data={"~nd": ["<f8", [10**9], b"12345678"]}),
            go(6, state="not a dict"),
            {k: v for k, v in go(7).items() if k != "data"},
            go(8),
        ]
        for message in hostile:
            send(message)
        with arrived:
            arrived.wait_for(lambda: len(answers) >= 16, 10)
        by_id = {(a["id"], a.get("seq")): a for a in answers}
        reasons = {key: a.get("reason", "") for key, a in by_id.items()}
        # refused as ckm-validate refuses a file, where the problem is in the offered text (D195)
        assert reasons[("no-dict", None)].startswith("<delegation from evil>:1:1: /: malformed XML")
        assert reasons[("bad-params", None)] == (
            "<delegation from evil>:1:1: /: a plugin description is configuration text, not dict"
        )
        where = "/Part/SmartResource[@name='evil']/Plugin[@name='h']/Param"
        assert f"{where}[@name='bogus']/@name: plugin kind 'resize' takes no parameter 'bogus'" in reasons[
            ("bad-param", None)
        ]
        assert f"{where}[@name='scale']/@value: plugin kind 'resize': parameter 'scale' = 'big'" in reasons[
            ("bad-value", None)
        ]
        assert reasons[("bad-param", None)].startswith("<delegation from evil>:6:14:")  # its name, line 6 of the text
        assert reasons[("include", None)] == (
            "<delegation from evil>:3:12: /Part/Include/@href: cannot include /etc/passwd: "
            "text received from another process includes no file"
        )
        assert reasons[("bad-state", None)] == "field 'state' has type list"
        missing = "Plugin[@name='h']/@kind: processing plugin 'rm-rf' does not exist in the registry"
        assert missing in reasons[("no-kind", None)]
        assert by_id[("ok", None)]["op"] == "ready"
        assert reasons[("ok", 1)] == "BadMessage: PROCESS before GO"
        assert reasons[("ok", 2)] == "BadMessage: field 'frame' has type str"
        assert "over the 1048576-byte limit" in reasons[("ok", 3)]
        assert "dtype '|O' is not allowed" in reasons[("ok", 4)]
        assert "needs 8000000000 bytes, got 8" in reasons[("ok", 5)]
        assert reasons[("ok", 6)] == "BadMessage: field 'state' has type str"
        assert reasons[("ok", 7)] == "BadMessage: field 'data' is missing"
        assert by_id[("ok", 8)]["op"] == "result" and host.processed == {"h": 1}
        assert ("elsewhere", None) not in by_id  # never publishes outside the delegation topics
        logged = "\n".join(host.rejected)
        for reason in ("not a delegation message: int", "unknown op 'explode'", "field 'id' is missing"):
            assert reason in logged
        assert "no delegation 'unknown'" in logged and "reply topic '/robot/cmd_vel'" in logged
        # Still serving real work.
        run = Run()
        acc = run.wrap("acc", giver)
        acc.delegate("taker", timeout=10)
        run.frames(3)
        assert acc.remote_calls == 3 and run.matches(reference)


# ---------------------------------------------------------------------- across processes


def test_plugins_move_to_another_process_and_survive_its_death(reference: list[Any], tmp_path: Path) -> None:
    settings = private_network()
    giver = open_transport(settings, name="giver")
    giver.setup()
    giver.start()
    log = tmp_path / "taker.log"
    args = [settings.group, str(settings.discovery_port), str(settings.base_port), "taker"]
    taker = subprocess.Popen(
        [sys.executable, "-m", "tests.runtime.resources.plugin_host_peer", *args],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=log.open("w"),
    )
    try:
        run = Run()
        acc, half = run.wrap("acc", giver, frame_timeout=FRAME_TIMEOUT), run.wrap("half", giver)
        run.frames(4)
        try:
            acc.delegate("taker", timeout=30)  # the child's start-up is inside this bound
        except Exception as exc:
            raise AssertionError(f"{exc}; the taker logged: {log.read_text()[-2000:]}") from None
        half.delegate("taker", timeout=10)
        run.frames(6)
        assert (acc.remote_calls, half.remote_calls) == (6, 6)
        half.recall()  # an orderly return across processes
        run.frames(3)
        assert (acc.remote_calls, half.remote_calls) == (9, 6) and half.taker is None
        taker.kill()  # dies holding acc
        taker.wait(10)
        acc.frame_timeout = 0.5
        run.frames(4)
        assert acc.taker is None and acc.events[-1].kind == "delegation-fallback"
        assert (acc.local_calls, acc.remote_calls) == (8, 9)
        assert run.matches(reference) and len(run.outputs) == 17
    finally:
        if taker.stdin is not None:
            taker.stdin.close()  # the taker exits when its stdin closes
        try:
            taker.wait(10)
        finally:
            taker.kill()
            taker.wait(10)
            giver.stop()
