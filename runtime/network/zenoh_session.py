"""Zenoh naming and session settings of the Zenoh transport (``<Network transport="zenoh">``, ``<Zenoh>``).

Naming — every CKM name lives under the ``ckm`` prefix:

    topic "/a/b" (or "a/b")      → key expression "ckm/a/b" (leading slash removed)
    ckm/@peer/<guid>             liveliness token of every transport: discovery, found / lost
    ckm/@sub/<guid>/a/b          liveliness token per subscribed topic: wait_for_subscribers

``@`` chunks are verbatim in Zenoh, so the token spaces never match a data key expression. A
transport's GUID is the low 48 bits of its session's random 128-bit ZenohId (the width of a
CKMultiPeer GUID), sent as each sample's attachment (:data:`SOURCE`). :func:`zenoh_config` turns
a ``<Network>`` into the session configuration.
"""

from __future__ import annotations

import functools
import json
import re
import struct
from typing import Any

import zenoh

from ckmconf.model import Network

from .api import NetworkError

PREFIX = "ckm"
PEER_TOKENS = f"{PREFIX}/@peer"
SUB_TOKENS = f"{PREFIX}/@sub"
GUID_MASK = (1 << 48) - 1
SOURCE = struct.Struct("!Q")
MIN_LEASE_MS = 1000  # a shorter lease lets a busy machine close healthy links (and lose data)
FORBIDDEN = set("*$?#")


@functools.lru_cache(maxsize=4096)
def topic_path(topic: str) -> str:
    """The key expression of ``topic`` without the prefix: "/a/b" → "a/b"; rejects wildcards."""
    path = topic.removeprefix("/")
    chunks = path.split("/")
    if not path or any(not c or c.startswith("@") or FORBIDDEN & set(c) for c in chunks):
        raise ValueError(f"topic {topic!r} cannot be a Zenoh key expression (empty, wildcard or '@' part)")
    return path


@functools.lru_cache(maxsize=4096)
def key_expr(topic: str) -> str:
    """The Zenoh key expression of a CKM topic: "/a/b" → "ckm/a/b"."""
    key = f"{PREFIX}/{topic_path(topic)}"
    try:
        zenoh.KeyExpr(key)
    except zenoh.ZError as exc:
        raise ValueError(f"topic {topic!r} cannot be a Zenoh key expression: {exc}") from None
    return key


def guid_of(zid: zenoh.ZenohId) -> int:
    """A transport's GUID: the low 48 bits of its session's ZenohId (random unless configured)."""
    return int(str(zid), 16) & GUID_MASK or 1


def zenoh_config(network: Network) -> zenoh.Config:
    """The session configuration for ``network``: peer mode with multicast scouting by default.

    Scouting uses the network's own multicast group, port and interface (so separate CKM
    systems, and tests, never hear each other); the link lease is heartbeat × lost_after.
    """
    settings = network.zenoh
    mode = settings.mode if settings is not None else "peer"
    scouting = settings.multicast_scouting if settings is not None else True
    listen = [e.endpoint for e in settings.listen] if settings is not None else []
    connect = [e.endpoint for e in settings.connect] if settings is not None else []
    wildcard = network.interface == "0.0.0.0"  # an IPv4 address (schema), or every interface
    if not listen and mode != "client":
        listen = [f"tcp/{network.interface}:{7447 if mode == 'router' else 0}"]  # a router needs a known port
    values: dict[str, Any] = {
        "mode": mode,
        "scouting/multicast/enabled": scouting,
        "scouting/multicast/address": f"{network.group}:{network.discovery_port}",
        "scouting/multicast/interface": "auto" if wildcard else network.interface,
        "listen/endpoints": listen,
        "connect/endpoints": connect,
        "transport/link/tx/lease": max(MIN_LEASE_MS, round(network.heartbeat * network.lost_after * 1000)),
        "transport/link/tx/keep_alive": max(1, network.lost_after),
    }
    config = zenoh.Config()
    for key, value in values.items():
        try:
            config.insert_json5(key, json.dumps(value))
        except zenoh.ZError as exc:  # e.g. a malformed <Connect>/<Listen> endpoint
            raise NetworkError(f"invalid Zenoh setting {key} = {value!r}: {zenoh_reason(exc)}") from None
    return config


def guid_after(key: str, prefix: str) -> int | None:
    """The GUID chunk right after ``prefix`` in a token's key expression, if well formed."""
    chunk = key.removeprefix(prefix + "/").partition("/")[0] if key.startswith(prefix + "/") else ""
    return int(chunk) if chunk.isdigit() else None


def zenoh_reason(exc: Exception) -> str:
    """Zenoh's message, without the Rust wrapper and source location around it."""
    text = str(exc)
    wrapped = re.search(r'msg: "(.*?)"', text)
    return (wrapped.group(1) if wrapped else text).split(" at /", 1)[0].strip()
