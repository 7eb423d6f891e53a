"""A running CKM node, built from its configuration record through the registry (§3.1.2).

``NodeRuntime(node, system, transport)`` only resolves plugins (unknown names are
ConfigErrors at their element); ``setup()`` opens the hardware; ``start()`` schedules the
services; ``stop()`` drives every actuator to its safe value and closes the hardware.

The node builds its services and schedules them; its other parts each have their module and a
narrow interface: controller switching (:mod:`.switching`), alarm reactions (:mod:`.reactions`,
through the ``ReactionHost`` protocol), the Smart Resources it hosts (:mod:`.hosting`), its event
log (:mod:`.events`) and code delegation (:mod:`.delegation`, through ``DelegationHost``).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import threading
from collections.abc import Callable
from typing import Any

from ckmconf.errors import ConfigError, located
from ckmconf.model import Alarm, Node, System
from ckmconf.model.kernel import Controller as ControllerRecord
from ckmconf.source import Limits, read_source

from ..network.api import Sample, Subscription, TopicQoS, Transport
from ..registry import Registry, default_registry
from ..resources.resource import SmartResourceRuntime
from .adaptation import build_chain
from .delegation import Delegation
from .events import EVENTS_KEPT, EventLog
from .hosting import ResourceHost
from .interfaces import Backend, Controller, ParamError
from .monitor import MonitorService
from .partitions import PartitionSupervisor
from .reactions import react
from .scheduler import Scheduler, Task
from .services import ActuationService, ControlService, FutureActions, SensorService
from .switching import ControllerSwitching
from .topics import declared_topic, topic_qos
from .vectors import chain_refusal, is_vector, scalar_refusals, shaper

LOG = logging.getLogger("ckm.node")
__all__ = ["EVENTS_KEPT", "NodeRuntime"]


def _only_partition(node: Node, partition: str) -> Node:
    """The node reduced to one partition's sensors, controllers and actuators and the channels they use."""
    wanted = partition or None
    sensors = tuple(s for s in node.sensors if s.partition == wanted)
    controllers = tuple(c for c in node.controllers if c.partition == wanted)
    actuators = tuple(a for a in node.actuators if a.partition == wanted)
    used = {s.channel for s in sensors} | {a.channel for a in actuators}
    channels = tuple(ch for ch in node.channels if ch.name in used)
    monitor = node.monitor if not partition else None  # the monitor lives with the node's main process
    return dataclasses.replace(
        node, sensors=sensors, controllers=controllers, actuators=actuators, channels=channels, monitor=monitor
    )


def _commands_to(service: ActuationService) -> Callable[[Sample], None]:
    return lambda sample: service.command(sample.value)


class NodeRuntime:
    """The kernel of one node: channels, sensors, controllers, actuators on one scheduler.

    Threads: :meth:`setup`, :meth:`start` and :meth:`stop` run on the host's thread; every task
    (sensors, controllers with their ``<Switch>`` criteria, the monitor and its reactions, the
    actuators' timeouts) on the scheduler's; an actuator's commands arrive on the transport's
    threads and only set its pending command. :meth:`add_controller`, :meth:`remove_controller`,
    :meth:`switch` and :meth:`statistics` may be called from any thread: they hold :attr:`lock`,
    as a switch does, so the set of controllers never changes under an iteration.
    """

    def __init__(
        self,
        node: Node,
        system: System,
        transport: Transport,
        *,
        registry: Registry | None = None,
        scheduler: Scheduler | None = None,
        partition: str | None = None,
    ) -> None:
        """``partition``: None runs every component; a name runs only that partition's components,
        and "" only the components outside any partition (the node's main process)."""
        # every lazy producer's topic, a partition's too: the monitor only observes them (D245), once computed
        self._lazy_topics = system.lazy_topics()
        if partition is not None:
            node = _only_partition(node, partition)
        self.partition = partition
        self.node = node
        self.system = system
        self.transport = transport
        self.registry = registry or default_registry()
        self.scheduler = scheduler or Scheduler(f"ckm-{node.name}")
        self._own_scheduler = scheduler is None
        self.backends: dict[str, Backend] = {}
        self.sensors: dict[str, SensorService] = {}
        self.controllers: dict[str, ControlService] = {}
        self.actuators: dict[str, ActuationService] = {}
        self.futures: dict[str, FutureActions] = {}
        self.log = EventLog(node.name, transport.publisher(TopicQoS(node.alarm_topic(), "event", history=16)))
        self.events: list[dict[str, Any]] = self.log.events  # the recent ones (bounded); all go to event_sinks
        self.event_sinks: list[Callable[[dict[str, Any]], None]] = self.log.sinks  # e.g. the run's events file
        self.monitor: MonitorService | None = None
        self.delegation: Delegation | None = None
        self.partitions: PartitionSupervisor | None = None  # the partition processes (ckm-run sets it)
        self.hosting = ResourceHost(node, system, transport, self.registry, lambda topic: self.topic(topic).name)
        self.resources: dict[str, SmartResourceRuntime] = self.hosting.resources  # hosted here (main process)
        self._final_tasks: dict[str, Any] | None = None
        self._watched: dict[str, Subscription] = {}
        self._ros: Any = None  # the ROS 2 types, for sensors publishing a ROS type (D193)
        self.lock = threading.RLock()  # the controllers and their hand-overs (see the class docstring)
        self.switching = ControllerSwitching(self.controllers, self._watch, self._watched, self.report, self.lock)
        self._controller_classes = {c.name: self.registry.resolve("controller", c.kind, c) for c in node.controllers}
        self._backend_classes = {
            ch.name: self.registry.resolve("hardware", ch.backend, ch, "backend") for ch in node.channels
        }

    # ------------------------------------------------------------------ topics

    def topic(self, name: str) -> TopicQoS:
        """QoS of a topic as this node sees it: its own topics first, then the system's external ones."""
        found = declared_topic(self.node, self.system, name)
        return TopicQoS(name) if found is None else topic_qos(self.node.name, found)

    # ------------------------------------------------------------------ lifecycle

    def setup(self) -> None:
        """Open the hardware and build the services; on failure, close what was opened, then raise."""
        try:
            self._setup()
        except BaseException:
            for channel, backend in self.backends.items():
                self._step(f"close channel {channel} after a failed set-up", backend.stop)
            raise

    def _setup(self) -> None:
        node = self.node
        self.delegation = Delegation(self)
        for channel in node.channels:
            try:
                backend = self._backend_classes[channel.name](channel)
                backend.setup()  # a plant's own checks (Params shared by channels) run here
            except ParamError as exc:
                raise self._error(channel, str(exc)) from None
            self.backends[channel.name] = backend
        channels = {c.name: c for c in node.channels}
        types = {m.name: m for m in self.system.message_types}
        for sensor in node.sensors:
            chain = build_chain(sensor.adaptation, self.registry, inverse=False)
            qos = self.topic(sensor.topic)
            publisher = self.transport.publisher(qos)
            asked = functools.partial(self.transport.subscribed, qos.name) if sensor.lazy else None
            channel = channels[sensor.channel]
            if not is_vector(channel, self._backend_classes[channel.name]):
                refusals = scalar_refusals(sensor, channel, qos.type, self._ros_config)
                if refusals:  # verify's sentence at the same FILE:LINE:COL (D193)
                    raise self._error(sensor, refusals[0], "topic")
                self.sensors[sensor.name] = SensorService(
                    sensor, self.backends[sensor.channel], chain, publisher, asked=asked
                )
                continue
            # decision D99: the whole read, shaped for the topic; a chain adapts each element apart
            refusal = chain_refusal(channel, self._backend_classes[channel.name]) if sensor.adaptation else None
            if refusal is not None:
                raise self._error(sensor, f"sensor {sensor.name!r}: {refusal}")
            try:
                shape = shaper(sensor, qos.type, channel, types, lambda: self._ros_config().ros)
            except ValueError as exc:  # verify's sentence at the same FILE:LINE:COL (D193)
                raise self._error(sensor, str(exc), "topic") from None
            chains = [build_chain(sensor.adaptation, self.registry, inverse=False) for _ in range(channel.size)]
            self.sensors[sensor.name] = SensorService(
                sensor, self.backends[sensor.channel], chain, publisher,
                shape=shape, chains=chains if sensor.adaptation is not None else None, asked=asked,
            )
        for actuator in node.actuators:
            # kernel.xsd: an actuator's steps are applied in order, engineering units → raw.
            inverse = build_chain(actuator.adaptation, self.registry, inverse=False)
            service = ActuationService(actuator, self.backends[actuator.channel], inverse, self.futures, self.report)
            self.actuators[actuator.name] = service
            self.transport.subscribe(self.topic(actuator.topic), _commands_to(service))
        extrapolation: dict[str, str] = {s.topic: s.extrapolation for s in node.sensors}
        for record in node.controllers:
            self.controllers[record.name] = self._control_service(record, extrapolation)
            self.switching.add_criteria(record)
        if node.monitor is not None:
            for alarm in node.monitor.alarms:
                if alarm.measure == "staleness" and alarm.topic:
                    self._watch(alarm.topic)
            self.monitor = MonitorService(
                node.monitor,
                node=node.name,
                scheduler=self.scheduler,
                subscriptions=self._watched,
                crashes=lambda partition: self.partitions.crashes(partition) if self.partitions is not None else 0,
                report=self.report,
                react=self._react,
                asked=lambda topic: self.transport.subscribed(self.topic(topic).name),
            )
            self.switching.monitor = self.monitor

        if self.partition in (None, ""):
            self.hosting.setup()

    def _ros_config(self) -> Any:
        """The system's ROS 2 types (``runtime.ros.config.ConfigRosTypes``), loaded on a sensor's first need (D193)."""
        if self._ros is None:
            from ..ros.config import ConfigRosTypes  # rosbags: only for a sensor on a ROS type

            self._ros = ConfigRosTypes(self.system)
        return self._ros

    def _watch(self, topic: str) -> Subscription:
        if topic not in self._watched:
            # a lazy producer's topic is only observed: the watch must not keep it producing (D245)
            passive = topic in self._lazy_topics
            self._watched[topic] = self.transport.subscribe(self.topic(topic), passive=passive)
        return self._watched[topic]

    def _control_service(self, record: ControllerRecord, extrapolation: dict[str, str]) -> ControlService:
        try:
            cls = self._controller_classes.get(record.name) or self.registry.resolve("controller", record.kind, record)
            controller: Controller = cls(record)
        except ParamError as exc:
            raise self._error(record, str(exc)) from None
        inputs = {}
        methods = {}
        roles = [port.role or port.topic for port in record.inputs]
        for index, port in enumerate(record.inputs):
            role = roles[index]
            if roles.count(role) > 1:  # a repeated role: role[0], role[1], … in document order (D91)
                role = f"{role}[{roles[:index].count(role)}]"
            qos = self.topic(port.topic)
            inputs[role] = self.transport.subscribe(
                TopicQoS(qos.name, qos.type, qos.reliability, max(qos.history, 3), qos.deadline, qos.lifespan)
            )
            methods[role] = extrapolation.get(port.topic, "hold")
        outputs = [self.transport.publisher(self.topic(port.topic)) for port in record.outputs]
        service = ControlService(record, controller, inputs, outputs, extrapolation=methods, futures=self.futures)
        if record.optional is not None:
            part = record.optional
            derived = dataclasses.replace(
                record, name=f"{record.name}.optional", kind=part.kind, params=part.params, optional=None, switches=()
            )
            try:
                service.optional = self.registry.resolve("controller", part.kind, part)(derived)
            except ParamError as exc:
                raise self._error(part, str(exc)) from None
        return service

    def start(self) -> None:
        """Schedule the sensors, controllers, monitor and actuators; start the scheduler and hosted resources."""
        for name, sensor in self.sensors.items():
            self.scheduler.add(
                Task(f"{self.node.name}.{name}", sensor.record.period, sensor.tick, priority=sensor.record.priority)
            )
        for control in self.controllers.values():
            self._schedule_control(control)
        if self.monitor is not None and self.node.monitor is not None:
            self.scheduler.add(
                Task(f"{self.node.name}.monitor", self.node.monitor.period, self.monitor.tick, priority=10)
            )
        for name, actuation in self.actuators.items():
            period = min(actuation.record.command_timeout / 4, 0.01)
            self.scheduler.add(
                Task(f"{self.node.name}.{name}", period, actuation.tick, priority=actuation.record.priority)
            )
        if self._own_scheduler:
            self.scheduler.start()
        self.hosting.start()

    def stop_monitoring(self) -> None:
        """Stop judging the node's alarms: the run is being stopped, and what a stop does (partitions
        ended, topics no longer published) is not a fault of the run (a short lab run once failed
        on ``scan_stale`` raised while its partitions stopped)."""
        self.scheduler.remove(f"{self.node.name}.monitor")

    def stop(self) -> None:
        """Drive every actuator to its safe value first, then stop the services and close the hardware.

        Each step is isolated: a failure is logged and the next step still runs, so nothing in
        statistics, resources or logging can skip the safe stop. The scheduler thread is stopped
        before the final statistics are taken.
        """
        for actuation in self.actuators.values():  # latched: a later command cannot move it again
            self._step(f"drive {actuation.record.name} to its safe value", actuation.safe_stop)
        mine = [t for name, t in list(self.scheduler.tasks.items()) if name.startswith(f"{self.node.name}.")]
        for task in mine:
            self._step(f"remove task {task.name}", functools.partial(self.scheduler.remove, task.name))
        if self._own_scheduler:
            self._step("stop the scheduler", self.scheduler.stop)
        self._step("take the task statistics", functools.partial(self._keep_task_statistics, mine))
        self._step("take the Smart Resource statistics", self.hosting.keep_statistics)
        for resource in self.resources.values():
            self._step(f"stop Smart Resource {resource.resource.name}", resource.stop)
        for sensor in self.sensors.values():
            self._step(f"stop sensor {sensor.record.name}", sensor.stop)
        for channel, backend in self.backends.items():
            self._step(f"close channel {channel}", backend.stop)

    def _step(self, what: str, action: Callable[[], Any]) -> None:
        try:
            action()
        except Exception:
            LOG.exception("%s: could not %s", self.node.name, what)

    def _keep_task_statistics(self, tasks: list[Task]) -> None:
        self._final_tasks = self.scheduler.statistics(tasks)

    # ------------------------------------------------------------------ alarms

    def _react(self, alarm: Alarm) -> None:
        react(self, alarm)

    def idle_node(self) -> str | None:
        """Where delegated work goes: the first other service node of the system (FCKM, §3.1.1.2)."""
        others = [n.name for n in self.system.nodes if n.name != self.node.name and n.kind == "service"]
        return others[0] if others else None

    # ------------------------------------------------------------------ run-time operations

    def _schedule_control(self, control: ControlService) -> None:
        record = control.record
        optional = record.optional
        self.scheduler.add(
            Task(
                f"{self.node.name}.{record.name}",
                record.period,
                self.switching.tick(control),
                priority=record.priority,
                optional=control.compute_optional if optional is not None else None,
                min_idle=optional.min_idle if optional is not None else 0.0,
                finish=control.publish,
            )
        )

    def add_controller(self, record: ControllerRecord) -> ControlService:
        """Add a controller while the node runs (§3.1.2.7); active ones take over their outputs bumplessly."""
        with self.lock:
            if record.name in self.controllers:
                raise ValueError(f"node {self.node.name!r} already runs a controller named {record.name!r}")
            extrapolation: dict[str, str] = {s.topic: s.extrapolation for s in self.node.sensors}
            control = self._control_service(record, extrapolation)
            self.switching.add_criteria(record)
            self.controllers[record.name] = control
            if record.active:
                control.active = False
                self.switch(record.name, reason="added")
            self._schedule_control(control)
        return control

    def remove_controller(self, name: str) -> None:
        """Stop and forget a controller; its outputs fall silent (the actuators then fail safe)."""
        with self.lock:
            control = self.controllers.pop(name)
            control.deactivate()
            self.scheduler.remove(f"{self.node.name}.{name}")
            self.switching.forget(name)
        self.report("controller-removed", {"controller": name})

    def switch(self, to: str, reason: str = "command") -> None:
        """Hand the outputs of the active controller(s) sharing ``to``'s outputs over to ``to``, bumplessly."""
        self.switching.switch(to, reason)

    def _task_statistics(self) -> dict[str, Any]:
        return {k: v for k, v in self.scheduler.statistics().items() if k.startswith(f"{self.node.name}.")}

    def statistics(self) -> dict[str, Any]:
        """Per-task scheduling figures (as they were at stop, once stopped), actuators, controllers."""
        return {
            "tasks": self._final_tasks if self._final_tasks is not None else self._task_statistics(),
            "actuators": {
                n: {"mode": a.mode, "value": a.value, "out_of_range": a.out_of_range} for n, a in self.actuators.items()
            },
            "controllers": self._controller_statistics(),
            "resources": self.hosting.statistics(),
        }

    def _controller_statistics(self) -> dict[str, Any]:
        with self.lock:
            return {n: {"active": c.active, "skipped": c.skipped, "optional_used": c.optional_used}
                    for n, c in self.controllers.items()}

    # ------------------------------------------------------------------ events

    def report(self, kind: str, detail: dict[str, Any]) -> None:
        """Record a node event: kept, logged, and published on the node's alarm topic."""
        self.log.report(kind, detail)

    def _error(self, record: Any, message: str, attr: str | None = None) -> ConfigError:
        """The problem at ``record`` (its attribute ``attr``: where ``verify`` places it, read from the file)."""
        if attr is not None:
            loc = located(record)
            try:
                return ConfigError.at(read_source(loc.file, Limits()).attr_loc_at(loc, attr), message)
            except (ConfigError, OSError):  # a record built in code: no file to read
                pass
        return ConfigError.of(record, message, attr)
