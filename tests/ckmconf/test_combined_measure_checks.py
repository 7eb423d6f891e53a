"""<CombinedMeasure> (eq. 4.5): the schema and the semantic checks of a combined quality measure,
each problem located at its element (FILE:LINE:COL)."""

from __future__ import annotations

import pytest

from ckmconf.loader import load_bytes

TEMPLATE = """<?xml version="1.0" encoding="UTF-8"?>
<System xmlns="urn:ckm:1" version="1.0" name="vision">
  <Topic name="/image" type="bytes"/>
  <Node name="pc" kind="service"/>
  <SmartResource name="cam" node="pc">
    <Plugin name="grab" kind="camera-acquisition"/>
    <Profile name="only"><Use plugin="grab"/></Profile>
    <Service name="recog">
      <Input name="image" topic="/image"/>
      <QualityMeasure name="processing" kind="qos" domain="temporal" source="latency" unit="s"/>
      <QualityMeasure name="age" kind="qos" domain="temporal" source="deadline" unit="s"/>
{combined}
      <Scenario name="quick" profile="only">
        <Policy measure="{policy}" upper="0.2" probability="0.9"/>
      </Scenario>
      <TCM period="1"/>
    </Service>
  </SmartResource>
</System>
"""


def problems(combined: str, policy: str = "response") -> list[str]:
    text = TEMPLATE.format(combined=combined, policy=policy)
    result = load_bytes(text.encode(), "combined.xml", strict=False)
    return [f"{e.line}:{e.column}: {e.message}" for e in result.errors]


def test_a_combined_measure_of_two_quality_measures_is_valid_and_policies_may_bound_it() -> None:
    text = TEMPLATE.format(
        combined='      <CombinedMeasure name="response" measures="processing age" resolution="0.001" unit="s"/>',
        policy="response",
    )
    system = load_bytes(text.encode(), "combined.xml")
    (resource,) = system.resources
    (service,) = resource.services
    assert service.combinations() == {"response": ("processing", "age")}
    assert service.combined[0].resolution == 0.001 and service.combined[0].unit == "s"
    assert service.measure_names() == ["processing", "age", "response"]


@pytest.mark.parametrize(
    ("combined", "expected"),
    [
        (
            '<CombinedMeasure name="response" measures="processing transport"/>',
            ["12:40: quality measure 'transport' does not exist in service cam.recog (defined: age, processing)"],
        ),
        (
            '<CombinedMeasure name="response" measures="processing processing"/>',
            ["12:40: measure 'processing' is summed twice (eq. 4.5 needs independent measures)"],
        ),
        (
            '<CombinedMeasure name="age" measures="processing age"/>',
            [
                "12:24: service cam.recog already has a quality measure 'age'",
                "14:17: quality measure 'response' does not exist in service cam.recog (defined: age, processing)",
            ],
        ),
        (
            '<CombinedMeasure name="response" measures="processing age"/>\n'
            '<CombinedMeasure name="total" measures="response age"/>',
            ["13:31: 'response' is a combined measure: sum its quality measures instead"],
        ),
        (
            '<CombinedMeasure name="response" measures="processing age"/>\n'
            '<CombinedMeasure name="response" measures="age processing"/>',
            ["13:18: duplicate combined measure 'response' in service cam.recog (first at line 12)"],
        ),
    ],
)
def test_bad_combined_measures_are_located(combined: str, expected: list[str]) -> None:
    assert problems("      " + combined) == expected


def test_a_policy_on_an_unknown_measure_lists_the_combined_ones_too() -> None:
    found = problems('      <CombinedMeasure name="response" measures="processing age"/>', policy="respnse")
    assert found == ["14:17: quality measure 'respnse' does not exist in service cam.recog; did you mean 'response'?"]


def test_a_combined_measure_sums_at_least_two_measures() -> None:
    (problem,) = problems('      <CombinedMeasure name="response" measures="processing"/>')
    assert problem == "12:40: a combined measure sums at least two quality measures (eq. 4.5)"
