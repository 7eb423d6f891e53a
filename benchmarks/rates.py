"""ckm-bench rates: the Table 7.8 measurement — remote services' rates and transport delays.

A "remote device" OS process (``benchmarks.rates_worker``) hosts the three services of the
thesis's cooperation experiment, each a periodic kernel task publishing over CKMultiPeer on
loopback: Pan-Tilt Camera every 0.5 s, Navigation and Global Recog. every 0.8 s. This process
subscribes to the three topics and records, per service, the inter-arrival periods (on its own
receive clock: what a consumer of the service sees) and the transport delays (``Sample.age``,
which corrects the publisher's stamp by the SYNCTIME clock offset; the raw same-host
``received - stamp`` is kept for comparison). The first sample of each service is discarded
(connection warm-up). The thesis's figures are reported next to ours.
"""

from __future__ import annotations

import itertools
import json
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Mapping
from typing import Any

from runtime.host_network import joined
from runtime.network import Sample

from .netbench import _line, private_settings
from .networker import network_from
from .rates_worker import SERVICES, payload_bytes, qos

#: Set rates (periods, seconds) of Table 7.8.
SET_RATES: dict[str, float] = {"Pan-Tilt Camera": 0.5, "Navigation": 0.8, "Global Recog.": 0.8}

#: Table 7.8 as printed: avg. transport delay, its std. deviation, avg. rate, rate std. deviation (s).
THESIS: dict[str, dict[str, float]] = {
    "Pan-Tilt Camera": {"avg_delay_s": 0.0047, "delay_std_s": 0.0039, "avg_rate_s": 0.5637, "rate_std_s": 0.7365},
    "Navigation": {"avg_delay_s": 0.0057, "delay_std_s": 0.0055, "avg_rate_s": 0.8002, "rate_std_s": 0.094},
    "Global Recog.": {"avg_delay_s": 0.0033, "delay_std_s": 0.0057, "avg_rate_s": 0.847, "rate_std_s": 0.1412},
}

RATE_STD_TARGET_S = 0.001  # issue 4, item 12
SETTLE_S = 0.5  # SYNCTIME settling time before the services start


def _spawn_device(settings: dict[str, Any]) -> subprocess.Popen[str]:
    command = [sys.executable, "-m", "benchmarks.rates_worker", json.dumps(settings)]
    return subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)


def _mean_std(values: list[float]) -> tuple[float | None, float | None]:
    if not values:
        return None, None
    return statistics.fmean(values), statistics.stdev(values) if len(values) > 1 else 0.0


def _round(value: float | None, digits: int = 6) -> float | None:
    return None if value is None else round(value, digits)


def _figures(name: str, set_rate: float, samples: list[Sample], warmup: int) -> dict[str, Any]:
    kept = samples[warmup:]
    received = [s.received for s in kept]
    stamps = [s.stamp for s in kept]
    periods = [b - a for a, b in itertools.pairwise(received)]
    publish_periods = [b - a for a, b in itertools.pairwise(stamps)]
    avg_rate, rate_std = _mean_std(periods)
    pub_rate, pub_std = _mean_std(publish_periods)
    avg_delay, delay_std = _mean_std([s.age for s in kept])
    raw_delay, raw_std = _mean_std([s.received - s.stamp for s in kept])
    seqs = [s.value["seq"] for s in kept if isinstance(s.value, dict) and isinstance(s.value.get("seq"), int)]
    lost = (max(seqs) - min(seqs) + 1 - len(seqs)) if seqs else 0
    thesis = THESIS.get(name, {})
    return {
        "name": name,
        "topic": SERVICES[name][0],
        "payload_bytes": payload_bytes(name),
        "set_rate_s": set_rate,
        "samples": len(kept),
        "discarded": len(samples) - len(kept),
        "lost": lost,
        "avg_rate_s": _round(avg_rate),
        "rate_std_s": _round(rate_std),
        "min_period_s": _round(min(periods)) if periods else None,
        "max_period_s": _round(max(periods)) if periods else None,
        "publish_avg_rate_s": _round(pub_rate),
        "publish_rate_std_s": _round(pub_std),
        "avg_delay_s": _round(avg_delay),
        "delay_std_s": _round(delay_std),
        "raw_avg_delay_s": _round(raw_delay),
        "raw_delay_std_s": _round(raw_std),
        "clock_offset_s": _round(kept[-1].offset, 9) if kept else None,
        "rate_std_within_target": rate_std is not None and rate_std <= RATE_STD_TARGET_S,
        "thesis_avg_rate_s": thesis.get("avg_rate_s"),
        "thesis_rate_std_s": thesis.get("rate_std_s"),
        "thesis_avg_delay_s": thesis.get("avg_delay_s"),
        "thesis_delay_std_s": thesis.get("delay_std_s"),
    }


def run(duration: float = 30.0, *, periods: Mapping[str, float] | None = None, warmup: int = 1) -> dict[str, Any]:
    """Measure the services' rates and delays for ``duration`` seconds.

    Args:
        duration: how long the remote device publishes, in seconds.
        periods: set rates per service name (defaults to Table 7.8's); tests pass faster ones.
        warmup: samples discarded at the start of each service (connection warm-up).
    """
    set_rates = dict(SET_RATES if periods is None else periods)
    unknown = sorted(set(set_rates) - set(SERVICES))
    if unknown:
        raise ValueError(f"unknown services {unknown}; known: {sorted(SERVICES)}")
    settings = private_settings("multipeer")
    lock = threading.Lock()
    collected: dict[str, list[Sample]] = {name: [] for name in set_rates}

    def recorder(name: str) -> Any:
        def on_sample(sample: Sample) -> None:
            with lock:
                collected[name].append(sample)

        return on_sample

    with joined(network_from(dict(settings)), "bench-rates") as transport:  # the host's way onto the network
        for name in set_rates:
            transport.subscribe(qos(name), recorder(name))
        device_settings = dict(settings, periods=set_rates, duration=duration, settle=SETTLE_S, limit=30.0)
        device = _spawn_device(device_settings)
        try:
            started = _line(device, 60)
            if "error" in started:
                raise RuntimeError(f"remote device: {started['error']}")
            report = _line(device, duration + 30)
            if "error" in report:
                raise RuntimeError(f"remote device: {report['error']}")
            time.sleep(0.1)  # the last frames are already on loopback; let the receiver deliver them
        finally:
            device.kill()
            device.wait(10)
    with lock:
        samples = {name: list(values) for name, values in collected.items()}
    services = [_figures(name, set_rates[name], samples[name], warmup) for name in set_rates]
    scheduler = report.get("statistics", {})
    for service in services:
        stats = scheduler.get(service["name"], {})
        service["published"] = report.get("published", {}).get(service["name"])
        service["release_jitter_p99_us"] = stats.get("jitter_p99_us")
        service["release_misses"] = stats.get("misses")
    return {
        "duration_s": duration,
        "transport": "multipeer",
        "warmup_discarded": warmup,
        "rate_std_target_s": RATE_STD_TARGET_S,
        "services": services,
    }


def _ms(value: float | None) -> str:
    return "—" if value is None else f"{value * 1e3:.2f}"


def _s(value: float | None) -> str:
    return "—" if value is None else f"{value:.4f}"


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench rates``'s table: each service's figures next to the thesis' (Table 7.8)."""
    rows: list[tuple[str, str]] = [
        ("remote device", f"1 process, 3 kernel tasks, CKMultiPeer on loopback, {result['duration_s']} s"),
        ("columns", "ours | thesis (Table 7.8)"),
    ]
    for s in result["services"]:
        name = s["name"]
        rows.append((f"{name}: set rate", f"{s['set_rate_s']} s ({s['samples']} samples, {s['lost']} lost)"))
        rows.append(
            (
                f"{name}: avg. rate / std. deviation",
                f"{_s(s['avg_rate_s'])} s / {_ms(s['rate_std_s'])} ms | "
                f"{_s(s['thesis_avg_rate_s'])} s / {_ms(s['thesis_rate_std_s'])} ms",
            )
        )
        rows.append(
            (
                f"{name}: avg. transport delay / std.",
                f"{_ms(s['avg_delay_s'])} / {_ms(s['delay_std_s'])} ms | "
                f"{_ms(s['thesis_avg_delay_s'])} / {_ms(s['thesis_delay_std_s'])} ms",
            )
        )
        rows.append(
            (
                f"{name}: raw received − stamp",
                f"{_ms(s['raw_avg_delay_s'])} / {_ms(s['raw_delay_std_s'])} ms (offset {_ms(s['clock_offset_s'])} ms)",
            )
        )
    return rows
