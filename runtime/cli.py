"""ckm-run CONFIG [--node NAME] [--duration S] [--log-dir DIR]: run the nodes of a configuration.

Without ``--node`` every node runs in this process (the embedded default); with it, just that
node (one process per node, on any machine of the network). SIGINT or SIGTERM stop the run
cleanly: the services stop, every actuator is driven to its safe value, the hardware closes.
The run directory receives the log, the events and each task's statistics.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from ckmconf import ConfigError, load
from ckmconf.model import Network, System

from .kernel.node import NodeRuntime
from .network import open_transport, read_group_key
from .network.api import GroupKeyError
from .network.multipeer import NetworkError

LOG = logging.getLogger("ckm.run")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ckm-run", description="Run the CKM nodes of a configuration.")
    parser.add_argument("config", help="System file")
    parser.add_argument("--node", help="run only this node (default: every node, in this process)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds (default: until a signal)")
    parser.add_argument("--log-dir", type=Path, help="run directory (default: runs/SYSTEM-TIMESTAMP)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        system = load(args.config)
    except ConfigError as error:
        print(error, file=sys.stderr)
        return 1
    nodes = list(system.nodes)
    if args.node is not None:
        nodes = [n for n in nodes if n.name == args.node]
        if not nodes:
            names = ", ".join(n.name for n in system.nodes) or "none"
            print(f"{args.config}: no node {args.node!r} (nodes: {names})", file=sys.stderr)
            return 1
    run_dir = args.log_dir or Path("runs") / f"{system.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    run_dir.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(run_dir / "ckm.log")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logging.getLogger().addHandler(handler)
    logging.getLogger().setLevel(logging.INFO)
    try:
        return _run(system, Path(args.config), nodes, args.duration, run_dir, args.node or system.name)
    finally:
        logging.getLogger().removeHandler(handler)
        handler.close()


def _run(system: System, config: Path, nodes: list[Any], duration: float | None, run_dir: Path, name: str) -> int:
    network = system.network or Network()
    try:
        key = read_group_key(network, config.parent)
        transport = open_transport(network, name=name, key=key)
        transport.setup()
    except (GroupKeyError, NetworkError, OSError, ValueError) as exc:
        print(f"{config}: cannot join the network: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        LOG.info("signal %s: stopping", signal.Signals(signum).name)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    runtimes: list[NodeRuntime] = []
    started = time.time()
    try:
        transport.start()
        for node in nodes:
            runtime = NodeRuntime(node, system, transport)
            runtime.setup()
            runtimes.append(runtime)
        for runtime in runtimes:
            runtime.start()
        LOG.info("running %s (%d node(s)) for %s", system.name, len(runtimes), duration or "ever")
        stop.wait(duration)
    except ConfigError as error:
        print(error, file=sys.stderr)
        return 1
    finally:
        for runtime in reversed(runtimes):
            runtime.stop()
        transport.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _write_run(run_dir, config, system, runtimes, started)
    return 0


def _write_run(run_dir: Path, config: Path, system: System, runtimes: list[NodeRuntime], started: float) -> None:
    summary = {
        "config": str(config),
        "system": system.name,
        "started": started,
        "stopped": time.time(),
        "nodes": {r.node.name: r.statistics() for r in runtimes},
    }
    (run_dir / "stats.json").write_text(json.dumps(summary, indent=2, default=str))
    with (run_dir / "events.jsonl").open("w") as events:
        for runtime in runtimes:
            for event in runtime.events:
                events.write(json.dumps(event, default=str) + "\n")


if __name__ == "__main__":
    sys.exit(main())
