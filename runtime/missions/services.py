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

from ..network.api import Sample, TopicQoS, Transport
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
        self._outputs: dict[str, Any] = {}
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
        self.outputs = [
            transport.subscribe(TopicQoS(o.topic, "ckm/service-data"), self._output(o.name), passive=True)
            for o in service.outputs
        ]
        self._subscriptions = [transport.subscribe(qos["quality"], self._on_quality), *self.outputs]

    def _output(self, name: str) -> Any:
        def store(sample: Sample) -> None:
            try:
                value = codec.decode(sample.value)
            except ValueError:
                return  # a malformed sample is not a value
            with self._lock:
                self._outputs[name] = value
                self._heard = time.monotonic()

        return store

    def _on_quality(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict) or message.get("client") != "":
            return
        with self._lock:
            self._heard = time.monotonic()
            if message.get("type") == "ack" and isinstance(message.get("id"), int):
                self.acks[message["id"]] = message
                if not message.get("accepted"):
                    self.errors.extend(str(e) for e in message.get("errors") or ())
            measures = message.get("measures")
            if message.get("type") == "quality" and isinstance(message.get("scenario"), str):
                self.scenario = message["scenario"]
            if message.get("type") == "quality" and isinstance(measures, dict):
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

    def output(self, name: str) -> Any:
        """Newest value the service published on output ``name`` (None before the first)."""
        with self._lock:
            return self._outputs.get(name)

    def measures(self) -> dict[str, float]:
        """Newest value of each quality measure the service reported (§4.2.1.1)."""
        with self._lock:
            return dict(self._measures)

    def samples(self, measure: str) -> list[float]:
        """Recent values of ``measure`` (the service state of eq. 5.1)."""
        with self._lock:
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
