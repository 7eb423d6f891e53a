"""The service API of a Smart Resource (§4.3, Fig. 4.6) over a real transport on loopback: a client
discovers a service, connects, consumes its data, sees scenario changes on the quality topic and
alarms on the alarm topic; hostile requests are refused with the field named."""

from __future__ import annotations

import functools
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, ClassVar

import pytest

from ckmconf.loader import load
from ckmconf.model.resources import SmartResource
from runtime.network import Transport
from runtime.registry import Registry
from runtime.resources.api import Bounds, parse_request
from runtime.resources.client import ServiceClient, ServiceDirectory, ServiceError
from runtime.resources.resource import SmartResourceRuntime
from runtime.resources.spt import Context, ProcessingPlugin
from tests import waiting

SYSTEM = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="service-api-test">
  <Topic name="/cam/raw" type="bytes"/>
  <Topic name="/recog/objects" type="bytes"/>
  <Node name="camera-pc" kind="service"/>
  <SmartResource name="Camera" node="camera-pc">
    <Plugin name="grab" kind="test-source"/>
    <Plugin name="work_hi" kind="test-work"><Param name="cost" value="3"/></Plugin>
    <Plugin name="work_lo" kind="test-work"><Param name="cost" value="1"/></Plugin>
    <Profile name="HI" output="work_hi"><Use plugin="grab"><Use plugin="work_hi"/></Use></Profile>
    <Profile name="LO" output="work_lo"><Use plugin="grab"><Use plugin="work_lo"/></Use></Profile>
    <Service name="Recog" performance="reliability">
      <Input name="image" topic="/cam/raw"/>
      <Output name="objects" topic="/recog/objects"/>
      <Parameter name="resolution" type="enum" values="HI LO" default="HI"/>
      <Parameter name="threshold" type="float" default="0.5" min="0" max="1"/>
      <QualityMeasure name="reliability" kind="qoc" domain="performance" source="reliability"/>
      <QualityMeasure name="deadline" kind="qos" domain="temporal" source="deadline" unit="s"/>
      <QualityMeasure name="cpu" kind="qoc" domain="spatial" source="cpu"/>
      <QualityMeasure name="processing" kind="qos" domain="temporal" source="latency" unit="s"/>
      <QualityMeasure name="period" kind="qos" domain="temporal" source="rate" unit="s"/>
      <QualityMeasure name="rss" kind="qoc" domain="spatial" source="memory" unit="MiB"/>
      <Scenario name="HI" profile="HI" weight="2">
        <Policy measure="deadline" upper="0.05" probability="0.9" window="5"/>
      </Scenario>
      <Scenario name="LO" profile="LO" weight="1">
        <Policy measure="deadline" upper="0.5" probability="0.9" window="5"/>
      </Scenario>
      <TCM threshold="0.1" period="0.05" learning="none" initial="HI"/>
    </Service>
  </SmartResource>
</System>
"""


class Load:
    """The cost of a unit of work, in seconds; tests raise it to overload the service."""

    unit = 0.001
    calls: ClassVar[dict[str, int]] = {}
    lock = threading.Lock()


class SourcePlugin(ProcessingPlugin):
    def process(self, data: Any, context: Context) -> Any:
        return data


class WorkPlugin(ProcessingPlugin):
    PARAMS: ClassVar[Mapping[str, Any]] = {"cost": 1}

    def process(self, data: Any, context: Context) -> Any:
        with Load.lock:
            Load.calls[self.name] = Load.calls.get(self.name, 0) + 1
        time.sleep(self.params["cost"] * Load.unit)
        return {"frame": data, "by": self.name, "reliability": 0.9 if self.name == "work_hi" else 0.6}


@pytest.fixture
def resource(tmp_path: Path) -> SmartResource:
    path = tmp_path / "system.xml"
    path.write_text(SYSTEM)
    record = load(path).resource("Camera")
    assert record is not None
    return record


@pytest.fixture
def registry() -> Registry:
    registry = Registry(load_entry_points=False)
    registry.register("plugin", "test-source", SourcePlugin)
    registry.register("plugin", "test-work", WorkPlugin)
    Load.unit = 0.001
    Load.calls.clear()
    return registry


def frames() -> Callable[[], int]:
    counter = iter(range(10**9))
    return lambda: next(counter)


until = functools.partial(waiting.until, interval=0.01)  # this file's polling period


def test_a_client_discovers_configures_and_sees_the_scenario_change(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"grab": frames()}, frame_period=0.01, announce_period=0.2
    )
    with runtime:
        entry = ServiceDirectory(remote).wait_for("Camera", "Recog", timeout=10)
        assert entry["config"] == "/Camera/Recog/config" and entry["quality"] == "/Camera/Recog/quality"
        assert [s["name"] for s in entry["scenarios"]] == ["HI", "LO"]
        with ServiceClient(remote, entry, "nav-1") as client:
            received: list[Any] = []
            client.data("objects", received.append)
            ack = client.connect(parameters={"resolution": "HI", "threshold": 0.7}, timeout=10)
            assert ack["scenario"] == "HI" and ack["outputs"] == {"objects": "/recog/objects/nav-1"}
            assert ack["parameters"]["threshold"] == 0.7
            assert until(lambda: len(received) >= 5)
            assert {r["by"] for r in received} == {"work_hi"}
            assert client.wait(lambda c: len(c.quality) >= 3, 10)
            measures = client.quality[-1]["measures"]
            assert client.quality[-1]["scenario"] == "HI"
            assert {"deadline", "cpu", "processing", "period", "rss", "reliability"} <= set(measures)
            assert measures["reliability"] == 0.9 and measures["rss"] > 1.0  # a Python process: MiBs
            assert 0.0 < measures["processing"] <= measures["deadline"]

            Load.unit = 0.03  # HI now takes 90 ms per frame: its deadline policy is neglected
            assert client.wait(lambda c: any(e["to"] == "LO" for e in c.events), 10)
            event = next(e for e in client.events if e["to"] == "LO")
            assert event["from"] == "HI" and event["reason"] == "neglected" and event["penalty"] > 0
            count = len(received)
            assert until(lambda: len(received) > count + 2 and received[-1]["by"] == "work_lo")

            # A requirement no scenario can promise: an alarm on the alarm topic.
            client.configure(requirements=[Bounds("deadline", upper=0.001, probability=0.9)], timeout=10)
            assert client.wait(lambda c: any(a["raised"] for a in c.alarms), 10)
            client.configure(requirements=[], timeout=10)
            assert client.wait(lambda c: bool(c.alarms) and not c.alarms[-1]["raised"], 10)

            client.disconnect(timeout=10)
            assert runtime.instance("Recog", "nav-1") is None
            with pytest.raises(ServiceError, match="not connected"):
                client.configure(parameters={"threshold": 0.2}, timeout=10)
        # The service's own instance ran all along on the configured topic.
        own = runtime.instance("Recog")
        assert own is not None and own.published > 0


def test_hostile_requests_are_refused_naming_the_field(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    runtime = SmartResourceRuntime(resource, server, registry=registry, sources={"grab": frames()}, frame_period=0.02)
    with runtime:
        entry = ServiceDirectory(remote).wait_for("Camera", "Recog", timeout=10)
        with ServiceClient(remote, entry, "c1") as client:
            cases: list[tuple[dict[str, Any], str]] = [
                ({"parameters": {"resolution": "4K"}}, "'4K' is not one of HI, LO"),
                ({"parameters": {"threshold": 7}}, "above its maximum 1"),
                ({"parameters": {"threshold": float("nan")}}, "must be a finite float"),
                ({"parameters": {"speed": 1}}, "no parameter 'speed'"),
                ({"requirements": [Bounds("latency", upper=1.0)]}, "'latency' is not a measure of this service"),
                ({"requirements": [Bounds("deadline", lower=2.0, upper=1.0)]}, "lower 2 is above upper 1"),
                ({"requirements": [Bounds("deadline", upper=1.0, probability=1.5)]}, "probability must be in (0, 1]"),
            ]
            for kwargs, expected in cases:
                with pytest.raises(ServiceError, match=expected.replace("(", r"\(").replace(")", r"\)")):
                    client.connect(timeout=10, **kwargs)
            assert runtime.instance("Recog", "c1") is None  # nothing partly applied
            with pytest.raises(ServiceError, match="cannot be disconnected"):
                ServiceClient(remote, entry, "").disconnect(timeout=10)
    service = resource.services[0]
    for message, expected in [
        ("connect", "a request must be an object"),
        ({"op": "explode", "client": "c"}, "op 'explode' is not one of"),
        ({"op": "connect", "client": "../etc"}, "client '../etc' must be"),
        ({"op": "connect", "client": "c", "id": "1"}, "id '1' must be an integer"),
        ({"op": "connect", "client": "c", "requirements": [{"measure": "deadline"}] * 40}, "at most 32"),
        ({"op": "connect", "client": "c", "requirements": [{"measure": "deadline"}]}, "needs a lower or an upper"),
        ({"op": "connect", "client": "c", "requirements": [{"measure": "deadline", "upper": 1, "x": 0}]}, "unknown"),
    ]:
        request, errors = parse_request(service, message)
        assert request is None and any(expected in e for e in errors), (message, errors)


def test_clients_beyond_the_limit_are_refused(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"grab": frames()}, frame_period=0.02, max_clients=2
    )
    with runtime:
        entry = ServiceDirectory(remote).wait_for("Camera", "Recog", timeout=10)
        clients = [ServiceClient(remote, entry, f"c{i}") for i in range(3)]
        clients[0].connect(timeout=10)
        clients[1].connect(timeout=10)
        with pytest.raises(ServiceError, match="already has its 2 clients"):
            clients[2].connect(timeout=10)
        for client in clients:
            client.close()


@pytest.mark.parametrize("share", [True, False])
def test_replicas_share_processing_unless_replicated(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport], share: bool
) -> None:
    server, _ = pair
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"grab": frames()}, frame_period=0.01, share=share, primary=False
    )
    with runtime:
        entry = ServiceDirectory(server).wait_for("Camera", "Recog", timeout=10)
        clients = [ServiceClient(server, entry, f"r{i}") for i in range(3)]
        for client in clients:
            client.connect(parameters={"resolution": "LO"}, timeout=10)
        stream = runtime.streams["grab"]
        assert until(lambda: all(runtime.instance("Recog", f"r{i}") for i in range(3)))
        time.sleep(0.05)  # the selection of the last client reaches the next frame
        stream.topology.reset_stats()
        assert until(lambda: stream.topology.stats()["grab"].calls >= 20)
        stats = stream.topology.stats()
        grabs, works = stats["grab"].calls, stats["work_lo"].calls
        assert stats["work_hi"].calls == 0  # the preference is a ceiling: never above LO
        # Shared: one run of work_lo per frame for the three clients; replicated: one per client
        # (a frame in flight at the reset may count one side only).
        assert (grabs - 1 <= works <= grabs + 1) if share else (3 * grabs - 3 <= works <= 3 * grabs + 3)
        for client in clients:
            client.close()


FUSION = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="fusion-test">
  <Topic name="/a" type="bytes"/>
  <Topic name="/b" type="bytes"/>
  <Topic name="/fused" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="Global" node="pc">
    <Plugin name="merge" kind="test-source"/>
    <Profile name="ONLY" output="merge"><Use plugin="merge"/></Profile>
    <Service name="Fusion" rate="0.02">
      <Input name="a" topic="/a"/>
      <Input name="b" topic="/b"/>
      <Output name="fused" topic="/fused"/>
      <QualityMeasure name="deadline" kind="qos" domain="temporal" source="deadline" unit="s"/>
      <Scenario name="ONLY" profile="ONLY"><Policy measure="deadline" upper="1"/></Scenario>
    </Service>
  </SmartResource>
</System>
"""


def test_input_topics_feed_the_stream_each_sample_once(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    from runtime.network import TopicQoS

    server, remote = pair
    runtime = SmartResourceRuntime(resource, server, registry=registry, frame_period=0.005)
    with runtime:
        out = remote.subscribe(TopicQoS("/recog/objects", "ckm/service-data", history=64))
        camera = remote.publisher(TopicQoS("/cam/raw", "ckm/raw", reliability="best-effort"))
        assert remote.wait_for_subscribers("/cam/raw", 1, 10)

        def seen(index: int) -> bool:
            return any(s.value["frame"] == {"frame": index} for s in out.history())

        for index in range(5):
            camera.publish({"frame": index})
            assert until(functools.partial(seen, index))
        time.sleep(0.1)  # several acquisition periods with no new sample
        assert Load.calls.get("work_hi", 0) == 5  # each sample processed once, none twice


def test_a_service_with_several_inputs_and_no_tcm_gets_them_together(
    tmp_path: Path, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    from runtime.network import TopicQoS

    path = tmp_path / "fusion.xml"
    path.write_text(FUSION)
    record = load(path).resource("Global")
    assert record is not None
    server, remote = pair
    with SmartResourceRuntime(record, server, registry=registry) as runtime:
        received: list[Any] = []
        remote.subscribe(TopicQoS("/fused", "ckm/service-data", history=64), lambda s: received.append(s.value))
        a = remote.publisher(TopicQoS("/a", "ckm/raw"))
        b = remote.publisher(TopicQoS("/b", "ckm/raw"))
        assert remote.wait_for_subscribers("/a", 1, 10) and remote.wait_for_subscribers("/b", 1, 10)
        a.publish(1)
        assert until(lambda: {"a": 1, "b": None} in received)
        b.publish(2)
        assert until(lambda: {"a": 1, "b": 2} in received)
        instance = runtime.instance("Fusion")
        assert instance is not None and instance.scenario == "ONLY"


def test_a_new_client_joins_at_the_current_operating_point_then_recovers(
    resource: SmartResource, registry: Registry, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    runtime = SmartResourceRuntime(
        resource, server, registry=registry, sources={"grab": frames()}, frame_period=0.01, primary=False
    )
    with runtime:
        entry = ServiceDirectory(remote).wait_for("Camera", "Recog", timeout=10)
        first, second = ServiceClient(remote, entry, "first"), ServiceClient(remote, entry, "second")
        assert first.connect(parameters={"resolution": "LO"}, timeout=10)["scenario"] == "LO"
        ack = second.connect(timeout=10)  # prefers HI (the default) but the service runs at LO
        assert ack["scenario"] == "LO"
        # Light load: the newcomer recovers to its preference; the first stays under its ceiling.
        assert second.wait(lambda c: any(e["to"] == "HI" and e["reason"] == "recovered" for e in c.events), 10)
        assert not any(e["to"] == "HI" for e in first.events)
        first.close()
        second.close()
