"""ckm-run CONFIG [--node NAME [--partition PART]] [--plan PLAN] [--duration S] [--log-dir DIR]: run a configuration.

Without ``--node`` every node runs in this process (the embedded default); with it, just that
node (one process per node, on any machine of the network). A node with partitions (§3.1.3.2)
runs its unpartitioned components and its monitor here and each partition as a child process
(``--partition``), supervised and restarted on its own, logging to RUN_DIR/PART (RUN_DIR/NODE/PART
when several nodes run). SIGINT or SIGTERM stop the run cleanly: the partitions stop, the
services stop, every actuator is driven to its safe value, the hardware closes. The run
directory receives the log, the events and each task's statistics. That lifecycle is the host's
(:mod:`runtime.host`); this module adds what is ckm-run's own: its arguments, the check before
anything starts, ``--record``, a partition's memory budget and the plans' agents.

With ``--plan`` the agents of that plan whose node runs here run their missions too (§5.3),
recording them in the run directory (``ckm-mission report RUN_DIR``); the run then also ends when
every local agent's mission has ended.

``ckm-run --await-config [NETWORK.xml] --name AGENT`` runs no configuration: it joins the network
of NETWORK.xml (a System or Part holding a <Network>; the default Network without it), announces
itself and runs whatever node the editor pushes it (runtime.distribution).

Exit codes (docs/exit-codes.md): 0 the run went as configured; 1 the configuration was refused
(load, ``verify``, build), each problem printed as ``FILE:LINE:COL: …``; 2 a usage error; 3 a
partition over its memory budget (partition processes only); 4 the network could not be joined;
5 something failed while running (a partition crashed or could not build, a task raised); 6 a
plan's agent did not end in its mission's success final (gave up, crashed, stopped). Each
failure's first error is printed on stderr; with several, the lowest code wins.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from ckmconf import ConfigError, load
from ckmconf.model import Network, Node, Partition, System

from . import lockstep, simtime
from .distribution import NAME, run_agent
from .host import Host, stop_on_signals
from .host_network import PORTS_VARIABLE, JoinError, Namesakes, parse_ports, with_ports
from .kernel.partitions import MEMORY_EXIT, MemoryWatch, enter_partition
from .kernel.runlog import RunLog
from .missions.agent import AgentRunner
from .network import NetworkEvent, Transport
from .ros.recording import RECORD_FORMATS, RecordingError, RunRecorder
from .runrecord import EXIT_AGENTS as EXIT_AGENTS  # the exit codes, re-exported for callers
from .runrecord import EXIT_CONFIG as EXIT_CONFIG
from .runrecord import EXIT_FAILED as EXIT_FAILED
from .runrecord import EXIT_NETWORK as EXIT_NETWORK
from .verification.verify import verify_or_report

LOG = logging.getLogger("ckm.run")
STATS_EVERY = 2.0  # seconds between rewrites of the statistics file while running


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="ckm-run", description="Run the CKM nodes of a configuration.")
    parser.add_argument("config", nargs="?", help="System file (with --await-config: the bootstrap network file)")
    parser.add_argument("--node", help="run only this node (default: every node, in this process)")
    parser.add_argument("--partition", help="with --node: run only this partition of the node (as its supervisor does)")
    parser.add_argument("--duration", type=float, help="stop after this many seconds (default: until a signal)")
    parser.add_argument("--log-dir", type=Path, help="run directory (default: runs/SYSTEM-TIMESTAMP)")
    parser.add_argument("--plan", help="also run this plan's agents whose node runs here")
    parser.add_argument("--ports", nargs=2, metavar=("DISCOVERY", "BASE"),
                        help="run on these network ports instead of the <Network>'s discoveryPort and basePort: a "
                        "second run of one system beside the first (D258)")
    parser.add_argument(
        "--await-config", action="store_true", help="run no configuration: announce an agent and wait for pushes"
    )
    parser.add_argument("--name", help="with --await-config: the agent's name (default: the host name)")
    parser.add_argument(
        "--record",
        metavar="TOPICS",
        help="record these topics (comma-separated, or 'all') as a rosbag2 bag (run dir); NAME@HZ records at most "
        "HZ messages a second, NAME:jpeg (or :png) an image topic as CompressedImage on BAG_NAME/compressed: "
        "/nao/camera/image@0.5:jpeg (runtime.ros.sparse, D197)",
    )
    parser.add_argument(
        "--record-format", choices=RECORD_FORMATS, default="mcap", help="storage of the --record bag (default: mcap)"
    )
    parser.add_argument(
        "--time-scale", metavar="S", help="run every process on a clock S (0 < S <= 1) times the wall clock's "
        "speed, as on a machine 1/S times faster (runtime.simtime; default: the wall clock)",
    )
    parser.add_argument(
        "--lockstep", metavar="STEP", type=float, help="run every process on a simulated clock that moves (by at "
        "most STEP seconds at a time) only when every task waits: as fast as the machine allows, the same result "
        "under any load (runtime.lockstep, D190)",
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``ckm-run``: parse ``argv`` (default: the command line), run, return the exit code (docs/exit-codes.md)."""
    parser = _parser()
    args = parser.parse_args(argv)
    if args.await_config:
        return _await_config(parser, args)
    if args.config is None:
        parser.error("the following arguments are required: config")
    if args.name is not None:
        parser.error("--name goes with --await-config")
    if args.ports is not None:  # in the environment: the run's partitions and a lock-step re-start inherit it
        try:
            os.environ[PORTS_VARIABLE] = "{} {}".format(*parse_ports(" ".join(args.ports), "--ports"))
        except ValueError as error:
            parser.error(str(error))
    if args.lockstep is not None and args.time_scale is not None:
        parser.error("--lockstep and --time-scale exclude each other")
    if args.lockstep is not None and args.node is not None and lockstep.active() is None:
        parser.error("--lockstep runs every node in one ckm-run (their partitions share its clock); a --node run "
                     "has no clock to share with the other nodes' processes")
    if args.lockstep is not None and lockstep.active() is None:  # start again on the run's clock (as below)
        try:
            os.environ.update(lockstep.create(args.lockstep, Path(tempfile.mkdtemp(prefix="ckm-lockstep-"))))
        except ValueError as error:
            parser.error(f"--lockstep: {error}")
        os.execv(sys.executable, [sys.executable, "-m", "runtime.cli", *(sys.argv[1:] if argv is None else argv)])
    if args.time_scale is not None:
        try:
            scale = simtime.parse_scale(args.time_scale)
        except ValueError as error:
            parser.error(f"--time-scale: {error}")
        if simtime.scale() != scale:  # every clock of the process (default arguments too) must be the scaled one:
            os.environ.update(simtime.environment(scale))  # start again on it; partitions and the world inherit it
            os.execv(sys.executable, [sys.executable, "-m", "runtime.cli", *(sys.argv[1:] if argv is None else argv)])
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
    partition: Partition | None = None
    if args.partition is not None:
        if args.node is None:
            parser.error("--partition needs --node")
        partition = next((p for p in nodes[0].partitions if p.name == args.partition), None)
        if partition is None:
            names = ", ".join(p.name for p in nodes[0].partitions) or "none"
            print(f"{args.config}: no partition {args.partition!r} (partitions: {names})", file=sys.stderr)
            return 1
        enter_partition(partition)  # first: tie this process to its supervisor
    if partition is None:  # a partition's supervisor verified the system before starting it
        refused = verify_or_report(system, args.config)
        if refused is not None:
            return refused
    if args.plan is not None and system.plan(args.plan) is None:
        names = ", ".join(p.name for p in system.plans) or "none"
        print(f"{args.config}: no plan {args.plan!r} (plans: {names})", file=sys.stderr)
        return 1
    run_dir = args.log_dir or Path("runs") / f"{system.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    label = f"{args.node}.{args.partition}" if partition is not None else args.node
    record_args = (args.record, args.record_format)
    try:  # every --record problem before anything starts (runtime.ros.recording)
        recorder = None if args.record is None else RunRecorder.in_run(system, nodes, run_dir, label, *record_args)
    except RecordingError as error:
        print(f"{args.config}: {error}", file=sys.stderr)
        return 1
    with _logging_to(run_dir):
        name = f"{args.node}.{args.partition}" if partition is not None else args.node or system.name
        # Several `--node` processes may share a run directory: each keeps its own files (D64).
        run_log = RunLog(run_dir, shared_as=args.node if args.node is not None and partition is None else None)
        try:
            return _run(system, Path(args.config), nodes, args.duration, run_log, name, partition, args.plan, recorder)
        finally:
            run_log.close()


@contextlib.contextmanager
def _logging_to(run_dir: Path) -> Iterator[None]:
    """Log to RUN_DIR/ckm.log while the run lasts."""
    run_dir.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(run_dir / "ckm.log")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    logging.getLogger().addHandler(handler)
    logging.getLogger().setLevel(logging.INFO)
    try:
        yield
    finally:
        logging.getLogger().removeHandler(handler)
        handler.close()


def _await_config(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """ckm-run --await-config: a node agent waiting for the editor's configurations."""
    for option in ("node", "partition", "plan"):
        if getattr(args, option) is not None:
            parser.error(f"--{option} cannot go with --await-config (the editor chooses the node)")
    name = args.name or socket.gethostname().split(".")[0]
    if not NAME.fullmatch(name):
        parser.error(f"agent name {name!r}: use 1-64 letters, digits, '_', '.' or '-'")
    run_dir = args.log_dir or Path("runs") / f"agent-{name}-{time.strftime('%Y%m%d-%H%M%S')}"
    with _logging_to(run_dir):
        return run_agent(Path(args.config) if args.config else None, name, run_dir, args.duration)


def _run(
    system: System,
    config: Path,
    nodes: list[Node],
    duration: float | None,
    run_log: RunLog,
    name: str,
    partition: Partition | None,
    plan: str | None = None,
    recorder: RunRecorder | None = None,
) -> int:
    host = Host(system, config, run_log.run_dir)
    namesakes = Namesakes(name, with_ports(system.network or Network()))

    def network_event(event: NetworkEvent) -> None:
        _network_event(run_log, event)
        namesakes.heard(event)

    try:
        transport = host.join(name, network_event)
    except JoinError as exc:
        print(f"{config}: {exc}", file=sys.stderr)
        return EXIT_NETWORK
    agents: list[_Agent] = []
    memory: MemoryWatch | None = None

    def extra() -> dict[str, Any]:
        record = {"recording": recorder.statistics()} if recorder is not None else {}
        if partition is None:
            return record
        return {"partition": partition.name, "memory": memory.statistics() if memory else None, **record}

    if recorder is not None:  # after the nodes' last samples, before the transport goes
        host.on_stop("finish the recording", recorder.stop)
    with stop_on_signals(host.stopping):
        try:
            host.start_sessions(nodes)  # before any node is built or partition started (runtime.sessions)
            transport.start()
            namesakes.listening()
            if recorder is not None:  # subscribed before any node publishes
                recorder.start(transport)
            for node in nodes:
                host.build(node, transport, partition=partition, several=len(nodes) > 1, sinks=[run_log.event])
            # a namesake heard within ms of joining: refused before any node runs (D257); a partition's own
            # process is started by a run that checked already, and its restart must not wait
            if partition is None and (clash := namesakes.clash()) is not None:
                print(f"{config}: {clash}", file=sys.stderr)
                return EXIT_NETWORK
            host.start()
            if partition is not None:  # its memory budget counts from the runtime it started with

                def over_budget(used: int, limit: int) -> None:
                    LOG.error("partition %s: %d MiB over its memory budget: stopping", partition.name,
                              (used - limit) >> 20)
                    host.fail(MEMORY_EXIT)

                memory = MemoryWatch(partition, over_budget)
            LOG.info("running %s (%d node(s)) for %s", system.name, len(host.runtimes), duration or "ever")
            if plan and partition is None:
                agents = _start_agents(system, plan, nodes, transport, run_log.run_dir)
            # kept current: a SIGKILL loses at most STATS_EVERY
            keep = (STATS_EVERY, lambda: host.keep_statistics(run_log, extra()))
            host.wait(duration, done=lambda: bool(agents) and all(not a.thread.is_alive() for a in agents), every=keep)
            for agent in agents:
                agent.runner.stop()
                agent.thread.join(5.0)
        except ConfigError as error:
            print(error, file=sys.stderr)
            return EXIT_CONFIG
        except Exception as exc:  # a backend's own failure at set-up: reported, never a traceback
            LOG.exception("%s: the run failed", name)
            print(f"{config}: {name}: {type(exc).__name__}: {exc}", file=sys.stderr)
            return EXIT_FAILED
        finally:
            host.stop()  # the partitions, the nodes (actuators safe), the recording, the transport, the sessions
            host.keep_statistics(run_log, extra())
    recorded = []
    if recorder is not None and recorder.failure is not None:  # watched like a task: stderr and the exit code
        print(f"{config}: {recorder.failure}", file=sys.stderr)
        recorded.append(EXIT_FAILED)
    return _verdict(host.failures() + recorded, agents)


def _network_event(run_log: RunLog, event: Any) -> None:
    """A network event (peer found, lost, linked, unlinked; deadline missed…), written as it happens."""
    record = {"kind": f"network-{event.kind}", "time": time.time(), "peer": event.peer}
    if event.topic is not None:
        record["topic"] = event.topic
    if event.detail:
        record["detail"] = event.detail
    run_log.event(record)
    if event.kind in ("found", "lost", "linked", "unlinked"):
        LOG.info("network: %s %s %s", event.kind, event.peer, event.detail)


def _verdict(codes: list[int], agents: list[_Agent]) -> int:
    """The exit code: the lowest of the host's failures (``codes``, already on stderr) and of the
    plan's agents, whose first error is printed here (issue G)."""
    for agent in agents:
        outcome = agent.outcome or "stopped"
        succeeded = agent.error is None and agent.runner.succeeded
        LOG.log(logging.INFO if succeeded else logging.ERROR, "agent %s: outcome %s", agent.name, outcome)
        if not succeeded:
            detail = f": {type(agent.error).__name__}: {agent.error}" if agent.error is not None else ""
            failures = agent.runner.engine.failures
            detail += f" (last failed state: {failures[-1]})" if failures and agent.error is None else ""
            print(f"agent {agent.name}: mission ended {outcome}{detail}", file=sys.stderr)
            codes.append(EXIT_AGENTS)
    return min(codes) if codes else 0


class _Agent:
    """A plan's agent running its mission in a thread; the outcome (or exception) kept for the verdict."""

    def __init__(self, runner: AgentRunner, name: str) -> None:
        self.runner = runner
        self.name = name
        self.outcome: str | None = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name=f"agent-{name}", daemon=True)

    def _run(self) -> None:
        try:
            self.outcome = self.runner.run()
        except BaseException as error:  # the runner recorded it; the run's verdict reports it
            self.error, self.outcome = error, "crashed"


def _progress(line: str) -> None:
    """An agent's progress line on the terminal (the run's record has every event)."""
    print(line, flush=True)


def _start_agents(system: System, plan: str, nodes: list[Node], transport: Transport, run_dir: Path) -> list[_Agent]:
    """The plan's agents whose node runs here, each running its mission in a thread."""
    record = system.plan(plan)
    assert record is not None
    here = {n.name for n in nodes}
    started = []
    for agent in record.agents:
        if agent.node in here:
            running = _Agent(AgentRunner(system, plan, agent.name, transport, run_dir, progress=_progress), agent.name)
            running.thread.start()
            started.append(running)
            LOG.info("plan %s: agent %s runs mission %s", plan, agent.name, agent.mission)
    return started


if __name__ == "__main__":
    sys.exit(main())
