"""Delegation of an SPT processing plugin to an idle node (§3.1.2.5–6, "code delegation"): the giver.

The messages are :mod:`runtime.resources.delegation_protocol`; the taker that runs a delegated
plugin is :class:`runtime.resources.plugin_host.PluginHost` (both re-exported here).

Atomic handover. ``DelegatedPlugin`` stands in for the plugin in the Topology and serialises its
calls and its switches on one lock, so each ``process()`` call runs on exactly one side and a
switch falls between two calls: for a plugin used once per frame, at a frame boundary (a plugin
used in several chains of one frame may switch between them; its state moves with the switch, so
its results are the same either way). Every call gets exactly one result, never none and never
two, because a remote call that does not succeed falls back locally before returning.

Fallback. RESULT carries the plugin's state after that call, so the giver always holds the state
after the last call it accepted. If an answer is late, an ERROR, or malformed, the giver restores
that state, computes the call itself, *revokes* the delegation (RELEASE; late answers are
dropped by ``seq``) and reports a ``delegation-fallback`` alarm. Revoking rather than retrying
keeps one authoritative history: the taker may have advanced past the accepted state with an
answer that got lost. The price is shipping the state with every result, which is small for the
plugins this targets (counters, filters, models updated per frame).
"""

from __future__ import annotations

import contextlib
import logging
import secrets
import threading
import time
from collections.abc import Callable, Hashable, Mapping
from typing import Any

from ckmconf.model.resources import SmartResource

from ..network.api import Publisher, Sample, Subscription, TopicQoS, Transport
from . import codec
from .delegation_protocol import (
    MAX_NAME,
    PREFIX,
    BadMessage,
    DelegationError,
    DelegationEvent,
    DelegationRefused,
    channel,
    describe,
    get_field,
    plugin_of,
)
from .plugin_host import PluginHost
from .spt import Context, ProcessingPlugin, Topology

LOG = logging.getLogger("ckm.plugin-delegation")
__all__ = [
    "MAX_NAME",
    "PREFIX",
    "BadMessage",
    "DelegatedPlugin",
    "DelegationError",
    "DelegationEvent",
    "DelegationRefused",
    "PluginHost",
    "channel",
    "describe",
    "plugin_of",
]


class _Mailbox:
    """Answers awaited by key; answers nobody waits for (late, forged) are dropped."""

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._wanted: set[Hashable] = set()
        self._got: dict[Hashable, dict[str, Any]] = {}

    def expect(self, key: Hashable) -> None:
        with self._cond:
            self._wanted.add(key)

    def deliver(self, key: Hashable, message: dict[str, Any]) -> bool:
        with self._cond:
            if key not in self._wanted:
                return False
            self._wanted.discard(key)
            self._got[key] = message
            self._cond.notify_all()
            return True

    def wait(self, key: Hashable, timeout: float) -> dict[str, Any] | None:
        with self._cond:
            self._cond.wait_for(lambda: key in self._got, max(0.0, timeout))
            self._wanted.discard(key)
            return self._got.pop(key, None)


class DelegatedPlugin(ProcessingPlugin):
    """Stands in for a local plugin; runs each call locally or on the node it was delegated to (§3.1.2.5–6).

    Install it with ``wrap()`` (before or while frames run: while local it only forwards to the
    original, so swapping mid-frame changes no result), then ``delegate()`` and ``recall()`` from
    any thread. ``frame_timeout`` bounds each remote call; past it the call falls back locally.
    """

    def __init__(
        self,
        inner: ProcessingPlugin,
        transport: Transport,
        node: str,
        *,
        timeout: float = 5.0,
        frame_timeout: float = 1.0,
        on_event: Callable[[DelegationEvent], None] | None = None,
        resource: SmartResource | None = None,
    ) -> None:
        """``resource``: the giver's record, whose name and services the offer's text carries (D195)."""
        # No super().__init__: the original already read and checked the params.
        self.record, self.name, self.params = inner.record, inner.name, inner.params
        self.resource = resource
        self.inner = inner
        self.transport = transport
        self.node = node
        self.timeout = timeout
        self.frame_timeout = frame_timeout
        self.on_event = on_event
        self.events: list[DelegationEvent] = []
        self.local_calls = 0
        self.remote_calls = 0
        self._reply = TopicQoS(f"{PREFIX}{node}/reply/{self.name}/{secrets.token_hex(4)}", "plugin-delegation")
        self._call = threading.RLock()  # one call or one switch at a time: a call runs on one side
        self._switching = threading.Lock()  # one delegate() at a time
        self._mail = _Mailbox()
        self._subscription: Subscription | None = None
        # The delegation: LOCAL (taker None) → ARMED (taker set, not started) → REMOTE (started).
        self._taker: str | None = None
        self._id = ""
        self._out: Publisher | None = None
        self._started = False
        self._go_state: Any = None  # encoded state the next call ships with GO, if any
        self._mirror: Any = None  # encoded state after the last accepted remote call
        self._seq = 0

    @classmethod
    def wrap(cls, topology: Topology, name: str, transport: Transport, node: str, **options: Any) -> DelegatedPlugin:
        """Put a DelegatedPlugin in place of plugin ``name`` of ``topology`` (in every profile tree)."""
        original = topology.plugins.get(name)
        if original is None:
            known = ", ".join(topology.plugins) or "none"
            raise ValueError(f"resource {topology.name!r} has no plugin {name!r} (plugins: {known})")
        if isinstance(original, DelegatedPlugin):
            return original
        wrapper = cls(original, transport, node, resource=topology.resource, **options)
        _swap(topology, original, wrapper)
        return wrapper

    def unwrap(self, topology: Topology) -> ProcessingPlugin:
        """Recall if needed and put the original plugin back in ``topology``."""
        self.recall()
        _swap(topology, self, self.inner)
        return self.inner

    @property
    def taker(self) -> str | None:
        """The node the plugin is delegated to, or None while it runs here."""
        return self._taker

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Set up the wrapped local plugin."""
        self.inner.setup()

    def stop(self) -> None:
        """Recall a delegated plugin, stop listening to its taker and stop the local plugin."""
        self.recall()
        if self._subscription is not None:
            self._subscription.close()
            self._subscription = None
        self.inner.stop()

    def state(self) -> dict[str, Any]:
        """The plugin's state: the local one, or the mirror of the state the taker last returned."""
        with self._call:
            if not self._started:
                return self.inner.state()
            state: dict[str, Any] = codec.decode(self._mirror)
            return state

    def restore(self, state: Mapping[str, Any]) -> None:
        """Restore the local plugin and, while delegated, ship ``state`` with the next call."""
        with self._call:
            self.inner.restore(state)
            if self._started:  # the next call ships it: GO restores before processing
                self._go_state = self._mirror = codec.encode(dict(state))

    # ------------------------------------------------------------------ switching

    def delegate(self, taker: str, timeout: float | None = None) -> None:
        """Offer the plugin to ``taker``; once it is READY, the next call runs there.

        Raises DelegationRefused with the taker's reason, or DelegationError if nobody answers;
        either way the plugin keeps running here.
        """
        timeout = self.timeout if timeout is None else timeout
        deadline = time.monotonic() + timeout
        with self._switching:
            if self._taker is not None:
                raise DelegationError(f"plugin {self.name!r} is already delegated to {self._taker!r}")
            if self._subscription is None:
                self._subscription = self.transport.subscribe(self._reply, self._on_reply)
            target = channel(taker)
            out = self.transport.publisher(target)
            self.transport.wait_for_subscribers(target.name, 1, timeout)  # the taker's host, if any
            ident = secrets.token_hex(8)
            try:
                with self._call:
                    state = codec.encode(self.inner.state())
            except codec.CodecError as exc:
                raise DelegationError(
                    f"cannot delegate plugin {self.name!r}: its state cannot be sent: {exc}"
                ) from None
            self._mail.expect(("offer", ident))
            offer = {"op": "offer", "id": ident, "from": self.node, "reply": self._reply.name}
            out.publish(offer | {"plugin": describe(self.record, self.node, self.resource), "state": state})
            answer = self._mail.wait(("offer", ident), deadline - time.monotonic())
            if answer is None:
                out.publish({"op": "release", "id": ident})  # in case it was built after all
                reason = f"node {taker!r} did not answer within {timeout:g} s (is a PluginHost running there?)"
                self._report("delegation-timeout", taker, reason)
                raise DelegationError(f"cannot delegate plugin {self.name!r}: {reason}")
            if answer["op"] != "ready":
                reason = str(answer.get("reason", "no reason given"))
                self._report("delegation-refused", taker, reason)
                raise DelegationRefused(f"node {taker!r} refused plugin {self.name!r}: {reason}")
            with self._call:
                self._taker, self._id, self._out, self._started = taker, ident, out, False

    def recall(self, timeout: float | None = None) -> None:
        """Bring the plugin back: RELEASE, then continue here from the taker's final state."""
        with self._call:
            if self._taker is None or self._out is None:
                return
            taker, key = self._taker, ("released", self._id)
            self._mail.expect(key)
            self._out.publish({"op": "release", "id": self._id})
            answer = self._mail.wait(key, self.frame_timeout if timeout is None else timeout)
            if self._started:  # else the local plugin never stopped being the authority
                final = codec.decode(self._mirror)  # equal to RELEASED's state; used if that one is lost or bad
                with contextlib.suppress(ValueError):
                    released = codec.decode(answer.get("state")) if answer is not None else None
                    final = released if isinstance(released, dict) else final
                self.inner.restore(final)
            self._forget()
            self._report("recalled", taker)

    # ------------------------------------------------------------------ calls

    def process(self, data: Any, context: Context) -> Any:
        """One SPT call (§3.2.2), locally or on the taker (local fallback past ``frame_timeout``)."""
        with self._call:
            if self._taker is None:
                self.local_calls += 1
                return self.inner.process(data, context)
            return self._remote(data, context)

    def _remote(self, data: Any, context: Context) -> Any:
        assert self._out is not None
        try:
            if not self._started:  # the switch: GO carries the state after the last local call
                self._go_state = self._mirror = codec.encode(self.inner.state())
            payload = codec.encode(data)
        except codec.CodecError as exc:
            return self._fallback(data, context, f"cannot send the input or state: {exc}")
        self._seq += 1
        key = ("result", self._id, self._seq)
        message = {"op": "process", "id": self._id, "seq": self._seq, "frame": context.frame}
        message |= {"stamp": context.stamp, "resource": context.resource, "data": payload}
        if self._go_state is not None:
            message |= {"op": "go", "state": self._go_state}
        self._mail.expect(key)
        self._out.publish(message)
        answer = self._mail.wait(key, self.frame_timeout)
        if answer is None:
            return self._fallback(data, context, f"no answer within {self.frame_timeout:g} s")
        if answer["op"] != "result":
            return self._fallback(data, context, f"the taker failed: {answer.get('reason', 'no reason given')}")
        try:
            result = codec.decode(get_field(answer, "result"))
            if not isinstance(codec.decode(get_field(answer, "state")), dict):  # a fallback must be able to restore it
                raise BadMessage("the state is not a dict")
        except ValueError as exc:
            return self._fallback(data, context, f"bad answer: {exc}")
        self._mirror, self._go_state = answer["state"], None
        self.remote_calls += 1
        if not self._started:
            self._started = True
            self._report("delegated", self._taker or "")
        return result

    def _fallback(self, data: Any, context: Context, reason: str) -> Any:
        """Revoke the delegation and compute this call here, from the last accepted state."""
        taker = self._taker or ""
        if self._out is not None:
            self._out.publish({"op": "release", "id": self._id})
        if self._mirror is not None:
            self.inner.restore(codec.decode(self._mirror))
        self._forget()
        self._report("delegation-fallback", taker, reason)
        self.local_calls += 1
        return self.inner.process(data, context)

    def _forget(self) -> None:
        self._taker, self._id, self._out, self._started = None, "", None, False
        self._go_state = self._mirror = None

    def _on_reply(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict):
            return
        op, ident, seq = message.get("op"), message.get("id"), message.get("seq")
        if not isinstance(ident, str) or not (seq is None or isinstance(seq, int)):
            return  # not ours; and keys must stay hashable
        if op in ("ready", "refuse"):
            key: Hashable = ("offer", ident)
        elif op in ("result", "error"):
            key = ("result", ident, seq)
        elif op == "released":
            key = ("released", ident)
        else:
            return
        if not self._mail.deliver(key, message):
            LOG.debug("plugin %s: dropped an unexpected %r (late or foreign)", self.name, op)

    def _report(self, kind: str, peer: str, reason: str = "") -> None:
        event = DelegationEvent(kind, self.name, peer, reason)
        self.events.append(event)
        level = logging.INFO if kind in ("delegated", "recalled") else logging.WARNING
        LOG.log(level, "plugin %s: %s %s %s", self.name, kind, peer, reason)
        if self.on_event is not None:
            self.on_event(event)


def _swap(topology: Topology, old: ProcessingPlugin, new: ProcessingPlugin) -> None:
    """Replace ``old`` by ``new`` in the topology's plugin table and composition trees."""
    for plan in topology.profiles.values():
        for _, node in plan.tree.walk():
            if node.plugin is old:
                node.plugin = new
    topology.plugins[old.name] = new
