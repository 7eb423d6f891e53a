"""A Smart Resource at run time (thesis §3.2, §4.2–4.3): SPT streams, service instances, the service API.

Streams (:mod:`runtime.resources.stream`). The profiles that share an acquisition plugin form a
stream: one Topology, one triple buffer (§3.2.3), frames grabbed once for all clients (§3.2.2).

Instances (:mod:`runtime.resources.serving`). Each service with scenarios runs one
:class:`Instance` per client: its own TCM picks the instance's scenario, hence the profile it
selects in the stream's topology. With ``share=True`` (the default) two instances on one profile
get the same result from one run (no duplicate processing); ``share=False`` reproduces the
thesis' replicated services, where every client costs its own processing below the acquisition.

Measures (a QualityMeasure's ``source``). ``deadline``: from acquisition to publication of a
fresh result (wall clock, s). ``latency``: the processing time of that frame (s). ``rate``: the
time between two fresh publications of the instance (s). ``cpu``: the CPU time of the stream's
processing thread over the TCM period, as a share of one CPU (``time.thread_time``: other work in
the process is not counted). ``memory``: the process's resident memory (MiB, psutil) at each TCM
period. Any other source is the field of the result it names (e.g. ``reliability``).

Service parameters reach the plugins of the service's profiles that take them: a plugin with an
``apply_service_parameters(parameters)`` method (fusion's ``max_sensors``) gets the service's
defaults at start and each instance's parameters whenever a client connects or configures. A
plugin runs once for all clients (§3.2.2), so the value configured last holds for all of them.

The service API (see :mod:`runtime.resources.api`): requests on the config topic, every answer,
the periodic quality messages and the scenario events on the quality topic, alarms on the alarm
topic, and a directory entry on :data:`~runtime.resources.api.DIRECTORY_TOPIC` every
``announce_period``.
"""

from __future__ import annotations

import dataclasses
import functools
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any

import psutil

from ckmconf.errors import ConfigError
from ckmconf.model.resources import TCM_PERIOD, Service, SmartResource

from ..network.api import Publisher, Subscription, TopicQoS, Transport
from ..registry import Registry
from .api import DIRECTORY_TOPIC, client_topic, describe, preferred_scenario, topics, typed_default
from .instance import Instance
from .selection import SelectorFactory
from .serving import ServiceInstances
from .spt import Topology
from .stream import Source, Stream, newest_of
from .tcm import TaskConfiguringModule

DEFAULT_FRAME_PERIOD = 1 / 30


class SmartResourceRuntime(ServiceInstances):
    """Runs the SPT services of one ``<SmartResource>`` on a transport (§3.2, §4.2–4.3)."""

    def __init__(
        self,
        resource: SmartResource,
        transport: Transport,
        *,
        node: str | None = None,
        registry: Registry | None = None,
        sources: Mapping[str, Source] | None = None,
        frame_period: float | None = None,
        share: bool = True,
        primary: bool = True,
        announce_period: float = 1.0,
        max_clients: int = 16,
        supply_period: float | None = None,
        selector: SelectorFactory = TaskConfiguringModule,
        wire_name: Callable[[str], str] | None = None,
    ) -> None:
        self.resource, self.transport = resource, transport
        # a service Input names its topic as the configuration does; the hosting node gives the
        # name it travels under (an internal topic's node-local name)
        self.wire_name = wire_name or (lambda topic: topic)
        self.node = node or resource.node
        self.share, self.primary, self.max_clients = share, primary, max_clients
        self.selector = selector  # builds each instance's scenario selector: the TCM, or a benchmark's baseline
        self._supply_period = supply_period
        self.announce_period = announce_period
        self.services = {s.name: s for s in resource.services if s.scenarios}
        self.streams: dict[str, Stream] = {}
        self._service_stream: dict[str, Stream] = {}
        self._inputs: dict[str, Subscription] = {}
        self._sources = dict(sources or {})
        self._frame_period = frame_period
        self._registry = registry
        self._pub: dict[str, dict[str, Publisher]] = {}
        self._directory: Publisher | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._start_time = time.monotonic()
        self._lock = threading.Lock()
        self._answered: dict[tuple[str, str], tuple[int, dict[str, Any]]] = {}
        self._process_info = psutil.Process()

    # ------------------------------------------------------------------ build

    def _roots(self, service: Service) -> set[str]:
        profiles = {p.name: p for p in self.resource.profiles}
        return {profiles[s.profile].root.plugin for s in service.scenarios if s.profile in profiles}

    def _build_streams(self) -> None:
        by_root: dict[str, list[Service]] = {}
        for service in self.services.values():
            roots = self._roots(service)
            if len(roots) != 1:  # verify reports it first (ckm-validate, ckm-run before anything starts)
                raise ConfigError.of(
                    service,
                    f"service {self.resource.name}.{service.name}: its profiles must share one acquisition plugin, "
                    f"found {sorted(roots) or 'none'}",
                )
            by_root.setdefault(roots.pop(), []).append(service)
        for root, services in by_root.items():
            profiles = [p for p in self.resource.profiles if p.root.plugin == root]
            used = {name for p in profiles for name in p.root.plugins()}
            part = dataclasses.replace(
                self.resource,
                plugins=tuple(p for p in self.resource.plugins if p.name in used),
                profiles=tuple(profiles),
            )
            period = self._frame_period or min((s.rate for s in services if s.rate), default=DEFAULT_FRAME_PERIOD)
            supply = self._supply_period  # None: each result published as soon as it is computed (D234)
            lazy = all(s.lazy for s in services)
            source, inputs = self._source_for(root, services, passive=lazy)
            asked = functools.partial(self._asked, root) if lazy else None
            stream = Stream(root, Topology(part, self._registry), period, supply, source, asked=asked, inputs=inputs)
            self.streams[root] = stream
            for service in services:
                self._service_stream[service.name] = stream

    def _asked(self, root: str) -> bool:
        """Whether a subscriber asks for an output of one of the stream's instances (a lazy stream, D245)."""
        stream = self.streams[root]
        return any(
            self.transport.subscribed(client_topic(o.topic, i.client))
            for i in list(stream.instances.values())
            for o in i.service.outputs
        )

    def _source_for(self, root: str, services: list[Service], *, passive: bool) -> tuple[Source, list[Subscription]]:
        """The stream's acquisition and its input subscriptions: a given source, or the newest sample
        of its input topics (observed only, ``passive``, until a lazy stream is asked for, D245).

        See :func:`runtime.resources.stream.newest_of` for what the input topics give.
        """
        source = self._sources.get(root)
        if source is not None:
            return source, []
        inputs = {i.name: i.topic for s in services for i in s.inputs}
        if not inputs:  # verify reports it first: "has no Input: its stream … would have nothing to process"
            raise ConfigError.of(
                services[0], f"resource {self.resource.name}: stream {root!r} has no input topic and no source"
            )
        subscriptions = {
            name: self.transport.subscribe(
                TopicQoS(self.wire_name(topic), "ckm/raw", reliability="best-effort"), passive=passive
            )
            for name, topic in inputs.items()
        }
        self._inputs.update({f"{root}/{name}": sub for name, sub in subscriptions.items()})
        return newest_of(subscriptions), list(subscriptions.values())

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Build the streams and their plugins; a stream the records cannot make is a ConfigError at its service."""
        self._build_streams()
        for stream in self.streams.values():
            stream.topology.setup()
        for name, service in self.services.items():
            qos = topics(self.resource, service)
            self._pub[name] = {kind: self.transport.publisher(q) for kind, q in qos.items() if kind != "config"}
            self.transport.subscribe(qos["config"], functools.partial(self._on_request, service))
        self._directory = self.transport.publisher(TopicQoS(DIRECTORY_TOPIC, "ckm/service", history=64))

    def start(self) -> None:
        """Check parameter defaults, create the services' own instances, start buffers and loops."""
        self._start_time = time.monotonic()
        for service in self.services.values():
            # A default only the plugin can judge (no min/max on the Parameter): refused here, at start.
            defaults = {p.name: typed_default(p) for p in service.parameters if p.default is not None}
            problems = self._forward(service, defaults)
            if problems:
                raise ValueError(f"service {self.resource.name}.{service.name}: {'; '.join(problems)}")
        if self.primary:
            for name, service in self.services.items():
                initial = preferred_scenario(service, {p.name: p.default for p in service.parameters})
                send = self._sender(name)
                instance = Instance(
                    self.resource.name, service, "", self.transport, send, initial=initial, selector=self.selector
                )
                self._add(instance)
        for stream in self.streams.values():
            stream.buffer.start()
        for target, label in ((self._tcm_loop, "tcm"), (self._announce_loop, "announce")):
            thread = threading.Thread(target=target, name=f"{self.resource.name}-{label}", daemon=True)
            thread.start()
            self._threads.append(thread)

    def stop(self) -> None:
        """Stop the loops, triple buffers and topologies, and close the subscriptions."""
        self._stop.set()
        for thread in self._threads:
            thread.join(2.0)
        for stream in self.streams.values():
            stream.buffer.stop()
            stream.topology.stop()
        for subscription in self._inputs.values():
            subscription.close()

    def __enter__(self) -> SmartResourceRuntime:
        self.setup()
        self.start()
        return self

    def __exit__(self, *_: object) -> None:
        self.stop()

    # ------------------------------------------------------------------ periodic work

    def _tcm_loop(self) -> None:
        periods = {name: (s.tcm.period if s.tcm else TCM_PERIOD) for name, s in self.services.items()}
        due = dict.fromkeys(periods, time.monotonic())
        cpu_mark = {name: (time.monotonic(), 0.0) for name in periods}  # per service: its own TCM period
        while not self._stop.is_set():
            now = time.monotonic()
            for name, period in periods.items():
                if now < due[name]:
                    continue
                due[name] += period * max(1, int((now - due[name]) / period) + 1)
                stream = self._service_stream[name]
                last_wall, last_busy = cpu_mark[name]
                if now - last_wall > 1e-3:
                    busy = stream.busy_cpu
                    share = (busy - last_busy) / (now - last_wall)
                    cpu_mark[name] = (now, busy)
                    memory = self._process_info.memory_info().rss / 2**20
                    for instance in list(stream.instances.values()):
                        if instance.service.name == name:
                            instance.observe("cpu", share)
                            instance.observe("memory", memory)
                self._tick(name)
            self._stop.wait(max(0.001, min(due.values()) - time.monotonic()))

    def _tick(self, service: str) -> None:
        stream = self._service_stream[service]
        with self._lock:
            instances = [i for i in list(stream.instances.values()) if i.service.name == service]
            selection = {}
            for instance in instances:
                instance.tick(self.now())
                selection[instance.key] = instance.profile
            if selection:
                stream.topology.select_all(selection)

    def _announce_loop(self) -> None:
        while True:
            if self._directory is not None:
                for service in self.services.values():
                    self._directory.publish(describe(self.resource, service, self.node))
            if self._stop.wait(self.announce_period):
                return
