"""The world server's cost (issue J point 5, D103): ``python -m benchmarks.sim_server [--json]``.

The use case's world (configs/usecase/lab.xml: environment, turtlebot and nao placed by nodes.xml)
is served by a world server process and, for comparison, built in this process; the same devices
are read both ways, as a ``hardware.sim`` channel reads them (world synced to real time, the read
flattened into the channel's tuple):

- ``round_trip_ms``: per device (a wheel encoder, the 683-beam Hokuyo, the Xtion RGB and depth at
  VGA and QVGA), the mean time of one read through the server and in process, and the difference.
- ``blocking``: a wheel-encoder client reading as fast as it can while another client asks for
  VGA RGB frames back to back: the wheel read's median, 99th percentile and worst time, with and
  without the renders; with the render worker (the default, D103) and with the renders made in the
  server's physics thread (``--render-workers 0``), where a render delays every other request.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ckmconf
from plugins.hardware.sim import SimBackend
from plugins.sim.client import Link, RemoteDevice
from plugins.sim.devices import ChannelDevice, SimWorld, Spec, to_value
from plugins.sim.plan import WorldPlan
from plugins.sim.session import ServerProcess

LAB = Path(__file__).resolve().parent.parent / "configs" / "usecase" / "lab.xml"
NODES = ("kobuki", "turtlebot", "nao")
READS = {"wheel": 400, "lidar": 50, "rgb VGA": 4, "depth VGA": 4, "rgb QVGA": 10, "depth QVGA": 10}


def _specs() -> dict[str, Spec]:
    """The measured devices' specs, from the use case's channels (QVGA: the same camera, resized)."""
    nodes = [n for n in ckmconf.load(LAB).nodes if n.name in NODES]
    channels = {ch.name: ch for node in nodes for ch in node.channels if ch.backend == "sim"}
    spec = {name: SimBackend(channels[name]).spec() for name in ("left_encoder", "hokuyo", "xtion_rgb", "xtion_depth")}

    def resized(base: Spec, width: int, height: int, depth: int) -> Spec:
        values = {**base.values, "width": width, "height": height}
        return dataclasses.replace(base, size=width * height * depth, values=values)

    return {
        "wheel": spec["left_encoder"], "lidar": spec["hokuyo"],
        "rgb VGA": spec["xtion_rgb"], "depth VGA": spec["xtion_depth"],
        "rgb QVGA": resized(spec["xtion_rgb"], 320, 240, 3), "depth QVGA": resized(spec["xtion_depth"], 320, 240, 1),
    }


def _mean_ms(read: Callable[[], Any], count: int) -> float:
    read()  # the first read may build caches (a camera's first frame)
    start = time.perf_counter()
    for _ in range(count):
        read()
    return 1000 * (time.perf_counter() - start) / count


def _round_trips(
    server: ServerProcess, specs: dict[str, Spec], rounds: int = 3, reads: dict[str, int] | None = None
) -> dict[str, dict[str, float]]:
    """Mean read time of each device through ``server`` and in this process, measured in alternate
    rounds (the machine is shared: its load drifts), the median round of each kept."""
    plan = WorldPlan.of([n for n in ckmconf.load(LAB).nodes if n.name in NODES])
    assert plan is not None
    sim: SimWorld = plan.build()
    result = {}
    counts = reads or READS
    for name, spec in specs.items():
        device = ChannelDevice(sim, spec)
        remote = RemoteDevice(server.client_address(), spec)

        def here(device: ChannelDevice = device) -> Any:
            with sim.lock:
                sim.sync()
                return to_value(device.read())

        def there(remote: RemoteDevice = remote) -> Any:
            return to_value(remote.read())

        local, served = [], []
        for _ in range(rounds):
            local.append(_mean_ms(here, counts[name]))
            served.append(_mean_ms(there, counts[name]))
        remote.close()
        middle_local, middle_served = statistics.median(local), statistics.median(served)
        result[name] = {"server_ms": round(middle_served, 3), "in_process_ms": round(middle_local, 3),
                        "overhead_ms": round(middle_served - middle_local, 3)}
    sim.world.close()
    return result


def _latencies(read: Callable[[], Any], seconds: float) -> list[float]:
    times = []
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        start = time.perf_counter()
        read()
        times.append(1000 * (time.perf_counter() - start))
    return times


def _figures(times: list[float]) -> dict[str, float]:
    ordered = sorted(times)
    return {
        "reads": len(ordered), "median_ms": round(statistics.median(ordered), 3),
        "p99_ms": round(ordered[int(0.99 * (len(ordered) - 1))], 3), "max_ms": round(ordered[-1], 3),
    }


def _blocking(server: ServerProcess, specs: dict[str, Spec], seconds: float) -> dict[str, Any]:
    wheel = RemoteDevice(server.client_address(), specs["wheel"])
    camera = Link(server.client_address())
    handle = camera.request({"op": "open", "spec": specs["rgb VGA"].to_dict()})["handle"]
    alone = _figures(_latencies(wheel.read, seconds))
    renders: list[float] = []
    rendering = threading.Event()

    def frames() -> None:  # raw replies: no flattening in this process, which would hold the GIL
        while not rendering.is_set():
            start = time.perf_counter()
            camera.request({"op": "read", "handle": handle})
            renders.append(1000 * (time.perf_counter() - start))

    thread = threading.Thread(target=frames, daemon=True)
    thread.start()
    loaded = _figures(_latencies(wheel.read, seconds))
    rendering.set()
    thread.join(10.0)
    wheel.close()
    camera.close()
    return {"alone": alone, "with_vga_renders": loaded, "render_ms": round(statistics.mean(renders), 2)}


def run(argv: list[str] | None = None) -> dict[str, Any]:
    """Measure the world server's round trips and blocking (``--seconds``, ``--quick``), see the module docstring."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.sim_server", description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="length of each blocking measurement")
    parser.add_argument("--quick", action="store_true", help="one round of one read per device (a smoke test)")
    args = parser.parse_args(argv)
    specs = _specs()
    with tempfile.TemporaryDirectory() as folder, ServerProcess(LAB, Path(folder), NODES) as server:
        if args.quick:
            trips = _round_trips(server, specs, rounds=1, reads=dict.fromkeys(READS, 1))
        else:
            trips = _round_trips(server, specs)
        blocking = _blocking(server, specs, args.seconds)
    with tempfile.TemporaryDirectory() as folder, ServerProcess(LAB, Path(folder), NODES,
                                                                options=["--render-workers", "0"]) as server:
        in_thread = _blocking(server, specs, args.seconds)
    return {"round_trip_ms": trips, "blocking": blocking, "blocking_without_worker": in_thread}


def describe(result: dict[str, Any]) -> list[tuple[str, str]]:
    """The rows of the world server benchmark's table."""
    rows = [
        (f"{name} read", f"{row['server_ms']:.3f} ms via server, {row['in_process_ms']:.3f} ms in process")
        for name, row in result["round_trip_ms"].items()
    ]
    for how, name in (("render worker", "blocking"), ("renders in the physics thread", "blocking_without_worker")):
        block = result[name]
        for label, key in (("wheel read alone", "alone"), ("wheel read during VGA renders", "with_vga_renders")):
            f = block[key]
            rows.append((f"{label} ({how})", f"median {f['median_ms']} ms, p99 {f['p99_ms']} ms, max {f['max_ms']} ms"))
        rows.append((f"VGA render through the server ({how})", f"{block['render_ms']} ms"))
    return rows


if __name__ == "__main__":
    arguments = sys.argv[1:]
    as_json = "--json" in arguments
    outcome = run([a for a in arguments if a != "--json"])
    for label, value in describe(outcome):
        print(f"{label:58s} {value}")
    if as_json:
        print(json.dumps(outcome))
