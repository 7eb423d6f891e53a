"""Configuration distribution, the node side (§3.1.5.2): ``ckm-run --await-config``.

An agent joins a bootstrap network with no system yet, announces itself and waits. The editor
pushes it a configuration bundle (the main file and every file it includes) and the node to
run; the agent writes the bundle into a fresh directory, loads it strictly, builds and sets up
the node, and only then replaces the node it ran (stopped with its actuators safe). On any
error it refuses with the errors and keeps the old node running.

The messages, topics, limits and the bundle hash are those of :mod:`runtime.distribution_protocol`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import queue
import shutil
import socket
import sys
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ckmconf import ConfigError, load
from ckmconf.model import Network, System

from .distribution_protocol import (
    AGENTS_TOPIC,
    ANNOUNCE_PERIOD,
    MAX_BUNDLE,
    NAME,
    Push,
    Refused,
    ack_topic,
    bundle_hash,
    config_topic,
    parse_push,
)
from .distribution_staging import ScopedTransport, build_node, describe_error
from .host import Host, stop_on_signals, wait_for_stop
from .host_network import JoinError, join
from .kernel.node import NodeRuntime
from .network.api import Sample, Subscription, TopicQoS, Transport
from .registry import Registry
from .runrecord import EXIT_NETWORK

LOG = logging.getLogger("ckm.distribution")

__all__ = [  # the protocol's names stay importable from here, where they were first defined
    "AGENTS_TOPIC",
    "MAX_BUNDLE",
    "NAME",
    "ConfigAgent",
    "Push",
    "Refused",
    "ScopedTransport",
    "ack_topic",
    "bundle_hash",
    "config_topic",
    "parse_push",
    "run_agent",
]


@dataclass
class _Running:
    host: Host  # the node's objects, its scoped transport, its run record in ``directory``
    runtime: NodeRuntime
    scoped: ScopedTransport
    push: Push
    directory: Path

    @property
    def system(self) -> System:
        return self.host.system


class ConfigAgent:
    """Waits for configurations on ``transport`` and runs the node of the last accepted one."""

    def __init__(
        self,
        name: str,
        transport: Transport,
        run_dir: Path,
        *,
        announce_period: float = ANNOUNCE_PERIOD,
        max_bundle: int = MAX_BUNDLE,
        registry: Registry | None = None,
    ) -> None:
        if not NAME.fullmatch(name):
            raise ValueError(f"agent name {name!r}: use 1-64 letters, digits, '_', '.' or '-'")
        self.name = name
        self.transport = transport
        self.run_dir = Path(run_dir)
        self.announce_period = announce_period
        self.max_bundle = max_bundle
        self.registry = registry
        self.current: _Running | None = None
        self.status = "waiting"
        self.errors: list[str] = []
        self.last_id: str | int | None = None
        self._pushes = 0
        self._acks: OrderedDict[str | int, dict[str, Any]] = OrderedDict()  # the last answers, by id
        self._inbox: queue.Queue[Any] = queue.Queue(maxsize=4)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._changed = threading.Event()
        self._threads: list[threading.Thread] = []
        self._announcer = transport.publisher(TopicQoS(AGENTS_TOPIC, "agent", "best-effort"))
        self._acker = transport.publisher(TopicQoS(ack_topic(name), "ack"))
        self._subscription: Subscription | None = None

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Listen for pushes on the agent's config topic; start announcing and applying them."""
        self._subscription = self.transport.subscribe(TopicQoS(config_topic(self.name), "config"), self._receive)
        for target, label in ((self._announce_loop, "announce"), (self._work_loop, "apply")):
            thread = threading.Thread(target=target, name=f"ckm-agent-{label}", daemon=True)
            thread.start()
            self._threads.append(thread)
        LOG.info("agent %s waiting for a configuration on %s", self.name, config_topic(self.name))

    def stop(self) -> None:
        """Stop taking pushes, stop the running node (actuators safe), say goodbye."""
        if self._subscription is not None:
            self._subscription.close()
        self._stop.set()
        self._changed.set()
        for thread in self._threads:
            thread.join(30.0)
        with self._lock:
            current, self.current = self.current, None
            self.status = "stopped"
        if current is not None:
            self._retire(current)
        self._announcer.publish(self.announcement())

    def announcement(self) -> dict[str, Any]:
        """The agent's ``/ckm/agents`` message now (:mod:`runtime.distribution_protocol`)."""
        with self._lock:
            push = self.current.push if self.current is not None else None
            return {
                "type": "agent",
                "name": self.name,
                "host": socket.gethostname(),
                "pid": os.getpid(),
                "guid": self.transport.guid,
                "status": self.status,
                "config_hash": push.hash if push else None,
                "node": push.node if push else None,
                "system": self.current.system.name if self.current is not None else None,
                "errors": list(self.errors),
                "last_id": self.last_id,
            }

    # ------------------------------------------------------------------ threads

    def _receive(self, sample: Sample) -> None:
        try:  # network thread: never block it with a setup
            self._inbox.put_nowait(sample.value)
        except queue.Full:
            LOG.warning("agent %s: busy, a push was dropped (the editor resends)", self.name)

    def _announce_loop(self) -> None:
        while not self._stop.is_set():
            self._announcer.publish(self.announcement())
            self._changed.wait(self.announce_period)
            self._changed.clear()

    def _work_loop(self) -> None:
        while not self._stop.is_set():
            try:
                message = self._inbox.get(timeout=0.1)
            except queue.Empty:
                continue
            try:
                ack = self.handle(message)
            except Exception as exc:  # a bug must not end the agent: answer and go on
                LOG.exception("agent %s: a push failed", self.name)
                ident = message.get("id") if isinstance(message, dict) else None
                ack = self._answer(ident, False, "", None, [f"agent error: {describe_error(exc, self.run_dir)}"])
            self._acker.publish(ack)

    # ------------------------------------------------------------------ applying a push

    def handle(self, message: Any) -> dict[str, Any]:
        """Apply one push (or refuse it) and return the acknowledgement."""
        ident = message.get("id") if isinstance(message, dict) else None
        if isinstance(ident, (str, int)) and not isinstance(ident, bool) and ident in self._acks:
            return self._acks[ident]  # a resend: answer again, apply once
        hashed = ""
        try:
            push = parse_push(message, self.max_bundle)
            hashed = push.hash
            ack = self._install(push)
        except Refused as refused:
            if isinstance(message, dict) and isinstance(message.get("files"), dict):
                files = message["files"]
                if all(isinstance(p, str) and isinstance(t, str) for p, t in files.items()):
                    hashed = hashed or bundle_hash(files)
            node = message.get("node") if isinstance(message, dict) else None
            ack = self._answer(ident, False, hashed, node if isinstance(node, str) else None, refused.errors)
            with self._lock:
                if self.current is None:
                    self.status = "refused"
                self.errors = refused.errors
            LOG.warning("agent %s refused push %r: %s", self.name, ident, refused)
        if isinstance(ack["id"], (str, int)):
            self._acks[ack["id"]] = ack
            while len(self._acks) > 32:
                self._acks.popitem(last=False)
        with self._lock:
            self.last_id = ack["id"]
        self._changed.set()
        return ack

    def _answer(self, ident: Any, accepted: bool, hashed: str, node: str | None, errors: list[str]) -> dict[str, Any]:
        ident = ident if isinstance(ident, (str, int)) and not isinstance(ident, bool) else None
        return {
            "type": "ack",
            "agent": self.name,
            "id": ident,
            "accepted": accepted,
            "hash": hashed,
            "node": node,
            "errors": errors,
        }

    def _install(self, push: Push) -> dict[str, Any]:
        directory = self._write(push)
        try:
            host, runtime, scoped = build_node(push, directory, self.transport, self.registry)
        except Refused:
            shutil.rmtree(directory, ignore_errors=True)  # the errors are in the answer and the log
            raise
        with self._lock:
            old, self.current = self.current, None
        if old is not None:
            self._retire(old)  # the old node stops, its actuators safe, before the new one acts
        scoped.start()
        try:
            host.start()
        except Exception as exc:
            host.stop()  # the node, then its scoped transport
            errors = [f"{push.node} failed to start: {describe_error(exc, directory)}"]
            with self._lock:
                self.status, self.errors = "failed", errors
            LOG.exception("agent %s: node %s failed to start", self.name, push.node)
            return self._answer(push.id, False, push.hash, push.node, errors)
        host.started = time.time()  # its run record counts from here
        with self._lock:
            self.current = _Running(host, runtime, scoped, push, directory)
            self.status, self.errors = "running", []
        LOG.info("agent %s runs node %s of %s (%s)", self.name, push.node, host.system.name, push.hash[:12])
        return self._answer(push.id, True, push.hash, push.node, [])

    def _write(self, push: Push) -> Path:
        try:
            while True:  # a fresh directory, even in a run directory used before
                self._pushes += 1
                directory = self.run_dir / "configs" / f"{self._pushes:03d}-{push.hash[:12]}"
                with contextlib.suppress(FileExistsError):
                    directory.mkdir(parents=True)
                    break
            for path, text in push.files.items():
                target = directory / path
                target.parent.mkdir(parents=True, exist_ok=True)
                with target.open("x", encoding="utf-8") as out:
                    out.write(text)
        except (OSError, UnicodeError) as exc:
            raise Refused(f"cannot store the bundle: {exc}") from None
        return directory

    def _retire(self, running: _Running) -> None:
        """Stop a running node, actuators safe, and record its run in its directory; never raises."""
        running.scoped.open.clear()  # no command reaches it while it stops
        running.host.stop()  # the node (bounded), then its scoped transport
        extra = {"agent": self.name, "hash": running.push.hash}
        try:
            running.host.write_run(extra)
        except OSError:
            LOG.exception("agent %s: cannot record the run of %s", self.name, running.push.node)
        LOG.info("agent %s stopped node %s (%s)", self.name, running.push.node, running.push.hash[:12])


def run_agent(network_file: Path | None, name: str, run_dir: Path, duration: float | None = None) -> int:
    """``ckm-run --await-config [NETWORK.xml] --name NAME``: join, announce, apply pushes until a
    signal (or ``duration``); exit 0 on a clean stop, 1 for a bad network file, 4 (EXIT_NETWORK)
    if the network cannot be joined."""
    network = Network()
    try:
        if network_file is not None:
            network = load(network_file).network or Network()
        key_dir = network_file.parent if network_file is not None else None
        transport = join(network, name, key_dir=key_dir)  # no key without a bootstrap file
    except ConfigError as error:
        print(error, file=sys.stderr)
        return 1
    except JoinError as exc:
        print(f"{network_file or 'default network'}: {exc}", file=sys.stderr)
        return EXIT_NETWORK
    stop = threading.Event()
    with stop_on_signals(stop):
        agent = ConfigAgent(name, transport, run_dir)
        try:
            transport.start()
            agent.start()
            wait_for_stop(stop, duration)
        finally:
            agent.stop()
            transport.stop()
    return 0
