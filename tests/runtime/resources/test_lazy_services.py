"""A lazy Smart Resource service (``<Service lazy>``, D245) works only while a subscriber asks for its
output, and asks for its inputs only meanwhile, so lazy producers upstream rest too. Over a real
transport on loopback."""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

from ckmconf.loader import load
from ckmconf.model.resources import SmartResource
from runtime.network import TopicQoS, Transport
from runtime.registry import Registry
from runtime.resources.resource import SmartResourceRuntime
from tests import waiting
from tests.runtime.resources.test_service_api import FUSION, SourcePlugin

until = functools.partial(waiting.until, interval=0.01)


def fusion(tmp_path: Path, lazy: bool) -> SmartResource:
    path = tmp_path / "fusion.xml"
    path.write_text(FUSION.replace('<Service name="Fusion"', f'<Service name="Fusion" lazy="{str(lazy).lower()}"'))
    record = load(path).resource("Global")
    assert record is not None and record.services[0].lazy is lazy
    return record


def registry() -> Registry:
    made = Registry(load_entry_points=False)
    made.register("plugin", "test-source", SourcePlugin)
    return made


def test_a_lazy_service_works_only_while_its_output_is_asked_for(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    with SmartResourceRuntime(fusion(tmp_path, lazy=True), server, registry=registry()) as runtime:
        stream = runtime.streams["merge"]
        a = remote.publisher(TopicQoS("/a", "ckm/raw"))
        assert remote.wait_for_subscribers("/a", 1, 10)  # linked: it observes /a …
        assert not remote.subscribed("/a")  # … but does not ask for it
        a.publish(1)
        assert until(lambda: stream.rested > 20)
        assert stream.topology.frames == 0  # nothing taken while nobody asks

        received: list[Any] = []
        fused = remote.subscribe(TopicQoS("/fused", "ckm/service-data", history=64), lambda s: received.append(s.value))
        assert until(lambda: remote.subscribed("/a"))  # asked for its output, it asks for its inputs
        a.publish(2)
        assert until(lambda: {"a": 2, "b": None} in received)
        assert {"a": 1, "b": None} not in received  # what came while it rested is not processed late

        fused.demand(False)  # the reader only observes now: the service rests again
        assert until(lambda: not remote.subscribed("/a"))
        frames, count = stream.topology.frames, len(received)
        rested = stream.rested
        a.publish(3)
        assert until(lambda: stream.rested > rested + 20)
        assert stream.topology.frames == frames and len(received) == count
        assert runtime.statistics()["streams"]["merge"]["rested"] >= stream.rested - 1


def test_a_service_not_lazy_asks_for_its_inputs_from_the_start(
    tmp_path: Path, pair: tuple[Transport, Transport]
) -> None:
    server, remote = pair
    with SmartResourceRuntime(fusion(tmp_path, lazy=False), server, registry=registry()) as runtime:
        remote.publisher(TopicQoS("/a", "ckm/raw"))
        assert until(lambda: remote.subscribed("/a") and remote.subscribed("/b"))
        assert runtime.streams["merge"].asked is None and runtime.streams["merge"].rested == 0


def test_a_woken_service_fuses_no_input_from_before_its_rest(tmp_path: Path, pair: tuple[Transport, Transport]) -> None:
    """D249: on waking, an input not heard since is None, not its value from before the rest."""
    server, remote = pair
    with SmartResourceRuntime(fusion(tmp_path, lazy=True), server, registry=registry()) as runtime:
        stream = runtime.streams["merge"]
        a, b = remote.publisher(TopicQoS("/a", "ckm/raw")), remote.publisher(TopicQoS("/b", "ckm/raw"))
        received: list[Any] = []
        fused = remote.subscribe(TopicQoS("/fused", "ckm/service-data", history=64), lambda s: received.append(s.value))
        assert until(lambda: remote.subscribed("/a") and remote.subscribed("/b"))
        a.publish(1)
        b.publish(1)
        assert until(lambda: {"a": 1, "b": 1} in received)

        fused.demand(False)
        assert until(lambda: not remote.subscribed("/a"))
        rested = stream.rested
        assert until(lambda: stream.rested > rested + 20)
        instance = next(iter(stream.instances.values()))
        before = instance.measures.count.get("deadline", 0)

        fused.demand(True)  # woken: /b was last heard before the rest
        assert until(lambda: remote.subscribed("/a"))
        a.publish(2)
        assert until(lambda: any(r.get("a") == 2 for r in received))
        assert {"a": 2, "b": None} in received and {"a": 2, "b": 1} not in received
        assert instance.measures.count.get("deadline", 0) > before
        b.publish(2)
        assert until(lambda: {"a": 2, "b": 2} in received)


def test_a_woken_instance_counts_no_rest_as_a_period(tmp_path: Path, pair: tuple[Transport, Transport]) -> None:
    """D249: the first result after a rest observes no ``rate`` (the rest is no publication period)."""
    server, _ = pair
    path = tmp_path / "rate.xml"
    measure = '<QualityMeasure name="period" kind="qos" domain="temporal" source="rate" unit="s"/>'
    path.write_text(FUSION.replace("<Scenario", measure + "<Scenario", 1))
    record = load(path).resource("Global")
    assert record is not None
    with SmartResourceRuntime(record, server, registry=registry()) as runtime:
        instance = next(iter(runtime.streams["merge"].instances.values()))
        instance.deliver({"fused": 1}, 100.0, 100.0)
        instance.deliver({"fused": 2}, 100.5, 100.5)
        assert instance.measures.last["period"] == 0.5
        periods = instance.measures.count["period"]
        instance.resume()
        instance.deliver({"fused": 3}, 160.0, 160.0)  # a minute of rest later
        assert instance.measures.count["period"] == periods
        instance.deliver({"fused": 4}, 160.25, 160.25)
        assert instance.measures.last["period"] == 0.25 and instance.measures.count["period"] == periods + 1


def test_a_result_of_none_publishes_nothing_and_observes_no_measure(tmp_path: Path,
                                                                    pair: tuple[Transport, Transport]) -> None:
    """A kind with nothing yet (an input it needs not arrived) returns None: nothing goes on its Output."""
    server, remote = pair
    with SmartResourceRuntime(fusion(tmp_path, lazy=False), server, registry=registry()) as runtime:
        instance = next(iter(runtime.streams["merge"].instances.values()))
        received: list[Any] = []
        remote.subscribe(TopicQoS("/fused", "ckm/service-data", history=64), lambda s: received.append(s.value))
        assert server.wait_for_subscribers("/fused", 1, 10)
        published = instance.published
        instance.deliver(None, 100.0, 100.0)
        assert instance.published == published and "deadline" not in instance.measures.count
        instance.deliver({"fused": 1}, 100.5, 100.5)
        assert until(lambda: len(received) == 1)
        assert received[0] is not None and instance.published == published + 1
