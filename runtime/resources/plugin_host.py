"""The taker of SPT plugin delegation (§3.1.2.5–6): a node's PluginHost runs plugins other nodes give it.

The messages are :mod:`runtime.resources.delegation_protocol`. The host reads an offered plugin's
configuration text as ``ckm-validate`` reads a file (a bad one is refused with the located message,
D195), builds it through the registry, restores the offered state, and serves PROCESS calls in
order on one worker thread, returning each result with the plugin's state.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any

from ckmconf.model.resources import Plugin

from ..network.api import Publisher, Sample, Subscription, TopicQoS, Transport
from ..registry import Registry, default_registry
from . import codec
from .delegation_protocol import PREFIX, BadMessage, channel, get_field, plugin_of
from .spt import Context, ProcessingPlugin

LOG = logging.getLogger("ckm.plugin-delegation")


@dataclass
class _Hosted:
    plugin: ProcessingPlugin
    giver: str
    reply: Publisher
    started: bool = False


class PluginHost:
    """The taker of code delegation (§3.1.2.5–6): runs processing plugins delegated by other nodes, one worker thread.

    Requests are queued by the transport's thread and served in order by the worker, so a slow
    plugin never stalls the network (heartbeats, other topics). A giver has one request in flight
    per plugin (plus a RELEASE), so ``queue_size`` 32 serves ``max_plugins`` 16; when it is full a
    request is dropped and its giver falls back after its timeout. Bad messages are logged, kept in
    ``rejected``, answered with REFUSE/ERROR when they name a reply topic, and never raise.
    """

    def __init__(
        self,
        transport: Transport,
        node: str,
        registry: Registry | None = None,
        *,
        max_plugins: int = 16,
        max_bytes: int = codec.MAX_BYTES,
        queue_size: int = 32,
    ) -> None:
        self.transport = transport
        self.node = node
        self.registry = registry or default_registry()
        self.max_plugins = max_plugins
        self.max_bytes = max_bytes
        self.processed: Counter[str] = Counter()  # calls served, by plugin name
        self.rejected: deque[str] = deque(maxlen=100)  # why messages were refused or ignored
        self._hosted: dict[str, _Hosted] = {}
        self._queue: queue.Queue[dict[str, Any] | None] = queue.Queue(queue_size)
        self._subscription: Subscription | None = None
        self._worker: threading.Thread | None = None

    def start(self) -> None:
        """Start the worker thread and listen on this node's delegation channel."""
        self._worker = threading.Thread(target=self._serve, name=f"ckm-plugin-host-{self.node}", daemon=True)
        self._worker.start()
        self._subscription = self.transport.subscribe(channel(self.node), self._on_message)

    def stop(self, timeout: float = 2.0) -> None:
        """Stop listening, finish the queued request, stop every hosted plugin."""
        if self._subscription is not None:
            self._subscription.close()
            self._subscription = None
        if self._worker is not None:
            with contextlib.suppress(queue.Full):  # a worker stuck in a plugin: it is a daemon
                self._queue.put(None, timeout=timeout)
            self._worker.join(timeout)
            self._worker = None
        for hosted in self._hosted.values():
            self._stop_plugin(hosted)
        self._hosted.clear()

    def __enter__(self) -> PluginHost:
        self.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()

    @property
    def hosted(self) -> list[str]:
        """Names of the plugins run for other nodes."""
        return [h.plugin.name for h in list(self._hosted.values())]

    # ------------------------------------------------------------------ messages

    def _on_message(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict) or not isinstance(message.get("op"), str):
            self._reject(f"not a delegation message: {type(message).__name__}")
            return
        try:
            self._queue.put_nowait(message)
        except queue.Full:  # the giver times out and falls back: better than unbounded memory
            self._reject(f"queue full, {message['op']!r} dropped")

    def _serve(self) -> None:
        while (message := self._queue.get()) is not None:
            try:
                self._handle(message)
            except Exception as exc:  # a hostile request must never take the host down
                self._reject(f"{str(message.get('op'))[:40]!r}: {exc}")

    def _handle(self, message: dict[str, Any]) -> None:
        op = message["op"]
        if op == "offer":
            self._offer(message)
            return
        if op not in ("go", "process", "release"):
            raise BadMessage(f"unknown op {op[:40]!r}")
        ident = get_field(message, "id", str)
        hosted = self._hosted.get(ident)
        if hosted is None:
            raise BadMessage(f"no delegation {ident!r} on node {self.node!r}")
        if op == "release":
            del self._hosted[ident]
            state = self._stop_plugin(hosted)
            hosted.reply.publish({"op": "released", "id": ident, "state": state})
        else:
            self._process(ident, hosted, message)

    def _offer(self, message: dict[str, Any]) -> None:
        ident = get_field(message, "id", str)
        reply = get_field(message, "reply", str)
        if not reply.startswith(PREFIX):
            raise BadMessage(f"reply topic {reply!r} is not under {PREFIX}")
        publisher = self.transport.publisher(TopicQoS(reply, "plugin-delegation"))
        try:
            giver = get_field(message, "from", str)
            if ident in self._hosted:
                raise BadMessage(f"delegation {ident!r} already exists")
            if len(self._hosted) >= self.max_plugins:
                raise BadMessage(f"node {self.node!r} already runs {self.max_plugins} delegated plugins")
            record, cls = plugin_of(message.get("plugin"), giver, self.registry)  # refused where it is (D195)
            plugin = self._build(record, cls, get_field(message, "state", dict))
        except Exception as exc:
            self._reject(f"offer {ident!r} refused: {exc}")
            publisher.publish({"op": "refuse", "id": ident, "reason": str(exc)})
            return
        self._hosted[ident] = _Hosted(plugin, giver, publisher)
        # The giver subscribed to ``reply`` before offering; on a link that is already known.
        self.transport.wait_for_subscribers(reply, 1, 1.0)
        publisher.publish({"op": "ready", "id": ident})

    def _build(self, record: Plugin, cls: type[Any], state: Any) -> ProcessingPlugin:
        if not isinstance(cls, type) or not issubclass(cls, ProcessingPlugin):
            raise BadMessage(f"plugin kind {record.kind!r} is not a ProcessingPlugin on node {self.node!r}")
        plugin = cls(record)
        try:
            plugin.setup()
        except Exception as exc:
            raise BadMessage(f"setup of plugin {record.name!r} failed: {type(exc).__name__}: {exc}") from None
        try:
            plugin.restore(self._state(state))
        except Exception as exc:
            self._stop_plugin(plugin)
            raise BadMessage(f"plugin {record.name!r} cannot take the offered state: {exc}") from None
        return plugin

    def _process(self, ident: str, hosted: _Hosted, message: dict[str, Any]) -> None:
        seq = message.get("seq")
        try:
            seq = get_field(message, "seq", int)
            context = Context(
                get_field(message, "frame", int),
                float(get_field(message, "stamp", (int, float))),
                get_field(message, "resource", str),
            )
            data = self._decode(get_field(message, "data"))
            plugin = hosted.plugin
            if message["op"] == "go":
                plugin.restore(self._state(get_field(message, "state", dict)))
                hosted.started = True
            elif not hosted.started:
                raise BadMessage("PROCESS before GO")
            result = codec.encode(plugin.process(data, context), max_bytes=self.max_bytes)
            state = codec.encode(plugin.state(), max_bytes=self.max_bytes)
        except Exception as exc:
            self._reject(f"{message['op']} {ident!r}: {exc}")
            seq = seq if isinstance(seq, int) else None
            hosted.reply.publish({"op": "error", "id": ident, "seq": seq, "reason": f"{type(exc).__name__}: {exc}"})
            return
        self.processed[plugin.name] += 1  # counted before the answer: the giver may read it right after
        hosted.reply.publish({"op": "result", "id": ident, "seq": seq, "result": result, "state": state})

    def _decode(self, value: Any) -> Any:
        return codec.decode(value, max_bytes=self.max_bytes)

    def _state(self, value: Any) -> dict[str, Any]:
        state = self._decode(value)
        if not isinstance(state, dict):
            raise BadMessage(f"a state must be a dict, got {type(state).__name__}")
        return state

    def _stop_plugin(self, hosted: _Hosted | ProcessingPlugin) -> Any:
        plugin = hosted.plugin if isinstance(hosted, _Hosted) else hosted
        try:
            state = codec.encode(plugin.state(), max_bytes=self.max_bytes)
            plugin.stop()
        except Exception as exc:
            self._reject(f"stopping plugin {plugin.name!r}: {exc}")
            return None
        return state

    def _reject(self, reason: str) -> None:
        LOG.warning("plugin host %s: %s", self.node, reason)
        self.rejected.append(reason)
