"""What a lazy producer published before it rested is not news when a state asks for it again
(decision D249): a service handle's outputs and measures, and a behavior's input on a lazy
topic. A one-shot value on any other topic still reaches a state entered after it (D166)."""

from __future__ import annotations

import functools
from pathlib import Path

from ckmconf.loader import load
from ckmconf.model.system import System
from runtime.missions.agent import LiveFactory
from runtime.missions.hfsm import MissionEngine
from runtime.missions.services import NetworkServiceHandle
from runtime.missions.signals import Signals
from runtime.network import TopicQoS, Transport
from runtime.resources import codec
from runtime.resources.api import topics
from tests import waiting
from tests.runtime.resources.conftest import pair as pair  # the fixture: two transports on loopback

until = functools.partial(waiting.until, interval=0.01)

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="stale">
  <Topic name="/a" type="bytes"/>
  <Topic name="/fused" type="bytes"/>
  <Topic name="/target" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="Global" node="pc">
    <Plugin name="merge" kind="test-source"/>
    <Profile name="ONLY" output="merge"><Use plugin="merge"/></Profile>
    <Service name="Fusion" rate="0.02" lazy="LAZY">
      <Input name="a" topic="/a"/>
      <Output name="fused" topic="/fused"/>
      <QualityMeasure name="deadline" kind="qos" domain="temporal" source="deadline" unit="s"/>
      <Scenario name="ONLY" profile="ONLY"><Policy measure="deadline" upper="1"/></Scenario>
    </Service>
  </SmartResource>
  <Behavior name="LOOK" kind="wait-input">
    <Uses service="Global.Fusion" as="fusion"/>
    <Input name="objects" topic="/fused"/>
    <Input name="target" topic="/target"/>
  </Behavior>
  <Behavior name="AGAIN" kind="timer">
    <Param name="duration" value="1"/>
    <Input name="objects" topic="/fused"/>
  </Behavior>
  <Mission name="Look" initial="LOOK">
    <State name="LOOK" behavior="LOOK"/>
    <State name="AGAIN" behavior="AGAIN"/>
    <Final name="seen"/>
    <Transition from="LOOK" to="AGAIN" when="done()"/>
    <Transition from="AGAIN" to="seen" when="done()"/>
  </Mission>
</System>
"""


def system(tmp_path: Path, lazy: bool) -> System:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM.replace("LAZY", str(lazy).lower()))
    return load(path)


def handle_of(loaded: System, transport: Transport) -> NetworkServiceHandle:
    found = loaded.service("Global.Fusion")
    assert found is not None
    return NetworkServiceHandle(transport, *found)


def quality(deadline: float) -> dict[str, object]:
    return {"type": "quality", "client": "", "scenario": "ONLY", "measures": {"deadline": deadline}}


def test_a_lazy_services_output_and_measures_from_before_its_rest_are_forgotten(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    agent, service = pair
    loaded = system(tmp_path, lazy=True)
    handle = handle_of(loaded, agent)
    found = loaded.service("Global.Fusion")
    assert found is not None
    output = service.publisher(TopicQoS("/fused", "ckm/service-data"))
    report = service.publisher(topics(*found)["quality"])
    try:
        assert service.wait_for_subscribers("/fused", 1, 10)
        [fused] = handle.outputs
        fused.demand(True)  # a state asks
        output.publish(codec.encode({"objects": ["old"]}))
        assert until(lambda: handle.output("fused") == {"objects": ["old"]})
        report.publish(quality(0.1))
        assert until(lambda: handle.measures().get("deadline") == 0.1)

        fused.demand(False)  # the state is left; the service rests, its quality repeats its last measures
        output.publish(codec.encode({"objects": ["while resting"]}))
        assert until(lambda: fused.received == 2)
        assert handle.output("fused") is None  # not asked for: not read

        fused.demand(True)  # asked again
        assert handle.output("fused") is None and handle.measures() == {} and handle.samples("deadline") == []
        report.publish(quality(0.1))  # the resting service's repeated measure
        assert until(lambda: handle.running())
        output.publish(codec.encode({"objects": ["new"]}))
        assert until(lambda: handle.output("fused") == {"objects": ["new"]})
        assert handle.measures() == {}  # the repeat came before the first new result
        report.publish(quality(0.3))
        assert until(lambda: handle.measures().get("deadline") == 0.3)
        assert handle.samples("deadline") == [0.3]
    finally:
        handle.close()


def test_a_service_not_lazy_keeps_what_it_published_before_the_ask(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    agent, service = pair
    handle = handle_of(system(tmp_path, lazy=False), agent)
    output = service.publisher(TopicQoS("/fused", "ckm/service-data"))
    try:
        assert service.wait_for_subscribers("/fused", 1, 10)
        output.publish(codec.encode({"objects": ["once"]}))
        assert until(lambda: handle.output("fused") == {"objects": ["once"]})
        handle.outputs[0].demand(True)
        assert handle.output("fused") == {"objects": ["once"]}
    finally:
        handle.close()


def test_a_behavior_reads_a_lazy_topic_only_from_its_ask_and_a_one_shot_topic_from_before(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    agent, producer = pair
    factory = LiveFactory(system(tmp_path, lazy=True), agent, Signals())
    try:
        fused = producer.publisher(TopicQoS("/fused", "ckm/service-data"))
        target = producer.publisher(TopicQoS("/target", "ckm/behavior-output"))
        assert producer.wait_for_subscribers("/fused", 1, 10) and producer.wait_for_subscribers("/target", 1, 10)
        fused.publish(codec.encode(["from before the rest"]))
        target.publish(codec.encode({"x": 1.0}))  # one shot, before the state is entered (D166)
        assert until(lambda: factory._inputs["/target"].received == 1 and factory._inputs["/fused"].received == 1)

        look = factory("LOOK", "m/LOOK", lambda: 0.0)
        look.context.demand(True)
        assert look.context.inputs["target"]() == {"x": 1.0}
        assert look.context.inputs["objects"]() is None
        assert look.context.services["fusion"].output("fused") is None
        fused.publish(codec.encode(["fresh"]))
        assert until(lambda: look.context.inputs["objects"]() == ["fresh"])
        assert until(lambda: look.context.services["fusion"].output("fused") == ["fresh"])
        look.context.demand(False)
    finally:
        factory.close()


def test_a_topic_two_consecutive_states_read_is_asked_for_throughout(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    """The next state asks before the left one stops asking (D249): no rest, nothing forgotten between."""
    agent, producer = pair
    loaded = system(tmp_path, lazy=True)
    factory = LiveFactory(loaded, agent, Signals())
    clock = [0.0]
    engine = MissionEngine(loaded, "Look", factory=factory, clock=lambda: clock[0])
    try:
        fused = producer.publisher(TopicQoS("/fused", "ckm/service-data"))
        target = producer.publisher(TopicQoS("/target"))
        assert producer.wait_for_subscribers("/fused", 1, 10)
        reader = factory._inputs["/fused"]
        engine.start()
        assert engine.active_path() == "Look/LOOK" and not reader.passive and reader.asks == 1
        fused.publish(codec.encode(["seen"]))
        target.publish(codec.encode({"x": 1.0}))
        assert until(lambda: (engine.step(), engine.active_path())[1] == "Look/AGAIN")
        assert not reader.passive and reader.asks == 1  # asked for throughout the transition
        again = engine.top.behavior
        assert again is not None and again.context.inputs["objects"]() == ["seen"]  # LOOK's frame, still news
        assert factory.handles["Global.Fusion"].outputs[0].passive  # AGAIN uses no service
        clock[0] = 2.0
        engine.step()
        assert engine.outcome == "seen" and reader.passive
    finally:
        factory.close()
