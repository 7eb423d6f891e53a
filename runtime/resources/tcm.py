"""The Task Configuring Module of one service (thesis §4.2.1.3–4.2.1.5, eq. 4.6–4.10, Algorithm 1).

A scenario is an SPT profile with the quality policies it must meet (eq. 4.6); the TCM keeps one
active and switches when it must. Every ``period`` the service layer calls :meth:`evaluate`,
which rates every scenario on the current measure windows: the conditions (its policies, then
the client's quality requirements QR, changed at run time with :meth:`set_requirements`), f_ev
(Algorithm 1, eq. 4.8), S_state (eq. 4.7), usable and eligible — see
:mod:`runtime.resources.tcm_rating`. The windows, and the convolution a condition on a
``<CombinedMeasure>`` (eq. 4.5; :meth:`from_service` takes them) is evaluated on, are kept by
:mod:`runtime.resources.tcm_windows`. Whenever the TCM switches, it goes to the argmax of
``S_state`` among the scenarios it may switch to (eq. 4.9); it does not re-run the argmax at
every evaluation.

Switching (the thesis: "active scenario will remain selected while the quality requirements
(QR) are maintained and the implied quality measures remain between the expected ranges"):

1. **neglected** — the active scenario is not usable. The TCM moves to the usable scenario of
   highest state; the left scenario's ``ξ`` grows by ``penalty_step`` (capped at
   :data:`MAX_PENALTY`, so ξ stays in [0, 1)). When no scenario is usable an :class:`Alarm` is
   raised and, when the active scenario's own policies fail, the TCM falls back to the scenario
   whose policies are closest to holding (the largest worst-policy quantile margin) if that is
   strictly closer than the active one's — a service at the edge of its capacity still
   degrades. A failing requirement whose scenario is merely incompatible with it makes a
   requirements switch, not neglect (no penalty).
2. **requirements** — :meth:`set_requirements` reselects at once, without penalty (eq. 4.7:
   ξ is updated on neglect "instead of a change of the quality requirements"): the argmax of
   ``S_state`` over the active scenario if still usable and the eligible others (see 3; no
   dwell, no margin), or over the usable others when the active one is not usable any more.
3. **recovered** — another scenario merely scoring higher never switches. A candidate takes
   over only when, for ``dwell`` consecutive evaluations, it is *eligible* (every condition
   known and holding, its policies even on bounds narrowed by ``band`` · scale — a Schmitt
   trigger around each bound) and its state beats the active one's by ``margin``. No penalty.

Alarms: raised when no scenario holds (every one has a known failing condition), cleared when
one holds again. With ``alarm_after`` > 1 an alarm from the measures waits until that many
consecutive evaluations found none holding — a load change is first judged on samples of the
profile that caused it, and the switch it triggers needs a window to show its effect; an alarm
from requirements no scenario can promise is raised at once.

Penalty decay: at each evaluation where a scenario is *satisfied* (every condition known and
holding on the current windows) its ``ξ`` decreases by ``penalty_step / decay_evaluations``
(linear, floor 0): one neglect is forgiven after ``decay_evaluations`` satisfied evaluations.
An inactive scenario is measured on the active profile's output, so a higher scenario looks
satisfied once the load drops; its ξ decays and it comes back (§7.2: "always evaluating the
resources in order to increase again the resolution"). While the load stays high each futile
try costs a full step and is forgiven only slowly, so the tries become rare: that, plus the
band and the dwell, is what stops oscillation at a bound.

Learning (eq. 4.10, ``learning="svm"``): the question the model answers is "if this candidate
were activated now, would its policies hold?", so a record is made per activation: the
scenario's features (per policy: probability and quantile margin) at the evaluation that
activated it — measured, for a switch, on the previous profile's output; for the initial
scenario, at its first evaluation with all of them known. The record is labelled +1 when the
scenario is still active and not neglected ``horizon`` evaluations later, −1 when it is left for
neglect before; it is dropped when the scenario is left within ``horizon`` for another reason.
The learned factor ``c_i`` then scales the weight of the candidates (eq. 4.7, see
:mod:`runtime.resources.learning`): a scenario that failed every time it was tried from similar
measures is no longer tried, while its ξ keeps decaying, so it comes back as soon as the
measures look like those it held with.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from ckmconf.model.resources import TCM, Scenario, Service

from .learning import ScenarioLearner
from .quality import DEFAULT_WINDOW, PolicyEvaluator, QualityBounds
from .selection import Alarm, ConditionResult, Decision, Reason, ScenarioEvaluation, ScenarioEvent
from .tcm_rating import MAX_PENALTY, ScenarioState, rate
from .tcm_windows import MeasureWindows
from .threshold import ThresholdSelector, ThresholdSwitcher  # re-exported: they were defined here once


class TaskConfiguringModule:
    """Selects the active scenario of one service (Algorithm 1, eq. 4.7; see the module docstring for the rules)."""

    def __init__(
        self,
        scenarios: Sequence[Scenario],
        settings: TCM | None = None,
        *,
        requirements: Iterable[QualityBounds] = (),
        combined: Mapping[str, Sequence[str]] | None = None,
        resolution: float | None = None,
        resolutions: Mapping[str, float | None] | None = None,
        band: float = 0.05,
        margin: float = 0.2,
        dwell: int = 3,
        decay_evaluations: int | None = 100,
        horizon: int = 10,
        on_event: Callable[[ScenarioEvent], None] | None = None,
        on_alarm: Callable[[Alarm], None] | None = None,
        alarm_after: int = 1,
    ) -> None:
        if not scenarios:
            raise ValueError("a TCM needs at least one scenario")
        self.alarm_after = max(1, alarm_after)
        self._unheld = 0
        self.settings = settings if settings is not None else TCM()
        self.windows = MeasureWindows(combined, resolutions, resolution)
        self.resolution, self.band, self.margin, self.dwell = resolution, band, margin, max(1, dwell)
        self.decay = self.settings.penalty_step / decay_evaluations if decay_evaluations else 0.0
        self.horizon = max(1, horizon)
        self.on_event, self.on_alarm = on_event, on_alarm
        learning = self.settings.learning == "svm"
        initial_penalty = min(MAX_PENALTY, max(0.0, self.settings.penalty))
        self._scenarios = {
            s.name: ScenarioState(
                s,
                tuple(PolicyEvaluator(p) for p in s.policies),
                initial_penalty,
                ScenarioLearner(self.settings.c) if learning else None,
            )
            for s in scenarios
        }
        if len(self._scenarios) != len(scenarios):
            raise ValueError("scenario names must be unique")
        initial = self.settings.initial or scenarios[0].name
        if initial not in self._scenarios:
            raise ValueError(f"initial scenario {initial!r} is not one of {sorted(self._scenarios)}")
        self._active = initial
        self._requirements: tuple[PolicyEvaluator, ...] = ()
        self._tick = 0
        self._alarm = False
        self._starting = True
        self.switches = 0
        self._ceiling: float | None = None
        self.last: Decision | None = None
        self._set_requirements(requirements)

    @classmethod
    def from_service(cls, service: Service, **options: Any) -> TaskConfiguringModule:
        """The TCM of a configured service: its Scenario records, TCM settings and CombinedMeasures."""
        options.setdefault("combined", service.combinations())
        options.setdefault("resolutions", {c.name: c.resolution for c in service.combined})
        return cls(service.scenarios, service.tcm, **options)

    # -- state -------------------------------------------------------------------------------

    @property
    def active(self) -> str:
        """Name of the active scenario."""
        return self._active

    @property
    def profile(self) -> str:
        """SPT profile of the active scenario."""
        return self._scenarios[self._active].record.profile

    @property
    def combined(self) -> dict[str, tuple[str, ...]]:
        """Each combined measure's components (``<CombinedMeasure>``, eq. 4.5)."""
        return self.windows.combined

    @property
    def resolutions(self) -> dict[str, float | None]:
        """Each combined measure's resolution (the bin of its convolution, D72)."""
        return self.windows.resolutions

    @property
    def penalties(self) -> dict[str, float]:
        """Each scenario's penalty ξ (eq. 4.7)."""
        return {name: s.penalty for name, s in self._scenarios.items()}

    @property
    def requirements(self) -> tuple[QualityBounds, ...]:
        """The clients' quality requirements QR in force."""
        return tuple(e.policy for e in self._requirements)

    @property
    def alarm_active(self) -> bool:
        """True while no scenario meets the requirements (alarm raised, not cleared)."""
        return self._alarm

    def learner(self, scenario: str) -> ScenarioLearner | None:
        """The soft-margin classifier of ``scenario`` (eq. 4.10), None without learning."""
        return self._scenarios[scenario].learner

    # -- measures ----------------------------------------------------------------------------

    def observe(self, measure: str, value: float) -> None:
        """A new sample of a measure (a component of a combined measure feeds the sum)."""
        self.windows.observe(measure, value)

    def observe_many(self, samples: Mapping[str, float]) -> None:
        """Feed one sample of each measure (:meth:`observe`)."""
        for measure, value in samples.items():
            self.observe(measure, value)

    # -- requirements ------------------------------------------------------------------------

    def _set_requirements(self, requirements: Iterable[QualityBounds]) -> None:
        evaluators = []
        for requirement in requirements:
            windows = [
                e.window for s in self._scenarios.values() for e in s.evaluators if e.measure == requirement.measure
            ]
            evaluators.append(PolicyEvaluator(requirement, max(windows, default=DEFAULT_WINDOW)))
        self._requirements = tuple(evaluators)
        for evaluator in (*self._requirements, *(e for s in self._scenarios.values() for e in s.evaluators)):
            self.windows.need(evaluator.measure, evaluator.window)

    def set_requirements(self, requirements: Iterable[QualityBounds], now: float | None = None) -> Decision:
        """The client's new QR: reselect at once (eq. 4.9), without penalty.

        A requirement is judged on the samples measured after it was set (D201): those before came
        under another client's configuration or none (a recognition's reliability while the robot
        drove with nothing in view), and say nothing of whether it can be met now.
        """
        self._set_requirements(requirements)
        self.windows.requirements_set(e.measure for e in self._requirements)
        time = now if now is not None else self._tick * self.settings.period
        evaluations = self._evaluate_all()
        events: list[ScenarioEvent] = []
        active = evaluations[self._active]
        allowed = [e for e in evaluations.values() if self._allowed(e.name)]
        candidates = [e for e in allowed if (e.usable if e.name == self._active else e.eligible)]
        if not active.usable:
            candidates = [e for e in allowed if e.usable]
        if candidates:
            best = max(candidates, key=lambda e: e.state)
            if best.name != self._active:
                events.append(self._switch(best, "requirements", time, "quality requirements changed", False))
        return self._finish(time, evaluations, events)

    def _allowed(self, scenario: str) -> bool:
        return self._ceiling is None or self._scenarios[scenario].record.weight <= self._ceiling

    def set_ceiling(self, scenario: str) -> None:
        """No scenario of a higher weight than ``scenario`` is taken from now on (no switch now)."""
        if scenario not in self._scenarios:
            raise ValueError(f"no scenario {scenario!r} (scenarios: {', '.join(self._scenarios)})")
        self._ceiling = self._scenarios[scenario].record.weight

    def prefer(self, scenario: str, now: float | None = None) -> Decision:
        """The client names a scenario (a resolution parameter): switch to it now, without penalty.

        It is a ceiling, not a lock: the TCM lowers it when its policies are neglected (Table 7.1:
        "the TCM may lower it") and comes back up to it, never above it (no scenario of a higher
        weight is taken while the preference holds).
        """
        self.set_ceiling(scenario)
        time = now if now is not None else self._tick * self.settings.period
        evaluations = self._evaluate_all()
        events: list[ScenarioEvent] = []
        if scenario != self._active:
            detail = "the client prefers this scenario"
            events.append(self._switch(evaluations[scenario], "requirements", time, detail, False))
        return self._finish(time, evaluations, events)

    # -- evaluation --------------------------------------------------------------------------

    def _evaluate_all(self) -> dict[str, ScenarioEvaluation]:
        return {
            name: rate(
                s,
                active=name == self._active,
                windows=self.windows,
                requirements=self._requirements,
                band=self.band,
                threshold=self.settings.threshold,
            )
            for name, s in self._scenarios.items()
        }

    def evaluate(self, now: float | None = None) -> Decision:
        """One TCM period: rate every scenario, switch if the active one is neglected or a better one has recovered."""
        self._tick += 1
        time = now if now is not None else self._tick * self.settings.period
        evaluations = self._evaluate_all()
        active = evaluations[self._active]
        events: list[ScenarioEvent] = []
        others = [e for e in evaluations.values() if e.name != self._active and self._allowed(e.name)]
        if not active.usable:
            failing = active.failing
            by_requirements = bool(failing) and all(not c.compatible for c in failing)
            reason: Reason = "requirements" if by_requirements else "neglected"
            detail = "; ".join(c.describe() for c in failing) or f"state {active.state:.2f} ≤ 0"
            usable = [e for e in others if e.usable]
            if usable:
                best = max(usable, key=lambda e: e.state)
                events.append(self._switch(best, reason, time, detail, not by_requirements))
            elif others and any(c.kind == "policy" for c in failing):
                closest = max(others, key=lambda e: e.margin)
                if closest.margin > active.margin:
                    detail += "; no scenario meets its policies, closest taken"
                    events.append(self._switch(closest, reason, time, detail, not by_requirements))
        else:
            for e in others:
                scenario = self._scenarios[e.name]
                scenario.streak = scenario.streak + 1 if e.eligible and e.state > active.state + self.margin else 0
            ready = [e for e in others if self._scenarios[e.name].streak >= self.dwell]
            if ready:
                best = max(ready, key=lambda e: e.state)
                detail = f"state {best.state:.2f} > {active.state:.2f} for {self.dwell} evaluations"
                events.append(self._switch(best, "recovered", time, detail, False))
        penalized = {e.previous for e in events if e.reason == "neglected"}
        for name, e in evaluations.items():
            if e.satisfied and name not in penalized:
                scenario = self._scenarios[name]
                scenario.penalty = max(0.0, scenario.penalty - self.decay)
        return self._finish(time, evaluations, events, debounce=True)

    def _switch(
        self, target: ScenarioEvaluation, reason: Reason, time: float, detail: str, penalize: bool
    ) -> ScenarioEvent:
        left = self._scenarios[self._active]
        if penalize:
            left.penalty = min(MAX_PENALTY, left.penalty + self.settings.penalty_step)
        if left.learner is not None and left.pending is not None and penalize:
            left.learner.record(left.pending[1], False)
        left.pending, self._starting = None, False
        entered = self._scenarios[target.name]
        if entered.learner is not None and target.features is not None:
            entered.pending = (self._tick, target.features)
        event = ScenarioEvent(time, self._active, target.name, entered.record.profile, reason, detail, left.penalty)
        self._active = target.name
        self.switches += 1
        for scenario in self._scenarios.values():
            scenario.streak = 0
        if self.on_event is not None:
            self.on_event(event)
        return event

    def _finish(
        self,
        time: float,
        evaluations: dict[str, ScenarioEvaluation],
        events: list[ScenarioEvent],
        debounce: bool = False,
    ) -> Decision:
        active = self._scenarios[self._active]
        if active.learner is not None:
            features = evaluations[self._active].features
            if self._starting and features is not None:  # the initial scenario: activated at its first evidence
                active.pending, self._starting = (self._tick, features), False
            elif active.pending is not None and active.pending[0] <= self._tick - self.horizon:
                active.learner.record(active.pending[1], True)
                active.pending = None
        alarms: list[Alarm] = []
        any_holds = any(e.holds for e in evaluations.values())
        self._unheld = 0 if any_holds else self._unheld + 1
        persistent = not debounce or self._unheld >= self.alarm_after
        if any_holds == self._alarm and (any_holds or persistent):  # raised when none holds, cleared when one does
            self._alarm = not any_holds
            unmet = tuple(c.describe() for c in evaluations[self._active].failing)
            alarm = Alarm(time, self._alarm, self._active, unmet)
            alarms.append(alarm)
            if self.on_alarm is not None:
                self.on_alarm(alarm)
        self.last = Decision(time, self._active, active.record.profile, tuple(events), tuple(alarms), evaluations)
        return self.last


__all__ = [
    "MAX_PENALTY",
    "Alarm",
    "ConditionResult",
    "Decision",
    "ScenarioEvaluation",
    "ScenarioEvent",
    "TaskConfiguringModule",
    "ThresholdSelector",
    "ThresholdSwitcher",
]
