"""Port ranges for private test and benchmark networks on one host (``<Network basePort>``, §3.1.4.1).

A random base port inside the kernel's ephemeral range (Linux: 32768–60999) can collide with a
port the kernel has just handed to some outgoing connection, and a bind then fails with
EADDRINUSE. Private networks therefore take their ports below that range.

:func:`bind_listener` binds a peer's listening port, trying the next ones of its range when busy.
"""

from __future__ import annotations

import errno
import random
import socket
from pathlib import Path

from .api import NetworkError

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


def bind_listener(interface: str, base: int, tries: int) -> socket.socket:
    """A listening TCP socket on the first free port of ``base`` … ``base + tries − 1`` (``<Network basePort>``)."""
    last: OSError | None = None
    for port in range(base, min(base + tries, 65536)):
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        # A port held only by TIME_WAIT connections of an earlier run is free: a restarted
        # peer keeps its GUID. (Two live listeners still cannot share it.)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            server.bind((interface, port))
            # With SO_REUSEADDR two peers starting together can both bind a port no one listens
            # on yet; the second to listen then gets EADDRINUSE here: the port is taken, try the next.
            server.listen(64)
        except OSError as exc:
            server.close()
            if exc.errno not in (errno.EADDRINUSE, errno.EACCES):
                raise NetworkError(f"cannot listen on {interface}:{port}: {exc}") from exc
            last = exc
            continue
        server.settimeout(0.1)
        return server
    raise NetworkError(f"no free port on {interface} in {base}…{base + tries - 1}: {last}")
