"""Peer identity (§3.1.4.1): a 64-bit GUID holding the IPv4 address (32 bits) and TCP port (16 bits)."""

from __future__ import annotations

import ipaddress


def make_guid(address: str, port: int) -> int:
    """GUID of the peer listening on ``address:port``; ordering GUIDs orders the mandala."""
    if not 0 < port < 65536:
        raise ValueError(f"port {port} is out of range")
    return (int(ipaddress.IPv4Address(address)) << 16) | port


def guid_address(guid: int) -> tuple[str, int]:
    """The (IPv4 address, port) a GUID stands for."""
    if not 0 <= guid < 1 << 48:
        raise ValueError(f"GUID {guid} does not hold an IPv4 address and a port")
    return str(ipaddress.IPv4Address(guid >> 16)), guid & 0xFFFF


def guid_text(guid: int) -> str:
    """``address:port`` of a GUID, for logs and error messages."""
    address, port = guid_address(guid)
    return f"{address}:{port}"
