"""Staging a pushed configuration (§3.1.5.2): its node built beside the one the agent runs.

The configuration agent (:mod:`runtime.distribution`) stores each accepted bundle in a fresh
directory; :func:`build_node` loads it (every problem collected) and has a
:class:`~runtime.host.Host` build and set up its node on a :class:`ScopedTransport`, a view of
the agent's transport whose subscriptions stay muted until the new node takes over and are all
closed when it goes. Until then the running node is untouched, so a bundle that fails anywhere
here is refused and the old node keeps running.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path

from ckmconf import ConfigError, load

from .distribution_protocol import Push, Refused
from .host import Host
from .kernel.node import NodeRuntime
from .network.api import NetworkEvent, Publisher, Sample, Subscription, TopicQoS, Transport
from .registry import Registry


class ScopedTransport(Transport):
    """One runtime's view of the agent's transport: its subscriptions stay muted until the
    runtime takes over (a runtime set up beside the running one must not drive anything) and
    are all closed when it goes."""

    def __init__(self, transport: Transport) -> None:
        self.inner = transport
        self.open = threading.Event()
        self._subscriptions: list[Subscription] = []

    @property
    def guid(self) -> int:  # type: ignore[override]
        """The agent's transport's identity: the runtime speaks as the agent."""
        return self.inner.guid

    def setup(self) -> None:
        """Nothing: the agent owns the real transport's lifecycle."""

    def start(self) -> None:
        """Let the runtime's subscriptions through: it has taken over."""
        self.open.set()

    def stop(self) -> None:
        """Mute and close every subscription the runtime made; the real transport stays up."""
        self.open.clear()
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()

    def publisher(self, qos: TopicQoS) -> Publisher:
        """A publisher of the agent's transport."""
        return self.inner.publisher(qos)

    def subscribe(
        self, qos: TopicQoS, callback: Callable[[Sample], None] | None = None, *, passive: bool = False
    ) -> Subscription:
        """A subscription of the agent's transport whose callback stays muted until :meth:`start`."""
        gated = None
        if callback is not None:

            def gated(sample: Sample, callback: Callable[[Sample], None] = callback) -> None:
                if self.open.is_set():
                    callback(sample)

        subscription = self.inner.subscribe(qos, gated, passive=passive)
        self._subscriptions.append(subscription)
        return subscription

    def on_event(self, callback: Callable[[NetworkEvent], None]) -> None:
        """Network events of the agent's transport."""
        self.inner.on_event(callback)

    def peers(self) -> list[int]:
        """The peers of the agent's transport."""
        return self.inner.peers()

    def subscribed(self, topic: str) -> bool:
        """Whether the agent's transport has a subscriber asking for ``topic`` (D245)."""
        return self.inner.subscribed(topic)

    def wait_for_subscribers(self, topic: str, count: int, timeout: float) -> bool:
        """As the agent's transport does."""
        return self.inner.wait_for_subscribers(topic, count, timeout)


def build_node(
    push: Push, directory: Path, transport: Transport, registry: Registry | None
) -> tuple[Host, NodeRuntime, ScopedTransport]:
    """Load the stored bundle and build and set up its node beside the running one.

    Refused (with every problem, paths relative to the bundle) when the bundle does not load,
    an include leads out of it, the node is missing or partitioned, or the node's set-up fails;
    what a failed set-up opened is closed again without driving any actuator (:meth:`Host.build`).
    The node's :class:`~runtime.host.Host` stops it, then its scoped transport.
    """
    result = load(directory / push.main, strict=False)
    root = directory.resolve()
    outside = [f for f in result.files if not Path(f).resolve().is_relative_to(root)]
    if outside:  # an include reached out of the bundle: say so, show nothing of it
        raise Refused("an include leads out of the bundle; send every included file in it")
    if result.errors or result.system is None:
        raise Refused(*(describe_error(e, directory) for e in result.errors))
    system = result.system
    node = next((n for n in system.nodes if n.name == push.node), None)
    if node is None:
        names = ", ".join(n.name for n in system.nodes) or "none"
        raise Refused(f"{push.main}: no node {push.node!r} (nodes: {names})")
    if node.partitions:
        raise Refused(f"node {push.node!r} has partitions: run it with ckm-run --node, not through an agent")
    scoped = ScopedTransport(transport)
    host = Host(system, directory / push.main, directory, registry=registry)
    host.transport = scoped  # the agent owns the real transport; the host closes this view of it
    try:
        runtime = host.build(node, scoped)
    except Exception as exc:  # any error, a plugin's included: the old node keeps running
        scoped.stop()
        raise Refused(describe_error(exc, directory)) from None
    return host, runtime, scoped


def describe_error(error: BaseException, directory: Path) -> str:
    """One line per problem, file paths relative to the bundle."""
    if isinstance(error, ConfigError):
        name = os.path.relpath(error.file, directory) if os.path.isabs(error.file) else error.file
        return f"{Path(name).as_posix()}:{error.line}:{error.column}: {error.xpath}: {error.message}"
    text = str(error) or type(error).__name__
    return text if isinstance(error, (ValueError, OSError)) else f"{type(error).__name__}: {text}"
