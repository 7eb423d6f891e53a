"""How a Task Configuring Module rates one scenario (thesis §4.2.1.3–4.2.1.4, eq. 4.6–4.9, Algorithm 1).

A scenario is an SPT profile with the quality policies it must meet (eq. 4.6). :func:`rate`
evaluates it on the current measure windows (:mod:`runtime.resources.tcm_windows`):

- **Conditions** of a scenario: its policies, then the client's quality requirements QR (a list
  of Require-like bounds per measure).
- **f_ev** (Algorithm 1, eq. 4.8): ``acc`` counts the conditions that hold — the line
  ``if Q_i = RQ_i`` is read as "the condition's probability condition holds",
  ``P(lower ≤ Q ≤ upper) ≥ probability`` over its window (eq. 4.4); ``suit = acc / n``;
  ``f_ev = suit · (1 − ξ)``. Conditions on a measure without samples yet are unknown and left
  out of both ``acc`` and ``n`` (no condition known: ``suit = 1``), so a fresh TCM stays in its
  initial scenario and raises no alarm before evidence arrives. A requirement holds for a
  scenario when it holds on the measured window *and* the scenario's own policies on that
  measure lie within the requirement's bounds (:func:`within`): a scenario that tolerates values
  the client forbids cannot promise the requirement. That is what lets a changed QR select
  another profile.
- **State** (eq. 4.7): ``S_state = w_i · c_i · f_ev − th``; ``fy`` is read as the decision
  function of the soft-margin classifier, positive meaning usable. ``c_i`` is 1 unless
  ``learning="svm"`` has trained the scenario's model, see :mod:`runtime.resources.learning`;
  it is applied to the candidates only — the active scenario is judged by its conditions.
- **Usable** (eq. 4.9, ``F(Q_x) ≠ 0`` for all of its policies): no known condition fails and
  ``S_state > 0``. **Eligible** (to take over from a working scenario): every condition known and
  holding, its policies even on bounds narrowed by ``band`` · scale (a Schmitt trigger around
  each bound), and ``S_state > 0``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ckmconf.model.resources import Scenario

from .learning import ScenarioLearner
from .quality import PolicyEvaluator, QualityBounds
from .selection import ConditionResult, ScenarioEvaluation
from .tcm_windows import MeasureWindows

MAX_PENALTY = 0.99
"""Upper cap of ξ: a scenario's evaluation is scaled by 1 − ξ, which must stay positive."""


@dataclass
class ScenarioState:
    """What a TCM keeps of one scenario between evaluations: its penalty ξ (eq. 4.7), classifier (eq. 4.10), streak."""

    record: Scenario
    evaluators: tuple[PolicyEvaluator, ...]
    penalty: float
    learner: ScenarioLearner | None
    streak: int = 0
    pending: tuple[int, tuple[float, ...]] | None = None


def within(policy: QualityBounds, requirement: QualityBounds) -> bool:
    """The policy's interval lies inside the requirement's (None = unbounded)."""
    low = requirement.lower is None or (policy.lower is not None and policy.lower >= requirement.lower)
    high = requirement.upper is None or (policy.upper is not None and policy.upper <= requirement.upper)
    return low and high


def rate(
    scenario: ScenarioState,
    *,
    active: bool,
    windows: MeasureWindows,
    requirements: Sequence[PolicyEvaluator],
    band: float,
    threshold: float,
) -> ScenarioEvaluation:
    """Rate ``scenario`` on the current windows: its conditions, f_ev (eq. 4.8) and S_state (eq. 4.7)."""
    conditions: list[ConditionResult] = []
    entry_ok = True
    for evaluator in scenario.evaluators:
        source = windows.source(evaluator.measure, evaluator.window)
        result = evaluator.evaluate(source)
        conditions.append(
            ConditionResult("policy", result.measure, result.probability, result.required, result.met, result.margin)
        )
        entry_ok = entry_ok and evaluator.evaluate(source, band=band).met is True
    for evaluator in requirements:
        compatible = all(
            within(e.policy, evaluator.policy) for e in scenario.evaluators if e.measure == evaluator.measure
        )
        result = evaluator.evaluate(windows.required_source(evaluator))
        met = False if not compatible else result.met
        conditions.append(
            ConditionResult(
                "requirement", result.measure, result.probability, result.required, met, result.margin, compatible
            )
        )
    known = [c for c in conditions if c.met is not None]
    accepted = sum(1 for c in known if c.met)
    suit = accepted / len(known) if known else 1.0
    fev = suit * (1.0 - scenario.penalty)
    policies = conditions[: len(scenario.evaluators)]
    features = None
    if all(c.probability is not None and c.margin is not None for c in policies):
        features = tuple(v for c in policies for v in (c.probability or 0.0, c.margin or 0.0))
    confidence = 1.0
    if scenario.learner is not None and not active:
        confidence = scenario.learner.confidence(features)
    state = scenario.record.weight * confidence * fev - threshold
    holds = all(c.met is not False for c in conditions)
    satisfied = len(known) == len(conditions) and accepted == len(conditions)
    margins = [c.margin for c in policies if c.margin is not None]
    return ScenarioEvaluation(
        name=scenario.record.name,
        profile=scenario.record.profile,
        conditions=tuple(conditions),
        accepted=accepted,
        known=len(known),
        suit=suit,
        penalty=scenario.penalty,
        fev=fev,
        confidence=confidence,
        state=state,
        usable=holds and state > 0.0,
        satisfied=satisfied,
        eligible=satisfied and entry_ok and state > 0.0,
        margin=min(margins) if margins else float("-inf"),
        features=features,
    )
