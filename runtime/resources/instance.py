"""One client's instance of a Smart Resource service: its TCM, parameters, publishers and measures.

The service's own instance has client ``""`` and publishes on the configured output topics; a
client's instance (a *replica*, §7.2) publishes on ``OUTPUT/CLIENT``. Results travel in the
codec's plain form, under the Output topic's ROS 2 type when it has one (CDR on the wire, D194). Instances are driven by
:class:`runtime.resources.resource.SmartResourceRuntime`: the processing thread calls
:meth:`Instance.deliver` with each fresh result, the TCM thread calls :meth:`Instance.tick`.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from ckmconf.model.resources import TCM, Service

from ..network.api import Publisher, TopicQoS, Transport
from . import codec
from .api import Bounds, client_topic, preferred_scenario, typed_default
from .selection import Alarm, Decision, ScenarioEvent, ScenarioSelector, SelectorFactory
from .tcm import TaskConfiguringModule

KERNEL_MEASURES = ("deadline", "latency", "rate", "cpu", "memory")
"""Measures the runtime takes itself (a QualityMeasure's ``source``); any other source is a result field."""

ALARM_AFTER = 3
"""TCM evaluations with no scenario holding before a service raises an alarm (docs/decisions.md D55)."""

Send = Callable[[str, dict[str, Any]], None]
"""Publishes a message on the service's ``quality`` or ``alarms`` topic."""

SERVICE_DATA = "ckm/service-data"
"""The type a service result travels under when its Output topic is of no type the wire codes."""


def output_type(transport: Transport, topic: str) -> str:
    """The type an Output's results travel under: the ROS 2 type the topic is declared with when the
    transport's wire codec carries it (``runtime.ros.wire.CdrWire.topic_type``: CDR on the wire, as
    any producer of that topic sends; decision D194), else :data:`SERVICE_DATA` (msgpack).

    A replica's copy (``OUTPUT/CLIENT``) travels as its Output does.
    """
    named = getattr(getattr(transport, "codec", None), "topic_type", None)
    found = named(topic) if callable(named) else None
    return found if isinstance(found, str) and found else SERVICE_DATA


@dataclass
class MeasureLog:
    """Last value and count of each measure of an instance (for the quality messages and reports)."""

    last: dict[str, float] = field(default_factory=dict)
    count: dict[str, int] = field(default_factory=dict)

    def add(self, name: str, value: float) -> None:
        """Record one value of measure ``name``."""
        self.last[name] = value
        self.count[name] = self.count.get(name, 0) + 1


class Instance:
    """A service run for one client, with its own TCM (§4.2.1.5; see the module docstring)."""

    def __init__(
        self,
        resource: str,
        service: Service,
        client: str,
        transport: Transport,
        send: Send,
        *,
        initial: str | None = None,
        requirements: tuple[Bounds, ...] = (),
        parameters: Mapping[str, Any] | None = None,
        selector: SelectorFactory = TaskConfiguringModule,
    ) -> None:
        """``selector`` builds what selects the active scenario: the TCM, unless a benchmark injects another."""
        if not service.scenarios:
            raise ValueError(f"service {resource}.{service.name} has no scenarios")
        self.resource, self.service, self.client = resource, service, client
        self.key = service.name if not client else f"{service.name}/{client}"
        self.parameters: dict[str, Any] = {
            p.name: typed_default(p) for p in service.parameters if p.default is not None
        }
        self.parameters.update(parameters or {})
        preferred = preferred_scenario(service, self.parameters)
        initial = initial or preferred
        tcm = service.tcm or TCM(learning="none")  # one scenario and no TCM: a fixed profile
        settings = tcm if initial is None else dataclasses.replace(tcm, initial=initial)
        self.tcm: ScenarioSelector = selector(
            service.scenarios,
            settings,
            requirements=requirements,
            on_event=self._event,
            on_alarm=self._alarm,
            alarm_after=ALARM_AFTER,
            combined=service.combinations(),
            resolutions={c.name: c.resolution for c in service.combined},
        )
        if preferred is not None:
            self.tcm.set_ceiling(preferred)
        self.requirements = requirements
        self._send = send
        self._lock = threading.Lock()
        self.outputs: dict[str, Publisher] = {
            o.name: transport.publisher(TopicQoS(client_topic(o.topic, client), output_type(transport, o.topic)))
            for o in service.outputs
        }
        self._sources = {m.source: m.name for m in service.measures if m.source not in KERNEL_MEASURES}
        self._kernel_measures = {m.source: m.name for m in service.measures if m.source in KERNEL_MEASURES}
        self._last_publication: float | None = None
        self.measures = MeasureLog()
        self.published = 0
        self.events: list[ScenarioEvent] = []
        self.alarms: list[Alarm] = []
        self._now = 0.0

    def statistics(self) -> dict[str, Any]:
        """The figures a run record keeps of this instance: active scenario, results published, scenario switches."""
        return {"scenario": self.scenario, "published": self.published, "switches": self.tcm.switches}

    # ------------------------------------------------------------------ TCM

    @property
    def profile(self) -> str:
        """The SPT profile of the instance's active scenario."""
        with self._lock:
            return self.tcm.profile

    @property
    def scenario(self) -> str:
        """The instance's active scenario (chosen by its TCM, §4.2.1.5)."""
        with self._lock:
            return self.tcm.active

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...] | None, now: float) -> None:
        """New parameters and/or QR from the client: reselect at once, without penalty (eq. 4.7)."""
        with self._lock:
            self._now = now
            self.parameters.update(parameters)
            if requirements is not None:
                self.requirements = requirements
                self.tcm.set_requirements(requirements, now)
            preferred = preferred_scenario(self.service, parameters)
            if preferred is not None:
                self.tcm.prefer(preferred, now)

    def observe(self, measure: str, value: float) -> None:
        """A kernel measure (one of :data:`KERNEL_MEASURES`) under the service's name for it."""
        name = self._kernel_measures.get(measure)
        if name is not None and math.isfinite(value):
            with self._lock:
                self.tcm.observe(name, value)
                self.measures.add(name, value)

    def tick(self, now: float) -> Decision:
        """One TCM period: evaluate, then publish the quality message (events and alarms go out as they happen)."""
        with self._lock:
            self._now = now
            decision = self.tcm.evaluate(now)
            message = {
                "type": "quality",
                "resource": self.resource,
                "service": self.service.name,
                "client": self.client,
                "time": now,
                "scenario": decision.active,
                "profile": decision.profile,
                "measures": self._measures(),
                "probabilities": {
                    c.measure: c.probability
                    for e in (decision.evaluations.get(decision.active),)
                    if e is not None
                    for c in e.conditions
                    if c.kind == "policy" and c.probability is not None
                },
                "penalties": self.tcm.penalties,
                "alarm": self.tcm.alarm_active,
                "published": self.published,
            }
        self._send("quality", message)
        return decision

    def _measures(self) -> dict[str, float]:
        """The last value of each measure; a combined one's is the sum of its components' (eq. 4.5)."""
        values = dict(self.measures.last)
        for combined in self.service.combined:
            parts = [values.get(name) for name in combined.measures]
            if all(v is not None for v in parts):
                values[combined.name] = sum(v for v in parts if v is not None)
        return values

    def _event(self, event: ScenarioEvent) -> None:  # called by the TCM, under self._lock
        self.events.append(event)
        self._send(
            "quality",
            {
                "type": "event",
                "resource": self.resource,
                "service": self.service.name,
                "client": self.client,
                "time": event.time,
                "from": event.previous,
                "to": event.current,
                "profile": event.profile,
                "reason": event.reason,
                "detail": event.detail,
                "penalty": event.penalty,
            },
        )

    def _alarm(self, alarm: Alarm) -> None:  # called by the TCM, under self._lock
        self.alarms.append(alarm)
        self._send(
            "alarms",
            {
                "type": "alarm",
                "resource": self.resource,
                "service": self.service.name,
                "client": self.client,
                "time": alarm.time,
                "raised": alarm.raised,
                "scenario": alarm.active,
                "unmet": list(alarm.unmet),
            },
        )

    # ------------------------------------------------------------------ data

    def deliver(self, value: Any, stamp: float, now_wall: float, latency: float | None = None) -> None:
        """Record the measures of a fresh result (``stamp``: its acquisition time, wall clock;
        ``latency``: its processing time), then publish it: a quality message sent after the
        result carries its measures (D249)."""
        if value is None:  # the kind has nothing yet (an input it needs has not arrived): no publication
            return
        ports = self.outputs
        if len(ports) == 1:
            items = [(next(iter(ports.values())), value)]
        elif isinstance(value, Mapping):
            items = [(ports[name], v) for name, v in value.items() if name in ports]
        else:
            items = []
        self.observe("deadline", now_wall - stamp)
        if latency is not None:
            self.observe("latency", latency)
        if self._last_publication is not None:
            self.observe("rate", now_wall - self._last_publication)
        self._last_publication = now_wall
        if isinstance(value, Mapping):
            for source, name in self._sources.items():
                field_value = value.get(source)
                if isinstance(field_value, int | float) and not isinstance(field_value, bool):
                    with self._lock:
                        self.tcm.observe(name, float(field_value))
                        self.measures.add(name, float(field_value))
        for publisher, item in items:
            publisher.publish(codec.encode(item), stamp=stamp)
        self.published += 1

    def resume(self) -> None:
        """A lazy stream wakes (D245): the rest is no period between two results (D249)."""
        self._last_publication = None
