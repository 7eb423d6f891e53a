"""Mission marks with no service: ``init`` records what the mission is after, ``end`` closes it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from ckmconf.model import System
from ckmconf.model.missions import Behavior as BehaviorRecord
from runtime.missions.behaviors import Behavior, BehaviorStatus
from runtime.verification.manifest import P, Params

from .messages import TARGET_PARAMS


class Init(Behavior):
    """INIT: records what the mission is after (target, home); no service."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(*TARGET_PARAMS, P("home", "", "Name of the home Area of the map."))

    @classmethod
    def problems(cls, record: BehaviorRecord, system: System | None) -> list[tuple[Any, str]]:
        """A ``home`` that is no Area of the system's map (checked when the system has one)."""
        home = next((p for p in record.params if p.name == "home"), None)
        environment = system.environment if system is not None else None
        if home is None or not home.value.strip() or environment is None:
            return []
        names = [a.name for a in environment.areas]
        if home.value in names:
            return []
        return [(home, f"parameter 'home' = {home.value!r} is no Area of the map (its Areas: {names})")]

    def step(self) -> BehaviorStatus:
        """Done at once (INIT only records the mission's target and home, Table 7.5)."""
        return BehaviorStatus(progress=1.0, done=True, detail=f"target {self.params['target']}")


class End(Behavior):
    """END: closes the execution; its services were released by the previous states."""

    def step(self) -> BehaviorStatus:
        """Done at once: the previous states released their services."""
        return BehaviorStatus(progress=1.0, done=True)
