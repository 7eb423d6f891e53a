"""``ckm-ros-bridge SYSTEM.xml``: a running CKM system's ROS-typed topics to and from ROS 2 nodes on
rmw_zenoh (issue L points 3 and 5, thesis §4.4.1: the ROS MultiPeer Architecture; decision D159).

The command joins the system's network as one more peer (``ros-bridge``: CKMultiPeer or Zenoh, the
group key of ``groupKeyFile`` included), opens a Zenoh session as a client of the ROS side's router
(``rmw_zenohd``, ``tcp/localhost:7447`` by default, no multicast scouting, as rmw_zenoh nodes do)
and runs :class:`runtime.ros.bridge.RmwZenohBridge` until ``--duration`` seconds have passed or it
is interrupted (Ctrl-C, SIGTERM). It prints each bridged topic with its rmw_zenoh key expression,
and at the end one JSON line: per topic the samples passed each way and dropped. Exit 0; 1 when the
configuration does not load, names no bridgeable topic, or the network or router cannot be joined.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

import zenoh

from ckmconf import ConfigError, load
from ckmconf.model import Connect, Network, Zenoh

from ..host_network import JoinError, joined
from ..network.zenoh_session import zenoh_config
from .bridge import RmwZenohBridge
from .wire import install

ROUTER = "tcp/localhost:7447"
"""Where ``ros2 run rmw_zenoh_cpp rmw_zenohd`` listens by default."""


def router_session(endpoint: str) -> zenoh.Session:
    """A Zenoh session in client mode connected to the ROS side's router at ``endpoint``."""
    network = Network(
        transport="zenoh", zenoh=Zenoh(mode="client", multicast_scouting=False, connect=(Connect(endpoint=endpoint),))
    )
    return zenoh.open(zenoh_config(network))


def main(argv: Sequence[str] | None = None) -> int:
    """``ckm-ros-bridge SYSTEM.xml [--router E] [--domain N] [--topics A,B] [--duration S]``."""
    parser = argparse.ArgumentParser(
        prog="ckm-ros-bridge", description="Bridge a CKM system's ROS 2-typed topics to rmw_zenoh nodes."
    )
    parser.add_argument("config", type=Path, help="the system whose network and topics are bridged")
    parser.add_argument("--router", default=ROUTER, help=f"the rmw_zenohd endpoint (default {ROUTER})")
    parser.add_argument("--domain", type=int, default=0, help="the ROS domain id (ROS_DOMAIN_ID, default 0)")
    parser.add_argument("--topics", help="comma-separated topics (default: every external topic of a ROS 2 type)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds (default: until interrupted)")
    parser.add_argument(
        "--attachment", choices=("compact", "labelled"), default="compact",
        help="33-byte attachment of current rmw_zenoh (default) or the labelled one of Jazzy 0.2.3 and earlier",
    )
    args = parser.parse_args(argv)
    try:
        system = load(args.config)
        topics = [t.strip() for t in args.topics.split(",") if t.strip()] if args.topics else None
        with joined(system.network or Network(), "ros-bridge", key_dir=args.config.resolve().parent) as transport:
            install(transport, system)  # ROS-typed topics as CDR on the CKM side too, as ckm-run sends them (D157)
            bridge = RmwZenohBridge(
                system, transport, topics=topics, domain_id=args.domain, attachment=args.attachment
            )
            if not bridge.topics:
                print(f"{args.config}: no external topic of a ROS 2 type to bridge", file=sys.stderr)
                return 1
            session = router_session(args.router)
            try:
                bridge.start(session)
                for name, bridged in bridge.topics.items():
                    print(f"bridging {name} [{bridged.topic.type}] as {bridged.keyexpr}", flush=True)
                _wait(args.duration)
                bridge.stop()
            finally:
                session.close()  # type: ignore[no-untyped-call]
            print(json.dumps(bridge.statistics()), flush=True)
    except (ConfigError, JoinError, ValueError, zenoh.ZError) as error:
        print(f"{args.config}: {error}", file=sys.stderr)
        return 1
    return 0


def _wait(duration: float | None) -> None:
    """Until ``duration`` seconds have passed, or SIGINT / SIGTERM."""
    done = threading.Event()

    def stop(signum: int, frame: FrameType | None) -> None:
        done.set()

    previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        done.wait(duration)
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


if __name__ == "__main__":
    sys.exit(main())
