"""Top-level records: the System and Part documents (schemas/ckm.xsd)."""

from __future__ import annotations

from dataclasses import dataclass

from ..binding import Record, attr, child, children
from .environment import Environment
from .kernel import MessageType, Node, Topic
from .missions import Behavior, CompositionMatrix, Mission, Plan, Validation
from .network import Network
from .resources import Service, SmartResource


@dataclass(frozen=True, kw_only=True)
class Include(Record):
    """<Include>: pulls a Part file into this document."""

    TAG = "Include"
    href: str = attr()


@dataclass(frozen=True, kw_only=True)
class Content(Record):
    """What a System and a Part may hold, in schema order."""

    includes: tuple[Include, ...] = children()
    network: Network | None = child(default=None)
    message_types: tuple[MessageType, ...] = children()
    topics: tuple[Topic, ...] = children()
    nodes: tuple[Node, ...] = children()
    resources: tuple[SmartResource, ...] = children()
    behaviors: tuple[Behavior, ...] = children()
    matrices: tuple[CompositionMatrix, ...] = children()
    missions: tuple[Mission, ...] = children()
    plans: tuple[Plan, ...] = children()
    validation: Validation | None = child(default=None)
    environment: Environment | None = child(default=None)


@dataclass(frozen=True, kw_only=True)
class Part(Content):
    """<Part>: a piece of a system, pulled in with Include."""

    TAG = "Part"
    version: str = attr()
    description: str | None = attr(default=None)


@dataclass(frozen=True, kw_only=True)
class System(Content):
    """<System>: a whole CKM system. After load() it holds every included Part merged in."""

    TAG = "System"
    name: str = attr()
    version: str = attr()
    description: str | None = attr(default=None)

    def node(self, name: str) -> Node | None:
        """The ``<Node>`` named ``name``, None if absent."""
        return next((n for n in self.nodes if n.name == name), None)

    def resource(self, name: str) -> SmartResource | None:
        """The ``<SmartResource>`` named ``name``, None if absent."""
        return next((r for r in self.resources if r.name == name), None)

    def service(self, ref: str) -> tuple[SmartResource, Service] | None:
        """The resource and service named by a Resource.Service reference."""
        resource_name, _, service_name = ref.partition(".")
        resource = self.resource(resource_name)
        if resource is None:
            return None
        found = next((s for s in resource.services if s.name == service_name), None)
        return (resource, found) if found is not None else None

    def lazy_topics(self) -> set[str]:
        """Topics published only while asked for (D245): of lazy ``<Sensor>``s and lazy ``<Service>``s' outputs."""
        sensors = {s.topic for n in self.nodes for s in n.sensors if s.lazy}
        return sensors | {o.topic for r in self.resources for v in r.services if v.lazy for o in v.outputs}

    def behavior(self, name: str) -> Behavior | None:
        """The ``<Behavior>`` named ``name``, None if absent."""
        return next((b for b in self.behaviors if b.name == name), None)

    def mission(self, name: str) -> Mission | None:
        """The ``<Mission>`` named ``name``, None if absent."""
        return next((m for m in self.missions if m.name == name), None)

    def plan(self, name: str) -> Plan | None:
        """The ``<Plan>`` named ``name``, None if absent."""
        return next((p for p in self.plans if p.name == name), None)

    def matrix(self, name: str) -> CompositionMatrix | None:
        """The ``<CompositionMatrix>`` named ``name``, None if absent."""
        return next((m for m in self.matrices if m.name == name), None)


Document = System | Part
