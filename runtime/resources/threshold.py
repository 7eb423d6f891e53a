"""The threshold baseline the adaptation benchmark compares the TCM with (``ckm-bench adaptation``).

Not part of the thesis' design: it switches on the latest sample of each measure against the
scenarios' policy bounds, with no windows, probabilities, penalty, hysteresis or learning. That
is the naive rule whose oscillation at a bound §4.2.3 argues against. :class:`ThresholdSelector`
implements :class:`~runtime.resources.selection.ScenarioSelector`, so a Smart Resource built
with ``selector=ThresholdSelector`` runs it on the same load as the TCM.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from ckmconf.model.resources import TCM, Policy, Scenario

from .quality import QualityBounds
from .selection import Alarm, Decision, ScenarioEvent


class ThresholdSwitcher:
    """Baseline without windows, penalty or hysteresis: the highest-weight scenario whose policy
    bounds contain the latest sample of each measure (the lowest-weight one when none does); a
    combined measure's latest sample is the sum of its components' latest ones."""

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        initial: str | None = None,
        combined: Mapping[str, Sequence[str]] | None = None,
    ) -> None:
        self._ranked = sorted(scenarios, key=lambda s: -s.weight)
        self.active = initial or scenarios[0].name
        self._latest: dict[str, float] = {}
        self._combined = {name: tuple(parts) for name, parts in (combined or {}).items()}
        self.switches = 0

    def observe(self, measure: str, value: float) -> None:
        """Keep ``value`` as the latest sample of ``measure``."""
        self._latest[measure] = value

    def latest(self, measure: str) -> float | None:
        """The latest sample of a measure (of every component, summed, for a combined one)."""
        parts = self._combined.get(measure)
        if parts is None:
            return self._latest.get(measure)
        values = [self._latest.get(part) for part in parts]
        return None if any(v is None for v in values) else sum(v for v in values if v is not None)

    def evaluate(self) -> str:
        """Switch to the highest-weight scenario whose bounds contain the latest samples; its name."""

        def contains(scenario: Scenario) -> bool:
            for p in scenario.policies:
                value = self.latest(p.measure)
                if value is not None and not (
                    (p.lower is None or value >= p.lower) and (p.upper is None or value <= p.upper)
                ):
                    return False
            return True

        chosen = next((s.name for s in self._ranked if contains(s)), self._ranked[-1].name)
        if chosen != self.active:
            self.active, self.switches = chosen, self.switches + 1
        return self.active


class ThresholdSelector:
    """The :class:`ThresholdSwitcher` as a :class:`~runtime.resources.selection.ScenarioSelector`, so a
    service can run the baseline on the same load as the TCM (``ckm-bench adaptation``). No QR, no
    penalty; an alarm is raised while the latest samples lie outside the bounds of every scenario,
    cleared when one contains them again."""

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        settings: TCM | None = None,
        *,
        on_event: Callable[[ScenarioEvent], None] | None = None,
        on_alarm: Callable[[Alarm], None] | None = None,
        combined: Mapping[str, Sequence[str]] | None = None,
        **_: Any,
    ) -> None:
        self._records = {s.name: s for s in scenarios}
        self._switcher = ThresholdSwitcher(scenarios, (settings or TCM()).initial, combined)
        self.on_event, self.on_alarm = on_event, on_alarm
        self.alarm_active = False
        self.requirements: tuple[QualityBounds, ...] = ()
        self.last: Decision | None = None

    @property
    def active(self) -> str:
        """Name of the active scenario."""
        return self._switcher.active

    @property
    def profile(self) -> str:
        """SPT profile of the active scenario."""
        return self._records[self.active].profile

    @property
    def switches(self) -> int:
        """Scenario changes so far."""
        return self._switcher.switches

    @property
    def penalties(self) -> dict[str, float]:
        """All 0: the baseline has no penalty ξ."""
        return dict.fromkeys(self._records, 0.0)

    def observe(self, measure: str, value: float) -> None:
        """Keep one sample of a measure (only the latest counts)."""
        self._switcher.observe(measure, value)

    def set_requirements(self, requirements: Iterable[QualityBounds], now: float | None = None) -> Decision:
        """Keep the requirements for the record only (no QR here); decide on the active scenario."""
        self.requirements = tuple(requirements)  # kept for the record: thresholds know no QR
        return self._decide(now or 0.0, self.active)

    def set_ceiling(self, scenario: str) -> None:
        """Check the scenario name only: the baseline has no ceiling."""
        if scenario not in self._records:
            raise ValueError(f"no scenario {scenario!r} (scenarios: {', '.join(self._records)})")

    def prefer(self, scenario: str, now: float | None = None) -> Decision:
        """Switch to ``scenario`` (ValueError if unknown)."""
        if scenario not in self._records:
            raise ValueError(f"no scenario {scenario!r} (scenarios: {', '.join(self._records)})")
        return self._decide(now or 0.0, scenario)

    def evaluate(self, now: float | None = None) -> Decision:
        """The highest-weight scenario containing the latest samples (the lowest-weight one if none)."""
        ranked = sorted(self._records.values(), key=lambda s: -s.weight)  # the switcher's own rule
        chosen = next((s.name for s in ranked if self._contains(s)), ranked[-1].name)
        return self._decide(now or 0.0, chosen)

    def _contains(self, scenario: Scenario) -> bool:
        def within(p: Policy) -> bool:
            value = self._switcher.latest(p.measure)
            return value is None or ((p.lower is None or value >= p.lower) and (p.upper is None or value <= p.upper))

        return all(within(p) for p in scenario.policies)

    def _decide(self, time: float, chosen: str) -> Decision:
        events: list[ScenarioEvent] = []
        if chosen != self.active:
            previous, self._switcher.active = self.active, chosen
            self._switcher.switches += 1
            event = ScenarioEvent(time, previous, chosen, self.profile, "neglected", "threshold crossed", 0.0)
            events.append(event)
            if self.on_event is not None:
                self.on_event(event)
        alarms: list[Alarm] = []
        none_holds = not any(self._contains(s) for s in self._records.values())
        if none_holds != self.alarm_active:
            self.alarm_active = none_holds
            alarm = Alarm(time, none_holds, self.active, ("no scenario contains the latest measures",) * none_holds)
            alarms.append(alarm)
            if self.on_alarm is not None:
                self.on_alarm(alarm)
        self.last = Decision(time, self.active, self.profile, tuple(events), tuple(alarms), {})
        return self.last
