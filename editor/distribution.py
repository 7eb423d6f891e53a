"""Configuration distribution, the editor side (§3.1.5.2, §3.1.5.3), with no Qt: the GUI wraps it.

``AgentDirectory`` lists the agents (``ckm-run --await-config``) heard on the network;
``bundle`` gathers a configuration's main file and every file it includes; ``push`` sends one
agent one node of it and waits for the acknowledgement; ``distribute`` does that for a whole
mapping of nodes to agents at once. The protocol is described in :mod:`runtime.distribution_protocol`.
"""

from __future__ import annotations

import os
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ckmconf import load
from runtime.distribution_protocol import (
    AGENTS_TOPIC,
    MAX_BUNDLE,
    ack_topic,
    bundle_hash,
    bundle_size,
    config_topic,
)
from runtime.network import Sample, Subscription, TopicQoS, Transport

STALE_AFTER = 2.0  # seconds without an announcement before an agent is shown as stale


def config_hash(files: Mapping[str, str]) -> str:
    """The hash an agent acknowledges for ``files`` (see runtime.distribution_protocol.bundle_hash)."""
    return bundle_hash(files)


@dataclass(frozen=True)
class Agent:
    """One agent as last heard: its announcement and when it arrived (monotonic clock)."""

    name: str
    announcement: dict[str, Any]
    seen: float

    @property
    def status(self) -> str:
        """The agent's announced status (``unknown`` when missing)."""
        return str(self.announcement.get("status", "unknown"))

    @property
    def config_hash(self) -> str | None:
        """The hash of the configuration the agent runs, if any."""
        value = self.announcement.get("config_hash")
        return value if isinstance(value, str) else None

    @property
    def node(self) -> str | None:
        """The node the agent runs, if any."""
        value = self.announcement.get("node")
        return value if isinstance(value, str) else None

    @property
    def age(self) -> float:
        """Seconds since the agent was last heard."""
        return time.monotonic() - self.seen

    def stale(self, after: float = STALE_AFTER) -> bool:
        """Whether the agent has been silent for more than ``after`` seconds."""
        return self.age > after


class AgentDirectory:
    """The agents announcing themselves on ``transport``; ``on_change(agent)`` runs on the
    network thread for every announcement (a GUI posts it to its own thread)."""

    def __init__(self, transport: Transport, on_change: Callable[[Agent], None] | None = None) -> None:
        self._agents: dict[str, Agent] = {}
        self._cond = threading.Condition()
        self._on_change = on_change
        self._subscription: Subscription = transport.subscribe(TopicQoS(AGENTS_TOPIC, "agent"), self._heard)

    def _heard(self, sample: Sample) -> None:
        value = sample.value
        if not isinstance(value, dict) or value.get("type") != "agent" or not isinstance(value.get("name"), str):
            return
        agent = Agent(value["name"], value, time.monotonic())
        with self._cond:
            self._agents[agent.name] = agent
            self._cond.notify_all()
        if self._on_change is not None:
            self._on_change(agent)

    def agents(self) -> list[Agent]:
        """The agents heard so far, by name."""
        with self._cond:
            return sorted(self._agents.values(), key=lambda a: a.name)

    def get(self, name: str) -> Agent | None:
        """Agent ``name``, or None when not heard."""
        with self._cond:
            return self._agents.get(name)

    def wait_until(self, predicate: Callable[[dict[str, Agent]], bool], timeout: float) -> bool:
        """Wait until ``predicate(agents by name)`` holds; False after ``timeout`` seconds."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(dict(self._agents)), timeout)

    def wait_for(self, names: list[str], timeout: float) -> bool:
        """Wait until every agent of ``names`` is heard; False after ``timeout`` seconds."""
        return self.wait_until(lambda agents: all(n in agents for n in names), timeout)

    def close(self) -> None:
        """Stop listening to the announcements."""
        self._subscription.close()


class BundleError(ValueError):
    """A configuration that cannot be gathered for sending."""


@dataclass(frozen=True)
class Bundle:
    """What is sent: texts by path relative to the bundle's root, and the main file's path."""

    files: dict[str, str]
    main: str

    @property
    def hash(self) -> str:
        """The hash the receiving agent acknowledges for this bundle."""
        return bundle_hash(self.files)


def bundle(path: Path, max_bytes: int = MAX_BUNDLE) -> Bundle:
    """The main file ``path`` and every file it includes (as the loader follows them), keyed by
    their path relative to the folder holding them all."""
    result = load(path, strict=False)
    main = os.path.realpath(path)
    found = {os.path.realpath(f) for f in result.files}
    if main not in found:
        reason = str(result.errors[0]) if result.errors else "cannot be read"
        raise BundleError(f"{path}: {reason}")
    root = os.path.commonpath([os.path.dirname(f) for f in found])
    files: dict[str, str] = {}
    for name in sorted(found):
        try:
            files[Path(os.path.relpath(name, root)).as_posix()] = Path(name).read_text(encoding="utf-8")
        except (OSError, UnicodeError) as exc:
            raise BundleError(f"{name}: cannot be sent: {exc}") from None
    if bundle_size(files) > max_bytes:
        raise BundleError(f"{path}: the bundle is {bundle_size(files)} bytes; at most {max_bytes} can be sent")
    return Bundle(files, Path(os.path.relpath(main, root)).as_posix())


@dataclass(frozen=True)
class Ack:
    """An agent's answer to a push, or the editor's own verdict when none came."""

    agent: str
    node: str
    id: str
    accepted: bool
    hash: str
    errors: tuple[str, ...] = ()
    answered: bool = True  # False: no answer (timeout) or never sent
    expected: str = field(default="", repr=False)

    @property
    def confirmed(self) -> bool:
        """Accepted, and the agent hashed exactly what was sent."""
        return self.accepted and self.hash == self.expected


def push(
    transport: Transport,
    agent: str,
    node: str,
    files: Mapping[str, str],
    main: str,
    timeout: float = 10.0,
    *,
    resend: float = 1.0,
) -> Ack:
    """Send ``node`` of the bundle to ``agent`` and wait for its answer, resending every
    ``resend`` seconds (the agent applies an id once) until ``timeout``."""
    ident = uuid.uuid4().hex
    expected = bundle_hash(files)
    size = bundle_size(files)
    if size > MAX_BUNDLE:
        reason = f"the bundle is {size} bytes; at most {MAX_BUNDLE} can be sent"
        return Ack(agent, node, ident, False, "", (reason,), answered=False, expected=expected)
    answer: list[dict[str, Any]] = []
    got = threading.Event()

    def on_ack(sample: Sample) -> None:
        value = sample.value
        if isinstance(value, dict) and value.get("id") == ident and not got.is_set():
            answer.append(value)
            got.set()

    subscription = transport.subscribe(TopicQoS(ack_topic(agent), "ack", history=8), on_ack)
    publisher = transport.publisher(TopicQoS(config_topic(agent), "config"))
    message = {"id": ident, "node": node, "files": dict(files), "main": main}
    deadline = time.monotonic() + timeout
    try:
        next_send = 0.0
        while not got.is_set() and time.monotonic() < deadline:
            if time.monotonic() >= next_send:  # not yet heard of the agent: try again soon
                next_send = time.monotonic() + (resend if publisher.publish(message) else 0.05)
            got.wait(min(0.05, max(0.0, deadline - time.monotonic())))
    finally:
        subscription.close()
    if not answer:
        reason = f"no answer from agent {agent!r} within {timeout:g} s"
        return Ack(agent, node, ident, False, "", (reason,), answered=False, expected=expected)
    value = answer[0]
    errors = value.get("errors")
    return Ack(
        agent,
        node,
        ident,
        value.get("accepted") is True,
        str(value.get("hash") or ""),
        tuple(str(e) for e in errors) if isinstance(errors, list) else (),
        expected=expected,
    )


def distribute(
    transport: Transport, system_path: Path, mapping: Mapping[str, str], timeout: float = 10.0
) -> dict[str, Ack]:
    """Push every node of ``mapping`` (node → agent) its configuration, all at once."""
    agents = list(mapping.values())
    twice = sorted({a for a in agents if agents.count(a) > 1})
    if twice:
        raise ValueError(f"an agent runs one node: {', '.join(twice)} named for several")
    sent = bundle(system_path)
    with ThreadPoolExecutor(max_workers=max(1, len(mapping))) as pool:
        futures = {
            node: pool.submit(push, transport, agent, node, sent.files, sent.main, timeout)
            for node, agent in mapping.items()
        }
        return {node: future.result() for node, future in futures.items()}
