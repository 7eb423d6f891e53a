"""A delegated controller travels as configuration text (issue H point 4, D183): written by
ckmconf's binding, read back through the loader's own validation, refused with a located error."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import ckmconf
from ckmconf.errors import ConfigError
from ckmconf.model import System
from runtime.kernel.delegation import channel, controller_of, describe
from runtime.kernel.node import NodeRuntime
from runtime.kernel.topics import declared_topic, topic_qos
from runtime.network import Transport
from tests.runtime.network.conftest import private_network, transports  # noqa: F401 - the fixture
from tests.waiting import until

CONFIG = """<System xmlns="urn:ckm:1" version="1.0" name="delegation">
  <MessageType name="Reference"><Field name="value" type="float64"/></MessageType>
  <Topic name="r" type="Reference"/>
  <Node name="plant" kind="light">
    <Partition name="control"/>
    <Topic name="y" type="float64" scope="internal"/>
    <Topic name="u" type="float64" scope="internal"/>
    <Topic name="unused" type="float64" scope="internal"/>
    <Controller name="pid" kind="pid" period="0.02" priority="70" horizon="4" delegable="true" partition="control">
      <Param name="kp" value="0.8"/><Param name="ki" value="4"/>
      <Input topic="y" role="measure"/><Input topic="r" role="setpoint"/><Output topic="u"/>
      <Switch to="hold" when="stale('y')"/>
    </Controller>
    <Controller name="hold" kind="constant" period="0.02" active="false">
      <Param name="value" value="0"/><Input topic="y"/><Output topic="u"/>
    </Controller>
  </Node>
  <Node name="idle" kind="service"/>
</System>"""


@pytest.fixture
def system(tmp_path: Path) -> System:
    path = tmp_path / "delegation.xml"
    path.write_text(CONFIG)
    return ckmconf.load(path)


def test_a_delegated_controller_round_trips_through_the_binding(system: System) -> None:
    plant = system.nodes[0]
    pid = plant.controllers[0]
    text = describe(plant, system, pid)
    record, names = controller_of(text, "plant")
    # What runs moves; the partition, the switch to a controller left behind and the flags do not.
    assert record == dataclasses.replace(pid, partition=None, switches=(), delegable=True, active=True)
    assert (record.kind, record.period, record.priority, record.horizon) == ("pid", 0.02, 70, 4)
    assert [(p.name, p.value) for p in record.params] == [("kp", "0.8"), ("ki", "4")]
    # The taker names each topic as the giver's node does: internal ones node-local, external ones as they are.
    declared = {name: declared_topic(plant, system, name) for name in ("y", "r", "u")}
    assert names == {name: topic_qos("plant", topic).name for name, topic in declared.items() if topic is not None}
    assert names == {"y": "/plant/~y", "r": "r", "u": "/plant/~u"}
    # Only the topics and message types the controller uses travel.
    assert "unused" not in text and "<MessageType" in text and 'name="Reference"' in text
    assert describe(plant, system, record) == text  # read back, it writes the same text


def _bad(text: str, old: str, new: str) -> str:
    assert old in text
    return text.replace(old, new, 1)


def _position(text: str, needle: str) -> tuple[int, int]:
    before = text[: text.index(needle)]
    return before.count("\n") + 1, len(before.rsplit("\n", 1)[-1]) + 1


PID = "/Part/Node[@name='plant']/Controller[@name='pid']"


@pytest.mark.parametrize(
    ("old", "new", "needle", "xpath", "words"),
    [
        ('period="0.02"', 'period="-1"', 'period="-1"', f"{PID}/@period", "invalid period '-1'"),
        (
            '<Input topic="y"',
            '<Input topic="nowhere"',
            'topic="nowhere"',
            f"{PID}/Input[1]/@topic",
            "'nowhere' does not",
        ),
        (
            "<MessageType ",
            '<Include href="secret.xml"/><MessageType ',
            'href="',
            "/Part/Include/@href",
            "cannot include secret.xml",
        ),
        ('delegable="true"', 'delegable="false"', "<Node", "/Part/Node[@name='plant']", "one delegable Controller"),
    ],
)
def test_a_bad_description_is_refused_where_it_is(
    system: System, old: str, new: str, needle: str, xpath: str, words: str
) -> None:
    text = _bad(describe(system.nodes[0], system, system.nodes[0].controllers[0]), old, new)
    with pytest.raises(ConfigError) as caught:
        controller_of(text, "plant")
    error = caught.value
    line, column = _position(text, needle)
    assert (error.file, error.line, error.column, error.xpath) == ("<delegation from plant>", line, column, xpath)
    assert words in error.message
    assert str(error).startswith(f"<delegation from plant>:{line}:{column}: {xpath}: ")


def test_a_description_that_is_not_text_is_refused() -> None:
    with pytest.raises(ConfigError, match=r"^<delegation from plant>:1:1: /: a controller description is "):
        controller_of({"kind": "pid"}, "plant")


def test_the_taker_refuses_a_bad_offer_with_the_located_error(
    system: System,
    transports: Callable[..., Transport],  # noqa: F811 - the fixture
) -> None:
    network = private_network(heartbeat=0.05)
    taker_transport, tester = transports(network, "taker"), transports(network, "tester")
    taker = NodeRuntime(system.nodes[1], system, taker_transport)
    taker.setup()
    taker.start()
    try:
        answers: list[Any] = []
        tester.subscribe(channel("tester"), lambda sample: answers.append(sample.value))
        offers = tester.publisher(channel("idle"))
        text = _bad(describe(system.nodes[0], system, system.nodes[0].controllers[0]), 'period="0.02"', 'period="0"')

        def refused() -> bool:
            offers.publish({"op": "offer", "id": 7, "from": "tester", "controller": text})
            return bool(answers)

        assert until(refused, timeout=20, interval=0.2), "the taker never answered"
        answer = answers[0]
        assert answer["op"] == "refuse" and answer["id"] == 7
        line, column = _position(text, 'period="0"')
        assert answer["reason"].startswith(f"<delegation from tester>:{line}:{column}: {PID}/@period: invalid period")
        assert not taker.delegation or not taker.delegation.taken
    finally:
        taker.stop()
