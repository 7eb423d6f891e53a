"""Idle, unauthenticated TCP connections cannot crowd a real peer out of CKMultiPeer (issue G)."""

from __future__ import annotations

import contextlib
import logging
import socket
from collections.abc import Callable

import pytest

from runtime.network import Transport
from runtime.network import link as link_module
from runtime.network.multipeer import MAX_PENDING_LINKS
from runtime.network.pubsub import MultiPeerTransport
from tests.runtime.network.conftest import private_network
from tests.waiting import until


def test_idle_connections_do_not_block_a_real_peer(
    transports: Callable[..., Transport], monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    # Idle connections would stay for two minutes: only eviction can let the real peer in sooner.
    monkeypatch.setattr(link_module, "HANDSHAKE_TIMEOUT", 120.0)
    caplog.set_level(logging.INFO, logger="ckm.multipeer")
    network = private_network()
    # The flooded peer must be the higher GUID (the lower one connects): hold the base port first.
    holder = socket.socket()
    holder.bind((network.interface, network.base_port))
    holder.listen(1)
    flooded = transports(network, "flooded")
    holder.close()
    assert isinstance(flooded, MultiPeerTransport)
    port = flooded.peer.guid & 0xFFFF
    idle: list[socket.socket] = []
    try:
        for _ in range(MAX_PENDING_LINKS + 16):
            idle.append(socket.create_connection((network.interface, port), timeout=5))
        assert until(lambda: flooded.peer.evicted_links >= 16, 30), "the peer did not accept past its cap"
        real = transports(network, "real")
        assert isinstance(real, MultiPeerTransport) and real.peer.guid < flooded.peer.guid
        assert until(lambda: real.peer.guid in flooded.peer.links, 60), "idle connections blocked the real peer"
        assert flooded.peer.links[real.peer.guid].state == "open"
        assert "evicted" in caplog.text  # every closed link is logged with its reason
    finally:
        for sock in idle:
            with contextlib.suppress(OSError):
                sock.close()


def test_a_handshake_time_out_is_logged(
    transports: Callable[..., Transport], monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(link_module, "HANDSHAKE_TIMEOUT", 0.5)
    caplog.set_level(logging.INFO, logger="ckm.multipeer")
    peer = transports(private_network(), "alone")
    assert isinstance(peer, MultiPeerTransport)
    with socket.create_connection(("127.0.0.1", peer.peer.guid & 0xFFFF), timeout=5):
        assert until(lambda: "handshake timed out" in caplog.text, 20), caplog.text
