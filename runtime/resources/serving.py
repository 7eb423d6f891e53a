"""The service instances of a Smart Resource and the service API requests that manage them (thesis §4.3).

Each service with scenarios runs one :class:`~runtime.resources.instance.Instance` per client,
plus its own (client ``""``). A client's ``connect`` request creates its instance (starting at
the operating point the others have been pushed to, :meth:`ServiceInstances._joining_scenario`),
``configure`` changes its parameters and quality requirements, ``disconnect`` removes it; every
request is answered with an ``ack`` on the service's quality topic, a resent one (same request id)
answered again but applied once. Service parameters are forwarded to the plugins of the service's
profiles that take them (``apply_service_parameters``).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

from ckmconf.model.resources import Service, SmartResource

from ..network.api import Publisher, Sample, Transport
from . import api
from .api import Request, parse_request, preferred_scenario
from .instance import Instance
from .selection import SelectorFactory
from .stream import Stream

LOG = logging.getLogger("ckm.resources")


class ServiceInstances:
    """The instances of one Smart Resource's services and the requests of its service API (§4.3).

    A mixin of :class:`runtime.resources.resource.SmartResourceRuntime`, which sets the attributes
    declared here.
    """

    resource: SmartResource
    transport: Transport
    selector: SelectorFactory
    share: bool
    max_clients: int
    streams: dict[str, Stream]
    _service_stream: dict[str, Stream]
    _pub: dict[str, dict[str, Publisher]]
    _lock: threading.Lock
    _answered: dict[tuple[str, str], tuple[int, dict[str, Any]]]
    _start_time: float

    def now(self) -> float:
        """Seconds since :meth:`start` (the time base of the TCM)."""
        return time.monotonic() - self._start_time

    def _sender(self, service: str) -> Callable[[str, dict[str, Any]], None]:
        def send(kind: str, message: dict[str, Any]) -> None:
            publisher = self._pub.get(service, {}).get(kind)
            if publisher is not None:
                publisher.publish(message)
            if message.get("type") in ("event", "alarm"):
                LOG.info("%s.%s %s: %s", self.resource.name, service, message["type"], message)

        return send

    def _add(self, instance: Instance) -> None:
        stream = self._service_stream[instance.service.name]
        with stream.lock:
            stream.instances[instance.key] = instance
        stream.topology.select(instance.key, instance.profile, share=self.share)

    def statistics(self) -> dict[str, Any]:
        """Per instance (by key) and per stream (by acquisition plugin): what a run record keeps (stats.json)."""
        return {
            "instances": {i.key: i.statistics() for i in self.instances()},
            "streams": {root: stream.statistics() for root, stream in self.streams.items()},
        }

    def instances(self) -> list[Instance]:
        """Every live service instance, the services' own and the clients' replicas."""
        return [i for stream in self.streams.values() for i in list(stream.instances.values())]

    def instance(self, service: str, client: str = "") -> Instance | None:
        """The instance of ``service`` for ``client`` (``""``: the service's own), None if absent."""
        stream = self._service_stream.get(service)
        key = service if not client else f"{service}/{client}"
        return None if stream is None else stream.instances.get(key)

    def _on_request(self, service: Service, sample: Sample) -> None:
        request, errors = parse_request(service, sample.value)
        if request is None:
            client = sample.value.get("client") if isinstance(sample.value, Mapping) else None
            self._answer(service, client, sample.value, errors)
            LOG.warning("%s.%s: refused a request: %s", self.resource.name, service.name, "; ".join(errors))
            return
        with self._lock:
            key = (service.name, request.client)
            repeated = request.request_id and self._answered.get(key, (0, None))[0] == request.request_id
            if repeated:  # a client resending a request it has no answer for: answer again, apply once
                self._pub[service.name]["quality"].publish(self._answered[key][1])
                return
            errors = self._apply(service, request)
            answer = self._answer(service, request.client, sample.value, errors, request)
            self._answered[key] = (request.request_id, answer)

    def _apply(self, service: Service, request: Request) -> list[str]:
        existing = self.instance(service.name, request.client)
        if request.op == "disconnect":
            if not request.client:
                return ["the service's own instance cannot be disconnected"]
            if existing is None:
                return [f"client {request.client!r} is not connected"]
            stream = self._service_stream[service.name]
            with stream.lock:
                stream.instances.pop(existing.key, None)
            stream.topology.release(existing.key)
            return []
        if existing is None:
            if request.op == "configure":
                return [f"client {request.client!r} is not connected (send op=connect first)"]
            clients = sum(1 for i in self.instances() if i.service.name == service.name and i.client)
            if clients >= self.max_clients:
                return [f"service {service.name} already has its {self.max_clients} clients"]
            instance = Instance(
                self.resource.name,
                service,
                request.client,
                self.transport,
                self._sender(service.name),
                initial=self._joining_scenario(service, request.parameters),
                requirements=request.requirements or (),
                parameters=request.parameters,
                selector=self.selector,
            )
            problems = self._forward(service, request.parameters)
            if problems:
                return problems
            if request.requirements:
                instance.configure({}, request.requirements, self.now())
            self._add(instance)
            return []
        problems = self._forward(service, request.parameters)
        if problems:
            return problems
        existing.configure(request.parameters, request.requirements, self.now())
        self._service_stream[service.name].topology.select(existing.key, existing.profile, share=self.share)
        return []

    def _forward(self, service: Service, parameters: Mapping[str, Any]) -> list[str]:
        """Hand the parameters to the plugins of the service's profiles that take service parameters."""
        if not parameters:
            return []
        stream = self._service_stream[service.name]
        wanted = {s.profile for s in service.scenarios}
        names = {n for p in self.resource.profiles if p.name in wanted for n in p.root.plugins()}
        problems = []
        for name in sorted(names):
            apply = getattr(stream.topology.plugins.get(name), "apply_service_parameters", None)
            if apply is None:
                continue
            try:
                apply(dict(parameters))
            except ValueError as exc:
                problems.append(str(exc))
        return problems

    def _joining_scenario(self, service: Service, parameters: Mapping[str, Any]) -> str | None:
        """Where a new client's instance starts: its preference, or lower if the service's other
        instances have been pushed lower (joining at the current operating point, not above it,
        avoids a load spike that would hit every client); it may recover upwards as usual."""
        weights = {s.name: s.weight for s in service.scenarios}
        preferred = preferred_scenario(service, {p.name: p.default for p in service.parameters} | dict(parameters))
        ceiling = weights.get(preferred or "", max(weights.values()))
        others = [i.scenario for i in self.instances() if i.service.name == service.name]
        candidates = [name for name in others if weights[name] <= ceiling]
        if not candidates:
            return preferred
        return min(candidates, key=lambda name: weights[name])

    def _answer(
        self, service: Service, client: Any, message: Any, errors: list[str], request: Request | None = None
    ) -> dict[str, Any]:
        instance = self.instance(service.name, request.client) if request is not None else None
        answer: dict[str, Any] = {
            "type": "ack",
            "resource": self.resource.name,
            "service": service.name,
            "client": client if isinstance(client, str) else None,
            "op": message.get("op") if isinstance(message, Mapping) else None,
            "id": request.request_id if request is not None else api.request_id(message),
            "accepted": not errors,
            "errors": errors,
        }
        if instance is not None and not errors:
            answer.update(
                scenario=instance.scenario,
                profile=instance.profile,
                outputs={name: p.qos.name for name, p in instance.outputs.items()},
                parameters=dict(instance.parameters),
            )
        self._pub[service.name]["quality"].publish(answer)
        return answer
