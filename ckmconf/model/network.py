"""Records of the transport settings (``<Network>``, schemas/kernel.xsd NetworkType): CKMultiPeer (§3.1.4) or Zenoh."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..binding import Record, attr, child, children


@dataclass(frozen=True, kw_only=True)
class Endpoint(Record):
    """<Connect> or <Listen>: a Zenoh endpoint."""

    endpoint: str = attr()


@dataclass(frozen=True, kw_only=True)
class Connect(Endpoint):
    """<Connect>: a Zenoh endpoint to connect to."""

    TAG = "Connect"


@dataclass(frozen=True, kw_only=True)
class Listen(Endpoint):
    """<Listen>: a Zenoh endpoint to listen on."""

    TAG = "Listen"


@dataclass(frozen=True, kw_only=True)
class Zenoh(Record):
    """<Zenoh>: Zenoh session settings."""

    TAG = "Zenoh"
    mode: Literal["peer", "client", "router"] = attr(default="peer")
    multicast_scouting: bool = attr(default=True)
    connect: tuple[Connect, ...] = children()
    listen: tuple[Listen, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Network(Record):
    """<Network>: CKMultiPeer or Zenoh transport settings (§3.1.4)."""

    TAG = "Network"
    transport: Literal["multipeer", "zenoh"] = attr(default="multipeer")
    group: str = attr(default="239.255.42.99")
    discovery_port: int = attr(default=7400)
    interface: str = attr(default="127.0.0.1")
    base_port: int = attr(default=7410)
    port_tries: int = attr(default=32)
    heartbeat: float = attr(default=0.5)
    lost_after: int = attr(default=3)
    max_frame: int = attr(default=16777216)
    reconnect_min: float = attr(default=0.05)
    reconnect_max: float = attr(default=2.0)
    clock_sync: float = attr(default=1.0)
    group_key_file: str | None = attr(default=None)
    zenoh: Zenoh | None = child(default=None)
