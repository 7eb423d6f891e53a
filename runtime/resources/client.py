"""The client side of the service API (§4.3): discover services, connect, configure, consume.

A behavior, a mission, the editor or a benchmark uses it from any node of the network::

    directory = ServiceDirectory(transport)
    entry = directory.wait_for("RGBDCamera", "RGBRecog", timeout=5)
    with ServiceClient(transport, entry, "nav-1") as client:
        client.connect(requirements=[Bounds("deadline", upper=0.02)])
        sample = client.data("objects").latest()

Every method that waits takes a timeout; answers are matched to requests by ``id``.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from ..network.api import Sample, Subscription, TopicQoS, Transport
from . import codec
from .api import DIRECTORY_TOPIC, Bounds, client_topic

Entry = Mapping[str, Any]


class ServiceError(RuntimeError):
    """The service refused a request, or did not answer in time."""


class ServiceDirectory:
    """The services announced on the network (service API, §4.3), by (resource, service)."""

    def __init__(self, transport: Transport) -> None:
        self._entries: dict[tuple[str, str], dict[str, Any]] = {}
        self._changed = threading.Condition()
        self._subscription = transport.subscribe(TopicQoS(DIRECTORY_TOPIC, "ckm/service", history=64), self._on_entry)

    def _on_entry(self, sample: Sample) -> None:
        entry = sample.value
        if not isinstance(entry, dict) or entry.get("type") != "service":
            return
        resource, service = entry.get("resource"), entry.get("service")
        if not isinstance(resource, str) or not isinstance(service, str):
            return
        with self._changed:
            self._entries[(resource, service)] = entry
            self._changed.notify_all()

    def services(self) -> dict[tuple[str, str], dict[str, Any]]:
        """Every service announced so far, by (resource, service), with its announcement."""
        with self._changed:
            return dict(self._entries)

    def wait_for(self, resource: str, service: str, timeout: float) -> dict[str, Any]:
        """The announcement of ``resource.service``; ServiceError naming those seen if none in time."""
        with self._changed:
            if not self._changed.wait_for(lambda: (resource, service) in self._entries, timeout):
                known = ", ".join(f"{r}.{s}" for r, s in sorted(self._entries)) or "none"
                raise ServiceError(f"no service {resource}.{service} announced within {timeout:g} s (seen: {known})")
            return self._entries[(resource, service)]

    def close(self) -> None:
        """Stop listening to the announcements."""
        self._subscription.close()


class ServiceClient:
    """One client of one service (§4.3): its requests, its data, its quality messages, events and alarms."""

    _ids = itertools.count(1)

    def __init__(
        self,
        transport: Transport,
        entry: Entry,
        client: str,
        on_message: Callable[[dict[str, Any]], None] | None = None,
    ) -> None:
        self.transport, self.entry, self.client = transport, entry, client
        self.on_message = on_message
        self.acks: dict[int, dict[str, Any]] = {}
        self.quality: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []
        self.alarms: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        self._config = transport.publisher(TopicQoS(entry["config"], "ckm/service-config", history=32))
        self._subs = [
            transport.subscribe(TopicQoS(entry["quality"], "ckm/service-quality", history=64), self._on_message),
            transport.subscribe(TopicQoS(entry["alarms"], "ckm/service-alarm", history=32), self._on_message),
        ]
        self._data: dict[str, Subscription] = {}

    def _on_message(self, sample: Sample) -> None:
        message = sample.value
        if not isinstance(message, dict) or message.get("client") != self.client:
            return
        kind = message.get("type")
        with self._cond:
            if kind == "ack" and isinstance(message.get("id"), int):
                self.acks[message["id"]] = message
            elif kind == "quality":
                self.quality.append(message)
            elif kind == "event":
                self.events.append(message)
            elif kind == "alarm":
                self.alarms.append(message)
            self._cond.notify_all()
        if self.on_message is not None:
            self.on_message(message)

    # ------------------------------------------------------------------ requests

    def request(
        self,
        op: str,
        *,
        parameters: Mapping[str, Any] | None = None,
        requirements: Iterable[Bounds] | None = None,
        timeout: float = 5.0,
        retry: float = 0.5,
    ) -> dict[str, Any]:
        """Send a request and wait for its acknowledgement (resent every ``retry`` s until ``timeout``)."""
        request_id = next(self._ids)
        message: dict[str, Any] = {"op": op, "client": self.client, "id": request_id}
        if parameters:
            message["parameters"] = dict(parameters)
        if requirements is not None:
            message["requirements"] = [b.to_message() for b in requirements]
        end = time.monotonic() + timeout
        with self._cond:
            while request_id not in self.acks:
                remaining = end - time.monotonic()
                if remaining <= 0:
                    raise ServiceError(
                        f"{self.entry['resource']}.{self.entry['service']} did not answer {op} within {timeout:g} s"
                    )
                self._config.publish(message)
                self._cond.wait(min(retry, remaining))
            ack = self.acks.pop(request_id)
        if not ack.get("accepted"):
            raise ServiceError(f"{op} refused: " + "; ".join(map(str, ack.get("errors") or [])))
        return ack

    def connect(self, **kwargs: Any) -> dict[str, Any]:
        """Send ``connect`` (§4.3) with :meth:`request`'s arguments; returns the acknowledgement."""
        ack = self.request("connect", **kwargs)
        return ack

    def configure(self, **kwargs: Any) -> dict[str, Any]:
        """Send ``configure`` (new parameters and/or requirements); returns the acknowledgement."""
        return self.request("configure", **kwargs)

    def disconnect(self, timeout: float = 5.0) -> dict[str, Any]:
        """Send ``disconnect``: the service drops this client's instance; returns the acknowledgement."""
        return self.request("disconnect", timeout=timeout)

    # ------------------------------------------------------------------ data and quality

    def data(self, output: str, callback: Callable[[Any], None] | None = None) -> Subscription:
        """The subscription to this client's copy of ``output`` (values decoded with the codec)."""
        if output not in self.entry["outputs"]:
            raise ServiceError(f"{self.entry['service']} has no output {output!r} ({', '.join(self.entry['outputs'])})")
        if output not in self._data:
            topic = client_topic(self.entry["outputs"][output], self.client)
            wrapped = None if callback is None else (lambda sample: callback(codec.decode(sample.value)))
            self._data[output] = self.transport.subscribe(TopicQoS(topic, "ckm/service-data"), wrapped)
        return self._data[output]

    def wait(self, predicate: Callable[[ServiceClient], bool], timeout: float) -> bool:
        """Wait until ``predicate(self)`` holds (checked on every message received)."""
        with self._cond:
            return self._cond.wait_for(lambda: predicate(self), timeout)

    def close(self) -> None:
        """Close the client's subscriptions (config acks, data, quality); does not disconnect."""
        for subscription in (*self._subs, *self._data.values()):
            subscription.close()

    def __enter__(self) -> ServiceClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
