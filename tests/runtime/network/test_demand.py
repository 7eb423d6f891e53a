"""Asked-for and passive subscriptions (decision D245): what a lazy producer learns from CKMultiPeer.

A producer's transport tells whether any subscriber, here or at a peer, asks for a topic; a
passive subscriber gets what flows but asks for nothing. Every wait is bounded.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import pytest

from runtime.network import NetworkEvent, TopicQoS, Transport
from runtime.network.frames import Frame, FrameType
from runtime.network.pubsub import MultiPeerTransport

from .conftest import private_network
from .test_transports import TIMEOUT, wait_until

Make = Callable[..., Transport]


def test_a_peer_asks_only_while_one_of_its_subscriptions_is_not_passive(transports: Make) -> None:
    network = private_network("multipeer")
    producer, reader = transports(network, "producer"), transports(network, "reader")
    topic = TopicQoS("/camera/raw")
    watch = reader.subscribe(topic, passive=True)
    assert producer.wait_for_subscribers(topic.name, 1, TIMEOUT)  # linked, but only observed
    assert not producer.subscribed(topic.name) and not reader.subscribed(topic.name)

    # what flows reaches the passive subscriber all the same
    assert producer.publisher(topic).publish({"frame": 1}) == 1
    assert watch.wait(1, TIMEOUT)

    asking = reader.subscribe(topic)
    assert reader.subscribed(topic.name)
    assert wait_until(lambda: producer.subscribed(topic.name))
    asking.demand(False)
    assert wait_until(lambda: not producer.subscribed(topic.name))
    assert not reader.subscribed(topic.name)
    watch.demand(True)
    assert wait_until(lambda: producer.subscribed(topic.name))
    watch.close()
    assert wait_until(lambda: not producer.subscribed(topic.name))
    assert producer.wait_for_subscribers(topic.name, 1, TIMEOUT)  # `asking` is still linked, passive


def test_a_peer_that_leaves_asks_no_more(transports: Make) -> None:
    network = private_network("multipeer")
    producer, reader = transports(network, "producer"), transports(network, "reader")
    reader.subscribe(TopicQoS("/scan"))
    assert wait_until(lambda: producer.subscribed("/scan"))
    reader.stop()
    assert wait_until(lambda: not producer.subscribed("/scan"))


def test_local_subscriptions_ask_too(transports: Make) -> None:
    transport = transports(private_network("multipeer"), "alone")
    passive = transport.subscribe(TopicQoS("/t"), passive=True)
    assert passive.passive and not transport.subscribed("/t")
    passive.demand(True)
    assert not passive.passive and transport.subscribed("/t")
    passive.demand(True)  # twice is once
    passive.demand(False)
    assert not transport.subscribed("/t")


def test_a_zenoh_transport_cannot_tell_and_answers_asked(transports: Make) -> None:
    transport = transports(private_network("zenoh"), "z")
    transport.subscribe(TopicQoS("/t"), passive=True)
    assert transport.subscribed("/t") and transport.subscribed("/nobody")


def test_no_deadline_runs_for_a_passive_subscription_nobody_asks_for(transports: Make) -> None:
    transport = transports(private_network("multipeer"), "alone")
    events: list[NetworkEvent] = []
    transport.on_event(events.append)
    quiet = transport.subscribe(TopicQoS("/quiet", deadline=0.05), passive=True)
    assert isinstance(transport, MultiPeerTransport)
    time.sleep(0.3)  # several deadlines: none is missed, nobody asks for the topic
    assert not [e for e in events if e.kind == "deadline-missed"]
    quiet.demand(True)
    assert wait_until(lambda: any(e.kind == "deadline-missed" and e.topic == "/quiet" for e in events))


@pytest.mark.parametrize(
    "body",
    [["subs", ["/a"], "not a list"], ["subs", ["/a"], ["/a"], ["/b"]], ["subs"], ["links", ["/a"], ["/a"]]],
)
def test_a_malformed_topiclinks_frame_is_ignored_and_named(
    transports: Make, body: list[object], caplog: pytest.LogCaptureFixture
) -> None:
    transport = transports(private_network("multipeer"), "alone")
    assert isinstance(transport, MultiPeerTransport)
    transport._links(7, ["subs", ["/a"], []])  # a peer observing /a
    with caplog.at_level(logging.WARNING, logger="ckm.network"):
        transport._links(7, body)
    assert "malformed TOPICLINKS frame from 7" in caplog.text
    assert not transport.subscribed("/a")  # nothing of the bad frame applied
    assert transport._remote_subs["/a"] == {7}


def test_a_topiclinks_frame_without_demands_asks_for_every_topic(transports: Make) -> None:
    transport = transports(private_network("multipeer"), "alone")
    assert isinstance(transport, MultiPeerTransport)
    transport._on_links(9, Frame(FrameType.TOPICLINKS, ["subs", ["/a", "/b"]]))
    assert transport.subscribed("/a") and transport.subscribed("/b")
    transport._on_links(9, Frame(FrameType.TOPICLINKS, ["subs", ["/a", "/b"], ["/b", 3]]))
    assert not transport.subscribed("/a") and transport.subscribed("/b")


def test_a_sample_heard_before_the_last_ask_is_not_news(transports: Make) -> None:
    """D249: ``latest(since_ask=True)`` gives only what arrived since the topic was last asked for."""
    network = private_network("multipeer")
    producer, reader = transports(network, "producer"), transports(network, "reader")
    topic = TopicQoS("/camera/raw")
    watch, asking = reader.subscribe(topic, passive=True), reader.subscribe(TopicQoS("/camera/raw"))
    publisher = producer.publisher(topic)
    assert producer.wait_for_subscribers(topic.name, 1, TIMEOUT)
    publisher.publish(1)
    assert watch.wait(1, TIMEOUT) and asking.wait(1, TIMEOUT)
    observed = watch.latest()
    assert observed is not None and observed.value == 1  # observed …
    assert watch.latest(since_ask=True) is None and not watch.heard_since_ask()  # … never asked for
    assert asking.latest(since_ask=True) is not None  # asked for from its start
    asks = watch.asks
    watch.demand(True)
    assert watch.asks == asks + 1 and watch.latest(since_ask=True) is None
    publisher.publish(2)
    assert watch.wait(2, TIMEOUT) and watch.heard_since_ask()
    sample = watch.latest(since_ask=True)
    assert sample is not None and sample.value == 2
    watch.demand(False)
    watch.demand(True)  # asked again: 2 is from before
    assert watch.latest(since_ask=True) is None and watch.asks == asks + 2
    watch.demand(True)  # already asked: no new ask
    assert watch.asks == asks + 2
