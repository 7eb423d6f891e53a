"""CKMultiPeer between network namespaces: three peers on a private LAN, each in its own namespace.

The namespaces, the veth pairs and the bridge joining them are created here and deleted at the
end; the addresses (10.250.0.0/24) exist only inside them. Multicast discovery crosses the
bridge, links are TCP between the namespaces' addresses, samples flow over them.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import time
import uuid
from collections.abc import Iterator

import pytest

from runtime.network.guid import guid_address
from tests.runtime.network.conftest import private_network
from tests.runtime.network.peers import assert_one_link_per_pair, peer_processes, settled, wait_until

SUBNET = "10.250.0"


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True, timeout=20)


@pytest.fixture
def lan() -> Iterator[list[tuple[str, str]]]:
    """Three namespaces on one bridge: [(namespace, address)]."""
    tag = uuid.uuid4().hex[:8]
    hub = f"ckm-{tag}-hub"
    try:
        ip("netns", "add", hub)
    except subprocess.CalledProcessError as exc:
        if os.geteuid() != 0 or "permitted" in exc.stderr or "denied" in exc.stderr:
            pytest.skip(f"'ip netns add' needs privileges this session lacks: {exc.stderr.strip()}")
        raise
    created = [hub]
    try:
        ip("-n", hub, "link", "add", "br0", "type", "bridge")
        ip("-n", hub, "link", "set", "br0", "type", "bridge", "mcast_snooping", "0")
        ip("-n", hub, "link", "set", "br0", "up")
        members: list[tuple[str, str]] = []
        for index, name in enumerate("abc", start=1):
            namespace, address = f"ckm-{tag}-{name}", f"{SUBNET}.{index}"
            ip("netns", "add", namespace)
            created.append(namespace)
            # Both ends are created inside our namespaces: the host's interfaces are never touched.
            ip("link", "add", "eth0", "netns", namespace, "type", "veth", "peer", "name", f"v{name}", "netns", hub)
            ip("-n", hub, "link", "set", f"v{name}", "master", "br0")
            ip("-n", hub, "link", "set", f"v{name}", "up")
            ip("-n", namespace, "addr", "add", f"{address}/24", "dev", "eth0")
            ip("-n", namespace, "link", "set", "eth0", "multicast", "on")
            ip("-n", namespace, "link", "set", "eth0", "up")
            ip("-n", namespace, "link", "set", "lo", "up")
            ip("-n", namespace, "route", "add", "224.0.0.0/4", "dev", "eth0")
            members.append((namespace, address))
        yield members
    finally:
        for namespace in reversed(created):
            subprocess.run(["ip", "netns", "del", namespace], capture_output=True, timeout=20)


@pytest.mark.timeout(120)
def test_peers_in_three_namespaces_discover_link_and_exchange(lan: list[tuple[str, str]]) -> None:
    base = private_network(heartbeat=0.1, lost_after=5)
    with peer_processes() as spawn:
        peers = [
            spawn(dataclasses.replace(base, interface=address), name=namespace, netns=namespace)
            for namespace, address in lan
        ]
        for peer, (_, address) in zip(peers, lan, strict=True):
            peer.ready()
            assert guid_address(peer.guid) == (address, base.base_port)
        assert_one_link_per_pair(settled(peers, 2))

        first, second, third = peers
        for subscriber in (second, third):
            subscriber.request("subscribe", topic="/lan")
        reply = first.request("publish", topic="/lan", count=1, subscribers=2, wait=10.0, value="over the bridge")
        assert reply["subscribed"] and reply["sent"] == 2
        for subscriber in (second, third):
            received = subscriber.request("received", topic="/lan", count=1, wait=10.0)
            assert received["ok"] and received["values"] == ["over the bridge"]
            assert received["sources"] == [first.guid]

        killed_at = time.monotonic()
        third.kill()

        def lost_everywhere() -> bool:
            return all(any(e["kind"] == "lost" and e["peer"] == third.guid for e in p.events) for p in (first, second))

        assert wait_until(lost_everywhere, base.heartbeat * (base.lost_after + 1) + 5.0), "the killed peer was not lost"
        assert time.monotonic() - killed_at < 10
        assert set(first.links()) == {second.guid} and set(second.links()) == {first.guid}
