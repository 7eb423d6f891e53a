"""Fixtures for network tests: a private group and port range per test, both transports."""

from __future__ import annotations

import random
from collections.abc import Callable, Iterator

import pytest

from ckmconf.model import Network
from runtime.network import Transport, open_transport
from runtime.network.ports import private_base

TRANSPORTS = ["multipeer", "zenoh"]


def private_network(transport: str = "multipeer", **overrides: object) -> Network:
    """A Network on loopback with its own multicast group and ports, so tests never hear each other."""
    rng = random.Random()
    base = private_base(rng)  # below the ephemeral port range: no EADDRINUSE from other sockets
    settings: dict[str, object] = {
        "transport": transport,
        "group": f"239.255.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
        "discovery_port": base + 63,
        "interface": "127.0.0.1",
        "base_port": base,
        "port_tries": 48,
        "heartbeat": 0.05,
        "lost_after": 4,
        "reconnect_min": 0.02,
        "reconnect_max": 0.2,
        "clock_sync": 0.2,
    }
    settings.update(overrides)
    return Network(**settings)  # type: ignore[arg-type]


@pytest.fixture
def transports() -> Iterator[Callable[..., Transport]]:
    """Make started transports of one network; every one made is stopped at the end of the test."""
    made: list[Transport] = []

    def make(network: Network, name: str = "peer", key: bytes | None = None) -> Transport:
        transport = open_transport(network, name=name, key=key)
        made.append(transport)
        transport.setup()
        transport.start()
        return transport

    yield make
    for transport in reversed(made):
        transport.stop()
