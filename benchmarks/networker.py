"""Worker processes for the network benchmarks: ``python -m benchmarks.networker ROLE JSON``.

``sub``: subscribe to /bench, report one-way latencies of the paced phase and the throughput
of the saturated phase. ``peer``: set up, wait for "go" on stdin, report when linked to all.
Every worker prints one JSON line and exits; it never runs longer than its ``limit``.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from typing import Any

from ckmconf.model import Connect, Listen, Network, Zenoh
from runtime.host_network import joined
from runtime.network import Sample, TopicQoS

TOPIC = TopicQoS("/bench", "bytes", reliability="reliable", history=1)


def network_from(settings: dict[str, Any]) -> Network:
    """The ``<Network>`` record of ``settings`` (its ``zenoh`` entry becomes the ``<Zenoh>`` child)."""
    zenoh = settings.pop("zenoh", None)
    if zenoh is None:
        return Network(**settings)
    connect = tuple(Connect(endpoint=e) for e in zenoh.pop("connect", ()))
    listen = tuple(Listen(endpoint=e) for e in zenoh.pop("listen", ()))
    return Network(**settings, zenoh=Zenoh(**zenoh, connect=connect, listen=listen))


def subscriber(settings: dict[str, Any]) -> dict[str, Any]:
    """The ``sub`` role: subscribe to /bench; the paced phase's one-way latencies and the saturated throughput."""
    paced, total, limit = settings.pop("paced"), settings.pop("total"), settings.pop("limit")
    latencies: list[float] = []
    arrivals: list[float] = []
    done = threading.Event()

    def on_sample(sample: Sample) -> None:
        now = time.time()
        if len(latencies) < paced:
            latencies.append(now - sample.stamp)
        else:
            arrivals.append(now)
        if len(latencies) + len(arrivals) >= paced + total:
            done.set()

    with joined(network_from(settings), "bench-sub") as transport:  # the host's way onto the network
        transport.subscribe(TOPIC, on_sample)
        print(json.dumps({"ready": True}), flush=True)
        done.wait(limit)
    span = arrivals[-1] - arrivals[0] if len(arrivals) > 1 else 0.0
    return {"latencies": latencies, "received": len(arrivals), "span_s": span}


def peer(settings: dict[str, Any]) -> dict[str, Any]:
    """The ``peer`` role: join, wait for "go" on stdin, start; when it started and was linked to all the others."""
    count, limit = settings.pop("count"), settings.pop("limit")
    with joined(network_from(settings), "bench-peer", start=False) as transport:
        print(json.dumps({"ready": True}), flush=True)
        sys.stdin.readline()  # "go": every peer starts at once
        started = time.time()
        transport.start()
        linked_at = None
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            if len(transport.peers()) >= count - 1:
                linked_at = time.time()
                break
            time.sleep(0.0005)
        print(json.dumps({"started": started, "linked_at": linked_at}), flush=True)
        sys.stdin.readline()  # stay up until everyone is done, so nobody sees a peer leave
    return {"stopped": True}


def main() -> None:
    """Run the role of ``argv[1]`` with the JSON settings of ``argv[2]``; print its result as one JSON line."""
    role, settings = sys.argv[1], json.loads(sys.argv[2])
    result = subscriber(settings) if role == "sub" else peer(settings)
    print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
