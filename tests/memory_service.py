"""A service handle simulated in memory for behavior tests (§5.2's service interface: configure,
outputs, measures): the test writes its outputs and measures, and reads what it was configured with."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

from ckmconf.model import System
from runtime.missions.behaviors import Behavior, BehaviorContext
from runtime.registry import default_registry
from runtime.resources.api import Bounds


def wired_behavior(system: System, name: str, service: Callable[[str], Any], topics: Mapping[str, Any],
                   publish: Callable[[str, Any], None], now: Callable[[], float]) -> Behavior:
    """The real behavior ``name`` of ``system`` (its registered kind): its services are ``service(ref)``,
    its inputs read ``topics``, its outputs go to ``publish(topic, message)``."""
    record = system.behavior(name)
    assert record is not None
    context = BehaviorContext(
        services={u.alias: service(u.service) for u in record.uses},
        inputs={p.name: functools.partial(topics.get, p.topic) for p in record.inputs},
        outputs={p.name: functools.partial(publish, str(p.topic)) for p in record.outputs},
        now=now,
    )
    made: Behavior = default_registry().resolve("behavior", record.kind, record)(record, context)
    return made


class MemoryService:
    """A service handle whose outputs and measures the test sets; ``configured`` keeps every
    (parameters, requirements) a behavior configured it with, in order."""

    def __init__(self, ref: str) -> None:
        self.ref = ref
        self.outputs: dict[str, Any] = {}
        self.values: dict[str, float] = {}
        self.configured: list[tuple[dict[str, Any], tuple[Bounds, ...]]] = []

    def configure(self, parameters: Mapping[str, Any], requirements: tuple[Bounds, ...]) -> None:
        self.configured.append((dict(parameters), requirements))

    def output(self, name: str) -> Any:
        return self.outputs.get(name)

    def measures(self) -> dict[str, float]:
        return dict(self.values)

    def samples(self, measure: str) -> list[float]:
        return [self.values[measure]] if measure in self.values else []

    def running(self) -> bool:
        return True
