"""Private networks take their ports below the kernel's ephemeral range."""

from __future__ import annotations

import random
import socket
from typing import Any

import pytest

from runtime.network import ports
from runtime.network.ports import SPAN, ephemeral_low, private_base


def test_private_bases_keep_their_span_below_the_ephemeral_range() -> None:
    rng = random.Random(7)
    low = ephemeral_low()
    bases = {private_base(rng) for _ in range(500)}
    assert all(b >= 10000 and b + SPAN <= low and b % SPAN == 10000 % SPAN for b in bases)
    assert len(bases) > 100  # enough room that two private networks rarely meet


def test_a_port_another_peer_starts_listening_on_between_bind_and_listen_is_skipped(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Eight peers starting at once: with SO_REUSEADDR two of them bound one port and the second's
    listen failed with EADDRINUSE, which ended that peer; it now takes the next port."""
    base = private_base()
    other = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    other.bind(("127.0.0.1", base))  # bound, not listening yet: our bind of the same port succeeds

    class Racing(socket.socket):
        def bind(self, address: Any) -> None:
            super().bind(address)
            if address == ("127.0.0.1", base):
                other.listen(1)  # the other peer listens first

    monkeypatch.setattr(socket, "socket", Racing)  # what ports.bind_listener makes
    try:
        server = ports.bind_listener("127.0.0.1", base, 4)
        try:
            assert server.getsockname()[1] == base + 1
        finally:
            server.close()
    finally:
        other.close()
