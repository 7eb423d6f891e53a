"""Verify before build: a whole system checked against the kinds' manifests, nothing instantiated.

BehaviorTree.CPP's ``verifyXML`` checks a tree against the factory's manifests before it builds a
single node; ``verify`` does the same for a loaded System:

- every kind exists in the registry: hardware backends (``HWChannel/@backend``), adaptation
  functions (``Function/@plugin``), controllers and their optional parts, processing plugins and
  behaviors (``@kind``);
- every ``<Param>`` is declared by its kind, converts to the declared type and lies in the declared
  range; every required Param is given;
- the value types of producers, topics and consumers agree: what a sensor writes (one number, or a
  vector of ``size`` numbers, which its topic's type must carry as the kernel shapes it: D99, D193)
  and what controllers, actuators and behaviors read and write, against
  the ``type`` of the topic or plan signal (:mod:`runtime.verification.types`); a topic of a ROS 2
  type (``sensor_msgs/msg/LaserScan``) against its fields (:mod:`runtime.ros.config`, issue L), and
  a custom ROS type's ``.msg`` file must load;
- the topics of each Smart Resource service against its processing plugins: every ``<Output>``
  against what the output plugin of each of its scenarios' profiles returns (one Output: the whole
  result; several: the field of the Output's name), every ``<Input>`` of a stream against what its
  acquisition (root) plugin accepts (one Input: the value itself; several: the dict's entry of the
  Input's name). A ``bytes`` topic carries the codec's encoding of any value (D98);
- each service's interface (``interface=`` or its output plugin kind's ``PROVIDES``) and its ports,
  and each behavior's ``<Uses>`` against the services its kind ``USES`` (:mod:`.interface_checks`);
- each ``<Output>``'s topic type holds every field its output plugin writes (its ``WRITES``, else its
  interface port's fields; :mod:`.message_checks`);
- channel sizes are ones the backend serves (a loopback plant has one output);
- what the runtime would silently not run is refused: Smart Resources on a ROS kernel (no ROS
  kernel runs here), services without scenarios (only SPT scenarios are executed), services whose
  scenarios start from different acquisition plugins, and streams no service feeds an Input.

Classes are imported to read their manifests; none is instantiated, no file or device is opened.
Every problem is a ConfigError at its element (attribute when there is one), ``FILE:LINE:COL``.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

from ckmconf.binding import Record
from ckmconf.errors import ConfigError
from ckmconf.model import (
    Actuator,
    Behavior,
    Controller,
    Function,
    HWChannel,
    Node,
    Param,
    Plugin,
    Profile,
    Sensor,
    Service,
    SmartResource,
    System,
)
from ckmconf.rostypes import is_ros_type

from ..kernel.vectors import chain_refusal, is_vector, problem, refusal, scalar_refusals
from ..registry import Registry, default_registry
from .interface_checks import InterfaceChecks
from .manifest import ANY, MAPPING, NUMBER, NUMBERS, ports_of
from .message_checks import MessageChecks
from .types import describe, fits

_ChannelRead = tuple[HWChannel, str | None, type[Any] | None]
"""A channel, what its sensor reads (None if unknown) and its backend class."""


def verify(system: System, registry: Registry | None = None) -> list[ConfigError]:
    """Every problem ``system`` would meet when built, sorted by file and position.

    Args:
        system: a loaded, schema-valid system (``ckmconf.load``).
        registry: the kinds to check against (default: the installed entry points).
    """
    checker = _Verifier(system, registry or default_registry())
    checker.run()
    return sorted(set(checker.report.errors), key=ConfigError.sort_key)


class _Verifier(InterfaceChecks, MessageChecks):
    """One pass over a system, element by element (the shared checks are :class:`Checker`'s)."""

    def run(self) -> None:
        self.interfaces, self.lacking = {}, {}
        self._ros_topics()
        for node in self.system.nodes:
            self._node(node)
        for resource in self.system.resources:
            self._resource(resource)
        for behavior in self.system.behaviors:
            self._behavior(behavior)

    # ------------------------------------------------------------------ nodes

    def _node(self, node: Node) -> None:
        channels: dict[str, _ChannelRead] = {}
        for channel in node.channels:
            channels[channel.name] = (channel, *self._channel(channel))
        for sensor in node.sensors:
            self._sensor(node, sensor, channels.get(sensor.channel))
        for controller in node.controllers:
            self._controller(node, controller)
        for actuator in node.actuators:
            self._actuator(node, actuator)

    def _channel(self, channel: HWChannel) -> tuple[str | None, type[Any] | None]:
        """Checks one channel; returns what its sensor reads (None when the backend is unknown), and the backend."""
        cls = self._checked(channel, "hardware", channel.backend, channel.params, "backend")
        if cls is None:
            return None, None
        problems = getattr(cls, "problems", None)  # what the backend finds wrong across the channel's Params
        for element, message in problems(channel, self.system) if callable(problems) else ():
            self.report.error(element, f"hardware {channel.backend!r} channel {channel.name!r}: {message}",
                              "value" if isinstance(element, Param) else None)
        ports = ports_of(cls)
        if ports.sizes and channel.size not in ports.sizes:
            sizes = ", ".join(map(str, ports.sizes))
            self.report.error(
                channel, f"hardware {channel.backend!r} serves channels of size {sizes}, not {channel.size}", "size"
            )
        typed = getattr(cls, "value_type", None)  # a backend whose reads depend on its Params
        read = typed(channel) if callable(typed) else ports.output("*")
        if read == NUMBERS:
            return (NUMBER if channel.size == 1 else NUMBERS), cls
        return read, cls

    def _functions(self, steps: Iterable[Record]) -> None:
        for step in steps:
            if isinstance(step, Function):
                self._checked(step, "function", step.plugin, step.params, "plugin")

    def _sensor(self, node: Node, sensor: Sensor, channel: _ChannelRead | None) -> None:
        if sensor.adaptation is not None:
            self._functions(sensor.adaptation.steps)
        if channel is None:
            return
        record, value, cls = channel
        if value is None or cls is None:
            return
        if is_vector(record, cls):  # decision D99: the whole read, shaped for the topic's type
            self._vector_sensor(node, sensor, record, cls)
            return
        carried = self._topic_type(sensor.topic, node)
        if carried is not None and is_ros_type(carried):  # the kernel's own check (D193)
            for refusal_text in scalar_refusals(sensor, record, carried, self._ros):
                self.report.error(sensor, refusal_text, "topic")
            return
        self._flow(
            sensor,
            "topic",
            value,
            self._topic_type(sensor.topic, node),
            f"sensor {sensor.name!r} writes {{}} (channel {record.name!r}, size {record.size}) "
            f"onto topic {sensor.topic!r}",
            record.size,
        )

    def _vector_sensor(self, node: Node, sensor: Sensor, record: HWChannel, cls: type[Any]) -> None:
        """A vector sensor: its chain must apply per element, its topic must carry the read (D99)."""
        chain = chain_refusal(record, cls) if sensor.adaptation is not None else None
        if chain is not None:
            self.report.error(sensor.adaptation or sensor, f"sensor {sensor.name!r}: {chain}")
        carried = self._topic_type(sensor.topic, node)
        why = None if carried is None else problem(carried, record, self.types, lambda: self._ros().ros)
        if carried is not None and why is not None:  # the kernel's sentence, at the same place (D193)
            self.report.error(sensor, refusal(sensor, record, carried, why), "topic")

    def _controller(self, node: Node, controller: Controller) -> None:
        cls = self._checked(controller, "controller", controller.kind, controller.params)
        if controller.optional is not None:
            part = controller.optional
            self._checked(part, "controller", part.kind, part.params)
        if cls is None:
            return
        ports = ports_of(cls)
        owner = f"controller {controller.name!r} ({controller.kind})"
        for port in controller.inputs:
            role = port.role or port.topic
            self._flow(
                port,
                "topic",
                ports.input(role),
                self._topic_type(port.topic, node),
                f"{owner} reads {{}} as {role!r}, but topic {port.topic!r} is",
            )
        for index, out in enumerate(controller.outputs):
            self._flow(
                out,
                "topic",
                ports.output(out.role or str(index)),
                self._topic_type(out.topic, node),
                f"{owner} writes {{}} onto topic {out.topic!r}",
            )

    def _actuator(self, node: Node, actuator: Actuator) -> None:
        if actuator.adaptation is not None:
            self._functions(actuator.adaptation.steps)
        self._flow(
            actuator,
            "topic",
            NUMBER,
            self._topic_type(actuator.topic, node),
            f"actuator {actuator.name!r} takes {{}}, but topic {actuator.topic!r} is",
        )

    # ------------------------------------------------------------------ resources and behaviors

    def _resource(self, resource: SmartResource) -> None:
        if resource.kernel == "ros":
            for service in resource.services:
                self._service_interface(resource, service, [], {})
            self.report.error(
                resource,
                f"Smart Resource {resource.name!r} runs on a ROS kernel, which this runtime does not provide: "
                "nothing would run its services (not runnable)",
                "kernel",
            )
            return
        kinds: dict[str, tuple[Plugin, type[Any] | None]] = {}
        for plugin in resource.plugins:
            kinds[plugin.name] = (plugin, self._checked(plugin, "plugin", plugin.kind, plugin.params))
            problems = getattr(kinds[plugin.name][1], "problems", None)  # what the kind finds across its Params
            for element, message in problems(plugin, self.system) if callable(problems) else ():
                self.report.error(element, f"plugin {plugin.name!r} ({plugin.kind}): {message}",
                                  "value" if isinstance(element, Param) else None)
        profiles = {p.name: p for p in resource.profiles}
        node = next((n for n in self.system.nodes if n.name == resource.node), None)
        streams: dict[str, list[Service]] = {}  # acquisition (root) plugin → the services it feeds
        for service in resource.services:
            ref = f"'{resource.name}.{service.name}'"
            if not service.scenarios:
                self.report.error(
                    service,
                    f"service {ref} has no Scenario: the runtime executes services "
                    "through their scenarios' SPT profiles, so nothing would produce its outputs (not runnable)",
                )
                self._service_interface(resource, service, [], kinds)
                continue
            roots = sorted({profiles[s.profile].root.plugin for s in service.scenarios if s.profile in profiles})
            if len(roots) > 1:
                self.report.error(
                    service,
                    f"service {ref}: the profiles of its scenarios must share one acquisition (root) plugin, "
                    f"found {', '.join(roots)} (not runnable)",
                )
            elif roots:
                streams.setdefault(roots[0], []).append(service)
            used = [profiles[s.profile] for s in service.scenarios if s.profile in profiles]
            self._service_outputs(resource, service, used, kinds, node)
            self._service_interface(resource, service, used, kinds)
            self._output_fields(resource, service, used, kinds, node)
        for root, services in streams.items():
            self._stream_inputs(resource, root, services, kinds, node)
            if not any(service.inputs for service in services):
                for service in services:
                    self.report.error(
                        service,
                        f"service '{resource.name}.{service.name}' has no Input: its stream (acquisition plugin "
                        f"{root!r}) would have nothing to process (not runnable)",
                    )

    def _service_outputs(
        self,
        resource: SmartResource,
        service: Service,
        used: list[Profile],
        kinds: dict[str, tuple[Plugin, type[Any] | None]],
        node: Node | None,
    ) -> None:
        """Each ``<Output>`` against what each profile's output plugin returns (runtime.resources.instance.deliver).

        One problem per Output and value type, naming every plugin that writes it (one per profile).
        """
        ref = f"service '{resource.name}.{service.name}'"
        for profile in {p.name: p for p in used}.values():
            plugin, cls = kinds.get(profile.output_plugin(), (None, None))
            if plugin is not None and cls is not None and len(service.outputs) > 1:
                result = ports_of(cls).output("*")
                if result not in (MAPPING, ANY):
                    self.report.error(
                        service,
                        f"{ref}: plugin {plugin.name!r} ({plugin.kind}, profile {profile.name!r}) returns "
                        f"{describe(result)}, but its {len(service.outputs)} Outputs each take a field of a dict: "
                        "nothing would be published (not runnable)",
                    )
        for out in service.outputs:
            carried = self._topic_type(out.topic, node)
            if carried is None or carried == "bytes":  # bytes: the codec's encoding of any value (D98)
                continue
            writers: dict[str, dict[str, str]] = {}  # value type → plugin name → kind
            for profile in {p.name: p for p in used}.values():
                plugin, cls = kinds.get(profile.output_plugin(), (None, None))
                if plugin is None or cls is None:
                    continue
                ports = ports_of(cls)
                value = ports.output("*") if len(service.outputs) == 1 else ports.outputs.get(out.name, ANY)
                if is_ros_type(carried):  # a ROS type: its fields decide (runtime.ros.config, D131)
                    misfit = bool(self._ros().value_problems(value, carried))
                else:
                    misfit = not fits(value, carried, self.types)
                if misfit:
                    writers.setdefault(value, {})[plugin.name] = plugin.kind
            for value, plugins in writers.items():
                names = ", ".join(repr(name) for name in plugins)
                self.report.error(
                    out,
                    f"{ref} publishes {describe(value)} onto topic {out.topic!r} of type {carried} "
                    f"(the result of plugin {names}: {', '.join(dict.fromkeys(plugins.values()))})",
                    "topic",
                )

    def _stream_inputs(
        self,
        resource: SmartResource,
        root: str,
        services: list[Service],
        kinds: dict[str, tuple[Plugin, type[Any] | None]],
        node: Node | None,
    ) -> None:
        """The Inputs of one stream against what its acquisition plugin accepts (resource._source_for)."""
        plugin, cls = kinds.get(root, (None, None))
        if plugin is None or cls is None:
            return
        ports = ports_of(cls)
        inputs = {i.name: i for s in services for i in s.inputs}  # the runtime keys the stream's inputs by name
        for name, source in inputs.items():
            if "*" not in ports.inputs and name not in ports.inputs:  # a kind naming its Inputs reads no other
                self.report.error(
                    source,
                    f"acquisition plugin {plugin.name!r} ({plugin.kind}) of resource {resource.name!r} reads no "
                    f"Input {name!r} (it reads: {', '.join(ports.inputs)})",
                    "name",
                )
                continue
            accepted = ports.input("*") if len(inputs) == 1 else ports.input(name)
            carried = self._topic_type(source.topic, node)
            if carried != "bytes":
                self._flow(
                    source,
                    "topic",
                    accepted,
                    carried,
                    f"acquisition plugin {plugin.name!r} ({plugin.kind}) of resource {resource.name!r} "
                    f"reads {{}} from Input {name!r}, but topic {source.topic!r} is",
                )

    def _behavior(self, behavior: Behavior) -> None:
        cls = self._checked(behavior, "behavior", behavior.kind, behavior.params)
        if cls is None:
            return
        self._behavior_uses(behavior, cls)
        ports = ports_of(cls)
        owner = f"behavior {behavior.name!r} ({behavior.kind})"
        problems = getattr(cls, "problems", None)  # what the kind finds wrong beyond single Params (D268)
        for element, message in problems(behavior, self.system) if callable(problems) else ():
            self.report.error(element, f"{owner}: {message}", "value" if isinstance(element, Param) else None)
        for port in behavior.outputs:
            value = ports.output(port.name)
            for carried, where, attr in self._port_types(port.topic, port.signal):
                self._flow(port, attr, value, carried, f"{owner} writes {{}} onto {where}")
        for source in behavior.inputs:
            value = ports.input(source.name)
            for carried, where, attr in self._port_types(source.topic, source.signal):
                self._flow(source, attr, value, carried, f"{owner} reads {{}} from {where}, which is")

    def _port_types(self, topic: str | None, signal: str | None) -> list[tuple[str | None, str, str]]:
        """(type, words, attribute) of what a behavior port is bound to."""
        if topic is not None:
            return [(self._topic_type(topic, None), f"topic {topic!r}", "topic")]
        if signal is not None:
            return [(t, f"signal {signal!r}", "signal") for t in dict.fromkeys(self._signal_types(signal))]
        return []


def verify_safely(system: System, registry: Registry | None = None) -> list[ConfigError]:
    """``verify``, with an unexpected failure of the verifier itself turned into one located problem.

    A broken third-party manifest must not make ``ckm-validate`` print a traceback.
    """
    try:
        return verify(system, registry)
    except Exception as exc:  # the contract: never a traceback for any input
        return [ConfigError.of(system, f"verification failed: {type(exc).__name__}: {exc}")]


def verify_or_report(system: System, path: str, registry: Registry | None = None) -> int | None:
    """For ``ckm-run``: verify before anything starts; print each problem on stderr.

    Returns:
        None when the system verifies, else 1 (the exit code of a configuration problem).
    """
    errors = verify_safely(system, registry)
    for error in errors:
        print(error, file=sys.stderr)
    if errors:
        print(f"{path}: {len(errors)} problem(s) found before start; nothing was started", file=sys.stderr)
        return 1
    return None
