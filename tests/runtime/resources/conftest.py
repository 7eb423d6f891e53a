"""Fixtures shared by the Smart Resource tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from runtime.network import Transport, open_transport
from tests.runtime.network.conftest import private_network


@pytest.fixture
def pair() -> Iterator[tuple[Transport, Transport]]:
    """Two started transports on a private loopback network: the resource's side and a client's."""
    network = private_network()
    made = [open_transport(network, name="resource"), open_transport(network, name="client")]
    try:
        for transport in made:
            transport.setup()
            transport.start()
        yield made[0], made[1]
    finally:
        for transport in made:
            transport.stop()
