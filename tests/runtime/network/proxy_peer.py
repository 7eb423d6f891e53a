"""A peer for the PROXYWRAPPER test, run inside a network namespace: ``python proxy_peer.py ROLE ADDRESS PORTS``.

ROLE is ``listen`` (subscribe to /chat and report the first sample), ``talk`` (publish to /chat)
or ``relay`` (just link). Each prints one JSON line per finding and stops after 15 s at most.
"""

from __future__ import annotations

import json
import sys
import time

from ckmconf.model import Network
from runtime.network.api import TopicQoS
from runtime.network.guid import guid_text
from runtime.network.pubsub import MultiPeerTransport


def main() -> None:
    role, address, base = sys.argv[1], sys.argv[2], int(sys.argv[3])
    network = Network(
        group="239.255.77.77",
        discovery_port=base + 100,
        interface=address,
        base_port=base,
        port_tries=4,
        heartbeat=0.1,
        lost_after=5,
        reconnect_min=0.05,
        reconnect_max=0.2,
    )
    transport = MultiPeerTransport(network, name=role)
    transport.setup()
    transport.start()
    topic = TopicQoS("/chat", "string")
    deadline = time.monotonic() + 15
    try:
        if role == "listen":
            subscription = transport.subscribe(topic)
            if subscription.wait(1, 14):
                sample = subscription.history()[-1]
                routes = {guid_text(d): guid_text(v) for d, v in transport.peer.router.routes.items()}
                direct = [guid_text(g) for g in transport.peer.linked()]
                print(
                    json.dumps(
                        {"got": sample.value, "from": guid_text(sample.source), "routes": routes, "direct": direct}
                    )
                )
        elif role == "talk":
            publisher = transport.publisher(topic)
            while time.monotonic() < deadline:
                publisher.publish(f"hello from {address}")
                time.sleep(0.05)
        else:
            time.sleep(14)
        sys.stdout.flush()
    finally:
        transport.stop()


if __name__ == "__main__":
    main()
