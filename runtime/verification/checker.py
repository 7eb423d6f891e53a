"""The shared part of ``verify``: a system's kinds, Params and topic types, looked up and reported.

:class:`Checker` holds one pass's state (the system, the registry, the reporter with the files'
text for attribute locations, the message types and external topics) and the checks every
element kind needs: a kind exists in the registry and its ``<Param>`` elements fit its manifest
(:mod:`.manifest`: a per-name value at its bad entry, :mod:`.entries`), and a value type fits a
topic's type (:mod:`.types`, ROS 2 types through :mod:`runtime.ros.config`). The element checks
that use them are in :mod:`.verify`.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any

from ckmconf.binding import Record, walk
from ckmconf.checks.report import Reporter
from ckmconf.errors import ConfigError
from ckmconf.model import MessageType, Node, Param, System, Topic
from ckmconf.rostypes import is_ros_type
from ckmconf.source import Limits, SourceFile, read_source

from ..registry import NOUNS, Registry, RegistryError
from .manifest import param_problems, params_of
from .types import describe, fits


def _sources(system: System) -> dict[str, SourceFile]:
    """The files the system was read from, for attribute locations (unreadable ones are skipped)."""
    found: dict[str, SourceFile] = {}
    for record in walk(system):
        if record.loc is not None and record.loc.file not in found:
            try:
                found[record.loc.file] = read_source(record.loc.file, Limits())
            except ConfigError:
                continue
    return found


class Checker:
    """One pass over a system: its state, and the kind, Param and topic-type checks; problems collect in ``report``."""

    def __init__(self, system: System, registry: Registry) -> None:
        self.system = system
        self.registry = registry
        self.report = Reporter(_sources(system))
        self.types: dict[str, MessageType] = {m.name: m for m in system.message_types}
        self._ros_types: Any = None
        self.external: dict[str, Topic] = {t.name: t for t in system.topics}
        for node in system.nodes:
            for topic in node.topics:
                if topic.scope == "external":
                    self.external.setdefault(topic.name, topic)

    # ------------------------------------------------------------------ kinds and Params

    def _kind(self, record: Record, category: str, kind: str, attr: str) -> type[Any] | None:
        """The class of ``kind``, or None after reporting why there is none."""
        try:
            cls = self.registry.find(category, kind)
        except RegistryError as exc:
            self.report.error(record, str(exc), attr)
            return None
        if cls is None:
            self.report.error(record, self.registry.missing(category, kind), attr)
        return cls

    def _params(self, record: Record, cls: type[Any], params: Iterable[Param], owner: str) -> None:
        """Each Param against the kind's declaration (a per-name value at its bad entry); missing
        required ones at ``record``. The same conversions as ``read_params``, which builds the kind."""
        for problem in param_problems(cls, tuple(params), owner):
            if problem.param is None:
                self.report.error(record, problem.message)
            else:
                self.report.error(problem.param, problem.message, problem.attr, problem.offset)
        declared = params_of(cls).specs
        for param in params:
            entry = declared.get(param.name)
            if entry is not None and entry.place:
                unknown = self.place_problem(param.value)
                if unknown:
                    self.report.error(param, f"{owner}: parameter {param.name!r}: {unknown}", "value")

    def place_problem(self, value: str) -> str:
        """Why ``value`` is no place of the system's map: neither a pose ``"x y yaw"`` nor an Area or
        Object of its ``<Environment>`` ("" when it is one, is empty, or the system has no map)."""
        environment = self.system.environment
        words = value.replace(",", " ").split()
        if environment is None or not words or _is_pose(words):
            return ""
        names = [a.name for a in environment.areas] + [o.name for o in environment.objects]
        if value.strip() in names:
            return ""
        close = difflib.get_close_matches(value.strip(), names, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else f" (it has: {', '.join(names) or 'none'})"
        return (f"{value!r} is neither a pose 'x y yaw' nor an Area or Object of the map "
                f"{environment.name!r}{hint}")

    def _checked(
        self, record: Record, category: str, kind: str, params: Iterable[Param], attr: str = "kind"
    ) -> type[Any] | None:
        cls = self._kind(record, category, kind, attr)
        if cls is not None:
            self._params(record, cls, params, f"{NOUNS[category]} {kind!r}")
        return cls

    # ------------------------------------------------------------------ topics and types

    def _topic_type(self, name: str, node: Node | None) -> str | None:
        """The type a topic carries as ``node`` sees it (its own topics first), None if unknown."""
        if node is not None:
            own = next((t for t in node.topics if t.name == name), None)
            if own is not None:
                return own.type
        found = self.external.get(name)
        return found.type if found is not None else None

    def _signal_types(self, name: str) -> list[str]:
        """The declared types of the plan signals called ``name``."""
        return [s.type for plan in self.system.plans for s in plan.signals if s.name == name and s.type]

    def _ros(self) -> Any:
        """The ROS types of the system (runtime.ros.config.ConfigRosTypes), loaded on first need."""
        if self._ros_types is None:
            from ..ros.config import ConfigRosTypes  # rosbags' store: only for systems naming ROS types

            self._ros_types = ConfigRosTypes(self.system)
        return self._ros_types

    def _ros_topics(self) -> None:
        """Each topic of a custom ROS type whose ``.msg`` definition does not load, at the topic."""
        for topic in [*self.system.topics, *(t for n in self.system.nodes for t in n.topics)]:
            if is_ros_type(topic.type) and topic.type in self._ros().problems:
                self.report.error(topic, self._ros().problems[topic.type], "type")

    def _flow(self, record: Record, attr: str, value: str, carried: str | None, sentence: str, size: int = 1) -> None:
        """Report when ``value`` does not fit a topic of type ``carried``; ``sentence`` holds a {} for it."""
        if carried is not None and is_ros_type(carried):
            for problem in self._ros().value_problems(value, carried):
                self.report.error(
                    record, sentence.format(describe(value, size)) + f" of ROS type {carried}: {problem}", attr
                )
            return
        if carried is not None and not fits(value, carried, self.types):
            self.report.error(record, sentence.format(describe(value, size)) + f" of type {carried}", attr)


def _is_pose(words: list[str]) -> bool:
    try:
        [float(w) for w in words]
    except ValueError:
        return False
    return True
