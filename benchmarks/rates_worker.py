"""The remote device of ``ckm-bench rates``: ``python -m benchmarks.rates_worker JSON``.

One process hosts the three remote services of the thesis's cooperation experiment (Fig. 7.7,
Table 7.8) — Pan-Tilt Camera, Navigation and Global Recog. — each a periodic kernel task on one
``Scheduler`` that publishes a realistic payload over CKMultiPeer. The worker waits until the
benchmark subscribes to every topic, lets SYNCTIME settle, prints ``{"started": …}``, publishes
for ``duration`` seconds, then prints its scheduler statistics and exits. Every wait is bounded.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import msgpack

from runtime.host_network import joined
from runtime.kernel.scheduler import Scheduler, Task
from runtime.network import TopicQoS

from .networker import network_from

Payload = Callable[[int], dict[str, Any]]  # sample number → the value published


def pan_tilt_payload(n: int) -> dict[str, Any]:
    """A pan-tilt camera state with the objects its recognizer tracks (Nao camera, §7.3.2)."""
    pan, tilt = 0.6 * math.sin(n / 10), 0.2 * math.cos(n / 15)
    return {
        "seq": n,
        "frame_id": "pantilt_camera",
        "pan": round(pan, 4),
        "tilt": round(tilt, 4),
        "zoom": 1.0,
        "resolution": "QVGA",
        "tracking": "cup",
        "objects": [
            {"label": "cup", "confidence": 0.87, "bbox": [112 + n % 7, 64, 38, 45]},
            {"label": "box", "confidence": 0.64, "bbox": [201, 90 + n % 5, 60, 52]},
        ],
    }


def navigation_payload(n: int) -> dict[str, Any]:
    """A localized pose with covariance, velocity and goal status (AMCL + move_base style)."""
    t = n * 0.8
    return {
        "seq": n,
        "frame_id": "map",
        "pose": {"x": round(1.5 + 0.1 * t, 4), "y": round(2.0 + 0.05 * math.sin(t), 4), "theta": round(0.3, 4)},
        "covariance": [0.02, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.005],
        "velocity": {"v": 0.12, "w": 0.01},
        "goal": {"x": 4.2, "y": 3.1, "theta": 1.57},
        "status": "active",
        "particles": 500,
    }


def global_recog_payload(n: int) -> dict[str, Any]:
    """Fused detections from the RGB, depth and pan-tilt recognizers (§6.3, §7.4)."""
    return {
        "seq": n,
        "frame_id": "map",
        "objects": [
            {
                "label": "cup",
                "confidence": 0.91,
                "position": [3.02, 1.44, 0.74],
                "sources": ["rgb", "depth", "pantilt"],
            },
            {"label": "box", "confidence": 0.78, "position": [2.51, 0.93, 0.0], "sources": ["rgb", "depth"]},
            {"label": "chair", "confidence": 0.66, "position": [0.8, 2.7, 0.0], "sources": ["depth"]},
        ],
        "fusion": "bayes",
    }


#: The services of Table 7.8: name → (topic, payload builder). Set rates come from the caller.
SERVICES: dict[str, tuple[str, Payload]] = {
    "Pan-Tilt Camera": ("/rates/pantilt_camera", pan_tilt_payload),
    "Navigation": ("/rates/navigation", navigation_payload),
    "Global Recog.": ("/rates/global_recog", global_recog_payload),
}


def qos(name: str) -> TopicQoS:
    """The topic (reliable, history 1) service ``name`` publishes on."""
    return TopicQoS(SERVICES[name][0], "dict", reliability="reliable", history=1)


def payload_bytes(name: str) -> int:
    """The size (bytes, msgpack) of one message of service ``name``."""
    packed: bytes = msgpack.packb(SERVICES[name][1](1))
    return len(packed)


def device(settings: dict[str, Any]) -> dict[str, Any]:
    """Run the three services for ``duration`` seconds; return the scheduler's statistics."""
    periods: dict[str, float] = settings.pop("periods")
    duration: float = settings.pop("duration")
    settle: float = settings.pop("settle")
    limit: float = settings.pop("limit")
    with joined(network_from(settings), "remote-device") as transport:  # the host's way onto the network
        for name in periods:
            if not transport.wait_for_subscribers(SERVICES[name][0], 1, limit):
                return {"error": f"nobody subscribed to {SERVICES[name][0]} within {limit} s"}
        time.sleep(settle)  # SYNCTIME bursts settle the clock offset before the first sample
        scheduler = Scheduler("remote-device")
        published: dict[str, int] = {}
        for name, period in periods.items():
            publisher = transport.publisher(qos(name))
            build = SERVICES[name][1]
            published[name] = 0

            def publish(name: str = name, publisher: Any = publisher, build: Payload = build) -> None:
                published[name] += 1
                publisher.publish(build(published[name]))

            scheduler.add(Task(name, period, publish, priority=60))
        scheduler.start()
        print(json.dumps({"started": time.time()}), flush=True)
        time.sleep(duration)
        scheduler.stop()
        time.sleep(0.2)  # let the last samples leave before the links close
        return {"published": published, "statistics": scheduler.statistics()}


def main() -> None:
    """Run the remote device with the JSON settings of ``argv[1]``; print its statistics as one JSON line."""
    print(json.dumps(device(json.loads(sys.argv[1]))), flush=True)


if __name__ == "__main__":
    main()
