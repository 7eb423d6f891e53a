"""The Task Configuring Module on scripted measure sequences (thesis §4.2.1.3–5, §7.2)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pytest

import ckmconf
from ckmconf.model.missions import Require
from ckmconf.model.resources import TCM, Policy, Scenario
from runtime.resources.learning import ScenarioLearner
from runtime.resources.tcm import (
    MAX_PENALTY,
    Alarm,
    Decision,
    ScenarioEvent,
    TaskConfiguringModule,
    ThresholdSelector,
    ThresholdSwitcher,
)

REPO = Path(__file__).resolve().parents[3]
BOUNDS = {"VGA": 0.012, "QVGA": 0.017, "QQVGA": 0.020}  # configs/usecase/resources.xml, RGBRecog
WEIGHTS = {"VGA": 3.0, "QVGA": 2.0, "QQVGA": 1.0}
COST = {"VGA": 1.0, "QVGA": 0.6, "QQVGA": 0.4}  # processing cost relative to VGA


def scenarios(cpu: bool = False) -> list[Scenario]:
    """The RGBRecog scenarios; deadline policies only unless ``cpu``."""
    cpu_bounds = {"VGA": 0.36, "QVGA": 0.42, "QQVGA": 0.45}
    result = []
    for name, upper in BOUNDS.items():
        policies = [Policy(measure="deadline", upper=upper, probability=0.95, window=50)]
        if cpu:
            policies.append(Policy(measure="cpu", upper=cpu_bounds[name], probability=0.9, window=50))
        result.append(Scenario(name=name, profile=name, weight=WEIGHTS[name], policies=tuple(policies)))
    return result


def tcm(initial: str = "VGA", learning: Literal["svm", "none"] = "none", **options: Any) -> TaskConfiguringModule:
    return TaskConfiguringModule(scenarios(), TCM(initial=initial, learning=learning), **options)


def feed(module: TaskConfiguringModule, deadlines: Iterable[float]) -> list[Decision]:
    """One sample, one evaluation."""
    decisions = []
    for value in deadlines:
        module.observe("deadline", value)
        decisions.append(module.evaluate())
    return decisions


def actives(decisions: Sequence[Decision]) -> list[str]:
    """The sequence of active scenarios, repeats collapsed."""
    seen: list[str] = []
    for decision in decisions:
        if not seen or seen[-1] != decision.active:
            seen.append(decision.active)
    return seen


class Plant:
    """A deadline that depends on the load and on the active scenario's cost (the feedback that
    makes a higher resolution look fine while a lower one runs)."""

    def __init__(self, seed: int = 0, per_evaluation: int = 10) -> None:
        self.rng = np.random.default_rng(seed)
        self.per_evaluation = per_evaluation

    def deadline(self, load: float, scenario: str) -> float:
        return 0.008 * load * COST[scenario] + float(self.rng.normal(0.0, 0.0004))

    def run(self, module: TaskConfiguringModule, loads: Sequence[float]) -> list[Decision]:
        decisions = []
        for load in loads:
            for _ in range(self.per_evaluation):
                module.observe("deadline", self.deadline(load, module.active))
            decisions.append(module.evaluate())
        return decisions

    def baseline(self, loads: Sequence[float], initial: str = "VGA") -> ThresholdSwitcher:
        switcher = ThresholdSwitcher(scenarios(), initial)
        for load in loads:
            for _ in range(self.per_evaluation):
                switcher.observe("deadline", self.deadline(load, switcher.active))
                switcher.evaluate()
        return switcher


def events(decisions: Sequence[Decision]) -> list[ScenarioEvent]:
    return [e for d in decisions for e in d.events]


# -- start, stay, step down ---------------------------------------------------------------------


def test_starts_in_initial_and_stays_while_the_policies_hold() -> None:
    module = tcm("VGA")
    assert module.active == "VGA" and module.profile == "VGA"
    first = module.evaluate()  # no sample yet: nothing known, nothing neglected, no alarm
    assert first.active == "VGA" and not first.events and not first.alarms
    rng = np.random.default_rng(1)
    decisions = feed(module, 0.008 + rng.normal(0, 0.0005, 2000))
    assert actives(decisions) == ["VGA"]
    assert not events(decisions) and not any(d.alarms for d in decisions)
    assert module.penalties == {"VGA": 0.0, "QVGA": 0.0, "QQVGA": 0.0}
    last = decisions[-1].evaluations["VGA"]
    assert last.suit == 1.0 and last.fev == 1.0 and last.state == pytest.approx(3.0 - 0.5)
    assert TaskConfiguringModule(scenarios()).active == "VGA"  # no initial: the first scenario
    with pytest.raises(ValueError):
        tcm("SVGA")


def test_time_defaults_to_evaluations_times_period() -> None:
    module = TaskConfiguringModule(scenarios(), TCM(period=0.5))
    assert module.evaluate().time == 0.5
    assert module.evaluate().time == 1.0
    assert module.evaluate(now=42.0).time == 42.0


def test_steps_down_vga_qvga_qqvga_as_the_deadline_grows() -> None:
    rng = np.random.default_rng(2)
    ramp = np.linspace(0.008, 0.0195, 3000) + rng.normal(0, 0.0002, 3000)
    module = tcm("VGA")
    decisions = feed(module, ramp)
    assert actives(decisions) == ["VGA", "QVGA", "QQVGA"]
    changes = events(decisions)
    assert [(e.previous, e.current, e.reason) for e in changes] == [
        ("VGA", "QVGA", "neglected"),
        ("QVGA", "QQVGA", "neglected"),
    ]
    first, second = (next(i for i, d in enumerate(decisions) if d.events and d.events[0] is e) for e in changes)
    # Each step comes once the deadline has passed the active scenario's bound, not before.
    assert 0.012 < ramp[first] < 0.0135
    assert 0.017 < ramp[second] < 0.0185
    assert not any(d.alarms for d in decisions)
    assert changes[0].profile == "QVGA" and "deadline" in changes[0].detail


# -- penalty, decay, coming back ------------------------------------------------------------------


def test_penalty_grows_on_each_forced_switch() -> None:
    module = tcm("VGA", decay_evaluations=None)
    good, bad = [0.008] * 80, [0.016] * 5  # 5 late samples of 50: P = 0.90 < 0.95
    decisions = feed(module, (good + bad) * 5 + good)
    forced = [e for e in events(decisions) if e.reason == "neglected"]
    assert [e.previous for e in forced] == ["VGA"] * 3
    assert [e.penalty for e in forced] == pytest.approx([0.1, 0.2, 0.3])
    recovered = [e for e in events(decisions) if e.reason == "recovered"]
    assert [e.current for e in recovered] == ["VGA", "VGA"]  # ξ = 0.3: 3·0.7 − 0.5 = 1.6 < 1.5 + margin
    assert module.active == "QVGA" and module.penalties["VGA"] == pytest.approx(0.3)
    assert module.penalties["QVGA"] == 0.0  # never left for neglect


def test_penalty_stays_below_one() -> None:
    settings = TCM(initial="VGA", penalty=0.8, penalty_step=0.5, learning="none")
    module = TaskConfiguringModule(scenarios(), settings)
    module.observe("deadline", 0.015)
    decision = module.evaluate()  # VGA's deadline fails; QVGA rates 2·0.2 − 0.5 < 0: none usable
    assert decision.events[0].reason == "neglected" and decision.active == "QQVGA"  # the closest
    assert decision.events[0].penalty == MAX_PENALTY < 1.0
    assert module.penalties["VGA"] == MAX_PENALTY


def test_steps_back_up_after_the_load_drops_thanks_to_the_decay() -> None:
    loads = [1] * 30 + [2] * 300 + [1] * 300
    decayed = tcm("VGA")
    decisions = Plant(seed=3).run(decayed, loads)
    assert decisions[29].active == "VGA" and decisions[329].active == "QVGA"
    assert decisions[-1].active == "VGA"
    back = [e for e in events(decisions[330:]) if e.current == "VGA"]
    assert back and back[0].reason == "recovered"
    # The same run without decay: the futile tries at load 2 left VGA so penalised that it
    # never rates above QVGA again.
    frozen = tcm("VGA", decay_evaluations=None)
    decisions = Plant(seed=3).run(frozen, loads)
    assert frozen.penalties["VGA"] >= 0.3 - 1e-9
    assert decisions[-1].active == "QVGA"


def test_follows_the_load_down_and_up_through_all_scenarios() -> None:
    loads = [1] * 30 + [3] * 100 + [5] * 100 + [1] * 500
    module = tcm("VGA")
    decisions = Plant(seed=4).run(module, loads)
    assert decisions[129].active in ("QVGA", "QQVGA")  # load 3: QVGA (0.0144 s) suffices
    assert decisions[229].active == "QQVGA"  # load 5: only QQVGA (0.016 s) holds
    assert decisions[-1].active == "VGA"


# -- no oscillation ---------------------------------------------------------------------------


def baseline_switches(deadlines: Sequence[float]) -> int:
    switcher = ThresholdSwitcher(scenarios(), "VGA")
    for value in deadlines:
        switcher.observe("deadline", value)
        switcher.evaluate()
    return switcher.switches


def test_no_oscillation_when_the_measure_hovers_exactly_at_a_bound() -> None:
    rng = np.random.default_rng(5)
    hovering = (0.012 + rng.normal(0, 0.0003, 5000)).tolist()
    module = tcm("VGA")
    feed(module, hovering)
    naive = baseline_switches(hovering)
    assert module.switches == 1 and module.active == "QVGA"
    assert naive > 1000
    # Hovering so that P(deadline ≤ bound) itself hovers around the policy's 0.95.
    near = (0.011 + rng.normal(0, 0.0006, 5000)).tolist()
    module = tcm("VGA")
    feed(module, near)
    naive = baseline_switches(near)
    assert module.switches < naive / 10
    assert module.switches <= 12


def test_no_oscillation_in_the_feedback_trap() -> None:
    """At load 2 VGA misses its deadline, but while QVGA runs VGA's policy looks met."""
    loads = [1] * 30 + [2] * 1000
    module = tcm("VGA")
    decisions = Plant(seed=6).run(module, loads)
    naive = Plant(seed=6).baseline(loads)
    assert naive.switches > 5000  # flips at almost every sample
    # About one try of VGA per decay_evaluations (100) evaluations, two switches each.
    assert module.switches <= 30
    assert not any(d.alarms for d in decisions)
    assert sum(d.active == "QVGA" for d in decisions[30:]) > 0.95 * 1000


# -- alarms and requirements ------------------------------------------------------------------------


def test_alarm_when_no_scenario_meets_the_requirements() -> None:
    raised: list[Alarm] = []
    seen: list[ScenarioEvent] = []
    module = tcm("VGA", on_alarm=raised.append, on_event=seen.append)
    decisions = feed(module, [0.008] * 100 + [0.05] * 100 + [0.010] * 200)
    assert [a.raised for a in raised] == [True, False]
    assert 100 < raised[0].time / 0.5 < 110 and raised[0].unmet
    alarmed = [d for d in decisions if d.alarms]
    assert [d.alarms for d in alarmed] == [(raised[0],), (raised[1],)]
    # Degraded to the scenario closest to its policies while no scenario held, then came back.
    assert actives(decisions) == ["VGA", "QQVGA", "VGA"]
    assert seen[0].reason == "neglected" and "closest" in seen[0].detail
    assert seen[1].reason == "recovered"
    assert not module.alarm_active


def test_changed_requirements_switch_immediately() -> None:
    module = tcm("QQVGA")
    for _ in range(20):
        module.observe("deadline", 0.010)
    assert module.evaluate().active == "QQVGA"  # VGA would recover only after the dwell
    decision = module.set_requirements([Require(measure="deadline", upper=0.015)])
    assert decision.active == "VGA"
    assert [(e.previous, e.reason) for e in decision.events] == [("QQVGA", "requirements")]
    assert module.penalties["QQVGA"] == 0.0  # a change of QR is no neglect
    qqvga = decision.evaluations["QQVGA"]
    assert not qqvga.usable and not qqvga.conditions[-1].compatible  # tolerates up to 0.020 s
    assert module.requirements == (Require(measure="deadline", upper=0.015),)
    # Stays while the requirement and the policies hold.
    assert actives(feed(module, [0.010] * 200)) == ["VGA"]


def test_requirements_no_scenario_can_promise_raise_an_alarm() -> None:
    module = TaskConfiguringModule(scenarios(cpu=True), TCM(initial="VGA", learning="none"))
    for _ in range(50):
        module.observe_many({"deadline": 0.008, "cpu": 0.25})
    module.evaluate()
    decision = module.set_requirements([Require(measure="cpu", upper=0.30)])  # every scenario allows more
    assert [a.raised for a in decision.alarms] == [True] and not decision.events
    later = [module.evaluate() for _ in range(5)]
    assert all(d.active == "VGA" and not d.events for d in later)  # degrading would not help: no switch
    assert module.penalties["VGA"] == 0.0
    decision = module.set_requirements([])
    assert [a.raised for a in decision.alarms] == [False]


def test_a_new_requirement_is_judged_on_the_samples_measured_after_it() -> None:
    """D201: a recognition's reliability was 0 while nothing was in view; a client then asks for
    reliability ≥ 0.5: the old zeros do not fail it (no switch, no alarm), the new samples do judge it."""
    module = tcm("VGA")
    for _ in range(50):
        module.observe_many({"deadline": 0.008, "reliability": 0.0})
    decision = module.set_requirements([Require(measure="reliability", lower=0.5, probability=0.9)])
    assert decision.active == "VGA" and not decision.events and not any(a.raised for a in decision.alarms)
    requirement = decision.evaluations["VGA"].conditions[-1]
    assert requirement.kind == "requirement" and requirement.met is None  # nothing measured under it yet
    for _ in range(10):
        module.observe_many({"deadline": 0.008, "reliability": 0.8})
    assert module.evaluate().evaluations["VGA"].conditions[-1].met is True
    for _ in range(50):
        module.observe_many({"deadline": 0.008, "reliability": 0.1})
    assert module.evaluate().evaluations["VGA"].conditions[-1].met is False  # and it fails on its own samples


def test_a_measured_requirement_counts_in_f_ev() -> None:
    module = tcm("VGA", requirements=[Require(measure="reliability", lower=0.8, probability=0.9)])
    for _ in range(50):
        module.observe_many({"deadline": 0.008, "reliability": 0.9})
    decision = module.evaluate()
    assert decision.evaluations["VGA"].accepted == 2 and decision.evaluations["VGA"].suit == 1.0
    for _ in range(10):
        module.observe("reliability", 0.5)  # 10 of 50 below: P = 0.8 < 0.9
    decision = module.evaluate()
    vga = decision.evaluations["VGA"]
    assert (vga.accepted, vga.known, vga.suit) == (1, 2, 0.5)
    assert vga.fev == 0.5 and vga.state == pytest.approx(3 * 0.5 - 0.5)
    assert [a.raised for a in decision.alarms] == [True] and not decision.events


def test_combined_measure_is_evaluated_on_the_convolution() -> None:
    total = Scenario(
        name="only", profile="p", policies=(Policy(measure="total", upper=0.015, probability=0.75, window=10),)
    )
    module = TaskConfiguringModule([total], combined={"total": ("processing", "transport")})
    assert module.evaluate().evaluations["only"].known == 0  # a component without samples: unknown
    for value in (0.005, 0.010):
        module.observe("processing", value)
        module.observe("transport", value)
    condition = module.evaluate().evaluations["only"].conditions[0]
    assert condition.probability == pytest.approx(0.75) and condition.met is True  # 0.01: .25, 0.015: .5


def test_from_service_uses_the_configured_scenarios() -> None:
    lab = ckmconf.load(REPO / "configs" / "usecase" / "lab.xml")
    found = lab.service("RGBDCamera.RGBRecog")
    assert found is not None
    module = TaskConfiguringModule.from_service(found[1])
    assert module.active == "VGA" and module.learner("VGA") is not None
    for _ in range(50):
        module.observe_many({"deadline": 0.008, "cpu": 0.30})
    assert module.evaluate().active == "VGA"
    for _ in range(10):
        module.observe_many({"deadline": 0.008, "cpu": 0.40})  # VGA allows 0.36 with P ≥ 0.9
    decision = module.evaluate()
    assert decision.active == "QVGA" and decision.events[0].reason == "neglected"


# -- learning (eq. 4.10) ------------------------------------------------------------------------------


def test_learner_separates_recorded_evaluations() -> None:
    learner = ScenarioLearner(c=1.0)
    assert not learner.trained and learner.decision((1.0, 0.5)) is None and learner.confidence((1.0, 0.5)) == 1.0
    rng = np.random.default_rng(8)
    for margin in rng.uniform(0.35, 0.7, 10):
        learner.record((1.0, float(margin)), True)
    assert not learner.trained  # one label only
    for margin in rng.uniform(0.0, 0.2, 10):
        learner.record((1.0, float(margin)), False)
    assert learner.trained
    high, low = learner.decision((1.0, 0.6)), learner.decision((1.0, 0.1))
    assert high is not None and low is not None and high > 0 > low
    assert learner.confidence((1.0, 0.9)) == 1.0 and learner.confidence((1.0, -0.2)) == 0.0
    assert 0.0 <= learner.confidence((1.0, 0.27)) <= 1.0
    assert learner.confidence(None) == 1.0
    with pytest.raises(ValueError):
        ScenarioLearner(c=0.0)


def test_svm_learns_when_a_higher_resolution_will_hold() -> None:
    loads = [1] * 30 + [2] * 300 + [1] * 100 + [2] * 300 + [1] * 100
    learned, plain = tcm("VGA", "svm"), tcm("VGA", "none")
    with_svm = Plant(seed=9).run(learned, loads)
    without = Plant(seed=9).run(plain, loads)
    learner = learned.learner("VGA")
    assert learner is not None and learner.trained and plain.learner("VGA") is None
    labels = [label for _, label in learner.records]
    assert True in labels and False in labels
    # At load 2, VGA measured through QVGA looks fine, but the model expects it to fail...
    features = with_svm[700].evaluations["VGA"].features
    assert with_svm[700].active == "QVGA" and features is not None
    decision = learner.decision(features)
    assert decision is not None and decision < 0
    assert with_svm[700].evaluations["VGA"].confidence < 0.5 and not with_svm[700].evaluations["VGA"].usable
    # ... and at load 1 to hold: the learned run comes back to VGA after each low phase.
    assert with_svm[429].active == "VGA" and with_svm[-1].active == "VGA"
    # So it wastes fewer switches on futile tries than the configured weights alone.
    second_high = slice(430, 730)
    assert len(events(with_svm[second_high])) < len(events(without[second_high]))
    assert learned.switches < plain.switches


def test_a_preferred_scenario_is_taken_without_penalty_and_left_when_neglected() -> None:
    module = tcm(initial="QQVGA")
    decision = module.prefer("VGA")
    assert decision.active == "VGA" and decision.events[0].reason == "requirements"
    assert module.penalties == {"VGA": 0.0, "QVGA": 0.0, "QQVGA": 0.0}
    assert module.prefer("VGA").events == ()  # already active: nothing happens
    decisions = feed(module, [0.015] * 60)  # too slow for VGA, fine for QVGA
    assert actives(decisions) == ["QVGA"]
    assert decisions[0].events[0].previous == "VGA" and decisions[0].events[0].reason == "neglected"
    assert module.penalties["VGA"] > 0.0
    with pytest.raises(ValueError, match="no scenario 'HD'"):
        module.prefer("HD")


def test_a_preferred_scenario_is_a_ceiling() -> None:
    module = tcm(initial="VGA")
    assert module.prefer("QVGA").active == "QVGA"
    decisions = feed(module, [0.005] * 200)  # VGA would hold and be recovered without the preference
    assert actives(decisions) == ["QVGA"]
    assert module.prefer("VGA").active == "VGA"


def test_threshold_selector_runs_the_baseline_behind_the_tcm_interface() -> None:
    events: list[ScenarioEvent] = []
    alarms: list[Alarm] = []
    selector = ThresholdSelector(scenarios(), TCM(initial="VGA"), on_event=events.append, on_alarm=alarms.append)
    for value, expected in [(0.010, "VGA"), (0.015, "QVGA"), (0.011, "VGA"), (0.019, "QQVGA"), (0.030, "QQVGA")]:
        selector.observe("deadline", value)
        assert selector.evaluate(1.0).active == expected
    assert selector.switches == 3 and [e.current for e in events] == ["QVGA", "VGA", "QQVGA"]
    assert [a.raised for a in alarms] == [True]  # 0.030 is outside every scenario's bounds
    selector.observe("deadline", 0.005)
    assert selector.evaluate(2.0).active == "VGA" and [a.raised for a in alarms] == [True, False]
    assert selector.penalties == {"VGA": 0.0, "QVGA": 0.0, "QQVGA": 0.0}
    assert selector.prefer("QVGA").active == "QVGA"


def test_alarm_after_waits_for_persistent_failure() -> None:
    immediate = tcm("VGA")
    patient = tcm("VGA", alarm_after=3)
    for module in (immediate, patient):
        feed(module, [0.008] * 60)
    spike = [0.05] * 3 + [0.008] * 200  # a short burst: every scenario fails for a few evaluations
    assert any(d.alarms for d in feed(immediate, spike))
    assert not any(d.alarms for d in feed(patient, spike[:2]))  # two evaluations: not yet
    sustained = feed(patient, [0.05] * 200)
    raised = [a for d in sustained for a in d.alarms if a.raised]
    assert len(raised) == 1
    # An alarm from requirements nobody can promise does not wait.
    module = tcm("VGA", alarm_after=5)
    feed(module, [0.008] * 60)
    assert [a.raised for a in module.set_requirements([Require(measure="deadline", upper=0.001)]).alarms] == [True]
