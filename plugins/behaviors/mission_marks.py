"""Mission marks with no service: ``init`` records what the mission is after, ``end`` closes it."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from runtime.missions.behaviors import Behavior, BehaviorStatus
from runtime.verification.manifest import P, Params

from .messages import TARGET_PARAMS


class Init(Behavior):
    """INIT: records what the mission is after (target, home); no service."""

    PARAMS: ClassVar[Mapping[str, Any]] = Params(*TARGET_PARAMS, P("home", "", "Name of the home area."))

    def step(self) -> BehaviorStatus:
        """Done at once (INIT only records the mission's target and home, Table 7.5)."""
        return BehaviorStatus(progress=1.0, done=True, detail=f"target {self.params['target']}")


class End(Behavior):
    """END: closes the execution; its services were released by the previous states."""

    def step(self) -> BehaviorStatus:
        """Done at once: the previous states released their services."""
        return BehaviorStatus(progress=1.0, done=True)
