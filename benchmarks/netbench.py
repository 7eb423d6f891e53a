"""ckm-bench pubsub and discovery: CKMultiPeer (and Zenoh) between OS processes on loopback."""

from __future__ import annotations

import json
import random
import statistics
import subprocess
import sys
import time
from typing import Any

from runtime.host_network import joined
from runtime.network.ports import private_base

from .networker import TOPIC, network_from

PAYLOAD = bytes(range(64))
PERIOD = 0.001


def private_settings(transport: str) -> dict[str, Any]:
    """``<Network>`` settings (kernel.xsd ``NetworkType``) of a private loopback network (random group, ports)."""
    rng = random.Random()
    base = private_base(rng)  # below the ephemeral port range: no EADDRINUSE from other sockets
    settings: dict[str, Any] = {
        "transport": transport,
        "group": f"239.255.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}",
        "discovery_port": base + 63,
        "base_port": base,
        "port_tries": 40,
        "heartbeat": 0.05,
        "reconnect_min": 0.01,
        "reconnect_max": 0.1,
    }
    if transport == "zenoh":
        settings["zenoh"] = {"mode": "peer", "multicast_scouting": False, "listen": [f"tcp/127.0.0.1:{base + 62}"]}
    return settings


def _spawn(role: str, settings: dict[str, Any]) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "benchmarks.networker", role, json.dumps(settings)]
    return subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def _line(process: subprocess.Popen[str], timeout: float) -> dict[str, Any]:
    assert process.stdout is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if line.strip():
            parsed: dict[str, Any] = json.loads(line)
            return parsed
        if process.poll() is not None:
            break
    raise RuntimeError(f"worker gave no answer within {timeout} s (exit code {process.poll()})")


def _pace(start: float, index: int) -> None:
    # Sleep most of the way, then spin: sub-millisecond pacing without a busy core the whole time.
    target = start + index * PERIOD
    remaining = target - time.perf_counter()
    if remaining > 0.0003:
        time.sleep(remaining - 0.0002)
    while time.perf_counter() < target:
        pass


def pubsub_one(kind: str, paced: int = 3000, total: int = 50000) -> dict[str, Any]:
    """One-way latency at 1 kHz and saturated throughput, publisher here, subscriber in another process."""
    settings = private_settings(kind)
    sub_settings = dict(settings, paced=paced, total=total, limit=120)
    pub_settings = dict(settings)
    if kind == "zenoh":
        port = settings["zenoh"]["listen"][0]
        pub_settings["zenoh"] = {"mode": "peer", "multicast_scouting": False, "connect": [port]}
    worker = _spawn("sub", json.loads(json.dumps(sub_settings)))
    try:
        _line(worker, 60)
        with joined(network_from(pub_settings), "bench-pub") as transport:  # the host's way onto the network
            if not transport.wait_for_subscribers(TOPIC.name, 1, 30):
                raise RuntimeError(f"{kind}: the subscriber never appeared")
            publisher = transport.publisher(TOPIC)
            start = time.perf_counter()
            for index in range(paced):
                _pace(start, index)
                publisher.publish(PAYLOAD)
            for _ in range(total):
                publisher.publish(PAYLOAD)
            result = _line(worker, 120)
    finally:
        worker.kill()
        worker.wait(10)
    latencies = sorted(result["latencies"][paced // 20 :])  # the first 5% warm the caches up
    if not latencies:
        raise RuntimeError(f"{kind}: no paced sample arrived")
    return {
        "p50_us": round(statistics.median(latencies) * 1e6, 1),
        "p99_us": round(latencies[int(len(latencies) * 0.99) - 1] * 1e6, 1),
        "msgs_per_s": round(result["received"] / result["span_s"]) if result["span_s"] > 0 else 0,
        "received": result["received"] + len(result["latencies"]),
        "sent": paced + total,
    }


def run_pubsub() -> dict[str, Any]:
    """One-way latency and saturated throughput between two processes (§3.1.4), CKMultiPeer then Zenoh."""
    report: dict[str, Any] = {"message_bytes": len(PAYLOAD), "rate_hz": round(1 / PERIOD)}
    for kind, prefix in (("multipeer", "ckm"), ("zenoh", "zenoh")):
        try:
            figures = pubsub_one(kind)
        except (ImportError, RuntimeError, ValueError) as exc:
            figures = {"p50_us": None, "p99_us": None, "msgs_per_s": None, "error": str(exc)}
        for key, value in figures.items():
            report[f"{prefix}_{key}"] = value
    return report


def describe_pubsub(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench pubsub``'s table."""
    rows = []
    for prefix, label in (("ckm", "CKMultiPeer"), ("zenoh", "Zenoh")):
        if result.get(f"{prefix}_error"):
            rows.append((label, f"failed: {result[f'{prefix}_error']}"))
            continue
        rows.append(
            (f"{label} one-way latency p50 / p99", f"{result[f'{prefix}_p50_us']} / {result[f'{prefix}_p99_us']} µs")
        )
        rows.append((f"{label} saturated throughput", f"{result[f'{prefix}_msgs_per_s']} msgs/s"))
    return rows


def run_discovery(peers: int = 10) -> dict[str, Any]:
    """Time from a simultaneous start of ``peers`` processes until every pair is linked."""
    settings = dict(private_settings("multipeer"), count=peers, limit=30)
    workers = [_spawn("peer", settings) for _ in range(peers)]
    try:
        for worker in workers:
            _line(worker, 60)
        go = time.time()
        for worker in workers:
            assert worker.stdin is not None
            worker.stdin.write("go\n")
            worker.stdin.flush()
        reports = [_line(worker, 40) for worker in workers]
        for worker in workers:
            assert worker.stdin is not None
            worker.stdin.write("stop\n")
            worker.stdin.flush()
    finally:
        for worker in workers:
            worker.kill()
            worker.wait(10)
    linked = [r["linked_at"] for r in reports]
    if any(t is None for t in linked):
        return {"peers": peers, "all_connected_s": None, "error": "some peers never linked to all others"}
    return {
        "peers": peers,
        "all_connected_s": round(max(linked) - go, 4),
        "first_connected_s": round(min(linked) - go, 4),
        "start_skew_s": round(max(r["started"] for r in reports) - go, 4),
    }


def describe_discovery(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench discovery``'s table."""
    return [
        ("peers", str(result["peers"])),
        ("all pairs linked after the start signal", f"{result['all_connected_s']} s"),
        ("first peer fully linked", f"{result.get('first_connected_s')} s"),
        ("last peer received the start signal", f"{result.get('start_skew_s')} s"),
    ]
