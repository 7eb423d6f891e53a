"""Live service handles: how a behavior reaches a Smart Resource service over the network (§4.3).

A behavior configures the *service's own instance* (client ``""``): the mission sets the
service's parameters and quality requirements (§4.4, docs/decisions.md D47), and reads the
service's configured output topics and quality messages. Requests are fire-and-forget with
their acknowledgement recorded, so a mission step never waits on the network.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import threading
import time
from collections.abc import Mapping
from typing import Any

from ckmconf.model.resources import Service, SmartResource

from ..network.api import Sample, Subscription, TopicQoS, Transport
from ..resources import codec
from ..resources.api import Bounds, check_parameter, topics

WINDOW = 50
RESEND_PERIOD = 0.25
RESENDS = 40  # 10 s of resending, then the request is given up and reported in ``errors``


class NetworkServiceHandle:
    """One service, as every behavior of this agent sees it, reached through the service API (§4.3)."""

    _ids = itertools.count(1)

    def __init__(self, transport: Transport, resource: SmartResource, service: Service, *, stale: float = 3.0) -> None:
        self.ref = f"{resource.name}.{service.name}"
        self.service = service
        self.stale = stale
        self._lock = threading.Lock()
        self._outputs: dict[str, tuple[Any, int]] = {}  # value, and the ask it was heard in (0: none)
        self._measures: dict[str, float] = {}
        self._samples: dict[str, collections.deque[float]] = {}
        self._heard = -1e9
        self.scenario: str | None = None
        self.acks: dict[int, dict[str, Any]] = {}
        self._pending: tuple[dict[str, Any], int] | None = None
        self._wake, self._closed = threading.Event(), threading.Event()
        threading.Thread(target=self._resend, name=f"resend-{self.ref}", daemon=True).start()
        self.errors: list[str] = []
        qos = topics(resource, service)
        self._config = transport.publisher(qos["config"])
        # the outputs are observed only until a state using the service asks for them (D245)
        self._by_output: dict[str, Subscription] = {}  # filled one by one: a sample may arrive meanwhile
        for o in service.outputs:
            topic = TopicQoS(o.topic, "ckm/service-data")
            self._by_output[o.name] = transport.subscribe(topic, self._output(o.name), passive=True)
        self.outputs = list(self._by_output.values())
        # a lazy service's results from before it rested are not news when it is asked again (D249)
        self.lazy = service.lazy and bool(self.outputs)
        self._asks = self._ask_count()
        self._subscriptions = [transport.subscribe(qos["quality"], self._on_quality), *self.outputs]

    def _output(self, name: str) -> Any:
        def store(sample: Sample) -> None:
            try:
                value = codec.decode(sample.value)
            except ValueError:
                return  # a malformed sample is not a value
            subscription = self._by_output.get(name)
            ask = 0 if subscription is None or subscription.passive else subscription.asks
            with self._lock:
                self._outputs[name] = (value, ask)
                self._heard = time.monotonic()

        return store

    def _on_quality(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict) or message.get("client") != "":
            return
        with self._lock:
            self._heard = time.monotonic()
            self._forget_rested()
            if message.get("type") == "ack" and isinstance(message.get("id"), int):
                self.acks[message["id"]] = message
                if not message.get("accepted"):
                    self.errors.extend(str(e) for e in message.get("errors") or ())
            measures = message.get("measures")
            if message.get("type") == "quality" and isinstance(message.get("scenario"), str):
                self.scenario = message["scenario"]
            if message.get("type") == "quality" and isinstance(measures, dict) and self._awake():
                for name, value in measures.items():
                    if isinstance(value, int | float) and not isinstance(value, bool):
                        self._measures[name] = float(value)
                        self._samples.setdefault(name, collections.deque(maxlen=WINDOW)).append(float(value))

    # ------------------------------------------------------------------ ServiceHandle

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        """Send Configure/Require to the service's own instance (§4.3), resent until acknowledged."""
        typed: dict[str, Any] = {}
        known = {p.name: p for p in self.service.parameters}
        for name, raw in parameters.items():
            parameter = known.get(name)
            value: Any = raw
            if parameter is not None and parameter.type in ("int", "float") and isinstance(raw, str):
                with contextlib.suppress(ValueError):  # else the service refuses it with the reason
                    value = float(raw)
            elif parameter is not None and parameter.type == "bool" and isinstance(raw, str):
                value = raw.strip().lower() in ("true", "1", "yes")
            if parameter is not None:
                converted, error = check_parameter(parameter, value)
                value = converted if error is None else value
            typed[name] = value
        message = {
            "op": "configure",
            "client": "",
            "id": next(self._ids),
            "parameters": typed,
            "requirements": [b.to_message() for b in requirements],
        }
        with self._lock:
            self._pending = (message, RESENDS)
        self._config.publish(message)
        self._wake.set()

    def _resend(self) -> None:
        """Resend the newest request until it is acknowledged (the service applies a repeated id once):
        a request sent before the service's config topic was linked would otherwise be lost."""
        while not self._closed.is_set():
            self._wake.wait(RESEND_PERIOD)
            self._wake.clear()
            if self._closed.wait(RESEND_PERIOD):
                return
            with self._lock:
                if self._pending is None:
                    continue
                message, left = self._pending
                if message["id"] in self.acks or left <= 0:
                    if left <= 0:
                        self.errors.append(f"{self.ref}: no answer to configure #{message['id']}")
                    self._pending = None
                    continue
                self._pending = (message, left - 1)
            self._config.publish(message)

    def _ask_count(self) -> int:
        return sum(s.asks for s in self.outputs)

    def _forget_rested(self) -> None:
        """Asked again: a lazy service's measures from before are forgotten (D249). Under the lock."""
        asks = self._ask_count()
        if self.lazy and asks != self._asks:
            self._measures.clear()
            self._samples.clear()
        self._asks = asks

    def _awake(self) -> bool:
        """Whether a lazy service published a result since it was last asked for: its quality
        messages meanwhile repeat the measures of its last result before it rested (D249)."""
        return not self.lazy or any(s.heard_since_ask() for s in self.outputs)

    def output(self, name: str) -> Any:
        """Newest value the service published on output ``name`` (None before the first; for a
        lazy service, None until its first since the output was last asked for, D249)."""
        with self._lock:
            value, ask = self._outputs.get(name, (None, 0))
        subscription = self._by_output.get(name)
        if self.lazy and subscription is not None and (subscription.passive or ask != subscription.asks):
            return None
        return value

    def measures(self) -> dict[str, float]:
        """Newest value of each quality measure the service reported (§4.2.1.1)."""
        with self._lock:
            self._forget_rested()
            return dict(self._measures)

    def samples(self, measure: str) -> list[float]:
        """Recent values of ``measure`` (the service state of eq. 5.1)."""
        with self._lock:
            self._forget_rested()
            return list(self._samples.get(measure, ()))

    def running(self) -> bool:
        """True if the service was heard from within ``stale`` seconds."""
        with self._lock:
            return time.monotonic() - self._heard < self.stale

    def close(self) -> None:
        """Stop resending and close every subscription."""
        self._closed.set()
        self._wake.set()
        for subscription in self._subscriptions:
            subscription.close()
