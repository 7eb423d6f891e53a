"""Name tables of a merged system (§3.1.5.2), built once and shared by every check."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..model import BUILTIN_TYPES, MessageType, Node, Service, SmartResource, System, Topic


@dataclass
class Scope:
    """Where names resolve: topics per node and system-wide, services, types, signals."""

    system: System
    external: dict[str, Topic] = field(default_factory=dict)
    node_topics: dict[str, dict[str, Topic]] = field(default_factory=dict)
    services: dict[str, tuple[SmartResource, Service]] = field(default_factory=dict)
    types: dict[str, MessageType] = field(default_factory=dict)
    signals: set[str] = field(default_factory=set)

    @classmethod
    def of(cls, system: System) -> Scope:
        """Build the name tables of ``system`` (the first declaration of a name wins; duplicates are checked apart)."""
        scope = cls(system)
        for topic in system.topics:
            scope.external.setdefault(topic.name, topic)
        for node in system.nodes:
            table = scope.node_topics.setdefault(node.name, {})
            for topic in node.topics:
                table.setdefault(topic.name, topic)
                if topic.scope == "external":
                    scope.external.setdefault(topic.name, topic)
        for resource in system.resources:
            for service in resource.services:
                scope.services.setdefault(f"{resource.name}.{service.name}", (resource, service))
        for message_type in system.message_types:
            scope.types.setdefault(message_type.name, message_type)
        scope.signals = {signal.name for plan in system.plans for signal in plan.signals}
        return scope

    def topic(self, node: Node | None, name: str) -> Topic | None:
        """A topic as seen from a node: its own topics first, then the external ones."""
        if node is not None:
            own = self.node_topics.get(node.name, {}).get(name)
            if own is not None:
                return own
        return self.external.get(name)

    def visible_topics(self, node: Node | None) -> list[str]:
        """Topic names ``node`` can use: its own, then the system's external ones."""
        own = list(self.node_topics.get(node.name, {})) if node is not None else []
        return own + list(self.external)

    def type_exists(self, name: str) -> bool:
        """True if ``name`` is a built-in type or a declared ``<MessageType>``."""
        return name in BUILTIN_TYPES or name in self.types

    def type_names(self) -> list[str]:
        """Every usable type name, built-ins first (for error messages)."""
        return sorted(BUILTIN_TYPES) + sorted(self.types)
