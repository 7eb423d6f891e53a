"""The host of a process's nodes: one lifecycle for ``ckm-run`` and the configuration agent (issue H point 2).

A CKM node (§3.1.1) is a set of objects built from its ``<Node>`` record: its channels'
backends, its sensor, control and actuation services, its monitor, the Smart Resources it
hosts and, for a node with ``<Partition>`` elements (§3.1.3.2), the supervisor of the partition
processes. :class:`Host` owns what happens to them in one process, in this order:

1. **join** the network of the system's ``<Network>`` (:mod:`runtime.host_network`);
2. enter the run-wide **hardware sessions** of the backends (:mod:`runtime.sessions`);
3. **build** and set up each node (a failed set-up is **discarded**: what it opened is closed,
   no actuator is driven);
4. **start** the nodes, then their partition supervisors;
5. **wait** until SIGINT/SIGTERM (:func:`stop_on_signals`), the run's duration, a failure
   (:meth:`Host.fail`) or the caller's own end condition;
6. **stop**, each step isolated and bounded by ``stop_timeout``: the alarms' judging (a stop's own
   effects are not faults), the partitions, the nodes in
   reverse order (each drives its actuators to their safe values first), whatever the caller
   registered with :meth:`Host.on_stop`, the transport, the hardware sessions;
7. write the **run record** (:mod:`runtime.runrecord`) and report every failure on stderr with
   the exit code of docs/exit-codes.md (:meth:`Host.failures`).

``ckm-run`` (:mod:`runtime.cli`) hosts the nodes of a configuration file; the configuration
agent (:mod:`runtime.distribution`) one :class:`Host` per pushed bundle, on its own transport.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from ckmconf.model import Network, Node, Partition, System

from .host_network import join
from .kernel.node import NodeRuntime
from .kernel.partitions import PartitionSupervisor
from .kernel.runlog import RunLog
from .network import NetworkEvent, Transport
from .registry import Registry
from .ros.wire import install as install_cdr
from .runrecord import EXIT_FAILED, keep_statistics, write_run
from .sessions import HardwareSessions

LOG = logging.getLogger("ckm.run")

STOP_TIMEOUT = 30.0  # seconds one stop step may take before the host gives up on it (D148)


@contextlib.contextmanager
def stop_on_signals(stop: threading.Event) -> Iterator[None]:
    """SIGINT and SIGTERM set ``stop`` while the block lasts (an orderly stop, never a traceback);
    the previous handlers are back when it ends. Call it from the main thread."""

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        LOG.info("signal %s: stopping", signal.Signals(signum).name)
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def wait_for_stop(
    stop: threading.Event,
    duration: float | None,
    *,
    done: Callable[[], bool] | None = None,
    every: tuple[float, Callable[[], None]] | None = None,
) -> None:
    """Return once ``stop`` is set, ``duration`` seconds have passed or ``done()`` is true.

    Args:
        stop: set by a signal or a failure.
        duration: the run's length in seconds (None: until stopped).
        done: the caller's own end condition, polled every 0.1 s (every plan agent has ended).
        every: (period, action): ``action()`` every ``period`` seconds while waiting (the
            statistics file kept current).
    """
    deadline = None if duration is None else time.monotonic() + duration
    next_tick = None if every is None else time.monotonic() + every[0]
    while not stop.is_set() and not (done is not None and done()):
        remaining = None if deadline is None else deadline - time.monotonic()
        if remaining is not None and remaining <= 0:
            break
        stop.wait(0.1 if remaining is None else min(0.1, remaining))
        if every is not None and next_tick is not None and time.monotonic() >= next_tick:
            next_tick = time.monotonic() + every[0]
            every[1]()


def isolated(what: str, action: Callable[[], Any]) -> None:
    """One stop step: a failure is logged, and the next step still runs."""
    try:
        action()
    except Exception:
        LOG.exception("could not %s", what)


def bounded(what: str, action: Callable[[], Any], timeout: float) -> bool:
    """One stop step run for at most ``timeout`` seconds: False when it did not end in time.

    The step runs in a daemon thread, so a backend stuck in its driver cannot keep the process
    (and every step after it: the transport, the sessions, the run record) from ending.
    """
    worker = threading.Thread(target=isolated, args=(what, action), name=f"ckm-stop: {what}", daemon=True)
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        LOG.error("could not %s within %g s: going on without it", what, timeout)
        return False
    return True


class Host:
    """The nodes one process runs for one configuration, and what they run on.

    Args:
        system: the loaded (and verified) ``<System>``.
        config: the configuration file it was loaded from: stderr messages start with it, the
            group key file and the partition processes are found from it.
        run_dir: the run directory (the partitions' directories are made under it).
        registry: where kinds are found (default: the installed ``ckm.plugins``).
        stop_timeout: the bound of each stop step, in seconds.
    """

    def __init__(
        self,
        system: System,
        config: Path,
        run_dir: Path,
        *,
        registry: Registry | None = None,
        stop_timeout: float = STOP_TIMEOUT,
    ) -> None:
        self.system, self.config, self.run_dir = system, config, run_dir
        self.registry = registry
        self.stop_timeout = stop_timeout
        self.runtimes: list[NodeRuntime] = []
        self.transport: Transport | None = None  # stopped after the nodes and the on_stop steps
        self.sessions: HardwareSessions | None = None  # ended last
        self.stopping = threading.Event()  # set by a signal (stop_on_signals) or by fail()
        self.code = 0  # set by fail(): the code a failure while running asks for
        self.started = time.time()  # the run record's start
        self.stuck: list[str] = []  # the stop steps that did not end within stop_timeout
        self._on_stop: list[tuple[str, Callable[[], Any]]] = []

    # ------------------------------------------------------------------ set-up

    def join(self, name: str, on_event: Callable[[NetworkEvent], None] | None = None) -> Transport:
        """Join the system's network as ``name`` (set up, not started); raises
        :class:`~runtime.host_network.JoinError`. Topics of a ROS 2 type travel as CDR (D157)."""
        network = self.system.network or Network()
        self.transport = join(network, name, key_dir=self.config.parent, on_event=on_event)
        install_cdr(self.transport, self.system)
        return self.transport

    def start_sessions(self, nodes: Iterable[Node]) -> None:
        """Enter the run-wide sessions of the backends ``nodes`` use, before any node is built; a
        session that breaks later fails the run (exit 5)."""
        self.sessions = HardwareSessions(
            self.system, self.config, self.run_dir, list(nodes), lambda message: self.fail(EXIT_FAILED, message),
            self.registry,
        )
        self.sessions.start()

    def on_stop(self, what: str, action: Callable[[], Any]) -> None:
        """Run ``action`` at the stop, after the nodes and before the transport (last registered, first run)."""
        self._on_stop.append((what, action))

    def build(
        self,
        node: Node,
        transport: Transport,
        *,
        partition: Partition | None = None,
        several: bool = False,
        sinks: Iterable[Callable[[dict[str, Any]], None]] = (),
    ) -> NodeRuntime:
        """Build and set up one node's objects; kept for :meth:`start` and :meth:`stop`.

        Args:
            node: the ``<Node>`` record.
            transport: what it publishes and subscribes on.
            partition: run only this ``<Partition>`` of the node (a partition's process).
            several: other nodes run in this process too (each node's partitions then log to
                RUN_DIR/NODE/PARTITION rather than RUN_DIR/PARTITION).
            sinks: event callbacks (the run's events file), attached before the set-up.

        Raises:
            ConfigError: a configuration problem found while building, at its element.
            Exception: whatever a backend or plugin raised in its set-up; what the set-up had
                opened is closed again, no actuator driven.
        """
        if partition is not None:
            runtime = NodeRuntime(node, self.system, transport, registry=self.registry, partition=partition.name)
        elif node.partitions:  # its unpartitioned part and monitor here, each partition a child process
            runtime = NodeRuntime(node, self.system, transport, registry=self.registry, partition="")
            home = self.run_dir / node.name if several else self.run_dir
            runtime.partitions = PartitionSupervisor(node, self.config, home, runtime.report)
        else:
            runtime = NodeRuntime(node, self.system, transport, registry=self.registry)
        runtime.event_sinks.extend(sinks)
        try:
            runtime.setup()  # its backends are closed again by a failing setup()
        except BaseException:
            self._close_resources(runtime)
            raise
        self.runtimes.append(runtime)
        return runtime

    def discard(self, runtime: NodeRuntime) -> None:
        """Undo the set-up of a node that never started: its Smart Resources and hardware are
        closed without driving any actuator, and it leaves the host."""
        self._close_resources(runtime)
        for channel, backend in runtime.backends.items():
            isolated(f"close channel {channel} of {runtime.node.name}", backend.stop)
        if runtime in self.runtimes:
            self.runtimes.remove(runtime)

    @staticmethod
    def _close_resources(runtime: NodeRuntime) -> None:
        for name, resource in runtime.resources.items():
            isolated(f"stop Smart Resource {name}", resource.stop)

    # ------------------------------------------------------------------ running

    def start(self) -> None:
        """Start every node built, then their partition supervisors (a raising start is the
        caller's to report; :meth:`stop` still stops what was built)."""
        for runtime in self.runtimes:
            runtime.start()
        for supervisor in self.supervisors:
            supervisor.start()

    @property
    def supervisors(self) -> list[PartitionSupervisor]:
        """The partition supervisors of the nodes built."""
        return [r.partitions for r in self.runtimes if r.partitions is not None]

    def fail(self, code: int, message: str | None = None) -> None:
        """Something failed while running: stop the run with exit ``code``; ``message`` goes to
        stderr after the configuration file's name (and to the log)."""
        if message is not None:
            print(f"{self.config}: {message}", file=sys.stderr)
            LOG.error("%s", message)
        self.code = code
        self.stopping.set()

    def wait(
        self,
        duration: float | None,
        *,
        done: Callable[[], bool] | None = None,
        every: tuple[float, Callable[[], None]] | None = None,
    ) -> None:
        """Run until stopped (a signal, :meth:`fail`), ``duration`` or ``done()`` (:func:`wait_for_stop`)."""
        wait_for_stop(self.stopping, duration, done=done, every=every)

    # ------------------------------------------------------------------ stopping

    def stop(self) -> None:
        """Stop everything, each step isolated and bounded: the alarms' judging, the partitions (their actuators
        safe), the nodes in reverse order, the :meth:`on_stop` steps, the transport, the
        sessions. Never raises; a step that does not end in time is listed in ``stuck``."""
        for runtime in self.runtimes:  # alarms first: a stop's own effects are not the run's faults
            isolated(f"stop monitoring node {runtime.node.name}", runtime.stop_monitoring)
        for supervisor in self.supervisors:  # bounded by its own stop_timeout per partition
            isolated(f"stop the partitions of {supervisor.node.name}", supervisor.stop)
        steps: list[tuple[str, Callable[[], Any]]] = [(f"stop node {r.node.name}", r.stop) for r in self.runtimes]
        steps.reverse()
        steps += reversed(self._on_stop)
        self._on_stop.clear()
        if self.transport is not None:
            steps.append(("stop the transport", self.transport.stop))
        if self.sessions is not None:
            steps.append(("end the hardware sessions", self.sessions.stop))
        for what, action in steps:
            if not bounded(what, action, self.stop_timeout):
                self.stuck.append(what)

    # ------------------------------------------------------------------ the run record

    def keep_statistics(self, run_log: RunLog, extra: dict[str, Any]) -> None:
        """Rewrite the run's statistics file now (``ckm-run``, while running and at the stop)."""
        keep_statistics(run_log, self.config, self.system, self.runtimes, self.started, extra)

    def write_run(self, extra: dict[str, Any]) -> None:
        """Write ``stats.json`` and ``events.jsonl`` of the finished run in one go (the agent's
        pushed nodes); raises OSError."""
        write_run(self.run_dir, self.config, self.system, self.runtimes, self.started, extra)

    def failures(self) -> list[int]:
        """The exit codes of everything that failed, each failure's first error on stderr (issue G).

        ``code`` (a :meth:`fail`), each partition that failed, each alarm the configuration
        calls an error or critical (D147), each task that raised, each stop step that did not
        end within ``stop_timeout`` (D148): all EXIT_FAILED but a fail()'s own code.
        """
        codes = [self.code] if self.code else []
        for runtime in self.runtimes:
            for partition, error in runtime.partitions.failures() if runtime.partitions is not None else []:
                print(f"{error}  [node {runtime.node.name}, partition {partition}]", file=sys.stderr)
                LOG.error("node %s: partition %s failed: %s", runtime.node.name, partition, error)
                codes.append(EXIT_FAILED)
            serious = runtime.log.serious
            if serious is not None:  # the configuration calls this alarm an error: the run broke (D147)
                message = (f"alarm {serious['alarm']} ({serious['severity']}) raised {runtime.log.serious_count} "
                           f"time(s), first: {serious['measure']} = {serious['value']}")
                print(f"{runtime.node.name}: {message}", file=sys.stderr)
                LOG.error("node %s: %s", runtime.node.name, message)
                codes.append(EXIT_FAILED)
            for task, figures in (runtime.statistics().get("tasks") or {}).items():
                if figures.get("failures"):
                    message = f"task {task} failed {figures['failures']} time(s), first: {figures.get('first_failure')}"
                    print(f"{runtime.node.name}: {message}", file=sys.stderr)
                    codes.append(EXIT_FAILED)
        for what in self.stuck:
            print(f"{self.config}: could not {what} within {self.stop_timeout:g} s", file=sys.stderr)
            codes.append(EXIT_FAILED)
        return codes
