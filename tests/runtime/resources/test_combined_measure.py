"""A combined quality measure configured in the XSD (<CombinedMeasure>, eq. 4.5) and used by the TCM:
configs/examples/combined_measure.xml's ``staleness`` = ``age`` + ``period``, evaluated on the
convolution of both windows; the TCM leaves the fine scenario when the sum's policy fails although
each component alone looks harmless; the threshold baseline sums the latest samples; and the
example's own service, on real plugins and synthetic frames, publishes the combined measure."""

from __future__ import annotations

import random
from typing import Any

import numpy as np
import pytest

from ckmconf.loader import load
from ckmconf.model.resources import Service, SmartResource
from runtime.network import TopicQoS, Transport
from runtime.resources.quality import combined_distribution
from runtime.resources.resource import SmartResourceRuntime
from runtime.resources.tcm import TaskConfiguringModule, ThresholdSelector
from tests.conftest import CONFIGS
from tests.runtime.resources.test_service_api import until

EXAMPLE = CONFIGS / "examples" / "combined_measure.xml"


@pytest.fixture(scope="module")
def resource() -> SmartResource:
    record = load(EXAMPLE).resource("Camera")
    assert record is not None
    return record


@pytest.fixture
def service(resource: SmartResource) -> Service:
    return resource.services[0]


def feed(tcm: TaskConfiguringModule | ThresholdSelector, ages: Any, periods: Any) -> None:
    for age, period in zip(ages, periods, strict=True):
        tcm.observe("age", float(age))
        tcm.observe("period", float(period))


def test_the_tcm_of_a_service_takes_its_combined_measures(service: Service) -> None:
    tcm = TaskConfiguringModule.from_service(service)
    assert tcm.combined == {"staleness": ("age", "period")}
    assert tcm.resolutions == {"staleness": 0.001}


def test_the_tcm_acts_on_the_convolution_of_the_components(service: Service) -> None:
    tcm = TaskConfiguringModule.from_service(service)
    rng = np.random.default_rng(4)
    feed(tcm, rng.uniform(0.02, 0.05, 40), rng.uniform(0.045, 0.055, 40))  # sum ≤ 0.105 < 0.12
    decision = tcm.evaluate(1.0)
    assert decision.active == "fine" and not decision.events
    (condition,) = decision.evaluations["fine"].conditions
    assert (condition.measure, condition.probability) == ("staleness", 1.0)

    # A slower processing and a jittery period: each stays below 0.08 s, their sum often exceeds 0.12 s.
    ages, periods = rng.uniform(0.03, 0.075, 40), rng.uniform(0.045, 0.08, 40)
    feed(tcm, ages, periods)
    expected = combined_distribution([ages, periods], 0.001).probability_within(None, 0.12)
    assert 0.3 < expected < 0.9  # the policy asks 0.9
    decision = tcm.evaluate(2.0)
    (condition,) = decision.evaluations["fine"].conditions
    assert condition.probability == pytest.approx(expected)
    (event,) = decision.events
    assert (event.previous, event.current, event.reason) == ("fine", "coarse", "neglected")
    assert "staleness" in event.detail and tcm.penalties["fine"] > 0


def test_the_threshold_baseline_sums_the_latest_samples(service: Service) -> None:
    baseline = ThresholdSelector(service.scenarios, service.tcm, combined=service.combinations())
    feed(baseline, [0.05], [0.05])
    assert baseline.evaluate(1.0).active == "fine"
    feed(baseline, [0.07], [0.06])  # 0.13 > 0.12
    assert baseline.evaluate(2.0).active == "coarse"
    blind = ThresholdSelector(service.scenarios, service.tcm)  # without the combination the bound is never seen
    feed(blind, [0.07], [0.06])
    assert blind.evaluate(1.0).active == "fine"


def test_the_example_service_publishes_its_combined_measure(
    resource: SmartResource, pair: tuple[Transport, Transport]
) -> None:
    """The example's own plugins (acquisition, resize, ORB recognition) on synthetic VGA frames."""
    from ckm_lab.scenes import USECASE_MODEL, load_catalog, render_rgb_scene

    names = [o.name for o in load_catalog(str(USECASE_MODEL)).objects]
    rng = random.Random(3)
    frames = [render_rgb_scene(rng.sample(names, 2), seed=i).image for i in range(3)]
    counter = iter(range(10**9))
    server, remote = pair
    quality: list[dict[str, Any]] = []
    remote.subscribe(
        TopicQoS("/Camera/Recog/quality", "ckm/service-quality", history=64), lambda s: quality.append(s.value)
    )
    runtime = SmartResourceRuntime(resource, server, sources={"grab": lambda: frames[next(counter) % 3]})

    def combined() -> list[dict[str, Any]]:
        return [m for m in quality if m.get("type") == "quality" and "staleness" in m.get("probabilities", {})]

    with runtime:
        assert until(lambda: len(combined()) >= 2, timeout=30)
    message = combined()[-1]
    measures = message["measures"]
    assert measures["staleness"] == pytest.approx(measures["age"] + measures["period"])
    assert 0.0 <= message["probabilities"]["staleness"] <= 1.0
    assert message["scenario"] in ("fine", "coarse")


def test_a_requirement_on_the_combined_measure_selects_the_scenario_that_can_promise_it(service: Service) -> None:
    """A client's QR on ``staleness`` (eq. 4.9) is evaluated on the convolution too: only the fine
    scenario's policy lies within 0.2 s, so a requirement of 0.2 s keeps the TCM there and one of
    0.05 s, which the measured sum cannot meet, raises an alarm."""
    from runtime.resources.api import Bounds

    tcm = TaskConfiguringModule.from_service(service, requirements=[Bounds("staleness", upper=0.2, probability=0.9)])
    rng = np.random.default_rng(9)
    feed(tcm, rng.uniform(0.02, 0.04, 40), rng.uniform(0.045, 0.055, 40))
    decision = tcm.evaluate(1.0)
    assert decision.active == "fine" and not decision.alarms
    requirement = decision.evaluations["fine"].conditions[-1]
    assert (requirement.kind, requirement.measure, requirement.probability) == ("requirement", "staleness", 1.0)
    assert decision.evaluations["coarse"].conditions[-1].compatible is False  # its 0.4 s bound exceeds 0.2 s
    decision = tcm.set_requirements([Bounds("staleness", upper=0.05, probability=0.9)], 2.0)
    assert any(alarm.raised for alarm in decision.alarms)


def test_the_quality_message_carries_the_sum_once_every_component_has_a_value(
    service: Service, pair: tuple[Transport, Transport]
) -> None:
    from runtime.resources.instance import Instance

    sent: list[tuple[str, dict[str, Any]]] = []
    instance = Instance("Camera", service, "", pair[0], lambda kind, message: sent.append((kind, message)))
    instance.observe("deadline", 0.03)  # the kernel's deadline is the service's "age"
    instance.tick(1.0)
    assert sent[-1][1]["measures"] == {"age": 0.03}
    instance.observe("rate", 0.05)  # and its rate the "period"
    instance.tick(2.0)
    assert sent[-1][1]["measures"] == pytest.approx({"age": 0.03, "period": 0.05, "staleness": 0.08})
    assert sent[-1][1]["probabilities"] == {"staleness": 1.0}


def test_a_client_may_require_a_combined_measure_and_discovers_it(resource: SmartResource, service: Service) -> None:
    from runtime.resources.api import describe, parse_request

    combined = service.combined[0].name
    request, errors = parse_request(
        service,
        {"op": "connect", "client": "c1", "id": 1, "requirements": [{"measure": combined, "upper": 1.0}]},
    )
    assert errors == [] and request is not None
    assert [r.measure for r in request.requirements or ()] == [combined]
    entry = describe(resource, service, "node")
    assert entry["combined"] == [
        {"name": combined, "measures": list(service.combined[0].measures), "unit": service.combined[0].unit}
    ]
