"""A service handle simulated in memory for behavior tests (§5.2's service interface: configure,
outputs, measures): the test writes its outputs and measures, and reads what it was configured with."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from runtime.resources.api import Bounds


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
