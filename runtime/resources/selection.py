"""What selects a service instance's active scenario (§4.2.3), and what a selection reports.

A Smart Resource service instance (:mod:`runtime.resources.instance`) hands its measures and its
clients' quality requirements to a :class:`ScenarioSelector` and publishes the
:class:`Decision` it returns: the scenario changes (:class:`ScenarioEvent`) and the alarms
(:class:`Alarm`). The thesis' selector is the Task Configuring Module
(:class:`runtime.resources.tcm.TaskConfiguringModule`, Algorithm 1 and eq. 4.7). The adaptation
benchmark compares it with a threshold baseline (:class:`runtime.resources.threshold.ThresholdSelector`).
Whoever builds the Smart Resource injects the one it wants as a :class:`SelectorFactory`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol

from ckmconf.model.resources import TCM, Scenario

from .quality import QualityBounds

Reason = Literal["neglected", "requirements", "recovered"]


@dataclass(frozen=True)
class ConditionResult:
    """One condition of a scenario at one evaluation; ``met`` None = unknown (no samples)."""

    kind: Literal["policy", "requirement"]
    measure: str
    probability: float | None
    required: float
    met: bool | None
    margin: float | None
    compatible: bool = True

    def describe(self) -> str:
        """One line for logs and alarms: the condition, its probability and whether it is met."""
        if not self.compatible:
            return f"{self.measure}: the scenario's policy exceeds the requested bounds"
        shown = "?" if self.probability is None else f"{self.probability:.2f}"
        relation = "≥" if self.met else "<"
        return f"{self.kind} {self.measure}: P={shown} {relation} {self.required:g}"


@dataclass(frozen=True)
class ScenarioEvaluation:
    """Algorithm 1 and eq. 4.7 for one scenario at one evaluation."""

    name: str
    profile: str
    conditions: tuple[ConditionResult, ...]
    accepted: int
    known: int
    suit: float
    penalty: float
    fev: float
    confidence: float
    state: float
    usable: bool
    satisfied: bool
    eligible: bool
    margin: float
    features: tuple[float, ...] | None

    @property
    def failing(self) -> tuple[ConditionResult, ...]:
        """The conditions known to fail (unknown ones excluded)."""
        return tuple(c for c in self.conditions if c.met is False)

    @property
    def holds(self) -> bool:
        """No known condition fails (the state aside)."""
        return not self.failing


@dataclass(frozen=True)
class ScenarioEvent:
    """A scenario change, for the service's quality topic (§4.3)."""

    time: float
    previous: str
    current: str
    profile: str
    reason: Reason
    detail: str
    penalty: float
    """ξ of the scenario left, after its update."""


@dataclass(frozen=True)
class Alarm:
    """Requirements met by no scenario (``raised``) or met again (not raised), for the alarm topic."""

    time: float
    raised: bool
    active: str
    unmet: tuple[str, ...]


@dataclass(frozen=True)
class Decision:
    """What one evaluation decided."""

    time: float
    active: str
    profile: str
    events: tuple[ScenarioEvent, ...]
    alarms: tuple[Alarm, ...]
    evaluations: Mapping[str, ScenarioEvaluation]

    @property
    def changed(self) -> bool:
        """True if the evaluation switched scenario."""
        return bool(self.events)


class ScenarioSelector(Protocol):
    """Selects one service instance's active scenario from its measures and requirements (§4.2.1.4)."""

    @property
    def active(self) -> str:
        """The active scenario's name."""
        ...

    @property
    def profile(self) -> str:
        """The active scenario's profile (the SPT plugin topology to run)."""
        ...

    @property
    def switches(self) -> int:
        """Scenario changes so far."""
        ...

    @property
    def penalties(self) -> dict[str, float]:
        """Each scenario's penalty ξ (eq. 4.7); all 0 for a selector without penalties."""
        ...

    @property
    def alarm_active(self) -> bool:
        """Whether an alarm is raised (no scenario holds) and not yet cleared."""
        ...

    def observe(self, measure: str, value: float) -> None:
        """One sample of a quality measure of the active profile's output."""
        ...

    def set_requirements(self, requirements: Iterable[QualityBounds], now: float | None = None) -> Decision:
        """The client's quality requirements changed: reselect at once."""
        ...

    def set_ceiling(self, scenario: str) -> None:
        """Never select a scenario above ``scenario`` (the one the client's parameters ask for)."""
        ...

    def prefer(self, scenario: str, now: float | None = None) -> Decision:
        """Switch to ``scenario`` (the client's parameters changed)."""
        ...

    def evaluate(self, now: float | None = None) -> Decision:
        """One periodic evaluation (every TCM ``period``)."""
        ...


class SelectorFactory(Protocol):
    """Builds the selector of one service instance: the TCM's class, or the baseline's."""

    def __call__(
        self,
        scenarios: Sequence[Scenario],
        settings: TCM | None = None,
        *,
        requirements: Iterable[QualityBounds] = (),
        combined: Mapping[str, Sequence[str]] | None = None,
        resolutions: Mapping[str, float | None] | None = None,
        on_event: Callable[[ScenarioEvent], None] | None = None,
        on_alarm: Callable[[Alarm], None] | None = None,
        alarm_after: int = 1,
    ) -> ScenarioSelector:
        """Build the selector of one instance from its ``<Scenario>`` and ``<TCM>`` records.

        Args:
            scenarios: The service's scenarios (eq. 4.6), highest weight first by convention.
            settings: The service's ``<TCM>`` (period, penalty, learning…); defaults when absent.
            requirements: The client's quality requirements QR in force at the start.
            combined: Each ``<CombinedMeasure>`` name → the measures whose samples it sums.
            resolutions: Each combined measure's histogram resolution (None: exact values).
            on_event: Called with every scenario change (the quality topic).
            on_alarm: Called when an alarm is raised or cleared (the alarm topic).
            alarm_after: Consecutive evaluations with no scenario holding before a measures alarm.
        """
