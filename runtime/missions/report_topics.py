"""What the run report looks for, taken from the recorded system's own configuration (issue M).

The report (:mod:`.html_report`) knows no system: the topics it reads from the bags
(:class:`.report_bag.ReportTopics`) and the states whose moments it shows come from the
configuration the run directory names (``stats.json``), by what each part *is*, not by its name:

- **estimate**: the ``pose`` Output of the first service whose interface (:mod:`runtime.verification.
  interfaces`: its ``interface=``, else what its output plugin kind ``PROVIDES``) is ``navigation`` or
  ``localization``; **zoom**: the ``zoom`` Outputs of those services (the Zoom Map a navigation
  service keeps, §6.1.3);
- **fused**: the ``objects`` Output of the first ``fusion`` service; **recognition**: the
  ``objects`` Outputs of the ``object-detection`` services;
- **cameras**: every topic whose type is an image (``sensor_msgs/msg/Image`` or a MessageType with
  ``width``, ``height``, ``encoding`` and ``data``: what ``--record CAMERA:jpeg`` accepts);
- **truth**: the topics of the sensors reading a simulated robot's true pose (a ``sim`` channel of
  ``sensor="pose"``, plugins/sim/devices.py: never noisy), one per robot that has one.

Every topic is named as the recorder names it in the bag (an internal topic ``T`` of node ``N`` is
``/N/T``, runtime.ros.recording). The **key states** of an agent's mission (:func:`key_states`) are
those on its success route: the fewest transitions from its initial state to its first final (the
success outcome, as the mission's progress counts, runtime.missions.hfsm), nested missions followed;
the **recognising states** (:func:`recognising_states`) those whose behavior uses a recognition
service or reads a recognition topic.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Collection, Iterator

from ckmconf.model import Behavior, Mission, Service, SmartResource, State, System

from ..registry import Registry, RegistryError, default_registry
from ..ros.config import ConfigRosTypes, all_topics
from ..ros.recording import bag_topic_name
from ..ros.sparse import is_image_type
from ..ros.types import RosTypeError
from ..verification.interfaces import service_interface
from .hfsm import distances_to_success
from .report_bag import ReportTopics

ESTIMATE_INTERFACES = ("navigation", "localization")
"""Interfaces whose ``pose`` Output is a robot's pose estimate on the map (docs/interfaces.md)."""
RECOGNITION_INTERFACES = ("object-detection", "fusion")
"""Interfaces whose ``objects`` Output is a recognition result."""


def recorded_name(system: System, topic: str, node: str | None) -> str:
    """The bag's name of ``topic`` as ``node`` uses it: ``/NODE/TOPIC`` for an internal topic of the node."""
    declared = system.node(node) if node is not None else None
    internal = declared is not None and any(t.name == topic and t.scope == "internal" for t in declared.topics)
    if internal:
        return bag_topic_name(f"/{node}/~{topic.lstrip('/')}")
    return bag_topic_name(topic)


def _interface(resource: SmartResource, service: Service, registry: Registry) -> str | None:
    try:
        return service_interface(resource, service, registry)
    except RegistryError:  # a kind that does not import: verify says so; the report goes without it
        return None


def _outputs(system: System, registry: Registry, interfaces: Collection[str], output: str) -> list[str]:
    """The recorded names of the Output ``output`` of every service of one of ``interfaces``, in document order."""
    found = []
    for resource in system.resources:
        for service in resource.services:
            if _interface(resource, service, registry) in interfaces:
                found += [recorded_name(system, o.topic, resource.node) for o in service.outputs if o.name == output]
    return list(dict.fromkeys(found))


def _cameras(system: System) -> list[str]:
    """The recorded names of the image-typed topics."""
    types = ConfigRosTypes(system)
    found = []
    for topic, node in all_topics(system):
        try:
            image = is_image_type(types.ros, types.ros_type_of(topic.type))
        except RosTypeError:
            continue
        if image:
            found.append(recorded_name(system, topic.name, node))
    return list(dict.fromkeys(found))


def _truths(system: System) -> list[str]:
    """The recorded names of the topics of the sensors reading a simulated robot's true pose."""
    found = []
    for node in system.nodes:
        truthful = {
            c.name for c in node.channels if c.backend == "sim" and any(p.name == "sensor" and p.value == "pose"
                                                                        for p in c.params)
        }  # fmt: skip
        found += [recorded_name(system, s.topic, node.name) for s in node.sensors if s.channel in truthful]
    return list(dict.fromkeys(found))


def topics_of(system: System, registry: Registry | None = None) -> ReportTopics:
    """The topics the report reads for ``system`` (see the module's rules; empty where it has none)."""
    registry = registry or default_registry()
    estimates = _outputs(system, registry, ESTIMATE_INTERFACES, "pose")
    fused = _outputs(system, registry, ("fusion",), "objects")
    return ReportTopics(
        estimate=estimates[0] if estimates else "",
        truth=tuple(_truths(system)),
        fused=fused[0] if fused else "",
        recognition=tuple(_outputs(system, registry, ("object-detection",), "objects")),
        cameras=tuple(_cameras(system)),
        zoom=tuple(_outputs(system, registry, ESTIMATE_INTERFACES, "zoom")),
    )


def _route(mission: Mission) -> list[State]:
    """The states on a fewest-transitions route from the initial state to the first final, in
    document order; every state when there is no such route (no final, or none reachable)."""
    to_goal = distances_to_success(mission)
    states = {s.name: s for s in mission.states}
    if mission.initial not in to_goal:
        return list(mission.states)
    from_start = {mission.initial: 0}
    queue = deque([mission.initial])
    while queue:
        name = queue.popleft()
        for transition in mission.transitions:
            if transition.from_ == name and transition.to in states and transition.to not in from_start:
                from_start[transition.to] = from_start[name] + 1
                queue.append(transition.to)
    length = to_goal[mission.initial]
    return [
        s for s in mission.states if s.name in from_start and from_start[s.name] + to_goal.get(s.name, -1) == length
    ]


def _walk(
    system: System, mission: Mission, path: str, route: bool, chain: tuple[str, ...]
) -> Iterator[tuple[str, State]]:
    """(path, state) of each behavior state under ``mission`` (only its success route's, ``route``)."""
    for state in _route(mission) if route else mission.states:
        here = f"{path}/{state.name}"
        nested = system.mission(state.mission) if state.mission else None
        if nested is not None and nested.name not in chain:
            yield from _walk(system, nested, here, route, (*chain, nested.name))
        elif state.behavior is not None:
            yield here, state


def key_states(system: System, mission: str) -> tuple[str, ...] | None:
    """The paths (``Top/Nested/STATE``) of the behavior states on ``mission``'s success route: the
    moments the report shows are each agent entering and ending them. None: no such mission."""
    top = system.mission(mission)
    if top is None:
        return None
    return tuple(path for path, _ in _walk(system, top, top.name, True, (top.name,)))


def _recognises(system: System, behavior: Behavior, topics: Collection[str], registry: Registry) -> bool:
    for use in behavior.uses:
        found = system.service(use.service)
        if found is not None and _interface(*found, registry) in RECOGNITION_INTERFACES:
            return True
    return any(i.topic is not None and bag_topic_name(i.topic) in topics for i in behavior.inputs)


def recognising_states(
    system: System, missions: Collection[str], topics: ReportTopics, registry: Registry | None = None
) -> set[str]:
    """The paths of the states of ``missions`` whose behavior uses a recognition service (its
    interface one of :data:`RECOGNITION_INTERFACES`) or reads ``topics``' recognition results."""
    registry = registry or default_registry()
    results = {t for t in (topics.fused, *topics.recognition) if t}
    found = set()
    for name in missions:
        top = system.mission(name)
        if top is None:
            continue
        for path, state in _walk(system, top, top.name, False, (top.name,)):
            behavior = system.behavior(state.behavior) if state.behavior else None
            if behavior is not None and _recognises(system, behavior, results, registry):
                found.add(path)
    return found
