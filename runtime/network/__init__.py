"""Networking: CKMultiPeer (§3.1.4) and a Zenoh transport behind one publish/subscribe interface."""

from __future__ import annotations

from ckmconf.model import Network

from .api import EVENTS_TOPIC, NetworkEvent, Publisher, Sample, Subscription, TopicQoS, Transport, read_group_key


def open_transport(network: Network, *, name: str = "peer", key: bytes | None = None) -> Transport:
    """The transport the configuration asks for (no I/O until ``setup()``)."""
    if network.transport == "zenoh":
        from .zenoh_transport import ZenohTransport

        return ZenohTransport(network, name=name, key=key)
    from .pubsub import MultiPeerTransport

    return MultiPeerTransport(network, name=name, key=key)


__all__ = [
    "EVENTS_TOPIC",
    "NetworkEvent",
    "Publisher",
    "Sample",
    "Subscription",
    "TopicQoS",
    "Transport",
    "open_transport",
    "read_group_key",
]
