"""ckm-bench soak [--minutes M] [--warmup S]: nodes at the use case's rates for M minutes; memory at the start and end.

The use case's nodes need the simulation's backends, so the soak runs a loopback system of the
same shape (issue G, decision D66): for every node of ``configs/usecase/lab.xml`` with hardware,
as many loopback sensors at the same periods, a relay controller at each controller's period,
as many actuators, and a monitor at the node's monitor period with jitter, deadline-miss,
staleness and CPU alarms. Each node runs in its own real ``ckm-run --node`` process on a private
loopback network, all writing into one run directory, so the statistics and events files that
are rewritten and appended while running are part of what is measured.

Resident memory (RSS) of every process of the run is summed every few seconds. ``rss_start_mb``
is taken once the warm-up (default: the first minute) is over, ``rss_end_mb`` at the end,
``rss_peak_mb`` is the largest sum seen; the target is an end within a few MB of the start.
"""

from __future__ import annotations

import argparse
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil

from ckmconf import load
from ckmconf.model import Node
from runtime.network.ports import private_base

REPO = Path(__file__).resolve().parents[1]
USE_CASE = REPO / "configs" / "usecase" / "lab.xml"
SAMPLE_EVERY = 5.0  # seconds between memory samples


def _node_xml(node: Node) -> str:
    """A loopback node with the shape and rates of ``node``."""
    name = node.name
    lines = [f'  <Node name="{name}" kind="service">']
    sensors = [(f"s{i}", s.period) for i, s in enumerate(node.sensors)]
    actuators = [f"a{i}" for i in range(len(node.actuators))]
    channels = [(f"in{i}", "in") for i in range(len(sensors))] + [(f"out{i}", "out") for i in range(len(actuators))]
    for channel, direction in channels:
        bounds = ' min="-1" max="1"' if direction == "out" else ""
        lines.append(f'    <HWChannel name="{channel}" direction="{direction}" kind="analog"{bounds}/>')
    topics = [f"/{name}/{s}" for s, _ in sensors] + [f"/{name}/cmd{i}" for i in range(len(node.controllers))]
    lines += [f'    <Topic name="{t}" type="float64"/>' for t in topics]
    for i, (sensor, period) in enumerate(sensors):
        lines.append(f'    <Sensor name="{sensor}" channel="in{i}" topic="/{name}/{sensor}" period="{period}"/>')
    for i, controller in enumerate(node.controllers):
        source = f"/{name}/{sensors[i % len(sensors)][0]}"
        lines.append(f'    <Controller name="c{i}" kind="relay" period="{controller.period}">')
        lines.append(f'      <Input topic="{source}"/>\n      <Output topic="/{name}/cmd{i}"/>\n    </Controller>')
    for i, actuator in enumerate(actuators):
        command = f"/{name}/cmd{i % max(1, len(node.controllers))}"
        lines.append(
            f'    <Actuator name="{actuator}" channel="out{i}" topic="{command}" min="-1" max="1" safeValue="0"/>'
        )
    period = node.monitor.period if node.monitor is not None else 0.5
    lines.append(f'    <Monitor period="{period}">')
    lines.append('      <Alarm name="cpu" measure="cpu" above="0.99" hold="5"/>')
    if node.controllers:
        lines.append('      <Alarm name="jitter" measure="jitter" task="c0" above="0.005"/>')
        lines.append('      <Alarm name="misses" measure="deadline-misses" task="c0" above="10"/>')
    if sensors:
        lines.append(f'      <Alarm name="stale" measure="staleness" topic="/{name}/s0" above="1"/>')
    lines.append("    </Monitor>\n  </Node>")
    return "\n".join(lines)


def system_xml(source: Path = USE_CASE) -> tuple[str, list[str]]:
    """The loopback system of ``source``'s shape (nodes with sensors only) and its node names."""
    nodes = [n for n in load(source).nodes if n.sensors]
    rng = random.Random()
    base = private_base(rng)
    network = (
        f'  <Network transport="multipeer" group="239.255.{rng.randrange(1, 255)}.{rng.randrange(1, 255)}" '
        f'discoveryPort="{base + 63}" interface="127.0.0.1" basePort="{base}" portTries="40"/>'
    )
    body = "\n".join(_node_xml(n) for n in nodes)
    text = '<?xml version="1.0" encoding="UTF-8"?>\n<System xmlns="urn:ckm:1" version="1.0" name="soak">\n'
    return text + f"{network}\n{body}\n</System>\n", [n.name for n in nodes]


def _rss_mb(processes: list[psutil.Process]) -> float:
    total = 0
    for process in processes:
        try:
            total += process.memory_info().rss
            total += sum(child.memory_info().rss for child in process.children(recursive=True))
        except psutil.Error:
            continue
    return total / (1 << 20)


def _per_minute(samples: list[tuple[float, float]]) -> list[float]:
    """The first sample of each minute (MB)."""
    firsts: dict[int, float] = {}
    for t, rss in samples:
        firsts.setdefault(int(t // 60), round(rss, 1))
    return list(firsts.values())


def run(argv: Sequence[str] | None = None) -> dict[str, Any]:
    """Run the soak; the figures (MB) and the processes' exit codes."""
    parser = argparse.ArgumentParser(prog="ckm-bench soak", description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="how long the nodes run (default 10)")
    parser.add_argument(
        "--warmup", type=float, help="seconds before rss_start_mb is taken (default: 60, at most a third of the run)"
    )
    args = parser.parse_args(list(argv or []))
    duration = args.minutes * 60
    warmup = args.warmup if args.warmup is not None else min(60.0, duration / 3)
    with tempfile.TemporaryDirectory(prefix="ckm-soak-") as folder:
        text, names = system_xml()
        config = Path(folder) / "soak.xml"
        config.write_text(text)
        command = [sys.executable, "-m", "runtime.cli", str(config), "--log-dir", str(Path(folder) / "run")]
        popens = [
            subprocess.Popen([*command, "--node", n], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for n in names
        ]
        processes = [psutil.Process(p.pid) for p in popens]
        samples: list[tuple[float, float]] = []
        started = time.monotonic()
        try:
            while (now := time.monotonic() - started) < duration and all(p.poll() is None for p in popens):
                samples.append((now, _rss_mb(processes)))
                time.sleep(min(SAMPLE_EVERY, max(0.0, duration - now)))
            samples.append((time.monotonic() - started, _rss_mb(processes)))
        finally:
            for popen in popens:
                if popen.poll() is None:
                    popen.send_signal(signal.SIGTERM)
            codes = [popen.wait(60) for popen in popens]
    after = [rss for t, rss in samples if t >= warmup] or [samples[-1][1]]
    start, end = after[0], samples[-1][1]
    return {
        "minutes": round(samples[-1][0] / 60, 2),
        "nodes": names,
        "rss_start_mb": round(start, 1),
        "rss_end_mb": round(end, 1),
        "rss_peak_mb": round(max(rss for _, rss in samples), 1),
        "growth_mb": round(end - start, 1),
        "samples": len(samples),
        "rss_per_minute_mb": _per_minute(samples),  # the trend: flat, or still climbing?
        "exit_codes": dict(zip(names, codes, strict=True)),
    }


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of ``ckm-bench soak``'s table."""
    return [
        ("minutes", f"{result['minutes']:g}"),
        ("nodes (one process each)", ", ".join(result["nodes"])),
        ("RSS after the warm-up", f"{result['rss_start_mb']:.1f} MB"),
        ("RSS at the end", f"{result['rss_end_mb']:.1f} MB"),
        ("RSS peak", f"{result['rss_peak_mb']:.1f} MB"),
        ("growth", f"{result['growth_mb']:+.1f} MB"),
        ("exit codes", ", ".join(f"{k}={v}" for k, v in result["exit_codes"].items())),
    ]
