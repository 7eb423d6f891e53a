"""Semantic checks of the kernel layer (kernel.xsd, §3.1.5.1): network, message types, topics, nodes."""

from __future__ import annotations

from ..binding import Record
from ..model import Adaptation, Alarm, Clamp, Controller, HWChannel, Lookup, Node, Partition, Switch, System, Topic
from ..rostypes import is_ros_type, ros_type_problem
from .report import Reporter, missing
from .scope import Scope

_TASK_MEASURES = ("deadline-misses", "jitter", "exec-time")


def check_kernel(system: System, scope: Scope, report: Reporter) -> None:
    """Check the kernel layer (kernel.xsd, §3.1): network, message types, topic scopes and names, nodes."""
    _check_network(system, report)
    _check_types(system, scope, report)
    report.unique(system.nodes, "node", "the system")
    external: dict[str, Record] = {}
    for topic in system.topics:
        if topic.scope == "internal":
            report.error(topic, "a system-level topic must be external (internal topics belong to a node)", "scope")
    for topic in [*system.topics, *(t for n in system.nodes for t in n.topics if t.scope == "external")]:
        if topic.name in external:
            report.error(
                topic, f"external topic {topic.name!r} is declared twice (first at {_at(external[topic.name])})", "name"
            )
        else:
            external[topic.name] = topic
        _check_topic_type(topic, scope, report)
    for node in system.nodes:
        _check_node(node, scope, report)


def _check_topic_type(topic: Topic, scope: Scope, report: Reporter) -> None:
    """A topic's type: built-in, a MessageType, or a ROS 2 type package/msg/Name (ckmconf.rostypes)."""
    if is_ros_type(topic.type):
        problem = ros_type_problem(topic.type, topic.loc.file if topic.loc else None)
        if problem is not None:
            report.error(topic, problem, "type")
    elif not scope.type_exists(topic.type):
        report.error(topic, missing("message type", topic.type, "the system", scope.type_names()), "type")


def _at(record: Record) -> str:
    return f"{record.loc.file}:{record.loc.line}" if record.loc else "elsewhere"


def _check_network(system: System, report: Reporter) -> None:
    net = system.network
    if net is None:
        return
    if net.zenoh is not None and net.transport != "zenoh":
        report.error(net.zenoh, 'Zenoh settings are only used with transport="zenoh"')
    if net.reconnect_min > net.reconnect_max:
        report.error(
            net,
            f"reconnectMin ({net.reconnect_min:g}) is larger than reconnectMax ({net.reconnect_max:g})",
            "reconnectMin",
        )
    last = net.base_port + net.port_tries - 1
    if last > 65535:
        report.error(net, f"basePort {net.base_port} + portTries {net.port_tries} runs past port 65535", "portTries")


def _check_types(system: System, scope: Scope, report: Reporter) -> None:
    report.unique(system.message_types, "message type", "the system")
    for message_type in system.message_types:
        if scope.type_exists(message_type.name) and message_type.name not in scope.types:
            report.error(message_type, f"{message_type.name!r} is a built-in type and cannot be redefined", "name")
        report.unique(message_type.fields, "field", f"message type {message_type.name!r}")
        for f in message_type.fields:
            if not scope.type_exists(f.type):
                report.error(f, missing("message type", f.type, "the system", scope.type_names()), "type")
    # A type that contains itself, directly or not, has no finite encoding.
    graph = {t.name: {f.type for f in t.fields if f.count != 0} for t in system.message_types}
    for message_type in system.message_types:
        if _reaches(graph, message_type.name, message_type.name):
            report.error(
                message_type,
                f'message type {message_type.name!r} contains itself (use count="0" for a recursive list)',
                "name",
            )


def _reaches(graph: dict[str, set[str]], start: str, goal: str) -> bool:
    todo, seen = list(graph.get(start, ())), set()
    while todo:
        current = todo.pop()
        if current == goal:
            return True
        if current not in seen:
            seen.add(current)
            todo.extend(graph.get(current, ()))
    return False


def _check_node(node: Node, scope: Scope, report: Reporter) -> None:
    where = f"node {node.name!r}"
    report.unique(node.partitions, "partition", where)
    report.unique(node.channels, "HWChannel", where)
    report.unique([t for t in node.topics if t.scope == "internal"], "topic", where)
    report.unique([*node.sensors, *node.controllers, *node.actuators], "task name", where)
    channels = {c.name: c for c in node.channels}
    partitions = [p.name for p in node.partitions]
    tasks = [s.name for s in node.sensors] + [c.name for c in node.controllers] + [a.name for a in node.actuators]
    for channel in node.channels:
        if channel.min is not None and channel.max is not None and channel.min >= channel.max:
            report.error(channel, f"min ({channel.min:g}) must be less than max ({channel.max:g})", "min")
    for topic in node.topics:
        if topic.scope == "internal":
            _check_topic_type(topic, scope, report)

    def topic_ref(record: Record, name: str, attr: str = "topic") -> None:
        if scope.topic(node, name) is None:
            report.error(record, missing("topic", name, where, scope.visible_topics(node)), attr)

    def partition_ref(record: Record, name: str | None) -> None:
        if name is not None and name not in partitions:
            report.error(record, missing("partition", name, where, partitions), "partition")

    publishers: dict[str, list[tuple[str, Record]]] = {}
    for sensor in node.sensors:
        _channel_ref(sensor, sensor.channel, "in", channels, where, report)
        topic_ref(sensor, sensor.topic)
        partition_ref(sensor, sensor.partition)
        _check_adaptation(sensor.adaptation, report)
        publishers.setdefault(sensor.topic, []).append((f"sensor {sensor.name}", sensor))
    controllers = [c.name for c in node.controllers]
    for controller in node.controllers:
        partition_ref(controller, controller.partition)
        for port in (*controller.inputs, *controller.outputs):
            topic_ref(port, port.topic)
        if controller.active:
            for port in controller.outputs:
                publishers.setdefault(port.topic, []).append((f"controller {controller.name}", port))
        for switch in controller.switches:
            if switch.to == controller.name:
                report.error(switch, "a controller cannot switch to itself", "to")
            elif switch.to not in controllers:
                report.error(switch, missing("controller", switch.to, where, controllers), "to")
            _check_switch_condition(switch, node, scope, report)
    for actuator in node.actuators:
        _channel_ref(actuator, actuator.channel, "out", channels, where, report)
        topic_ref(actuator, actuator.topic)
        partition_ref(actuator, actuator.partition)
        _check_adaptation(actuator.adaptation, report)
        if actuator.min >= actuator.max:
            report.error(actuator, f"min ({actuator.min:g}) must be less than max ({actuator.max:g})", "min")
        elif not actuator.min <= actuator.safe_value <= actuator.max:
            report.error(
                actuator,
                f"safeValue {actuator.safe_value:g} is outside [{actuator.min:g}, {actuator.max:g}]",
                "safeValue",
            )
        if actuator.fallback is not None and actuator.min < actuator.max:
            for action in actuator.fallback.actions:
                if not actuator.min <= action.value <= actuator.max:
                    report.error(
                        action,
                        f"fallback value {action.value:g} is outside [{actuator.min:g}, {actuator.max:g}]",
                        "value",
                    )
    for topic_name, writers in publishers.items():
        for label, record in writers[1:]:  # reported at each extra publisher
            report.error(
                record,
                f"{label} also publishes {topic_name!r}, already published by {writers[0][0]}"
                ' (a topic has one publisher; make switched-in controllers active="false")',
                "topic",
            )
    if node.monitor is not None:
        for alarm in node.monitor.alarms:
            _check_alarm(alarm, node, scope, tasks, controllers, partitions, report)
        report.unique(node.monitor.alarms, "alarm", where)


def _partition(node: Node, name: str) -> Partition:
    return next(p for p in node.partitions if p.name == name)


def _controller(node: Node, name: str) -> Controller:
    return next(c for c in node.controllers if c.name == name)


def _channel_ref(
    record: Record, name: str, direction: str, channels: dict[str, HWChannel], where: str, report: Reporter
) -> None:
    channel = channels.get(name)
    if channel is None:
        report.error(record, missing("HWChannel", name, where, channels), "channel")
    elif channel.direction != direction:
        kind = "a sensor" if direction == "in" else "an actuator"
        report.error(
            record,
            f"HWChannel {name!r} is an {channel.direction!r} channel; {kind} needs an {direction!r} one",
            "channel",
        )


def _check_adaptation(adaptation: Adaptation | None, report: Reporter) -> None:
    if adaptation is None:
        return
    for step in adaptation.steps:
        if isinstance(step, Clamp) and step.min >= step.max:
            report.error(step, f"min ({step.min:g}) must be less than max ({step.max:g})", "min")
        if isinstance(step, Lookup):
            for earlier, point in zip(step.points, step.points[1:], strict=False):
                if point.x <= earlier.x:
                    report.error(point, f"lookup x values must increase: {point.x:g} follows {earlier.x:g}", "x")


def _check_switch_condition(switch: Switch, node: Node, scope: Scope, report: Reporter) -> None:
    error = switch.condition_error  # parsed once, when the record was read
    if error is not None:
        report.error(switch, str(error), "when", error.column)
        return
    condition = switch.condition
    alarms = [a.name for a in node.monitor.alarms] if node.monitor else []
    for name, args in condition.calls:
        if name == "alarm" and args[0] not in alarms:
            report.error(switch, missing("alarm", str(args[0]), f"node {node.name!r}", alarms), "when")
        if name in ("stale", "value") and scope.topic(node, str(args[0])) is None:
            report.error(
                switch, missing("topic", str(args[0]), f"node {node.name!r}", scope.visible_topics(node)), "when"
            )


def _check_alarm(
    alarm: Alarm,
    node: Node,
    scope: Scope,
    tasks: list[str],
    controllers: list[str],
    partitions: list[str],
    report: Reporter,
) -> None:
    where = f"node {node.name!r}"
    if alarm.measure == "partition-crash":
        if alarm.above is not None or alarm.below is not None:
            report.error(alarm, "a partition-crash alarm fires on every crash and takes no threshold", "above")
    elif alarm.above is None and alarm.below is None:
        report.error(alarm, "an alarm needs a threshold: above, below or both")
    elif alarm.above is not None and alarm.below is not None and alarm.below >= alarm.above:
        report.error(
            alarm,
            f"below ({alarm.below:g}) must be less than above ({alarm.above:g}), or the alarm never clears",
            "below",
        )
    for attr, needed_by in (("task", _TASK_MEASURES), ("topic", ("staleness",))):
        if getattr(alarm, attr) is not None and alarm.measure not in needed_by:
            report.error(alarm, f"{attr} does not apply to a {alarm.measure} alarm", attr)
    if alarm.partition is not None and alarm.measure != "partition-crash" and alarm.action != "restart":
        report.error(alarm, "partition only applies to partition-crash alarms and the restart action", "partition")
    if alarm.measure in _TASK_MEASURES:
        if alarm.task is None:
            report.error(alarm, f'a {alarm.measure} alarm needs the task it watches (task="…")')
        elif alarm.task not in tasks:
            report.error(alarm, missing("task", alarm.task, where, tasks), "task")
    if alarm.measure == "staleness":
        if alarm.topic is None:
            report.error(alarm, 'a staleness alarm needs the topic it watches (topic="…")')
        elif scope.topic(node, alarm.topic) is None:
            report.error(alarm, missing("topic", alarm.topic, where, scope.visible_topics(node)), "topic")
    if alarm.measure == "partition-crash" or alarm.action == "restart":
        if alarm.partition is None:
            report.error(alarm, 'this alarm needs the partition it concerns (partition="…")')
        elif alarm.partition not in partitions:
            report.error(alarm, missing("partition", alarm.partition, where, partitions), "partition")
        elif alarm.action == "restart" and _partition(node, alarm.partition).restart == "never":
            report.error(alarm, f'partition {alarm.partition!r} has restart="never"; it cannot be restarted', "action")
    if alarm.action in ("switch", "delegate"):
        if alarm.target is None:
            report.error(alarm, f'action {alarm.action!r} needs the target controller (target="…")')
        elif alarm.target not in controllers:
            report.error(alarm, missing("controller", alarm.target, where, controllers), "target")
        elif alarm.action == "delegate" and not _controller(node, alarm.target).delegable:
            report.error(alarm, f'controller {alarm.target!r} is not delegable (set delegable="true")', "target")
