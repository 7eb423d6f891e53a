"""Records of the Control Kernel layer (schemas/kernel.xsd): message types, topics, nodes (§3.1).

A node's parts: partitions, hardware channels, sensors, controllers, actuators and its monitor.
The transport settings are in :mod:`ckmconf.model.network`, the adaptation chain in
:mod:`ckmconf.model.adaptation`, ``<Param>`` in :mod:`ckmconf.model.params`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from ..binding import Record, attr, child, children
from ..expressions import SWITCH, Vocabulary
from .adaptation import Adaptation
from .conditions import ConditionRecord
from .params import Param

Scope = Literal["internal", "external"]
Reliability = Literal["reliable", "best-effort"]


@dataclass(frozen=True, kw_only=True)
class Field(Record):
    """<Field>: one typed field of a message type."""

    TAG = "Field"
    name: str = attr()
    type: str = attr()
    count: int = attr(default=1)
    unit: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class MessageType(Record):
    """<MessageType>: a structured message made of fields."""

    TAG = "MessageType"
    name: str = attr()
    description: str | None = attr(default=None)
    fields: tuple[Field, ...] = children()


BUILTIN_TYPES = frozenset(
    {"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64"}
    | {"float32", "float64", "string", "bytes", "time"}
)


@dataclass(frozen=True, kw_only=True)
class Topic(Record):
    """<Topic>: a data topic with its QoS (§3.1.2.10)."""

    TAG = "Topic"
    name: str = attr()
    type: str = attr()
    scope: Scope = attr(default="external")
    reliability: Reliability = attr(default="reliable")
    history: int = attr(default=1)
    deadline: float | None = attr(default=None)
    lifespan: float | None = attr(default=None)
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Partition(Record):
    """<Partition>: an isolated part of a node, run and restarted as its own process (§3.1.3.2)."""

    TAG = "Partition"
    name: str = attr()
    criticality: Literal["safety", "mission", "best-effort"] = attr(default="mission")
    cpu: float | None = attr(default=None)
    memory: int | None = attr(default=None)
    restart: Literal["always", "on-failure", "never"] = attr(default="on-failure")
    max_restarts: int = attr(default=5)
    restart_delay: float = attr(default=0.5)


@dataclass(frozen=True, kw_only=True)
class HWChannel(Record):
    """<HWChannel>: a physical input or output served by a hardware backend."""

    TAG = "HWChannel"
    name: str = attr()
    direction: Literal["in", "out"] = attr()
    kind: Literal["analog", "digital", "counter", "pwm", "stream", "bus"] = attr(default="analog")
    backend: str = attr(default="loopback")
    units: str = attr(default="")
    min: float | None = attr(default=None)
    max: float | None = attr(default=None)
    size: int = attr(default=1)
    params: tuple[Param, ...] = children()


# ----------------------------------------------------------------- components


@dataclass(frozen=True, kw_only=True)
class Sensor(Record):
    """<Sensor>: the sensory perception service of one channel (§3.1.2.1)."""

    TAG = "Sensor"
    name: str = attr()
    channel: str = attr()
    topic: str = attr()
    period: float = attr()
    priority: int = attr(default=50)
    partition: str | None = attr(default=None)
    extrapolation: Literal["none", "hold", "linear", "quadratic"] = attr(default="linear")
    lazy: bool = attr(default=False)
    adaptation: Adaptation | None = child(default=None)


@dataclass(frozen=True, kw_only=True)
class PortRef(Record):
    """<Input>/<Output> of a controller: a topic and its role."""

    topic: str = attr()
    role: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class ControllerInput(PortRef):
    """<Input> of a controller."""

    TAG = "Input"


@dataclass(frozen=True, kw_only=True)
class ControllerOutput(PortRef):
    """<Output> of a controller."""

    TAG = "Output"


@dataclass(frozen=True, kw_only=True)
class OptionalPart(Record):
    """<Optional>: the optional part of a controller, run only when resources allow (§3.1.2.8)."""

    TAG = "Optional"
    kind: str = attr()
    min_idle: float = attr(default=0.2)
    params: tuple[Param, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Switch(ConditionRecord):
    """<Switch>: a controller switching criterion (§3.1.2.7), its condition parsed once (``condition``)."""

    TAG = "Switch"
    VOCABULARY: ClassVar[Vocabulary] = SWITCH
    to: str = attr()
    when: str = attr()


@dataclass(frozen=True, kw_only=True)
class Controller(Record):
    """<Controller>: the control service of one loop (§3.1.2.2)."""

    TAG = "Controller"
    name: str = attr()
    kind: str = attr()
    period: float = attr()
    priority: int = attr(default=50)
    partition: str | None = attr(default=None)
    active: bool = attr(default=True)
    delegable: bool = attr(default=False)
    horizon: int = attr(default=10)
    params: tuple[Param, ...] = children()
    inputs: tuple[ControllerInput, ...] = children()
    outputs: tuple[ControllerOutput, ...] = children()
    optional: OptionalPart | None = child(default=None)
    switches: tuple[Switch, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Action(Record):
    """<Action>: one step of an actuator's fallback sequence."""

    TAG = "Action"
    value: float = attr()
    duration: float = attr()


@dataclass(frozen=True, kw_only=True)
class Fallback(Record):
    """<Fallback>: actions played when commands stop, before the safe value."""

    TAG = "Fallback"
    actions: tuple[Action, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Actuator(Record):
    """<Actuator>: the actuation service of one channel (§3.1.2.3)."""

    TAG = "Actuator"
    name: str = attr()
    channel: str = attr()
    topic: str = attr()
    min: float = attr()
    max: float = attr()
    safe_value: float = attr()
    rate_limit: float | None = attr(default=None)
    on_out_of_range: Literal["clamp", "reject"] = attr(default="clamp")
    command_timeout: float = attr(default=0.5)
    priority: int = attr(default=60)
    partition: str | None = attr(default=None)
    adaptation: Adaptation | None = child(default=None)
    fallback: Fallback | None = child(default=None)


AlarmMeasure = Literal["cpu", "memory", "deadline-misses", "jitter", "exec-time", "staleness", "partition-crash"]


@dataclass(frozen=True, kw_only=True)
class Alarm(Record):
    """<Alarm>: a monitored measure, its thresholds and the kernel's reaction (§3.1.2.4)."""

    TAG = "Alarm"
    name: str = attr()
    measure: AlarmMeasure = attr()
    task: str | None = attr(default=None)
    topic: str | None = attr(default=None)
    partition: str | None = attr(default=None)
    above: float | None = attr(default=None)
    below: float | None = attr(default=None)
    hold: float = attr(default=0.0)
    severity: Literal["info", "warning", "error", "critical"] = attr(default="warning")
    action: Literal["none", "safe-stop", "delegate", "switch", "restart"] = attr(default="none")
    target: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class Monitor(Record):
    """<Monitor>: the node's resource and task monitor."""

    TAG = "Monitor"
    period: float = attr(default=1.0)
    topic: str | None = attr(default=None)
    alarms: tuple[Alarm, ...] = children()


@dataclass(frozen=True, kw_only=True)
class Node(Record):
    """<Node>: a CKM node and everything it runs (§3.1.1, Fig. 3.8)."""

    TAG = "Node"
    name: str = attr()
    kind: Literal["light", "service"] = attr(default="service")
    host: str = attr(default="127.0.0.1")
    description: str | None = attr(default=None)
    partitions: tuple[Partition, ...] = children()
    channels: tuple[HWChannel, ...] = children()
    topics: tuple[Topic, ...] = children()
    sensors: tuple[Sensor, ...] = children()
    controllers: tuple[Controller, ...] = children()
    actuators: tuple[Actuator, ...] = children()
    monitor: Monitor | None = child(default=None)

    def alarm_topic(self) -> str:
        """Where the node's alarms and events are published."""
        return self.monitor.topic if self.monitor and self.monitor.topic else f"/{self.name}/alarms"
