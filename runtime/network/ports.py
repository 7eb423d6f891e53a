"""Port ranges for private test and benchmark networks on one host (``<Network basePort>``, §3.1.4.1).

A random base port inside the kernel's ephemeral range (Linux: 32768–60999) can collide with a
port the kernel has just handed to some outgoing connection, and a bind then fails with
EADDRINUSE. Private networks therefore take their ports below that range.
"""

from __future__ import annotations

import random
from pathlib import Path

SPAN = 64
"""Ports a private network uses from its base (links, fallbacks and the discovery port)."""


def ephemeral_low() -> int:
    """The first port of the kernel's ephemeral range (32768 when it cannot be read)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def private_base(rng: random.Random | None = None, low: int = 10000) -> int:
    """A random base port, a multiple of SPAN, whose whole span lies below the ephemeral range."""
    high = max(low + SPAN, ephemeral_low() - SPAN)
    return (rng or random.Random()).randrange(low, high, SPAN)
